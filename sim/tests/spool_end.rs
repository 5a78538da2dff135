//! A spool that ends while the printer prints, with Prusa's printer logic driving the unit
//! (book: "Spool end"): the printer's own runout check (`CheckFINDARunout`) must start its
//! filament change while the tail can still be unloaded, so that SpoolJoin goes on with the next
//! slot, or the plain `M600` stops on the filament-change screen with the old filament out of
//! the path, on every printer family.

use mmu_firmware::registers::LEFT;
use mmu_model::Fault;
use mmu_protocol::{ButtonCode, ErrorCode, Request, RequestCode, ResultCode};
use mmu_sim::{
    Decision, Link, Operator, Outcome, Personality, Printer, PrinterEvent, PrinterOptions, Sim, SimFault,
    SimLink, SimOptions,
};

/// Records what the printer saw; gives up on any error screen but the eject dialog, where it
/// takes the ejected filament out of its slot (as the screen asks) and presses Continue.
#[derive(Default)]
struct Watcher {
    events: Vec<(u64, PrinterEvent)>,
    /// At the eject dialog: the hub sensor and the printer's sensor, as the model has them.
    at_eject_dialog: Option<(bool, u8)>,
}

impl Operator<SimLink> for Watcher {
    fn event(&mut self, link: &mut SimLink, event: &PrinterEvent) {
        if !matches!(event, PrinterEvent::Heartbeat(_)) {
            self.events.push((link.now_ms(), event.clone()));
        }
    }

    fn decide(&mut self, link: &mut SimLink, request: Request, error: ErrorCode) -> Decision {
        if error != ErrorCode::FILAMENT_EJECTED || request.code != RequestCode::Eject {
            return Decision::GiveUp;
        }
        let model = link.sim_mut().model_mut();
        self.at_eject_dialog = Some((model.hub_filament_present(), model.fsensor_state()));
        model.remove_filament(usize::from(request.value));
        Decision::Press(ButtonCode::MIDDLE)
    }
}

impl Watcher {
    fn errors(&self) -> Vec<ErrorCode> {
        self.events
            .iter()
            .filter_map(|(_, e)| match e {
                PrinterEvent::Error(_, error) => Some(*error),
                _ => None,
            })
            .collect()
    }

    fn runouts(&self) -> Vec<(u8, Option<u8>)> {
        self.events
            .iter()
            .filter_map(|(_, e)| match e {
                PrinterEvent::Runout { slot, join } => Some((*slot, *join)),
                _ => None,
            })
            .collect()
    }

    fn sent_commands(&self) -> Vec<Request> {
        self.events
            .iter()
            .filter_map(|(_, e)| match e {
                PrinterEvent::Sent(r) if r.code.is_command() => Some(*r),
                _ => None,
            })
            .collect()
    }
}

/// How long the print goes on after the spool ends, ms: the tail reaches the hub after 95 s at
/// the default 1 mm/s, so a unit that lets FINDA tell only the truth gets its runout too.
const PRINT_AFTER_END_MS: u64 = 240_000;

/// A printer of `personality` (SpoolJoin `join`) printing with slot 0 loaded.
fn printing(personality: Personality, join: bool) -> (Printer<SimLink>, Watcher) {
    let (mut printer, mut op) = changed(personality, join);
    assert_eq!(printer.print(&mut op, 10_000).unwrap(), None, "{personality}");
    let model = printer.link().sim().model();
    assert_eq!(
        (model.loaded_slot(), model.fsensor_state()),
        (Some(0), 2),
        "{personality}"
    );
    op.events.clear();
    (printer, op)
}

/// A printer of `personality` (SpoolJoin `join`) right after its tool change to slot 0.
fn changed(personality: Personality, join: bool) -> (Printer<SimLink>, Watcher) {
    let sim = Sim::new(SimOptions {
        printer: personality,
        ..SimOptions::default()
    })
    .unwrap();
    let options = PrinterOptions {
        spool_join: join,
        ..PrinterOptions::of(personality)
    };
    let mut printer = Printer::new(SimLink::new(sim), options);
    let mut op = Watcher::default();
    printer.connect(&mut op).expect("connects");
    let outcome = printer
        .command(&mut op, Request::new(RequestCode::Tool, 0))
        .unwrap();
    assert_eq!(
        outcome,
        Outcome::Finished(ResultCode::OK),
        "{personality}: {:?}",
        op.events
    );
    assert_eq!(printer.print(&mut op, 10_000).unwrap(), None, "{personality}");
    let model = printer.link().sim().model();
    assert_eq!(
        (model.loaded_slot(), model.fsensor_state()),
        (Some(0), 2),
        "{personality}"
    );
    op.events.clear();
    (printer, op)
}

