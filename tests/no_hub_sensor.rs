//! A unit without a hub sensor (the BMCU-C profile) tells FINDA from each lane's odometry,
//! homed at the lane's presence sensor: the tip estimate follows the filament, every unload
//! proves it again at the sensor's edge, and what the printer reads stays MMU3's.

mod common;

use common::*;
use mmu_firmware::profile::BMCU_C;
use mmu_firmware::unit::Lane;
use mmu_firmware::{App, Config};
use mmu_model::{Fault, ModelConfig, MotionSensor, Rail, SensorId};
use mmu_protocol::{ErrorCode, ParamCode, Request, RequestCode};

/// Where the model's hub sensor would be, seen from a lane's presence sensor, mm.
const SENSOR_TO_HUB_MM: f32 = 95.0;

fn bmcu_rig() -> Rig<4> {
    let mut rig = bmcu_unit();
    rig.boot();
    rig.handshake();
    rig
}

/// A BMCU-C unit before its start-up check: four angle-sensor lanes with tension sliders.
fn bmcu_unit() -> Rig<4> {
    let mut rig = Rig::<4>::new();
    rig.app = App::with_profile(&BMCU_C, Config::for_profile(&BMCU_C)).expect("4 lanes");
    rig.model = mmu_model::Model::new(
        ModelConfig {
            motion_sensor: MotionSensor::Angle,
            lane_tension: true,
            mm_per_rev: 23.56,
            ..ModelConfig::default()
        },
        4,
        7,
    );
    rig
}

/// How far the unit's estimate of `slot`'s tip is from the model's tip, mm.
fn estimate_error(rig: &Rig<4>, slot: usize) -> Option<f32> {
    let estimate = rig.app.unit().tip_centi(slot)? as f32 / 100.0;
    let truth = rig.model.tip_mm(slot)? + SENSOR_TO_HUB_MM;
    Some(estimate - truth)
}

/// A lane whose angle sensor does not answer (a BMCU370x lane module, whose pins carry other
/// signals; a lane board unplugged; no magnet) stops the start-up check before anything moves,
/// with the error of a lane's sensor; Retry once it answers starts the unit.
#[test]
fn a_lane_whose_angle_sensor_does_not_answer_stops_the_start_up_check() {
    let mut rig = bmcu_unit();
    rig.disconnect(SensorId::MotorHall(3), Rail::Low);
    let x0 = Request::new(RequestCode::Reset, 0);
    assert_eq!(rig.boot(), error(x0, ErrorCode::MOVE_PULLEY_FAILED));
    assert!(rig.nothing_moved_since(0));
    rig.retry_fails_until_fixed(x0, ErrorCode::MOVE_PULLEY_FAILED, |rig| rig.model.clear_all());
    assert!(rig.nothing_moved_since(0));
}

#[test]
fn a_tool_change_homes_the_lane_then_finda_follows_its_tip() {
    let mut rig = bmcu_rig();
    assert_eq!(rig.app.unit().tip_centi(1), None, "no tip is known at start");
    let run = rig.command(t(1));
    assert_eq!(run.last, finished(t(1)), "{:?}", run.progress);
    let error = estimate_error(&rig, 1).expect("homed on the way");
    assert!(error.abs() < 2.0, "estimate off by {error} mm");
    assert_eq!(rig.app.read_register(0x08), Some(1), "FINDA: filament in the hub");
    // The next change parks lane 1 at its park position, homed again on the way back.
    let run = rig.command(t(2));
    assert_eq!(run.last, finished(t(2)));
    assert_parked(&rig, 1);
    assert_eq!(rig.app.unit().lane(1), Lane::Parked);
    let error = estimate_error(&rig, 1).expect("homed");
    assert!(error.abs() < 2.0, "estimate off by {error} mm");
}

