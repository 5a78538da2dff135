//! Home (`H0`, `src/commands/home.rs`): nothing to home on this hardware; the unit checks its
//! sensors against the known state, as after a restart. Its happy path, and every error of the
//! start-up check's recovery table raised by `H0` on the rig, with what Retry then does.
//!
//! Also testing `H0`: `tests/printer_truth.rs` (`H0 F0` once, then `X0 F0`; a dropped `B1` after
//! an `H0` error).

mod common;

use common::{PARK_MM, Rig, error, finished, t};
use mmu_model::{Rail, SensorId};
use mmu_protocol::{ErrorCode, Request, RequestCode};

#[test]
fn home_checks_the_sensors_against_the_known_state() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let run = rig.command(h0());
    assert_eq!(run.last, finished(h0()));
    // Filament pushed into the hub by hand: the unit does not know whose it is.
    rig.model.insert_filament(1, 5.0);
    rig.idle(100);
    let run = rig.command(h0());
    assert_eq!(run.last, error(h0(), ErrorCode::FINDA_VS_EEPROM_DISREPANCY));
}

// ---- recovery: every row of the check's table, raised by `H0` on the rig --------------------
//
// `H0` moves no motor, so the motion rows' `STALLED_PULLEY` and `INTERNAL` cannot be raised by
// it; its `FINDA_FLICKERS` and `MOVE_PULLEY_FAILED` are the check's own rows below.

fn h0() -> Request {
    Request::new(RequestCode::Home, 0)
}

/// `H0` stops on `code`; the cause is removed (`fix`) and Retry checks again: `H0 F0`.
fn fails_then_retry_after(rig: &mut Rig<3>, code: ErrorCode, fix: impl FnOnce(&mut Rig<3>)) {
    let before = rig.motor_log.len();
    let run = rig.command(h0());
    assert_eq!(run.last, error(h0(), code));
    assert!(rig.nothing_moved_since(before), "a check moves no motor");
    rig.retry_fails_until_fixed(h0(), code, fix);
}

#[test]
fn filament_in_the_hub_then_retry_after_it_is_pulled_back_finishes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.model.insert_filament(1, 5.0);
    rig.idle(100);
    fails_then_retry_after(&mut rig, ErrorCode::FINDA_VS_EEPROM_DISREPANCY, |rig| {
        rig.model.insert_filament(1, -15.0);
    });
}

#[test]
fn loaded_slot_pulled_out_by_hand_then_retry_trusts_the_sensors_and_the_next_change_works() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    // The user pulls slot 0's filament back to the park position by hand.
    rig.model.insert_filament(0, PARK_MM);
    rig.idle(100);
    let run = rig.command(h0());
    assert_eq!(run.last, error(h0(), ErrorCode::FINDA_VS_EEPROM_DISREPANCY));
    // Retry: the user has looked; the hub sensor is believed over the known state.
    assert_eq!(rig.press_retry_then_query(), finished(h0()));
    rig.tool_change_loads(1);
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(tip < -8.0, "slot 0 stays out of the hub path: tip at {tip} mm");
}

#[test]
fn hub_sensor_disconnected_then_retry_after_it_is_reconnected_finishes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.disconnect(SensorId::HubFilament, Rail::High);
    rig.idle(1000);
    fails_then_retry_after(&mut rig, ErrorCode::FINDA_FLICKERS, |rig| {
        rig.model.clear_all();
    });
}

#[test]
fn slot_sensor_disconnected_then_retry_after_it_is_reconnected_finishes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.disconnect(SensorId::SlotFilament(2), Rail::Low);
    rig.idle(1000);
    fails_then_retry_after(&mut rig, ErrorCode::MOVE_PULLEY_FAILED, |rig| {
        rig.model.clear_all();
    });
}
