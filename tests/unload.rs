//! UnloadFromNozzle (`U0`, `src/commands/unload_from_nozzle.rs`): the slot that owns the hub path
//! comes back out of the printer and the hub and is parked. Its happy paths, and every error of
//! its recovery table and the shared motion rows raised on the rig, with what Retry then does.
//!
//! Also testing `U0`: `tests/safe_motion.rs` (Retry with the printer's sensor still stuck never
//! pulls the filament out of its drive), `tests/tool_change.rs`, `tests/eject.rs` and
//! `tests/cut.rs` (the unload as the first half of those commands).

mod common;

use common::{FsensorReports, Rig, assert_parked, error, finished, press, t};
use mmu_model::{Fault, Rail, SensorId};
use mmu_protocol::{ButtonCode, ErrorCode, ParamCode, ProgressCode as P, Request, RequestCode};

#[test]
fn unload_pulls_back_to_the_park_position() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(1));
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.progress, [P::UNLOADING_TO_FINDA, P::RETRACTING_FROM_FINDA]);
    assert_eq!(run.last, finished(unload));
    assert_parked(&rig, 1);
    assert_eq!(rig.model.fsensor_state(), 0);
}

#[test]
fn unload_with_nothing_loaded_finishes_at_once() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert!(run.progress.is_empty());
    assert_eq!(run.last, finished(unload));
}

#[test]
fn hub_never_clears_on_unload() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    // An "off" threshold no reading goes below: the hub seems to hold filament forever.
    assert_eq!(
        rig.send(Request::write(0xa0, 50)).unwrap().param,
        ParamCode::Accepted
    );
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.last, error(unload, ErrorCode::FINDA_DIDNT_SWITCH_OFF));
    assert!(rig.motors_stopped());
}

#[test]
fn printer_sensor_never_clears_on_unload() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.fsensor = FsensorReports::Stuck(1);
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.last, error(unload, ErrorCode::FSENSOR_DIDNT_SWITCH_OFF));
    assert!(rig.motors_stopped());
}

// ---- recovery: every row of the unload's table and the motion rows, raised on the rig -------
//
// `INTERNAL` (a motion without a budget) cannot be raised on the model: no fault reaches it.

/// Retry (the Middle button) after the printer has reported its sensor as it is now.
fn retry(rig: &mut Rig<3>) {
    rig.printer_step(None);
    press(rig, ButtonCode::MIDDLE);
}

/// Load slot 0, then play `U0` until `Q0` reports `progress`.
fn unload_until(rig: &mut Rig<3>, progress: P) -> Request {
    rig.boot();
    rig.command(t(0));
    let unload = Request::new(RequestCode::Unload, 0);
    rig.issue(unload);
    let run = rig.follow_until(unload, Some(progress), 120_000);
    assert_eq!(run.progress.last(), Some(&progress), "{:?}", run.last);
    unload
}

/// The unload stopped on `code` with every motor stopped; the fault is cleared and Retry
/// pressed: it goes on from the failed phase (`progress`) and parks slot 0.
fn fails_then_retry_parks(rig: &mut Rig<3>, unload: Request, code: ErrorCode, progress: &[P]) {
    let run = rig.follow(unload, 120_000);
    assert_eq!(run.last, error(unload, code), "progress {:?}", run.progress);
    rig.idle(10);
    assert!(rig.motors_stopped(), "every motor stops on {code}");
    rig.model.clear_all();
    rig.idle(1000);
    retry(rig);
    let run = rig.follow(unload, 120_000);
    assert_eq!(run.progress, progress);
    assert_eq!(run.last, finished(unload));
    assert_parked(rig, 0);
    assert_eq!(rig.model.loaded_slot(), None);
}

#[test]
fn printer_sensor_never_clears_on_unload_then_retry_unloads_and_parks() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.fsensor = FsensorReports::Stuck(1);
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.last, error(unload, ErrorCode::FSENSOR_DIDNT_SWITCH_OFF));
    assert!(rig.motors_stopped());
    // The printer's sensor works again and says so; the user presses Retry.
    rig.fsensor = FsensorReports::Truthful;
    retry(&mut rig);
    let run = rig.follow(unload, 120_000);
    assert_eq!(run.progress, [P::UNLOADING_TO_FINDA, P::RETRACTING_FROM_FINDA]);
    assert_eq!(run.last, finished(unload));
    assert_parked(&rig, 0);
}

