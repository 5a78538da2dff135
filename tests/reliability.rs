//! Reliability findings of an outside review (issue 24, item 5), each a test that failed on the
//! code before its fix: a driven motor that never shows a revolution, the stall rule switched off.

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
    samples.slots[slot].motor_hall = hall;
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
/// thresholds' on/off pair is.
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
    assert_eq!(write(&mut rig, 0x44, 600), Some(ParamCode::Accepted));
    assert_eq!(write(&mut rig, 0x43, 600), Some(ParamCode::Accepted));
    assert_eq!(write(&mut rig, 0x44, 601), Some(ParamCode::Rejected));
    let config = rig.app.config();
    assert_eq!((config.max_duty, config.stall_min_duty), (600, 600));
}

/// A stored pair below the defaults (highest duty 200, stall duty 150) comes back whole: the
/// restore writes its settings twice, so the highest duty, refused while the default stall duty
/// (250) is above it, goes in once the stall duty has.
#[test]
fn a_stored_duty_pair_below_the_defaults_is_restored() {
    let mut app = mmu_firmware::App::<3>::new(Config::default());
    let mut snapshot = mmu_firmware::persist::Snapshot::<3>::default();
    snapshot.settings.push((0x43, 200)).unwrap();
    snapshot.settings.push((0x44, 150)).unwrap();
    app.restore(&snapshot);
    assert_eq!((app.config().max_duty, app.config().stall_min_duty), (200, 150));
}
