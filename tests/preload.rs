//! Preload (`L<n>`, `src/commands/preload.rs`): slot *n* is fed until the hub sensor sees its
//! tip, then parked. Its happy path, and every error of its recovery table and the shared motion
//! rows raised on the rig, with what the printer's buttons then do.
//!
//! Also testing `L`: `tests/printer_truth.rs` (`8005` FILAMENT ALREADY LOADED: Continue, and
//! Unload from a Buddy printer and an MK3S).

mod common;

use common::{PARK_PROGRESS, Rig, assert_parked, error, finished, t};
use mmu_model::{Fault, Rail, SensorId};
use mmu_protocol::{ErrorCode, ProgressCode as P, Request, RequestCode};

#[test]
fn preload_feeds_to_the_hub_and_parks() {
    let mut rig = Rig::<3>::new();
    rig.model.insert_filament(1, -90.0);
    rig.boot();
    let load = Request::new(RequestCode::Load, 1);
    let run = rig.command(load);
    assert_eq!(run.progress, PARK_PROGRESS);
    assert_eq!(run.last, finished(load));
    assert_parked(&rig, 1);
}

// ---- recovery: every row of the preload's table and the motion rows, raised on the rig ------
//
// `8005` FILAMENT ALREADY LOADED, its Continue (`B1`) and Unload (`B0`, `B2`):
// `tests/printer_truth.rs` `continue_on_filament_already_loaded_finishes_the_preload` and
// `unload_on_filament_already_loaded_unloads_then_preloads`. `INTERNAL` (a motion without a
// budget) cannot be raised on the model: no fault reaches it.

fn l(slot: u8) -> Request {
    Request::new(RequestCode::Load, slot)
}

/// The preload of `slot` stopped on `code` with every motor stopped; the fault is cleared and
/// Retry pressed: it goes on from the failed phase (`progress`) and parks the slot.
fn fails_then_retry_parks(rig: &mut Rig<3>, slot: u8, code: ErrorCode, progress: &[P]) {
    rig.fails_then_retry_finishes(l(slot), code, progress);
    assert_parked(rig, slot.into());
}

#[test]
fn empty_slot_then_retry_after_the_user_inserts_filament_parks_it() {
    let mut rig = Rig::<3>::new();
    rig.model.remove_filament(1);
    rig.boot();
    let run = rig.command(l(1));
    assert_eq!(run.last, error(l(1), ErrorCode::FINDA_DIDNT_SWITCH_ON));
    assert!(rig.slot_never_ran(1), "slot 1's motor never ran");
    rig.model.insert_filament(1, -90.0);
    rig.idle(100);
    assert_eq!(rig.retry_finishes(l(1)).progress, PARK_PROGRESS);
    assert_parked(&rig, 1);
}

#[test]
fn hub_never_clears_after_the_preload_then_retry_finishes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let (failed, retried) = rig.hub_never_clears_then_retry(l(1));
    assert_eq!(failed.progress, PARK_PROGRESS);
    assert_eq!(retried.progress, [P::RETRACTING_FROM_FINDA]);
    let tip = rig.model.tip_mm(1).unwrap();
    assert!(tip < 0.0, "slot 1 is out of the hub path: tip at {tip} mm");
}

#[test]
fn filament_in_the_hub_no_slot_owns_then_retry_after_it_is_pulled_back_preloads() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let run = rig.filament_in_the_hub_no_slot_owns_then_pulled_back(l(2));
    assert_eq!(run.progress, PARK_PROGRESS);
    assert_eq!(run.last, finished(l(2)));
    assert_parked(&rig, 2);
}

#[test]
fn stalled_motor_on_preload_then_retry_after_the_jam_is_cleared_parks() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(Fault::Jam { slot: 1 });
    rig.issue(l(1));
    fails_then_retry_parks(&mut rig, 1, ErrorCode::STALLED_PULLEY, &PARK_PROGRESS);
}

#[test]
fn hub_sensor_disconnected_on_preload_then_retry_parks() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command_until(l(0), P::FEEDING_TO_FINDA);
    rig.disconnect(SensorId::HubFilament, Rail::Low);
    // The tip passed the hub while its sensor could not see it: the repeated `P5` ends in its
    // first step, before the printer's next `Q0`.
    fails_then_retry_parks(
        &mut rig,
        0,
        ErrorCode::FINDA_FLICKERS,
        &[P::RETRACTING_FROM_FINDA],
    );
}

#[test]
fn motor_hall_sensor_disconnected_while_parking_then_retry_parks() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command_until(l(2), P::RETRACTING_FROM_FINDA);
    rig.disconnect(SensorId::MotorHall(2), Rail::Low);
    fails_then_retry_parks(
        &mut rig,
        2,
        ErrorCode::MOVE_PULLEY_FAILED,
        &[P::RETRACTING_FROM_FINDA],
    );
}

#[test]
fn hub_never_clears_after_the_preload_then_retry_parks_where_the_next_load_finds_the_hub() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.hub_never_clears_then_retry(l(1));
    // Recorded as parked: the next tool change searches the hub within `hub_search_mm` of it.
    let run = rig.command(t(1));
    assert_eq!(run.last, finished(t(1)), "tip at {:?} mm", rig.model.tip_mm(1));
}
