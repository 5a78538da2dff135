//! Preload (`L<n>`, `src/commands/preload.rs`): slot *n* is fed until the hub sensor sees its
//! tip, then parked. Its happy path, and every error of its recovery table and the shared motion
//! rows raised on the rig, with what the printer's buttons then do.
//!
//! Also testing `L`: `tests/printer_truth.rs` (`8005` FILAMENT ALREADY LOADED: Continue, and
//! Unload from a Buddy printer and an MK3S).

mod common;

use common::{Rig, assert_parked, error, finished, press, t};
use mmu_model::{Fault, Rail, SensorId};
use mmu_protocol::{ButtonCode, ErrorCode, ParamCode, ProgressCode as P, Request, RequestCode};

#[test]
fn preload_feeds_to_the_hub_and_parks() {
    let mut rig = Rig::<3>::new();
    rig.model.insert_filament(1, -90.0);
    rig.boot();
    let load = Request::new(RequestCode::Load, 1);
    let run = rig.command(load);
    assert_eq!(run.progress, [P::FEEDING_TO_FINDA, P::RETRACTING_FROM_FINDA]);
    assert_eq!(run.last, finished(load));
    assert_parked(&rig, 1);
}

// ---- recovery: every row of the preload's table and the motion rows, raised on the rig ------
//
// `8005` FILAMENT ALREADY LOADED, its Continue (`B1`) and Unload (`B0`, `B2`):
// `tests/printer_truth.rs` `continue_on_filament_already_loaded_finishes_the_preload` and
// `unload_on_filament_already_loaded_unloads_then_preloads`. `INTERNAL` (a motion without a
// budget) cannot be raised on the model: no fault reaches it.

/// Retry (the Middle button).
fn retry(rig: &mut Rig<3>) {
    press(rig, ButtonCode::MIDDLE);
}

fn l(slot: u8) -> Request {
    Request::new(RequestCode::Load, slot)
}

/// Play `L<slot>` until `Q0` reports `progress`.
fn preload_until(rig: &mut Rig<3>, slot: u8, progress: P) {
    rig.issue(l(slot));
    let run = rig.follow_until(l(slot), Some(progress), 120_000);
    assert_eq!(run.progress.last(), Some(&progress), "{:?}", run.last);
}

/// The preload of `slot` stopped on `code` with every motor stopped; the fault is cleared and
/// Retry pressed: it goes on from the failed phase (`progress`) and parks the slot.
fn fails_then_retry_parks(rig: &mut Rig<3>, slot: u8, code: ErrorCode, progress: &[P]) {
    let run = rig.follow(l(slot), 120_000);
    assert_eq!(run.last, error(l(slot), code), "progress {:?}", run.progress);
    rig.idle(10);
    assert!(rig.motors_stopped(), "every motor stops on {code}");
    rig.model.clear_all();
    rig.idle(1000);
    retry(rig);
    let run = rig.follow(l(slot), 120_000);
    assert_eq!(run.progress, progress);
    assert_eq!(run.last, finished(l(slot)));
    assert_parked(rig, slot.into());
}

#[test]
fn empty_slot_then_retry_after_the_user_inserts_filament_parks_it() {
    let mut rig = Rig::<3>::new();
    rig.model.remove_filament(1);
    rig.boot();
    let run = rig.command(l(1));
    assert_eq!(run.last, error(l(1), ErrorCode::FINDA_DIDNT_SWITCH_ON));
    assert!(
        rig.motor_log.iter().all(|motors| !motors[1].is_driving()),
        "slot 1's motor never ran"
    );
    rig.model.insert_filament(1, -90.0);
    rig.idle(100);
    retry(&mut rig);
    let run = rig.follow(l(1), 120_000);
    assert_eq!(run.progress, [P::FEEDING_TO_FINDA, P::RETRACTING_FROM_FINDA]);
    assert_eq!(run.last, finished(l(1)));
    assert_parked(&rig, 1);
}

