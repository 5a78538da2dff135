//! Filament left and lane health through the printer's own requests (`R`, as `M707` sends it),
//! while the simulated printer prints, and across a power cut (`SimFault::PowerLoss`).

use mmu_firmware::registers::{LEFT, LOAD_DISTANCE, SUCCESS, SUCCESS_OF};
use mmu_protocol::{ErrorCode, Request, RequestCode, ResultCode};
use mmu_sim::{
    Decision, Operator, Outcome, Printer, PrinterEvent, PrinterOptions, Sim, SimFault, SimLink, SimOptions,
};

/// Gives up on any error: none is expected.
struct Quiet;

impl Operator<SimLink> for Quiet {
    fn event(&mut self, _link: &mut SimLink, _event: &PrinterEvent) {}

    fn decide(&mut self, _link: &mut SimLink, _request: Request, _error: ErrorCode) -> Decision {
        Decision::GiveUp
    }
}

fn read(printer: &mut Printer<SimLink>, address: u8) -> u16 {
    let answer = printer
        .request(&mut Quiet, Request::new(RequestCode::Read, address))
        .unwrap();
    answer.param_value.unwrap()
}

/// The filament the model's slot has given off its spool since `tail`, m.
fn pulled_m(printer: &Printer<SimLink>, slot: usize, tail: f32) -> f32 {
    (printer.link().sim().model().tail_mm(slot).unwrap() - tail) / 1000.0
}

#[test]
fn filament_left_counts_the_print_and_survives_a_power_cut() {
    let sim = Sim::new(SimOptions {
        print_mm_s: 20.0,
        ..SimOptions::default()
    })
    .unwrap();
    let mut printer = Printer::new(SimLink::new(sim), PrinterOptions::default());
    printer.connect(&mut Quiet).unwrap();
    let tail = printer.link().sim().model().tail_mm(0).unwrap();
    assert_eq!(read(&mut printer, LEFT), 330);
    let change = printer
        .command(&mut Quiet, Request::new(RequestCode::Tool, 0))
        .unwrap();
    assert_eq!(change, Outcome::Finished(ResultCode::OK));
    // 10 minutes at 20 mm/s: 12 m.
    assert_eq!(printer.print(&mut Quiet, 600_000).unwrap(), None);
    let truth = 330.0 - pulled_m(&printer, 0, tail);
    assert!(truth < 319.0, "{truth}");
    let left = read(&mut printer, LEFT);
    assert!(
        (f32::from(left) - truth).abs() <= 0.5,
        "left {left} m, truth {truth} m"
    );
    // The power goes; the printer connects again.
    printer
        .link_mut()
        .sim_mut()
        .inject(SimFault::PowerLoss { off_ms: 1_000 });
    printer.connect(&mut Quiet).unwrap();
    let truth = 330.0 - pulled_m(&printer, 0, tail);
    let left = read(&mut printer, LEFT);
    // Kept in whole metres, restored to the middle of the metre: within a metre.
    assert!(
        (f32::from(left) - truth).abs() <= 1.0,
        "left {left} m, truth {truth} m"
    );
    // The tool change's health figures too.
    assert_eq!(read(&mut printer, SUCCESS_OF), 1);
    assert_eq!(read(&mut printer, SUCCESS), 100);
    let distance = read(&mut printer, LOAD_DISTANCE);
    assert!(distance.abs_diff(360) <= 15, "{distance} mm");
}
