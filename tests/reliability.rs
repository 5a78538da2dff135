//! Reliability findings of an outside review (issue 24, item 5), each a test that failed on the
//! code before its fix: a driven motor that never shows a revolution, the stall rule switched
//! off, and a slot whose odometry has passed the end of its 32 bits (21.47 km).

mod common;

use common::{Rig, STEP_MS, t};
use mmu_firmware::{Config, Instant, MotorCommand};
use mmu_model::{Fault, ModelConfig};
use mmu_protocol::{ParamCode, ProgressCode, Request, RequestCode};

/// `Q0` as the printer frames it.
const Q0: &[u8] = b"Q0*ea\n";

/// One rig step with slot `slot`'s motor Hall sensor reading `hall` whatever the motor does (a
/// sensor stuck mid-range: no edge, no fault), the printer polling every 100 ms. Returns the
/// motor commands of the step.
fn step_with_hall_stuck(rig: &mut Rig<3>, slot: usize, hall: u16) -> [MotorCommand; 3] {
    let mut samples = rig.model.samples::<3>();
    samples.slots[slot].motion = hall;
    let rx: &[u8] = if rig.now.is_multiple_of(100) { Q0 } else { b"" };
    let out = rig.app.step(Instant::from_millis(rig.now), &samples, rx);
    rig.model.step(STEP_MS as u32, &out.motors);
    rig.motor_log.push(out.motors);
    rig.now += STEP_MS;
    out.motors
}

/// Finding 2: a motor driven without a revolution while the stall rule is weak (its longest
/// timeout, 10 s) was driven for its phase's whole time budget or the stall timeout, whichever
/// came first: `P1c` (the slow feed to the printer's sensor) has about 13 s. A phase's still
/// limit of its own stops it within a few seconds.
#[test]
fn a_driven_motor_that_never_turns_is_stopped_within_the_phase_still_limit() {
    let config = Config {
        stall_timeout_ms: 10_000,
        ..Config::default()
    };
    let mut rig = Rig::<3>::with(config, ModelConfig::default());
    rig.boot();
    let request = t(0);
    rig.issue(request);
    let run = rig.follow_until(request, Some(ProgressCode::FEEDING_TO_FSENSOR), 60_000);
    assert_eq!(run.last.param, ParamCode::Processing);

    // The motor seizes, its Hall sensor stuck between its thresholds.
    rig.inject(Fault::MotorDead { slot: 0 });
    let seized_at = rig.now;
    let mut last_driven = None;
    for _ in 0..60_000 {
        if step_with_hall_stuck(&mut rig, 0, 2048)[0].is_driving() {
            last_driven = Some(rig.now);
        }
    }
    let driven_ms = last_driven.map_or(0, |at| at - seized_at);
    assert!(
        driven_ms <= u64::from(mmu_firmware::phases::STILL_MS) + 100,
        "the motor was driven {driven_ms} ms without a revolution"
    );
    assert!(rig.motors_stopped());
    let answer = rig.query();
    assert_eq!((answer.code, answer.param), (RequestCode::Tool, ParamCode::Error));
}

/// Finding 2: `stall_min_duty` (0x44) above `max_duty` (0x43) switched the stall rule off (no
/// duty reaches it); both writes that would make it so are refused, the pair as the sensor
/// thresholds' on/off pair is (the guards' `stall_duty_within_max`).
#[test]
fn the_stall_rule_cannot_be_switched_off_through_its_registers() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let write = |rig: &mut Rig<3>, address: u8, value: u16| {
        rig.send(Request::write(address, value))
            .map(|answer| answer.param)
    };
    // Above the highest duty: refused.
    assert_eq!(write(&mut rig, 0x44, 1000), Some(ParamCode::Accepted));
    assert_eq!(write(&mut rig, 0x43, 900), Some(ParamCode::Rejected));
    assert_eq!(write(&mut rig, 0x44, 700), Some(ParamCode::Accepted));
    assert_eq!(write(&mut rig, 0x43, 700), Some(ParamCode::Accepted));
    assert_eq!(write(&mut rig, 0x44, 701), Some(ParamCode::Rejected));
    let config = rig.app.config();
    assert_eq!((config.max_duty, config.stall_min_duty), (700, 700));
}

