use mmu_model::Fault;
use mmu_protocol::{ButtonCode, ErrorCode, Request, RequestCode};
use mmu_sim::{Decision, Link, Operator, Personality, Printer, PrinterEvent, PrinterOptions, Sim, SimFault, SimLink, SimOptions, EventKind};

#[derive(Default)]
struct W { n: u32 }
impl Operator<SimLink> for W {
    fn event(&mut self, link: &mut SimLink, event: &PrinterEvent) {
        match event {
            PrinterEvent::Heartbeat(_) | PrinterEvent::Received(_) => {}
            PrinterEvent::Sent(r) if matches!(r.code, RequestCode::Query | RequestCode::Read | RequestCode::FilamentSensor) => {}
            e => { let m = link.sim().model(); println!("{:>8} {e:?} tip1 {:?} tail1 {:?} fs {}", link.now_ms(), m.tip_mm(1), m.tail_mm(1), m.fsensor_state()); }
        }
        for e in link.sim_mut().take_events() { if let EventKind::Extruder{..} = e.what { println!("{:>8}   {:?}", e.t_ms, e.what); } }
    }
    fn decide(&mut self, link: &mut SimLink, request: Request, error: ErrorCode) -> Decision {
        self.n += 1; if self.n > 6 { return Decision::GiveUp; }
        if self.n == 4 { let k = SimFault::Model(Fault::SpoolRunout { slot: 1 }).kind(); println!("fix: {}", link.sim_mut().clear(k)); }
        if error == ErrorCode::FILAMENT_EJECTED { link.sim_mut().model_mut().remove_filament(request.value.into()); }
        Decision::Press(ButtonCode::MIDDLE)
    }
}

#[test]
fn dbg() {
    let p = Personality::Buddy64;
    let sim = Sim::new(SimOptions { printer: p, ..SimOptions::default() }).unwrap();
    let mut printer = Printer::new(SimLink::new(sim), PrinterOptions::of(p));
    let mut op = W::default();
    printer.connect(&mut op).unwrap();
    println!("{:?}", printer.command(&mut op, Request::new(RequestCode::Tool, 1)));
    printer.print(&mut op, 10_000).unwrap();
    printer.link_mut().sim_mut().inject(SimFault::Model(Fault::SpoolRunout { slot: 1 }));
    println!("{:?}", printer.print(&mut op, 200_000));
    let sim = printer.link_mut().sim_mut();
    sim.clear(SimFault::Model(Fault::SpoolRunout { slot: 1 }).kind());
    sim.model_mut().insert_filament(1, -15.0);
    op.n = 0;
    println!("---- T1 again");
    println!("{:?}", printer.command(&mut op, Request::new(RequestCode::Tool, 1)));
    let d: u64 = std::env::var("D").unwrap().parse().unwrap();
    if d > 0 { printer.print(&mut op, d).unwrap(); }
    println!("inject at {}", printer.link().now_ms());
    printer.link_mut().sim_mut().inject(SimFault::Model(Fault::SpoolRunout { slot: 1 }));
    println!("{:?}", printer.print(&mut op, 200_000));
}
