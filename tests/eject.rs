//! Eject (`E<n>`, `src/commands/eject.rs`): slot *n*'s filament is pulled out past its slot
//! sensor, then the unit asks the user to take it (`E800c`) and waits for Continue. Its happy
//! paths, and every error of its recovery tables (its own, the unload's when slot *n* is loaded,
//! the shared motion rows) raised on the rig, with what the printer's buttons then do.
//!
//! Also testing `E`: `tests/printer_truth.rs` (a `T` sent over the eject's question).

mod common;

use common::{
    FsensorReports, HUB_OFF_REGISTER, OFF_THRESHOLD_DEFAULT, OFF_THRESHOLD_NEVER, Rig, UNLOAD_PROGRESS,
    error, finished, press, t,
};
use mmu_model::{Fault, Rail, SensorId};
use mmu_protocol::{ButtonCode, ErrorCode, ProgressCode as P, Request, RequestCode};

#[test]
fn eject_waits_for_continue_then_finishes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let eject = Request::new(RequestCode::Eject, 1);
    let run = rig.command(eject);
    assert_eq!(run.progress, [P::EJECTING_FILAMENT]);
    assert_eq!(run.last, error(eject, ErrorCode::FILAMENT_EJECTED));
    assert_eq!(rig.model.slot_filament_present(1), Some(false));
    assert!(rig.motors_stopped());
    press(&mut rig, ButtonCode::MIDDLE);
    rig.idle(5);
    assert_eq!(rig.query(), finished(eject));
}

#[test]
fn eject_of_the_loaded_slot_unloads_it_first() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    let eject = Request::new(RequestCode::Eject, 0);
    let run = rig.command(eject);
    assert_eq!(
        run.progress,
        [&UNLOAD_PROGRESS[..], &[P::EJECTING_FILAMENT]].concat()
    );
    assert_eq!(run.last, error(eject, ErrorCode::FILAMENT_EJECTED));
}

// ---- recovery: every row of the eject's tables and the motion rows, raised on the rig -------
//
// `8008` (the unload's row) is not raised by `E`: its plan unloads only slot *n* when slot *n*
// is loaded and does not look at the hub. `INTERNAL` (a motion without a budget) cannot be
// raised on the model: no fault reaches it.

/// The eject of `slot` waits with `E800c`; Continue (`B1`) finishes it with the slot empty.
fn continue_finishes(rig: &mut Rig<3>, eject: Request) {
    assert_eq!(rig.query(), error(eject, ErrorCode::FILAMENT_EJECTED));
    press(rig, ButtonCode::MIDDLE);
    rig.idle(5);
    assert_eq!(rig.query(), finished(eject));
    assert_eq!(rig.model.slot_filament_present(eject.value.into()), Some(false));
}

/// The eject stopped on `code` with every motor stopped; the fault is cleared and Retry pressed:
/// it goes on from the failed phase (`progress`) to the question, and Continue finishes it.
fn fails_then_retry_ejects(rig: &mut Rig<3>, eject: Request, code: ErrorCode, progress: &[P]) {
    rig.fails_with(eject, code);
    rig.model.clear_all();
    rig.idle(1000);
    fails_then_retry_ejects_after(rig, eject, progress);
}

/// After the error shown now, every motor stopped: Retry goes on (`progress`) to the question; Continue finishes.
fn fails_then_retry_ejects_after(rig: &mut Rig<3>, eject: Request, progress: &[P]) {
    rig.idle(10);
    assert!(rig.motors_stopped());
    rig.retry();
    let run = rig.follow(eject, 120_000);
    assert_eq!(run.progress, progress);
    continue_finishes(rig, eject);
}

#[test]
fn eject_question_is_answered_by_continue_only() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let eject = Request::new(RequestCode::Eject, 2);
    assert_eq!(rig.command(eject).last, error(eject, ErrorCode::FILAMENT_EJECTED));
    let before = rig.motor_log.len();
    for other in [ButtonCode::RIGHT, ButtonCode::LEFT] {
        press(&mut rig, other);
        rig.idle(50);
        assert_eq!(
            rig.query(),
            error(eject, ErrorCode::FILAMENT_EJECTED),
            "{other:?}"
        );
    }
    assert!(
        rig.nothing_moved_since(before),
        "nothing moves while the question waits"
    );
    continue_finishes(&mut rig, eject);
}

#[test]
fn slot_sensor_never_clears_on_eject_then_retry_asks_to_take_the_filament() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    // An "off" threshold of slot 1's filament sensor no reading goes below.
    let slot_1_off = HUB_OFF_REGISTER + 5;
    rig.write(slot_1_off, OFF_THRESHOLD_NEVER);
    let eject = Request::new(RequestCode::Eject, 1);
    let run = rig.command_fails_with(eject, ErrorCode::MOVE_PULLEY_FAILED);
    assert_eq!(run.progress, [P::EJECTING_FILAMENT]);
    rig.write(slot_1_off, OFF_THRESHOLD_DEFAULT);
    rig.idle(100);
    rig.retry();
    rig.follow(eject, 120_000);
    continue_finishes(&mut rig, eject);
}

#[test]
fn printer_sensor_never_clears_on_the_eject_unload_then_retry_ejects() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.fsensor = FsensorReports::Stuck(1);
    let eject = Request::new(RequestCode::Eject, 0);
    let run = rig.command(eject);
    assert_eq!(run.last, error(eject, ErrorCode::FSENSOR_DIDNT_SWITCH_OFF));
    rig.fsensor = FsensorReports::Truthful;
    fails_then_retry_ejects_after(
        &mut rig,
        eject,
        &[&UNLOAD_PROGRESS[..], &[P::EJECTING_FILAMENT]].concat(),
    );
}

#[test]
fn hub_never_clears_on_the_eject_unload_then_retry_ejects() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.hub_never_clears();
    let eject = Request::new(RequestCode::Eject, 0);
    let run = rig.command(eject);
    assert_eq!(run.last, error(eject, ErrorCode::FINDA_DIDNT_SWITCH_OFF));
    rig.hub_clears_again();
    rig.retry();
    let run = rig.follow(eject, 120_000);
    assert_eq!(
        run.last,
        error(eject, ErrorCode::FILAMENT_EJECTED),
        "progress {:?}",
        run.progress
    );
    continue_finishes(&mut rig, eject);
}

/// Play `E<slot>` until `Q0` reports `P18`.
fn eject_until_it_pulls(rig: &mut Rig<3>, slot: u8) -> Request {
    let eject = Request::new(RequestCode::Eject, slot);
    rig.issue(eject);
    let run = rig.follow_until(eject, Some(P::EJECTING_FILAMENT), 120_000);
    assert_eq!(run.progress, [P::EJECTING_FILAMENT], "{:?}", run.last);
    eject
}

#[test]
fn stalled_motor_on_eject_then_retry_ejects() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let eject = eject_until_it_pulls(&mut rig, 1);
    rig.inject(Fault::MotorDead { slot: 1 });
    fails_then_retry_ejects(
        &mut rig,
        eject,
        ErrorCode::STALLED_PULLEY,
        &[P::EJECTING_FILAMENT],
    );
}

#[test]
fn hub_sensor_disconnected_on_eject_then_retry_ejects() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let eject = eject_until_it_pulls(&mut rig, 2);
    rig.disconnect(SensorId::HubFilament, Rail::High);
    fails_then_retry_ejects(
        &mut rig,
        eject,
        ErrorCode::FINDA_FLICKERS,
        &[P::EJECTING_FILAMENT],
    );
}