/// A stored set below the defaults (highest duty 200, stall duty 150, and speeds that duty can
/// give) comes back whole: the stored settings go in together and the guards judge them once,
/// so the highest duty, which the default stall duty (250) and speeds alone would refuse, is
/// taken with the rest.
#[test]
fn a_stored_duty_pair_below_the_defaults_is_restored() {
    let mut app = mmu_firmware::App::<3>::new(Config::default());
    let mut snapshot = mmu_firmware::persist::Snapshot::<3>::default();
    for setting in [(0x0d, 25), (0x11, 25), (0x14, 15), (0x43, 200), (0x44, 150)] {
        snapshot.settings.push(setting).unwrap();
    }
    app.restore(&snapshot);
    assert_eq!((app.config().max_duty, app.config().stall_min_duty), (200, 150));
    assert_eq!(app.config().slow_speed, 15);
}

/// Odometry 5 mm short of where an `i32` of hundredths ends (21.47 km): the next moves cross it.
const NEAR_THE_END: i32 = i32::MAX - 500;

/// Finding 1: the odometry saturated at 21.47 km fed per power-on, after which distances stopped
/// counting: feeds to a distance never got there, parking went wrong. Odometry wraps and every
/// distance is the difference of two readings: slots past it change tools as fresh ones do,
/// crossing the end both ways.
#[test]
fn a_slot_that_has_fed_past_21_km_changes_tools_as_a_fresh_one() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.app.set_odometry_centi(0, NEAR_THE_END);
    rig.app.set_odometry_centi(1, NEAR_THE_END);
    let run = rig.command(t(0));
    assert_eq!(run.last.param, ParamCode::Finished, "{run:?}");
    assert_eq!(rig.model.loaded_slot(), Some(0));
    // Slot 0's unload crosses the other end (pulled back past `i32::MIN`).
    rig.app.set_odometry_centi(0, i32::MIN + 500);
    let run = rig.command(t(1));
    assert_eq!(run.last.param, ParamCode::Finished, "{run:?}");
    assert_eq!(rig.model.loaded_slot(), Some(1));
    common::assert_parked(&rig, 0);
    let run = rig.command(t(0));
    assert_eq!(run.last.param, ParamCode::Finished, "{run:?}");
    common::assert_parked(&rig, 1);
}

/// How far `T0` feeds slot 0 with the hub sensor's threshold set above anything it reads (it
/// never sees the tip), slot 0's odometry starting from `odometry_centi`: the feeds to the hub
/// go their distance bounds and the command fails.
fn fed_with_a_blind_hub_sensor(odometry_centi: i32) -> f32 {
    let mut rig = Rig::<3>::new();
    rig.boot();
    for (address, value) in [(0x90, 4000), (0xa0, 3900)] {
        let answer = rig.send(Request::write(address, value));
        assert_eq!(answer.map(|a| a.param), Some(ParamCode::Accepted));
    }
    rig.app.set_odometry_centi(0, odometry_centi);
    let tip = rig.model.tip_mm(0).unwrap();
    let request = t(0);
    rig.issue(request);
    let run = rig.follow(request, 120_000);
    assert_eq!(run.last.param, ParamCode::Error, "{run:?}");
    rig.model.tip_mm(0).unwrap() - tip
}

/// Finding 1: bounded feeds crossing the end of the odometry still stop at their bounds, where
/// they stop on a fresh slot (before the fix they ran out their time bounds instead).
#[test]
fn a_bounded_feed_across_the_end_of_the_odometry_stops_at_its_bound() {
    let fresh = fed_with_a_blind_hub_sensor(0);
    let worn = fed_with_a_blind_hub_sensor(NEAR_THE_END);
    assert!(
        (worn - fresh).abs() <= 1.0,
        "fed {worn} mm across the end of the odometry, {fresh} mm fresh"
    );
}