#[test]
fn hub_never_clears_after_the_preload_then_retry_finishes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    // An "off" threshold no reading goes below: the hub seems to hold filament forever.
    assert_eq!(
        rig.send(Request::write(0xa0, 50)).unwrap().param,
        ParamCode::Accepted
    );
    let run = rig.command(l(1));
    assert_eq!(run.progress, [P::FEEDING_TO_FINDA, P::RETRACTING_FROM_FINDA]);
    assert_eq!(run.last, error(l(1), ErrorCode::FINDA_DIDNT_SWITCH_OFF));
    rig.idle(10);
    assert!(rig.motors_stopped());
    assert_eq!(
        rig.send(Request::write(0xa0, 2400)).unwrap().param,
        ParamCode::Accepted
    );
    rig.idle(100);
    retry(&mut rig);
    let run = rig.follow(l(1), 120_000);
    assert_eq!(run.progress, [P::RETRACTING_FROM_FINDA]);
    assert_eq!(run.last, finished(l(1)));
    let tip = rig.model.tip_mm(1).unwrap();
    assert!(tip < 0.0, "slot 1 is out of the hub path: tip at {tip} mm");
}

#[test]
fn filament_in_the_hub_no_slot_owns_then_retry_after_it_is_pulled_back_preloads() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    // Filament pushed into the hub by hand: the unit does not know whose it is.
    rig.model.insert_filament(1, 5.0);
    rig.idle(100);
    let before = rig.motor_log.len();
    let run = rig.command(l(2));
    assert_eq!(run.last, error(l(2), ErrorCode::FINDA_VS_EEPROM_DISREPANCY));
    retry(&mut rig);
    rig.idle(50);
    assert_eq!(
        rig.query(),
        error(l(2), ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
        "the cause is still there"
    );
    assert!(
        rig.motor_log[before..]
            .iter()
            .all(|motors| motors.iter().all(|m| !m.is_driving())),
        "no motor moves on a guess"
    );
    rig.model.insert_filament(1, -15.0);
    rig.idle(100);
    retry(&mut rig);
    let run = rig.follow(l(2), 120_000);
    assert_eq!(run.progress, [P::FEEDING_TO_FINDA, P::RETRACTING_FROM_FINDA]);
    assert_eq!(run.last, finished(l(2)));
    assert_parked(&rig, 2);
}

#[test]
fn stalled_motor_on_preload_then_retry_after_the_jam_is_cleared_parks() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(Fault::Jam { slot: 1 });
    rig.issue(l(1));
    fails_then_retry_parks(
        &mut rig,
        1,
        ErrorCode::STALLED_PULLEY,
        &[P::FEEDING_TO_FINDA, P::RETRACTING_FROM_FINDA],
    );
}

#[test]
fn hub_sensor_disconnected_on_preload_then_retry_parks() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    preload_until(&mut rig, 0, P::FEEDING_TO_FINDA);
    rig.inject(Fault::SensorDisconnected {
        sensor: SensorId::HubFilament,
        rail: Rail::Low,
    });
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
    preload_until(&mut rig, 2, P::RETRACTING_FROM_FINDA);
    rig.inject(Fault::SensorDisconnected {
        sensor: SensorId::MotorHall(2),
        rail: Rail::Low,
    });
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
    assert_eq!(
        rig.send(Request::write(0xa0, 50)).unwrap().param,
        ParamCode::Accepted
    );
    let run = rig.command(l(1));
    assert_eq!(run.last, error(l(1), ErrorCode::FINDA_DIDNT_SWITCH_OFF));
    assert_eq!(
        rig.send(Request::write(0xa0, 2400)).unwrap().param,
        ParamCode::Accepted
    );
    rig.idle(100);
    retry(&mut rig);
    assert_eq!(rig.follow(l(1), 120_000).last, finished(l(1)));
    // Recorded as parked: the next tool change searches the hub within `hub_search_mm` of it.
    let run = rig.command(t(1));
    assert_eq!(run.last, finished(t(1)), "tip at {:?} mm", rig.model.tip_mm(1));
}