#[test]
fn hub_never_clears_on_unload_then_retry_finishes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    assert_eq!(
        rig.send(Request::write(0xa0, 50)).unwrap().param,
        ParamCode::Accepted
    );
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.last, error(unload, ErrorCode::FINDA_DIDNT_SWITCH_OFF));
    assert_eq!(
        rig.send(Request::write(0xa0, 2400)).unwrap().param,
        ParamCode::Accepted
    );
    rig.idle(100);
    retry(&mut rig);
    let run = rig.follow(unload, 120_000);
    assert_eq!(run.last, finished(unload), "progress {:?}", run.progress);
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(tip < 0.0, "slot 0 is out of the hub path: tip at {tip} mm");
    assert_eq!(rig.model.loaded_slot(), None);
}

#[test]
fn filament_in_the_hub_no_slot_owns_then_retry_after_it_is_pulled_back_finishes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    // Filament pushed into the hub by hand: the unit does not know whose it is.
    rig.model.insert_filament(1, 5.0);
    rig.idle(100);
    let before = rig.motor_log.len();
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.last, error(unload, ErrorCode::FINDA_VS_EEPROM_DISREPANCY));
    // Retry with the filament still there: the same error, nothing moves.
    retry(&mut rig);
    rig.idle(50);
    assert_eq!(rig.query(), error(unload, ErrorCode::FINDA_VS_EEPROM_DISREPANCY));
    assert!(
        rig.motor_log[before..]
            .iter()
            .all(|motors| motors.iter().all(|m| !m.is_driving())),
        "no motor moves on a guess"
    );
    // The user pulls it back out of the hub: nothing is left to unload.
    rig.model.insert_filament(1, -15.0);
    rig.idle(100);
    retry(&mut rig);
    let run = rig.follow(unload, 120_000);
    assert_eq!(run.last, finished(unload));
    assert_parked(&rig, 1);
}

#[test]
fn stalled_motor_on_unload_then_retry_unloads_and_parks() {
    let mut rig = Rig::<3>::new();
    let unload = unload_until(&mut rig, P::UNLOADING_TO_FINDA);
    rig.inject(Fault::MotorDead { slot: 0 });
    fails_then_retry_parks(
        &mut rig,
        unload,
        ErrorCode::STALLED_PULLEY,
        &[P::UNLOADING_TO_FINDA, P::RETRACTING_FROM_FINDA],
    );
}

#[test]
fn hub_sensor_disconnected_on_unload_then_retry_unloads_and_parks() {
    let mut rig = Rig::<3>::new();
    let unload = unload_until(&mut rig, P::UNLOADING_TO_FINDA);
    rig.inject(Fault::SensorDisconnected {
        sensor: SensorId::HubFilament,
        rail: Rail::High,
    });
    fails_then_retry_parks(
        &mut rig,
        unload,
        ErrorCode::FINDA_FLICKERS,
        &[P::UNLOADING_TO_FINDA, P::RETRACTING_FROM_FINDA],
    );
}

#[test]
fn slot_sensor_disconnected_on_unload_then_retry_unloads_and_parks() {
    let mut rig = Rig::<3>::new();
    let unload = unload_until(&mut rig, P::UNLOADING_TO_FINDA);
    rig.inject(Fault::SensorDisconnected {
        sensor: SensorId::SlotFilament(0),
        rail: Rail::High,
    });
    fails_then_retry_parks(
        &mut rig,
        unload,
        ErrorCode::MOVE_PULLEY_FAILED,
        &[P::UNLOADING_TO_FINDA, P::RETRACTING_FROM_FINDA],
    );
}

#[test]
fn hub_never_clears_on_unload_then_retry_leaves_the_slot_loadable() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    assert_eq!(
        rig.send(Request::write(0xa0, 50)).unwrap().param,
        ParamCode::Accepted
    );
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.last, error(unload, ErrorCode::FINDA_DIDNT_SWITCH_OFF));
    assert_eq!(
        rig.send(Request::write(0xa0, 2400)).unwrap().param,
        ParamCode::Accepted
    );
    rig.idle(100);
    retry(&mut rig);
    assert_eq!(rig.follow(unload, 120_000).last, finished(unload));
    // The slot's drive gear still holds the filament: the next tool change loads it.
    let run = rig.command(t(0));
    assert_eq!(run.last, finished(t(0)), "tip at {:?} mm", rig.model.tip_mm(0));
}
