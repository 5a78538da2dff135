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
        if !event.is_routine() {
            self.events.push(event.clone());
        }
    }

    fn decide(&mut self, link: &mut SimLink, request: Request, error: ErrorCode) -> Decision {
        if error == ErrorCode::FILAMENT_EJECTED {
            link.sim_mut()
                .model_mut()
                .remove_filament(usize::from(request.value));
            Decision::Press(ButtonCode::MIDDLE)
        } else if error == ErrorCode::FINDA_VS_EEPROM_DISREPANCY {
            // Unload by hand, then come back to the screen and press Retry.
            if link.sim_mut().unload_manually() > 0 {
                Decision::Wait
            } else {
                Decision::Press(ButtonCode::MIDDLE)
            }
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
    // Back to back, each command reaches the unit well within the link timeout.
    assert!(
        !op.events.iter().any(|e| matches!(e, PrinterEvent::LinkLost(_))),
        "{:?}",
        op.events
    );
    // The printer sees what its once-a-second `Q0` catches: the short push into the nozzle
    // (5 mm) falls between two polls.
    let seen = op.progress();
    assert_eq!(
        &seen[seen.len() - 3..],
        [
            ProgressCode::FEEDING_TO_FINDA,
            ProgressCode::FEEDING_TO_BONDTECH,
            ProgressCode::FEEDING_TO_FSENSOR,
        ]
    );
    assert!(seen.contains(&ProgressCode::UNLOADING_TO_FINDA));
}

fn connected() -> (Printer<SimLink>, Watcher) {
    let mut printer = printer();
    let mut op = Watcher::default();
    printer.connect(&mut op).unwrap();
    (printer, op)
}

fn run(printer: &mut Printer<SimLink>, op: &mut Watcher, code: RequestCode, value: u8) -> Outcome {
    printer.command(op, Request::new(code, value)).unwrap()
}

const OK: Outcome = Outcome::Finished(ResultCode::OK);

#[test]
fn unload_parks_the_filament_and_preload_brings_a_new_one_to_park() {
    let (mut printer, mut op) = connected();
    assert_eq!(run(&mut printer, &mut op, RequestCode::Tool, 0), OK);
    assert_eq!(run(&mut printer, &mut op, RequestCode::Unload, 0), OK);
    let model = printer.link().sim().model();
    assert_eq!(model.loaded_slot(), None);
    let park = -f32::from(printer.link().sim().unit_config().park_mm);
    let tip = model.tip_mm(0).unwrap();
    assert!((tip - park).abs() < 3.0, "parked at {tip} mm, park is {park} mm");

    // The user puts a new spool in slot 2, its tip through the drive gear past the slot sensor.
    let model = printer.link_mut().sim_mut().model_mut();
    model.remove_filament(2);
    model.insert_filament(2, -90.0);
    assert_eq!(run(&mut printer, &mut op, RequestCode::Load, 2), OK);
    let tip = printer.link().sim().model().tip_mm(2).unwrap();
    assert!(
        (tip - park).abs() < 3.0,
        "preloaded to {tip} mm, park is {park} mm"
    );
}

#[test]
fn eject_waits_for_continue_then_the_slot_is_empty() {
    let (mut printer, mut op) = connected();
    assert_eq!(run(&mut printer, &mut op, RequestCode::Eject, 1), OK);
    assert!(op.events.contains(&PrinterEvent::Error(
        Request::new(RequestCode::Eject, 1),
        ErrorCode::FILAMENT_EJECTED
    )));
    assert_eq!(printer.link().sim().model().tip_mm(1), None);
    // The next tool change on that slot finds no filament and says so.
    let outcome = run(&mut printer, &mut op, RequestCode::Tool, 1);
    assert_eq!(outcome, Outcome::GaveUp(ErrorCode::FINDA_DIDNT_SWITCH_ON));
}

#[test]
fn a_slot_the_unit_lacks_is_an_invalid_tool_and_the_next_command_works() {
    let (mut printer, mut op) = connected();
    let outcome = run(&mut printer, &mut op, RequestCode::Tool, 7);
    assert_eq!(outcome, Outcome::GaveUp(ErrorCode::INVALID_TOOL));
    assert_eq!(run(&mut printer, &mut op, RequestCode::Tool, 2), OK);
}

#[test]
fn a_jam_fails_after_three_automatic_retries_and_clears_with_retry() {
    let (mut printer, mut op) = connected();
    printer
        .link_mut()
        .sim_mut()
        .inject(mmu_sim::SimFault::Model(mmu_model::Fault::BowdenJam));
    let outcome = run(&mut printer, &mut op, RequestCode::Tool, 1);
    let Outcome::GaveUp(error) = outcome else {
        panic!("a Bowden jam cannot load: {outcome:?}");
    };
    let retries = op
        .events
        .iter()
        .filter(|e| matches!(e, PrinterEvent::AutoRetry(..)))
        .count();
    assert_eq!(retries, 3, "{:?}", op.events);
    assert!(printer.link().sim().model().fsensor_state() == 0, "{error}");
}

#[test]
fn corrupted_and_dropped_bytes_cost_time_not_the_tool_change() {
    let (mut printer, mut op) = connected();
    let sim = printer.link_mut().sim_mut();
    sim.inject(mmu_sim::SimFault::UartCorrupt { probability: 0.003 });
    sim.inject(mmu_sim::SimFault::UartDrop { probability: 0.003 });
    for slot in [1, 2] {
        let outcome = run(&mut printer, &mut op, RequestCode::Tool, slot);
        assert_eq!(outcome, OK, "{:?}", op.events);
    }
    let lost = op
        .events
        .iter()
        .filter(|e| matches!(e, PrinterEvent::LinkLost(_)))
        .count();
    assert!(lost > 0, "the faults hit the link");
    assert_eq!(printer.link().sim().model().loaded_slot(), Some(2));
}

#[test]
fn a_reset_restarts_the_unit_and_the_printer_connects_again() {
    let (mut printer, mut op) = connected();
    let first = printer.reset(&mut op, 0).unwrap();
    assert_eq!(
        (first.code, first.param, first.param_value),
        (RequestCode::Reset, mmu_protocol::ParamCode::Finished, Some(0))
    );
    let connects = op
        .events
        .iter()
        .filter(|e| matches!(e, PrinterEvent::Connected { .. }))
        .count();
    assert_eq!(connects, 2);
}

#[test]
fn a_printer_expecting_another_version_stops_with_the_update_screen() {
    let sim = Sim::new(SimOptions::default()).unwrap();
    // 3.0.0 to 3.0.3 are negotiated (`S2` asked again); an MMU2S-era printer is not.
    let options = PrinterOptions {
        version: (2, 1, 9),
        ..PrinterOptions::default()
    };
    let mut printer = Printer::new(SimLink::new(sim), options);
    let error = printer.connect(&mut Watcher::default()).unwrap_err();
    assert!(
        matches!(
            error,
            mmu_sim::PrinterError::VersionMismatch {
                part: 0,
                got: Some(3)
            }
        ),
        "{error}"
    );
}

#[test]
fn a_slipping_drive_still_delivers_the_tip_into_the_extruder_gears() {
    let (mut printer, mut op) = connected();
    let gears = printer.link().sim().model().config().extruder_gears_mm;
    printer
        .link_mut()
        .sim_mut()
        .inject(mmu_sim::SimFault::Model(mmu_model::Fault::Slip {
            slot: 1,
            ratio: 0.6,
        }));
    assert_eq!(run(&mut printer, &mut op, RequestCode::Tool, 1), OK);
    let tip = printer.link().sim().model().tip_mm(1).unwrap();
    assert!(
        tip >= gears,
        "the tip stopped at {tip} mm, the gears are at {gears} mm"
    );
}

#[test]
fn noisy_sensors_do_not_end_the_push_into_the_extruder_early() {
    let (mut printer, mut op) = connected();
    let gears = printer.link().sim().model().config().extruder_gears_mm;
    printer
        .link_mut()
        .sim_mut()
        .inject(mmu_sim::SimFault::Model(mmu_model::Fault::SensorNoise {
            sigma: 90.0,
        }));
    for slot in [1, 0, 2] {
        assert_eq!(run(&mut printer, &mut op, RequestCode::Tool, slot), OK);
        let tip = printer.link().sim().model().tip_mm(usize::from(slot)).unwrap();
        assert!(tip >= gears, "slot {slot}: the tip stopped at {tip} mm");
    }
}

/// Clears every fault when the printer gives up retrying by itself, then presses Retry.
#[derive(Default)]
struct Fixer {
    errors: Vec<ErrorCode>,
}

impl Operator<SimLink> for Fixer {
    fn event(&mut self, _link: &mut SimLink, event: &PrinterEvent) {
        if let PrinterEvent::Error(_, error) = event {
            self.errors.push(*error);
        }
    }

    fn decide(&mut self, link: &mut SimLink, _request: Request, _error: ErrorCode) -> Decision {
        link.sim_mut().model_mut().clear_all();
        Decision::Press(ButtonCode::MIDDLE)
    }
}

#[test]
fn retry_after_a_bowden_jam_feeds_on_from_where_the_tip_stopped() {
    let mut printer = printer();
    let mut op = Fixer::default();
    printer.connect(&mut op).unwrap();
    let jam = mmu_sim::SimFault::Model(mmu_model::Fault::BowdenJam);
    printer.link_mut().sim_mut().inject(jam);
    let outcome = printer
        .command(&mut op, Request::new(RequestCode::Tool, 1))
        .unwrap();
    assert_eq!(outcome, OK, "{:?}", op.errors);
    assert!(!op.errors.is_empty(), "the jam stopped the feed");
    // Counting the Bowden distance again from zero would run the tip into the printer's sensor
    // during the fast feed.
    assert!(
        !op.errors.contains(&ErrorCode::FSENSOR_TOO_EARLY),
        "{:?}",
        op.errors
    );
    let gears = printer.link().sim().model().config().extruder_gears_mm;
    assert!(printer.link().sim().model().tip_mm(1).unwrap() >= gears);
}

#[test]
fn a_power_loss_mid_tool_change_is_carried_on_from_the_stored_slot() {
    let (mut printer, mut op) = connected();
    assert_eq!(run(&mut printer, &mut op, RequestCode::Tool, 0), OK);
    let now = printer.link().sim().now_ms();
    // Mid-way through the next change: slot 0 is out, slot 1 is on its way through the Bowden.
    printer.link_mut().sim_mut().schedule(mmu_sim::ScheduledFault {
        fault: mmu_sim::SimFault::PowerLoss { off_ms: 300 },
        at_ms: now + 6_000,
        until_ms: None,
    });
    assert_eq!(
        run(&mut printer, &mut op, RequestCode::Tool, 1),
        OK,
        "{:?}",
        op.events
    );
    assert!(
        op.events
            .contains(&PrinterEvent::Interrupted(Request::new(RequestCode::Tool, 1))),
        "{:?}",
        op.events
    );
    // Slot 1's tip stopped deep in the Bowden tube and the stored lane says it holds the path:
    // the printer's `U0` pulls it back, its slot sensor still seeing filament after the longest
    // slot path proves the belief (a slot that did not hold the path would have cleared it), and
    // the unload and the `T1` again carry on without UNLOAD MANUALLY.
    // (`sim/tests/restart_mid_tool_change.rs`: every phase.)
    assert!(
        !op.events
            .iter()
            .any(|e| matches!(e, PrinterEvent::Error(_, ErrorCode::FINDA_VS_EEPROM_DISREPANCY))),
        "{:?}",
        op.events
    );
    let model = printer.link().sim().model();
    assert_eq!(model.loaded_slot(), Some(1));
    assert!(model.tip_mm(1).unwrap() >= model.config().extruder_gears_mm);
    let parked = -f32::from(printer.link().sim().unit_config().park_mm);
    assert!((model.tip_mm(0).unwrap() - parked).abs() < 3.0);
}

#[test]
fn after_a_restart_the_unit_knows_which_slot_is_loaded() {
    let (mut printer, mut op) = connected();
    assert_eq!(run(&mut printer, &mut op, RequestCode::Tool, 2), OK);
    printer.link_mut().idle(5_000);
    printer
        .link_mut()
        .sim_mut()
        .inject(mmu_sim::SimFault::PowerLoss { off_ms: 1_000 });
    let state = printer.connect(&mut op).unwrap();
    // The stored lanes agree with the hub sensor: no UNLOAD MANUALLY.
    assert_eq!(
        (state.code, state.param, state.param_value),
        (RequestCode::Reset, mmu_protocol::ParamCode::Finished, Some(0))
    );
    assert_eq!(run(&mut printer, &mut op, RequestCode::Tool, 0), OK);
    assert_eq!(printer.link().sim().model().loaded_slot(), Some(0));
}

#[test]
fn erasing_forgets_the_loaded_slot_so_the_unit_asks_for_a_manual_unload() {
    let (mut printer, mut op) = connected();
    assert_eq!(run(&mut printer, &mut op, RequestCode::Tool, 1), OK);
    let state = printer.reset(&mut op, 42).unwrap();
    assert_eq!(
        (state.param, state.param_value),
        (
            mmu_protocol::ParamCode::Error,
            Some(ErrorCode::FINDA_VS_EEPROM_DISREPANCY.0)
        )
    );
}

#[test]
fn filament_found_where_the_stored_state_has_none_stops_the_unit_until_retry() {
    let (mut printer, mut op) = connected();
    let sim = printer.link_mut().sim_mut();
    sim.inject(mmu_sim::SimFault::PowerLoss { off_ms: 2_000 });
    // While the unit is off, someone pushes slot 2's filament into the hub.
    sim.model_mut().remove_filament(2);
    sim.model_mut().insert_filament(2, 20.0);
    let state = printer.connect(&mut op).unwrap();
    assert_eq!(
        (state.param, state.param_value),
        (
            mmu_protocol::ParamCode::Error,
            Some(ErrorCode::FINDA_VS_EEPROM_DISREPANCY.0)
        ),
        "no motor moves on a guess"
    );
    assert!(printer.link().sim().model().motor_speed_mm_s(2).unwrap().abs() < 0.1);
    // The user pulls it back to its park position and presses Retry: the unit checks again.
    let sim = printer.link_mut().sim_mut();
    sim.model_mut().remove_filament(2);
    sim.model_mut().insert_filament(2, -15.0);
    printer.link_mut().idle(500);
    let pressed = printer
        .request(&mut op, Request::new(RequestCode::Button, 1))
        .unwrap();
    assert_eq!(pressed.param, mmu_protocol::ParamCode::Accepted);
    printer.link_mut().idle(1_000);
    let state = printer
        .request(&mut op, Request::new(RequestCode::Query, 0))
        .unwrap();
    assert_eq!(
        (state.code, state.param),
        (RequestCode::Reset, mmu_protocol::ParamCode::Finished)
    );
    assert_eq!(run(&mut printer, &mut op, RequestCode::Tool, 2), OK);
}

#[test]
fn the_reported_version_is_a_setting_kept_across_restarts() {
    let (mut printer, mut op) = connected();
    let written = printer.request(&mut op, Request::write(0x52, 2)).unwrap();
    assert_eq!(written.param, mmu_protocol::ParamCode::Accepted);
    // Settings are written at most every 10 s.
    printer.link_mut().idle(11_000);
    let sim = printer.link_mut().sim_mut();
    sim.inject(mmu_sim::SimFault::PowerLoss { off_ms: 500 });
    // The 3.0.3 printer still connects after the restart (the unit offers the kept 2 first, then
    // the others when `S2` is asked again), and the revision it accepted is kept in its place.
    printer.connect(&mut op).unwrap();
    let reported = printer
        .request(&mut op, Request::new(RequestCode::Read, 0x52))
        .unwrap();
    assert_eq!(reported.param_value, Some(3));
    let sim = std::mem::replace(
        printer.link_mut().sim_mut(),
        Sim::new(SimOptions::default()).unwrap(),
    );
    let mk3s = PrinterOptions {
        version: (3, 0, 2),
        ..PrinterOptions::default()
    };
    let mut printer = Printer::new(SimLink::new(sim), mk3s);
    printer.connect(&mut op).unwrap();
}

/// Notes the errors the printer retried by itself (FSENSOR TOO EARLY: the unit learns the
/// Bowden length); gives up on any it asks about.
#[derive(Default)]
struct RetriesTooEarly {
    seen: Vec<ErrorCode>,
}

impl Operator<SimLink> for RetriesTooEarly {
    fn event(&mut self, _link: &mut SimLink, event: &PrinterEvent) {
        if let PrinterEvent::AutoRetry(error, _) = event {
            self.seen.push(*error);
        }
    }

    fn decide(&mut self, _link: &mut SimLink, _request: Request, error: ErrorCode) -> Decision {
        self.seen.push(error);
        Decision::GiveUp
    }
}

/// A Bowden length the Retry of FSENSOR TOO EARLY learned is a setting like one the printer
/// writes: the persistence keeper saves it within seconds, without a reset, and a power cut then
/// brings it back (the keeper notices it by the App's settings revision).
#[test]
fn a_learned_bowden_length_survives_a_power_cut() {
    // Not the default 360 mm: a setting equal to its default is not stored (the default applies
    // after a restart), and this simulated unit starts from 420 mm instead of the default.
    let tube = 330.0;
    let options = SimOptions {
        unit: mmu_firmware::Config {
            bowden_mm: 420,
            ..mmu_firmware::Config::default()
        },
        model: mmu_model::ModelConfig {
            bowden_length_mm: tube,
            extruder_gears_mm: tube + 4.0,
            nozzle_mm: tube + 60.0,
            ..mmu_model::ModelConfig::default()
        },
        ..SimOptions::default()
    };
    let mut printer = Printer::new(
        SimLink::new(Sim::new(options).unwrap()),
        PrinterOptions::default(),
    );
    let mut op = RetriesTooEarly::default();
    printer.connect(&mut op).unwrap();
    let outcome = printer
        .command(&mut op, Request::new(RequestCode::Tool, 0))
        .unwrap();
    assert_eq!(outcome, OK, "{:?}", op.seen);
    assert_eq!(op.seen, [ErrorCode::FSENSOR_TOO_EARLY]);
    let read = |printer: &mut Printer<SimLink>, op: &mut RetriesTooEarly, address| {
        printer
            .request(op, Request::new(RequestCode::Read, address))
            .unwrap()
            .param_value
            .unwrap()
    };
    let learned = read(&mut printer, &mut op, 0x22);
    assert!((f32::from(learned) - tube).abs() <= 8.0, "learned {learned} mm");
    printer.link_mut().idle(3_000);
    printer
        .link_mut()
        .sim_mut()
        .inject(mmu_sim::SimFault::PowerLoss { off_ms: 500 });
    printer.connect(&mut op).unwrap();
    assert_eq!(read(&mut printer, &mut op, 0x22), learned);
    assert_eq!(
        read(&mut printer, &mut op, 0x53),
        0,
        "learned since this start: nothing"
    );
}

#[test]
fn counters_are_saved_before_a_reset() {
    let (mut printer, mut op) = connected();
    printer
        .link_mut()
        .sim_mut()
        .inject(mmu_sim::SimFault::Model(mmu_model::Fault::BowdenJam));
    let outcome = run(&mut printer, &mut op, RequestCode::Tool, 1);
    assert!(matches!(outcome, Outcome::GaveUp(_)), "{outcome:?}");
    // The tip is stuck in the Bowden tube, past the hub sensor: after the reset the stored lanes
    // agree with the sensors and the start-up check adds no error.
    let errors = printer
        .request(&mut op, Request::new(RequestCode::Read, 0x04))
        .unwrap()
        .param_value;
    assert!(errors.is_some_and(|n| n >= 4), "{errors:?}");
    // At once, well within the 10 s the counters otherwise wait for.
    printer.reset(&mut op, 0).unwrap();
    let after = printer
        .request(&mut op, Request::new(RequestCode::Read, 0x04))
        .unwrap()
        .param_value;
    assert_eq!(after, errors);
}
