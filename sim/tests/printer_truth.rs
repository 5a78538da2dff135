//! Issue 12 end to end: the printer's protocol logic (as Prusa's `protocol_logic.cpp` and
//! `mmu2_mk4.cpp` play it: automatic Retry three times, then the screen) against the simulated
//! unit.

use mmu_protocol::{ButtonCode, ErrorCode, ParamCode, Request, RequestCode, ResultCode};
use mmu_sim::{Decision, Operator, Outcome, Printer, PrinterEvent, PrinterOptions, Sim, SimLink, SimOptions};

/// The person at the printer: on the screen, pulls the filament out of the hub (back to the park
/// position of slot 0) and presses Retry.
#[derive(Default)]
struct Fixer {
    events: Vec<PrinterEvent>,
    screens: Vec<ErrorCode>,
}

impl Operator<SimLink> for Fixer {
    fn event(&mut self, _link: &mut SimLink, event: &PrinterEvent) {
        self.events.push(event.clone());
    }

    fn decide(&mut self, link: &mut SimLink, _request: Request, error: ErrorCode) -> Decision {
        self.screens.push(error);
        link.sim_mut().model_mut().insert_filament(0, -15.0);
        link.idle(100);
        Decision::Press(ButtonCode::MIDDLE)
    }
}

/// #10: filament in the hub at power-up (`X0 E8008`), then the printer's `T1`: no endless `R`;
/// the printer retries three times, shows UNLOAD MANUALLY, the user fixes it and presses Retry,
/// and the tool change runs.
#[test]
fn start_up_error_then_tool_change_reaches_the_screen_and_its_retry_works() {
    let mut sim = Sim::new(SimOptions::default()).unwrap();
    sim.model_mut().insert_filament(0, 30.0);
    let mut link = SimLink::new(sim);
    link.idle(200);
    let mut printer = Printer::new(link, PrinterOptions::default());
    let mut op = Fixer::default();
    let first = printer.connect(&mut op).unwrap();
    assert_eq!(
        (first.code, first.param, first.param_value),
        (
            RequestCode::Reset,
            ParamCode::Error,
            Some(ErrorCode::FINDA_VS_EEPROM_DISREPANCY.0)
        )
    );
    let tool = Request::new(RequestCode::Tool, 1);
    let outcome = printer.command(&mut op, tool).unwrap();
    assert_eq!(
        outcome,
        Outcome::Finished(ResultCode::OK),
        "screens {:?}",
        op.screens
    );
    assert_eq!(op.screens, [ErrorCode::FINDA_VS_EEPROM_DISREPANCY]);
    let sent = op
        .events
        .iter()
        .filter(|e| matches!(e, PrinterEvent::Sent(r) if *r == tool))
        .count();
    assert_eq!(sent, 1, "T1 sent once");
    assert_eq!(printer.link().sim().model().loaded_slot(), Some(1));
}
