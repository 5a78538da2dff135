//! ToolChange (`T<n>`, `src/commands/tool_change.rs`): the loaded slot comes out
//! (UnloadFromNozzle) and slot *n* goes in to the nozzle (LoadToNozzle), as the printer drives it
//! against the physical model. Every happy path with its progress sequence, and every error of
//! the command's recovery tables (its own, the unload's, the load's and the shared motion rows)
//! raised on the rig, with what the printer's button then does.
//!
//! Also testing `T`: `tests/printer_truth.rs` (a `T` sent over a waiting error, Retry after an
//! error raised before anything moved), `tests/safe_motion.rs` (a jam while printing after the
//! change), `tests/properties.rs` (random commands and faults).

mod common;

use common::{FsensorReports, PARK_MM, Rig, assert_parked, error, finished, t};
use mmu_model::{Fault, Rail, SensorId};
use mmu_protocol::{ErrorCode, ParamCode, ProgressCode as P, Request, RequestCode};

fn failing_tool_change(rig: &mut Rig<3>, slot: u8, code: ErrorCode) {
    let run = rig.command(t(slot));
    assert_eq!(run.last, error(t(slot), code), "progress {:?}", run.progress);
    rig.idle(10);
    assert!(rig.motors_stopped(), "every motor stops on {code}");
}

#[test]
fn tool_change_loads_to_the_nozzle_with_the_mmu3_progress_sequence() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let run = rig.command(t(0));
    assert_eq!(
        run.progress,
        [
            P::FEEDING_TO_FINDA,
            P::FEEDING_TO_BONDTECH,
            P::FEEDING_TO_FSENSOR,
            P::FEEDING_TO_NOZZLE
        ]
    );
    assert_eq!(run.last, finished(t(0)));
    assert!(
        rig.model.fsensor_state() >= 1,
        "the filament reached the printer's sensor"
    );
    assert_eq!(rig.model.loaded_slot(), Some(0));
    // The slot motor follows the extruder's last push, then rests.
    rig.idle(2000);
    assert!(rig.motors_stopped());
    // Register 0x07 says InNozzle, the selector register says slot 0.
    assert_eq!(
        rig.send(Request::new(RequestCode::Read, 7)).unwrap().param_value,
        Some(8)
    );
    assert_eq!(
        rig.send(Request::new(RequestCode::Read, 0x1b))
            .unwrap()
            .param_value,
        Some(0)
    );
}

#[test]
fn tool_change_to_another_slot_unloads_first_and_parks_the_old_one() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    let run = rig.command(t(2));
    assert_eq!(
        run.progress,
        [
            P::UNLOADING_TO_FINDA,
            P::RETRACTING_FROM_FINDA,
            P::FEEDING_TO_FINDA,
            P::FEEDING_TO_BONDTECH,
            P::FEEDING_TO_FSENSOR,
            P::FEEDING_TO_NOZZLE
        ]
    );
    assert_eq!(run.last, finished(t(2)));
    assert_parked(&rig, 0);
    assert_eq!(rig.model.loaded_slot(), Some(2));
}

#[test]
fn tool_change_to_the_loaded_slot_finishes_at_once() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(1));
    rig.idle(3000);
    let tip = rig.model.tip_mm(1).unwrap();
    let run = rig.command(t(1));
    assert!(run.progress.is_empty());
    assert_eq!(run.last, finished(t(1)));
    assert!((rig.model.tip_mm(1).unwrap() - tip).abs() < 1.0);
}

#[test]
fn a_slot_the_unit_does_not_have_is_accepted_then_reported_invalid() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    assert_eq!(rig.send(t(3)).unwrap().encode().as_bytes(), b"T3 A*75\n");
    assert_eq!(rig.query(), error(t(3), ErrorCode::INVALID_TOOL));
    assert!(rig.motors_stopped());
    // The printer stops the print or resets the unit: the next command is not refused forever.
    assert_eq!(rig.send(t(0)).unwrap().param, ParamCode::Accepted);
}

#[test]
fn hub_never_sees_the_tip() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    // A hub threshold no reading reaches: the tip passes unseen.
    assert_eq!(
        rig.send(Request::write(0x90, 4090)).unwrap().param,
        ParamCode::Accepted
    );
    failing_tool_change(&mut rig, 0, ErrorCode::FINDA_DIDNT_SWITCH_ON);
    // Before a preload the unit does not know where the tip is: the bound is the preload distance.
    let tip = rig.model.tip_mm(0).unwrap();
    let bound = PARK_MM + f32::from(rig.app.config().preload_max_mm) + 5.0;
    assert!(
        tip < bound,
        "the search is bounded: tip at {tip} mm, bound {bound} mm"
    );
}

#[test]
fn printer_sensor_never_triggers_then_retry_recovers() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.fsensor = FsensorReports::Stuck(0);
    failing_tool_change(&mut rig, 1, ErrorCode::FSENSOR_DIDNT_SWITCH_ON);
    // The sensor works again; the printer (or the user) presses Retry.
    rig.fsensor = FsensorReports::Truthful;
    assert_eq!(
        rig.send(Request::new(RequestCode::Button, 1)).unwrap().param,
        ParamCode::Accepted
    );
    let run = rig.follow(t(1), 120_000);
    assert_eq!(run.last, finished(t(1)));
    assert_eq!(rig.model.loaded_slot(), Some(1));
}

#[test]
fn printer_sensor_triggering_too_early() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.fsensor = FsensorReports::Stuck(1);
    failing_tool_change(&mut rig, 2, ErrorCode::FSENSOR_TOO_EARLY);
}

#[test]
fn stalled_motor() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(Fault::Jam { slot: 1 });
    failing_tool_change(&mut rig, 1, ErrorCode::STALLED_PULLEY);
}

#[test]
fn empty_slot_fails_without_moving() {
    let mut rig = Rig::<3>::new();
    rig.model.remove_filament(2);
    rig.boot();
    failing_tool_change(&mut rig, 2, ErrorCode::FINDA_DIDNT_SWITCH_ON);
    assert!(
        rig.motor_log.iter().all(|motors| !motors[2].is_driving()),
        "slot 2's motor never ran"
    );
}

#[test]
fn disconnected_hub_sensor_is_reported_not_believed() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(Fault::SensorDisconnected {
        sensor: SensorId::HubFilament,
        rail: Rail::High,
    });
    failing_tool_change(&mut rig, 0, ErrorCode::FINDA_FLICKERS);
    assert_eq!(
        rig.send(Request::new(RequestCode::Read, 0x50))
            .unwrap()
            .param_value,
        Some(1)
    );
}

#[test]
fn disconnected_motor_hall_sensor() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(Fault::SensorDisconnected {
        sensor: SensorId::MotorHall(0),
        rail: Rail::Low,
    });
    failing_tool_change(&mut rig, 0, ErrorCode::MOVE_PULLEY_FAILED);
}