/// The loose end of slot 0's spool passes its slot sensor while the printer prints.
fn spool_ends(printer: &mut Printer<SimLink>) {
    let injected = printer
        .link_mut()
        .sim_mut()
        .inject(SimFault::Model(Fault::SpoolRunout { slot: 0 }));
    assert!(injected);
}

/// SpoolJoin went on with the next slot: `U0`, `T1`, no error screen, slot 1 printing.
fn went_on_with_the_next_slot(
    printer: &Printer<SimLink>,
    op: &Watcher,
    ended: Option<Outcome>,
    personality: Personality,
) {
    let errors = op.errors();
    assert_eq!(ended, None, "{personality}: {errors:x?} {:?}", op.sent_commands());
    assert!(errors.is_empty(), "{personality}: error screens {errors:x?}");
    assert_eq!(op.runouts(), [(0, Some(1))], "{personality}");
    let commands = op.sent_commands();
    assert_eq!(
        commands,
        [
            Request::new(RequestCode::Unload, 0),
            Request::new(RequestCode::Tool, 1)
        ],
        "{personality}"
    );
    let model = printer.link().sim().model();
    assert_eq!(
        model.loaded_slot(),
        Some(1),
        "{personality}: the next slot prints"
    );
    assert_eq!(model.fsensor_state(), 2, "{personality}");
    assert!(model.printing().is_some(), "{personality}: the print goes on");
    assert_eq!(printer.loaded_tool(), Some(1), "{personality}");
}

/// The plain filament change stopped on its screen with the old filament out of the path (Buddy
/// ejects it first: its dialog is the one screen).
fn stopped_with_the_path_clear(
    printer: &Printer<SimLink>,
    op: &Watcher,
    ended: Option<Outcome>,
    personality: Personality,
) {
    let errors = op.errors();
    assert_eq!(
        ended,
        Some(Outcome::FilamentChange(0)),
        "{personality}: {errors:x?} {:?}",
        op.sent_commands()
    );
    assert_eq!(op.runouts(), [(0, None)], "{personality}");
    let mut expected = vec![Request::new(RequestCode::Unload, 0)];
    if personality == Personality::Mk3s {
        assert!(errors.is_empty(), "{personality}: error screens {errors:x?}");
    } else {
        // Buddy ejects the old filament: its dialog is the one screen, with the path clear.
        expected.push(Request::new(RequestCode::Eject, 0));
        assert_eq!(errors, [ErrorCode::FILAMENT_EJECTED], "{personality}");
        assert_eq!(op.at_eject_dialog, Some((false, 0)), "{personality}");
    }
    assert_eq!(op.sent_commands(), expected, "{personality}");
    let model = printer.link().sim().model();
    assert_eq!(model.loaded_slot(), None, "{personality}");
    assert!(!model.hub_filament_present(), "{personality}: the hub is clear");
    assert_eq!(model.fsensor_state(), 0, "{personality}: the extruder is clear");
    assert_eq!(printer.loaded_tool(), None, "{personality}");
}

#[test]
fn with_spool_join_the_print_goes_on_with_the_next_slot() {
    for personality in Personality::ALL {
        let (mut printer, mut op) = printing(personality, true);
        spool_ends(&mut printer);
        let ended = printer.print(&mut op, PRINT_AFTER_END_MS).unwrap();
        went_on_with_the_next_slot(&printer, &op, ended, personality);
    }
}

#[test]
fn without_spool_join_the_print_stops_on_the_filament_change_screen_with_the_path_clear() {
    for personality in Personality::ALL {
        let (mut printer, mut op) = printing(personality, false);
        spool_ends(&mut printer);
        let ended = printer.print(&mut op, PRINT_AFTER_END_MS).unwrap();
        stopped_with_the_path_clear(&printer, &op, ended, personality);
    }
}

/// Slot 0's spool nearly used up, as the unit counts it: 1 m left (`M708 A0x59 X1`), within the
/// count's uncertainty (± 1 m on a fresh spool) of empty.
fn nearly_used_up(printer: &mut Printer<SimLink>, op: &mut Watcher) {
    let answer = printer.request(op, Request::write(LEFT, 1)).unwrap();
    assert_eq!(answer.param, mmu_protocol::ParamCode::Accepted);
    op.events.clear();
}

/// The end of slot 0's spool, fastened to its core, stops the filament where it is now.
fn fastened_end(printer: &mut Printer<SimLink>) {
    let injected = printer
        .link_mut()
        .sim_mut()
        .inject(SimFault::Model(Fault::SpoolFastened { slot: 0 }));
    assert!(injected);
}

/// How long the print goes on after a fastened end, ms: the follower's motor stands still for
/// 3 s before the unit decides.
const PRINT_AFTER_FASTENED_MS: u64 = 60_000;

