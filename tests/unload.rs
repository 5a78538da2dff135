//! UnloadFromNozzle (`U0`, `src/commands/unload_from_nozzle.rs`): the slot that owns the hub path
//! comes back out of the printer and the hub and is parked. Its happy paths, and every error of
//! its recovery table and the shared motion rows raised on the rig, with what Retry then does.
//!
//! Also testing `U0`: `tests/safe_motion.rs` (Retry with the printer's sensor still stuck never
//! pulls the filament out of its drive), `tests/tool_change.rs`, `tests/eject.rs` and
//! `tests/cut.rs` (the unload as the first half of those commands).

mod common;

use common::{FsensorReports, Rig, UNLOAD_PROGRESS, assert_parked, error, finished, t};
use mmu_model::{Fault, Rail, SensorId};
use mmu_protocol::{ErrorCode, ProgressCode as P, Request, RequestCode};

#[test]
fn unload_pulls_back_to_the_park_position() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(1));
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.progress, UNLOAD_PROGRESS);
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

fn u0() -> Request {
    Request::new(RequestCode::Unload, 0)
}

/// `U0` stops on `code`, every motor already stopped when `Q0` reports it.
fn unload_fails_with(rig: &mut Rig<3>, code: ErrorCode) {
    let run = rig.command(u0());
    assert_eq!(run.last, error(u0(), code));
    assert!(rig.motors_stopped());
}

#[test]
fn hub_never_clears_on_unload() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.hub_never_clears();
    unload_fails_with(&mut rig, ErrorCode::FINDA_DIDNT_SWITCH_OFF);
}

#[test]
fn printer_sensor_never_clears_on_unload() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.fsensor = FsensorReports::Stuck(1);
    unload_fails_with(&mut rig, ErrorCode::FSENSOR_DIDNT_SWITCH_OFF);
}

// ---- recovery: every row of the unload's table and the motion rows, raised on the rig -------
//
// `INTERNAL` (a motion without a budget) cannot be raised on the model: no fault reaches it.

/// Load slot 0, then play `U0` until `Q0` reports `progress`.
fn unload_until(rig: &mut Rig<3>, progress: P) {
    rig.boot();
    rig.command(t(0));
    rig.command_until(u0(), progress);
}

/// The unload stopped on `code` with every motor stopped; the fault is cleared and Retry
/// pressed: it goes on from the failed phase (`progress`) and parks slot 0.
fn fails_then_retry_parks(rig: &mut Rig<3>, code: ErrorCode, progress: &[P]) {
    rig.fails_then_retry_finishes(u0(), code, progress);
    assert_parked(rig, 0);
    assert_eq!(rig.model.loaded_slot(), None);
}

#[test]
fn printer_sensor_never_clears_on_unload_then_retry_unloads_and_parks() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.fsensor = FsensorReports::Stuck(1);
    unload_fails_with(&mut rig, ErrorCode::FSENSOR_DIDNT_SWITCH_OFF);
    // The printer's sensor works again and says so; the user presses Retry.
    rig.fsensor = FsensorReports::Truthful;
    assert_eq!(rig.retry_finishes(u0()).progress, UNLOAD_PROGRESS);
    assert_parked(&rig, 0);
}

#[test]
fn hub_never_clears_on_unload_then_retry_finishes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.hub_never_clears_then_retry(u0());
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(tip < 0.0, "slot 0 is out of the hub path: tip at {tip} mm");
    assert_eq!(rig.model.loaded_slot(), None);
}

#[test]
fn filament_in_the_hub_no_slot_owns_then_retry_after_it_is_pulled_back_finishes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    // Pulled back out of the hub, nothing is left to unload.
    let run = rig.filament_in_the_hub_no_slot_owns_then_pulled_back(u0());
    assert_eq!(run.last, finished(u0()));
    assert_parked(&rig, 1);
}

#[test]
fn stalled_motor_on_unload_then_retry_unloads_and_parks() {
    let mut rig = Rig::<3>::new();
    unload_until(&mut rig, P::UNLOADING_TO_FINDA);
    rig.inject(Fault::MotorDead { slot: 0 });
    fails_then_retry_parks(&mut rig, ErrorCode::STALLED_PULLEY, &UNLOAD_PROGRESS);
}

#[test]
fn hub_sensor_disconnected_on_unload_then_retry_unloads_and_parks() {
    let mut rig = Rig::<3>::new();
    unload_until(&mut rig, P::UNLOADING_TO_FINDA);
    rig.disconnect(SensorId::HubFilament, Rail::High);
    fails_then_retry_parks(&mut rig, ErrorCode::FINDA_FLICKERS, &UNLOAD_PROGRESS);
}

#[test]
fn slot_sensor_disconnected_on_unload_then_retry_unloads_and_parks() {
    let mut rig = Rig::<3>::new();
    unload_until(&mut rig, P::UNLOADING_TO_FINDA);
    rig.disconnect(SensorId::SlotFilament(0), Rail::High);
    fails_then_retry_parks(&mut rig, ErrorCode::MOVE_PULLEY_FAILED, &UNLOAD_PROGRESS);
}

#[test]
fn hub_never_clears_on_unload_then_retry_leaves_the_slot_loadable() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.hub_never_clears_then_retry(u0());
    // The slot's drive gear still holds the filament: the next tool change loads it.
    let run = rig.command(t(0));
    assert_eq!(run.last, finished(t(0)), "tip at {:?} mm", rig.model.tip_mm(0));
}