#[test]
fn a_slipping_drive_makes_the_estimate_drift_and_the_next_unload_homes_it_away() {
    let mut rig = bmcu_rig();
    rig.command(t(1));
    // The drive gear slips while lane 1 loads again: the angle sensor counts more than the
    // filament moves.
    rig.command(t(0));
    rig.inject(Fault::Slip { slot: 1, ratio: 0.9 });
    let run = rig.command(t(1));
    assert_eq!(run.last.param, ParamCode::Finished, "{:?}", run.progress);
    let drift = estimate_error(&rig, 1).expect("tracked");
    assert!(
        drift > 10.0,
        "a 10 % slip over the load drifts forward: {drift} mm"
    );
    rig.model.clear(mmu_model::FaultKind::Slip(1));
    let run = rig.command(t(2));
    assert_eq!(run.last, finished(t(2)));
    let error = estimate_error(&rig, 1).expect("homed");
    assert!(
        error.abs() < 2.0,
        "the unload's homing took the drift away: {error} mm"
    );
    assert_parked(&rig, 1);
}

#[test]
fn an_empty_lane_is_refused_with_finda_not_switching_on() {
    let mut rig = bmcu_rig();
    assert!(rig.model.remove_filament(3));
    rig.idle(200);
    let run = rig.command(t(3));
    assert_eq!(run.last.param, ParamCode::Error, "{:?}", run.progress);
    assert!(rig.motors_stopped());
    assert_eq!(rig.app.read_register(0x08), Some(0));
}

#[test]
fn a_hand_pushed_filament_is_homed_before_it_is_fed() {
    let mut rig = bmcu_rig();
    rig.command(t(0));
    rig.command(Request::new(RequestCode::Unload, 0));
    assert!(rig.model.remove_filament(0));
    rig.idle(200);
    // Pushed in by hand 30 mm past the presence sensor, undriven: its tip is not known.
    assert!(rig.model.insert_filament(0, -65.0));
    rig.idle(200);
    assert_eq!(rig.app.unit().tip_centi(0), None);
    let run = rig.command(t(0));
    assert_eq!(run.last, finished(t(0)), "{:?}", run.progress);
    let error = estimate_error(&rig, 0).expect("homed");
    assert!(error.abs() < 2.0, "{error} mm");
}

#[test]
fn a_lane_that_comes_out_of_its_drive_gear_while_parking_is_empty_and_the_change_goes_on() {
    use mmu_protocol::ProgressCode;
    let mut rig = bmcu_rig();
    rig.command(t(0));
    rig.issue(t(1));
    rig.follow_until(t(1), Some(ProgressCode::RETRACTING_FROM_FINDA), 60_000);
    // Lane 0's filament is pulled out by hand while the unit homes it.
    assert!(rig.model.remove_filament(0));
    let run = rig.follow(t(1), 60_000);
    assert_eq!(run.last, finished(t(1)), "{:?}", run.progress);
    assert_eq!(rig.app.unit().lane(0), Lane::Empty);
    assert_eq!(rig.app.unit().lane(1), Lane::Loaded);
}

#[test]
fn every_lane_not_seen_since_start_is_homed_before_a_load() {
    let mut rig = bmcu_rig();
    // Lane 2's tip rests in the merge (8 mm before the hub), nobody knows it.
    assert!(rig.model.insert_filament(2, -5.0));
    rig.idle(200);
    let run = rig.command(t(1));
    assert_eq!(run.last, finished(t(1)), "{:?}", run.progress);
    for lane in [0, 2, 3] {
        assert_eq!(rig.app.unit().lane(lane), Lane::Parked, "lane {lane}");
        let error = estimate_error(&rig, lane).expect("homed");
        assert!(error.abs() < 2.0, "lane {lane}: {error} mm");
        assert_parked(&rig, lane);
    }
}

/// A restart with a lane recorded as parked but its tip between the drive gear and the presence
/// sensor (a pull that stopped at the sensor's edge, then the power went): the start-up check
/// finds the sensor empty, yet the load homes the lane, finds the filament still in the gear's
/// grip, and loads it.
#[test]
fn a_parked_lane_whose_tip_rests_behind_its_sensor_after_a_restart_still_loads() {
    let mut rig = bmcu_unit();
    let gear = rig.model.config().drive_gear_mm;
    assert!(rig.model.remove_filament(0));
    assert!(rig.model.insert_filament(0, gear + 1.0));
    rig.app.restore(&mmu_firmware::persist::Snapshot {
        lanes: [Lane::Parked; 4],
        ..mmu_firmware::persist::Snapshot::default()
    });
    rig.boot();
    rig.handshake();
    let run = rig.command(t(0));
    assert_eq!(run.last, finished(t(0)), "{:?}", run.progress);
    assert_eq!(rig.model.loaded_slot(), Some(0));
}