#[test]
fn a_fastened_end_of_a_used_up_spool_with_spool_join_goes_on_with_the_next_slot() {
    for personality in Personality::ALL {
        let (mut printer, mut op) = printing(personality, true);
        nearly_used_up(&mut printer, &mut op);
        fastened_end(&mut printer);
        let ended = printer.print(&mut op, PRINT_AFTER_FASTENED_MS).unwrap();
        went_on_with_the_next_slot(&printer, &op, ended, personality);
    }
}

#[test]
fn a_fastened_end_of_a_used_up_spool_without_spool_join_stops_on_the_filament_change_screen() {
    for personality in Personality::ALL {
        let (mut printer, mut op) = printing(personality, false);
        nearly_used_up(&mut printer, &mut op);
        fastened_end(&mut printer);
        let ended = printer.print(&mut op, PRINT_AFTER_FASTENED_MS).unwrap();
        stopped_with_the_path_clear(&printer, &op, ended, personality);
    }
}

#[test]
fn a_tangle_on_a_used_up_spool_is_the_one_wrong_guess_and_the_printer_still_goes_on() {
    // Within the count's uncertainty of empty a tangle stops the filament as a fastened end
    // does, and nothing the unit senses tells them apart: it is reported as a spool end. The
    // printer's `U0` pulls the tangled filament back as it would the fastened one, and SpoolJoin
    // goes on with the next slot: no error screen, one spool end too many.
    for personality in Personality::ALL {
        let (mut printer, mut op) = printing(personality, true);
        nearly_used_up(&mut printer, &mut op);
        assert!(
            printer
                .link_mut()
                .sim_mut()
                .inject(SimFault::Model(Fault::Jam { slot: 0 }))
        );
        assert_eq!(printer.print(&mut op, PRINT_AFTER_FASTENED_MS).unwrap(), None);
        assert_eq!(op.runouts(), [(0, Some(1))], "{personality}");
        assert!(op.errors().is_empty(), "{personality}: {:x?}", op.errors());
        assert_eq!(
            printer.link().sim().model().loaded_slot(),
            Some(1),
            "{personality}"
        );
    }
}

#[test]
fn a_tangle_a_fastened_end_or_a_clog_with_filament_left_stays_an_error_and_is_never_a_runout() {
    for personality in Personality::ALL {
        let faults = [
            Fault::Jam { slot: 0 },
            Fault::SpoolFastened { slot: 0 },
            Fault::BowdenJam,
        ];
        for fault in faults {
            let (mut printer, mut op) = printing(personality, true);
            assert!(printer.link_mut().sim_mut().inject(SimFault::Model(fault)));
            printer.print(&mut op, 60_000).unwrap();
            assert!(
                op.runouts().is_empty(),
                "{personality} {fault:?}: reported as a runout"
            );
            // With 330 m left, a tangle, and a spool end fastened to the core (it cannot be told
            // from one with so much left), is the follower's jam: PULLEY CANNOT MOVE (`8047`
            // stalled, `804b` move failed). A clog in the Bowden tube holds the filament past the
            // hub: the unit feels nothing (the printer's extruder skips).
            let pulley = [ErrorCode::STALLED_PULLEY, ErrorCode::MOVE_PULLEY_FAILED];
            assert!(
                fault == Fault::BowdenJam || op.errors().iter().any(|e| pulley.contains(e)),
                "{personality} {fault:?}: {:x?}",
                op.errors()
            );
        }
    }
}

#[test]
fn a_spool_that_ends_as_the_print_starts_is_handled_too() {
    // The printer's load into the nozzle after the change may still run.
    for personality in Personality::ALL {
        for join in [false, true] {
            for delay_ms in (0..=6000).step_by(500) {
                let (mut printer, mut op) = changed(personality, join);
                if delay_ms > 0 {
                    assert_eq!(printer.print(&mut op, delay_ms).unwrap(), None);
                }
                op.events.clear();
                spool_ends(&mut printer);
                let ended = printer.print(&mut op, PRINT_AFTER_END_MS).unwrap();
                let model = printer.link().sim().model();
                let what = format!(
                    "{personality} join {join} at {delay_ms} ms: {ended:?} {:x?} {:?}; tip {:?} tail {:?}",
                    op.errors(),
                    op.sent_commands(),
                    model.tip_mm(0),
                    model.tail_mm(0)
                );
                assert_eq!(op.runouts().len(), 1, "{what}");
                if join {
                    assert_eq!(ended, None, "{what}");
                    assert_eq!(model.loaded_slot(), Some(1), "{what}");
                } else {
                    assert_eq!(ended, Some(Outcome::FilamentChange(0)), "{what}");
                    assert!(!model.hub_filament_present(), "{what}");
                }
                let unexpected: Vec<ErrorCode> = op
                    .errors()
                    .into_iter()
                    .filter(|&e| e != ErrorCode::FILAMENT_EJECTED)
                    .collect();
                assert!(unexpected.is_empty(), "{what}");
            }
        }
    }
}
