//! Any Prusa printer finds its version with default settings (issue 12, "Any Prusa printer, no
//! configuration"): the printer's handshake (as `protocol_logic.cpp` `ProcessVersionResponse`
//! plays it: the same `S<n>` again on a mismatch, six mismatches per handshake) against the
//! simulated unit, for each revision a printer family expects (Buddy >= 6.5.3 3.0.4, Buddy 6.4 3.0.3,
//! Buddy 5.2 / MK3S 3.13.3 3.0.2, MK3S 3.13.2 3.0.1, MK3S 3.13.0 3.0.0).

use mmu_protocol::{ErrorCode, Request, RequestCode};
use mmu_sim::{Decision, Operator, Printer, PrinterEvent, PrinterOptions, Sim, SimLink, SimOptions};

#[derive(Default)]
struct Watcher {
    events: Vec<PrinterEvent>,
}

impl Operator<SimLink> for Watcher {
    fn event(&mut self, _link: &mut SimLink, event: &PrinterEvent) {
        self.events.push(event.clone());
    }

    fn decide(&mut self, _link: &mut SimLink, _request: Request, _error: ErrorCode) -> Decision {
        Decision::GiveUp
    }
}

#[test]
fn printers_expecting_3_0_0_to_3_0_4_connect_with_default_settings() {
    for revision in [4u8, 3, 2, 1, 0] {
        let mut link = SimLink::new(Sim::new(SimOptions::default()).unwrap());
        link.idle(200);
        let options = PrinterOptions {
            version: (3, 0, revision),
            ..PrinterOptions::default()
        };
        let mut printer = Printer::new(link, options);
        let mut op = Watcher::default();
        let first = printer.connect(&mut op);
        assert!(first.is_ok(), "3.0.{revision}: {first:?}");
        let s2_sent = op
            .events
            .iter()
            .filter(|e| matches!(e, PrinterEvent::Sent(r) if r.code == RequestCode::Version && r.value == 2))
            .count();
        assert_eq!(s2_sent, usize::from(5 - revision), "3.0.{revision}: S2 sent");
        assert!(
            op.events.iter().any(
                |e| matches!(e, PrinterEvent::Connected { version, .. } if *version == (3, 0, revision))
            ),
            "3.0.{revision}: {:?}",
            op.events
        );
        assert!(
            !op.events.iter().any(|e| matches!(e, PrinterEvent::LinkLost(_))),
            "3.0.{revision}: one handshake"
        );
    }
}
