//! End-to-end sessions in virtual time: the printer's protocol logic drives the simulated unit.

use mmu_protocol::{ButtonCode, ErrorCode, ProgressCode, Request, RequestCode, ResultCode};
use mmu_sim::{Decision, Operator, Outcome, Printer, PrinterEvent, PrinterOptions, Sim, SimLink, SimOptions};

/// Records what the person at the printer saw; gives up on any error it is asked about, except
/// the eject dialog, where it pulls the filament out and presses Continue.
#[derive(Default)]
struct Watcher {
    events: Vec<PrinterEvent>,
}

impl Operator<SimLink> for Watcher {
    fn event(&mut self, _link: &mut SimLink, event: &PrinterEvent) {
        if !matches!(
            event,
            PrinterEvent::Sent(_) | PrinterEvent::Received(_) | PrinterEvent::Heartbeat(_)
        ) {
            self.events.push(event.clone());
        }
    }

    fn decide(&mut self, link: &mut SimLink, request: Request, error: ErrorCode) -> Decision {
        if error == ErrorCode::FILAMENT_EJECTED {
            link.sim_mut()
                .model_mut()
                .remove_filament(usize::from(request.value));
            Decision::Press(ButtonCode::MIDDLE)
        } else {
            Decision::GiveUp
        }
    }
}

impl Watcher {
    fn progress(&self) -> Vec<ProgressCode> {
        let mut seen = Vec::new();
        for event in &self.events {
            if let PrinterEvent::Progress(_, code) = event
                && seen.last() != Some(code)
            {
                seen.push(*code);
            }
        }
        seen
    }
}

fn printer() -> Printer<SimLink> {
    let sim = Sim::new(SimOptions::default()).unwrap();
    Printer::new(SimLink::new(sim), PrinterOptions::default())
}

#[test]
fn handshake_then_tool_changes_load_to_the_nozzle() {
    let mut printer = printer();
    let mut op = Watcher::default();
    let first = printer.connect(&mut op).unwrap();
    assert_eq!((first.code, first.value), (RequestCode::Reset, 0));
    for slot in [1u8, 2, 0] {
        let outcome = printer
            .command(&mut op, Request::new(RequestCode::Tool, slot))
            .unwrap();
        assert_eq!(outcome, Outcome::Finished(ResultCode::OK), "{:?}", op.events);
        let model = printer.link().sim().model();
        assert_eq!(model.loaded_slot(), Some(usize::from(slot)));
        assert_ne!(model.fsensor_state(), 0);
    }
    eprintln!("{:?}", op.progress());
}
