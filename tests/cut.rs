//! Cut (`K<n>`, `src/commands/cut.rs`): this unit has no blade, so `K` unloads whatever is loaded
//! and re-parks slot *n* (fed to the hub, parked again). Its happy path, and every error of its
//! recovery tables (its own, the unload's, the preload's motions, the shared motion rows) raised
//! on the rig, with what Retry then does.

mod common;

use common::{FsensorReports, PARK_PROGRESS, Rig, UNLOAD_PROGRESS, assert_parked, error, finished, t};
use mmu_model::{Fault, Rail, SensorId};
use mmu_protocol::{ErrorCode, ProgressCode as P, Request, RequestCode};

#[test]
fn cut_reparks_the_slot_as_this_unit_has_no_blade() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(2));
    let cut = Request::new(RequestCode::Cut, 2);
    let run = rig.command(cut);
    assert_eq!(run.progress, [UNLOAD_PROGRESS, PARK_PROGRESS].concat());
    assert_eq!(run.last, finished(cut));
    assert_parked(&rig, 2);
}

// ---- recovery: every row of the cut's tables and the motion rows, raised on the rig ---------
//
// `8005` (the preload's row) is not raised by `K`: a cut unloads whatever is loaded instead of
// refusing. `FINDA_DIDNT_SWITCH_OFF` is one row for both halves (tested in the re-park below;
// the unload's is in `tests/unload.rs`). `INTERNAL` (a motion without a budget) cannot be raised
// on the model: no fault reaches it.

fn k(slot: u8) -> Request {
    Request::new(RequestCode::Cut, slot)
}

/// The cut of `slot` stopped on `code` with every motor stopped; the fault is cleared and Retry
/// pressed: it goes on from the failed phase (`progress`) and re-parks the slot.
fn fails_then_retry_reparks(rig: &mut Rig<3>, slot: u8, code: ErrorCode, progress: &[P]) {
    rig.fails_then_retry_finishes(k(slot), code, progress);
    assert_parked(rig, slot.into());
}

#[test]
fn filament_in_the_hub_no_slot_owns_then_retry_after_it_is_pulled_back_reparks() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let run = rig.filament_in_the_hub_no_slot_owns_then_pulled_back(k(2));
    assert_eq!(run.progress, PARK_PROGRESS);
    assert_eq!(run.last, finished(k(2)));
    assert_parked(&rig, 2);
}

#[test]
fn printer_sensor_never_clears_on_the_cut_unload_then_retry_reparks() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(2));
    rig.fsensor = FsensorReports::Stuck(1);
    rig.command_fails_with(k(2), ErrorCode::FSENSOR_DIDNT_SWITCH_OFF);
    rig.fsensor = FsensorReports::Truthful;
    let run = rig.retry_finishes(k(2));
    assert_eq!(run.progress, [UNLOAD_PROGRESS, PARK_PROGRESS].concat());
    assert_parked(&rig, 2);
}

#[test]
fn hub_never_clears_on_the_repark_then_retry_finishes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let (failed, retried) = rig.hub_never_clears_then_retry(k(1));
    assert_eq!(failed.progress, PARK_PROGRESS);
    assert_eq!(retried.progress, [P::RETRACTING_FROM_FINDA]);
    let tip = rig.model.tip_mm(1).unwrap();
    assert!(tip < 0.0, "slot 1 is out of the hub path: tip at {tip} mm");
}

#[test]
fn empty_slot_then_retry_after_the_user_inserts_filament_reparks_it() {
    let mut rig = Rig::<3>::new();
    rig.model.remove_filament(1);
    rig.boot();
    let run = rig.command(k(1));
    assert_eq!(run.last, error(k(1), ErrorCode::FINDA_DIDNT_SWITCH_ON));
    assert!(rig.slot_never_ran(1), "slot 1's motor never ran");
    rig.model.insert_filament(1, -90.0);
    rig.idle(100);
    assert_eq!(rig.retry_finishes(k(1)).progress, PARK_PROGRESS);
    assert_parked(&rig, 1);
}

#[test]
fn stalled_motor_on_cut_then_retry_after_the_jam_is_cleared_reparks() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(Fault::Jam { slot: 0 });
    rig.issue(k(0));
    fails_then_retry_reparks(&mut rig, 0, ErrorCode::STALLED_PULLEY, &PARK_PROGRESS);
}

#[test]
fn hub_sensor_disconnected_on_cut_then_retry_reparks() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(1));
    rig.command_until(k(1), P::UNLOADING_TO_FINDA);
    rig.disconnect(SensorId::HubFilament, Rail::High);
    fails_then_retry_reparks(
        &mut rig,
        1,
        ErrorCode::FINDA_FLICKERS,
        &[UNLOAD_PROGRESS, PARK_PROGRESS].concat(),
    );
}

#[test]
fn motor_hall_sensor_disconnected_on_cut_then_retry_reparks() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command_until(k(2), P::RETRACTING_FROM_FINDA);
    rig.disconnect(SensorId::MotorHall(2), Rail::Low);
    fails_then_retry_reparks(
        &mut rig,
        2,
        ErrorCode::MOVE_PULLEY_FAILED,
        &[P::RETRACTING_FROM_FINDA],
    );
}
