//! The unload faults users report, in the physics: a printer sensor that clears late, a
//! deformed or stringy tip the gears keep, a long Bowden tube, a printer that retracts slowly;
//! and the record of pulls against gripping gears.

use mmu_model::{Duty, Fault, FaultKind, Model, ModelConfig, MotorCommand, PullAgainstGrip};

const SLOTS: usize = 3;

fn reverse(permille: u16) -> MotorCommand {
    MotorCommand::reverse(Duty::from_permille(permille))
}

fn slot0(command: MotorCommand) -> [MotorCommand; SLOTS] {
    [command, MotorCommand::Coast, MotorCommand::Coast]
}

/// The Nextruder's order: the gears 10 mm before the sensor, which a retract can clear.
fn gears_first() -> ModelConfig {
    let c = ModelConfig::default();
    ModelConfig {
        extruder_gears_mm: c.bowden_length_mm - 10.0,
        ..c
    }
}

fn tip(m: &Model) -> f32 {
    m.tip_mm(0).expect("slot 0 has filament")
}

/// A model whose slot 0 filament reaches `past_gears` mm past the extruder's gears.
fn loaded(config: ModelConfig, past_gears: f32) -> Model {
    let mut m = Model::new(config, SLOTS, 1);
    let gears = m.config().extruder_gears_mm;
    assert!(m.insert_filament(0, gears + past_gears));
    m
}

/// Steps 1 ms at a time until the printer's sensor reads no filament; the ms it took.
fn ms_until_sensor_clear(m: &mut Model, motors: &[MotorCommand], limit_ms: u32) -> Option<u32> {
    (1..=limit_ms).find(|_| {
        m.step(1, motors);
        m.fsensor_state() == 0
    })
}

#[test]
fn a_late_sensor_reads_filament_for_its_delay_after_the_tip_left() {
    for delay_ms in [500u32, 8000] {
        let mut on_time = loaded(gears_first(), 20.0);
        let mut late = loaded(gears_first(), 20.0);
        assert!(late.inject(Fault::FsensorLate { delay_ms }));
        for m in [&mut on_time, &mut late] {
            m.extruder_move(-40.0, 20.0);
        }
        let coast = slot0(MotorCommand::Coast);
        let cleared = ms_until_sensor_clear(&mut on_time, &coast, 5000).expect("clears");
        let cleared_late = ms_until_sensor_clear(&mut late, &coast, 20_000).expect("clears late");
        // The filament moved the same way in both: only the reading lags.
        assert_eq!(cleared_late - cleared, delay_ms, "late by {delay_ms} ms");
        assert!(tip(&late) < late.config().bowden_length_mm);
    }
    // Cleared, the sensor reads the filament as it is at once.
    let mut m = loaded(gears_first(), 20.0);
    m.inject(Fault::FsensorLate { delay_ms: 8000 });
    m.extruder_move(-40.0, 20.0);
    m.step(3000, &slot0(MotorCommand::Coast));
    assert_eq!(m.fsensor_state(), 1);
    assert!(m.clear(FaultKind::FsensorLate));
    assert_eq!(m.fsensor_state(), 0);
}

#[test]
fn a_caught_tip_stays_in_the_gears_until_it_is_its_length_behind_them() {
    let catch = 15.0;
    let mut m = loaded(ModelConfig::default(), 20.0);
    let gears = m.config().extruder_gears_mm;
    assert!(m.inject(Fault::TipCatch { slot: 0, mm: catch }));
    // The printer's retract takes the tip 5 mm behind its gears: without the fault the tip is
    // free there; with it the gears still hold it, and a motor pulling at full duty stalls.
    m.extruder_move(-25.0, 20.0);
    m.step(2000, &slot0(MotorCommand::Coast));
    assert!((tip(&m) - (gears - 5.0)).abs() < 0.05, "tip {}", tip(&m));
    m.step(1000, &slot0(reverse(1000)));
    assert!((tip(&m) - (gears - 5.0)).abs() < 0.05, "held: tip {}", tip(&m));
    // An extra retract of 11 mm lets it go: the motor pulls it back.
    m.extruder_move(-11.0, 20.0);
    m.step(1000, &slot0(MotorCommand::Coast));
    m.step(500, &slot0(reverse(1000)));
    assert!(tip(&m) < gears - catch - 20.0, "free: tip {}", tip(&m));

    // The same filament without the fault leaves the gears with the first retract.
    let mut clean = loaded(ModelConfig::default(), 20.0);
    clean.extruder_move(-25.0, 20.0);
    clean.step(2000, &slot0(MotorCommand::Coast));
    clean.step(500, &slot0(reverse(1000)));
    assert!(tip(&clean) < gears - 20.0, "tip {}", tip(&clean));
}

#[test]
fn a_slow_retract_moves_the_tip_at_its_fraction_of_the_speed() {
    for factor in [0.5f32, 0.25] {
        let mut m = loaded(ModelConfig::default(), 50.0);
        assert!(m.inject(Fault::SlowRetract { factor }));
        let start = tip(&m);
        m.extruder_move(-20.0, 20.0);
        m.step(500, &slot0(MotorCommand::Coast));
        // 0.5 s at 20 mm/s is 10 mm; the slow extruder does `factor` of it.
        let moved = start - tip(&m);
        assert!((moved - 10.0 * factor).abs() < 0.05, "{factor}: moved {moved}");
        assert!(m.extruder_busy());
        // Its feeds keep their speed.
        m.clear(FaultKind::SlowRetract);
        m.extruder_move(10.0, 20.0);
        let before = tip(&m);
        m.step(250, &slot0(MotorCommand::Coast));
        assert!((tip(&m) - before - 5.0).abs() < 0.05);
    }
}

#[test]
fn a_long_bowden_keeps_the_extruder_s_distances_and_takes_longer_to_reach() {
    let default = ModelConfig::default();
    for metres in [1.0f32, 5.0] {
        let config = default.with_bowden_length(metres * 1000.0);
        assert_eq!(config.bowden_length_mm, metres * 1000.0);
        assert_eq!(
            config.extruder_gears_mm - config.bowden_length_mm,
            default.extruder_gears_mm - default.bowden_length_mm
        );
        assert_eq!(
            config.nozzle_mm - config.extruder_gears_mm,
            default.nozzle_mm - default.extruder_gears_mm
        );
        // Full speed from the park position reaches the printer's sensor only after the tube.
        let mut m = Model::new(config.clone(), SLOTS, 1);
        let forward = slot0(MotorCommand::forward(Duty::from_permille(1000)));
        let at = (1..=60_000u32)
            .find(|_| {
                m.step(1, &forward);
                m.fsensor_state() != 0
            })
            .expect("reaches the sensor");
        let floor_ms = (config.bowden_length_mm - config.start_tip_mm) / config.max_speed_mm_s * 1000.0;
        assert!(f64::from(at) >= f64::from(floor_ms), "{metres} m: {at} ms");
        assert!(f64::from(at) < f64::from(floor_ms) + 200.0, "{metres} m: {at} ms");
    }
}

#[test]
fn pulls_against_gripping_gears_are_recorded_with_their_duty_and_length() {
    let mut m = loaded(ModelConfig::default(), 20.0);
    assert_eq!(m.max_pull_against_grip(), PullAgainstGrip::default());
    // A pull while the extruder retracts faster than the motor would: not against the grip.
    m.extruder_move(-5.0, 100.0);
    m.step(50, &slot0(reverse(300)));
    assert_eq!(m.max_pull_against_grip(), PullAgainstGrip::default());
    // The extruder idle, its gears holding the tip: 300 ms at 400 per mille, then 200 ms at 250.
    // The pull reaches the gears once it has taken up the tube's give (taut past 1 mm).
    m.step(300, &slot0(reverse(400)));
    m.step(200, &slot0(reverse(250)));
    let record = m.max_pull_against_grip();
    assert_eq!(record.max_duty_permille, 400);
    assert!((300..500).contains(&record.longest_ms), "{record:?}");
    assert_eq!(record.total_ms, record.longest_ms);
    let first = record.total_ms;
    // A break (the tube stays taut), then a shorter pull: the longest stays, the total adds up.
    m.step(10, &slot0(MotorCommand::Coast));
    m.step(100, &slot0(reverse(900)));
    let record = m.max_pull_against_grip();
    assert_eq!(
        (record.max_duty_permille, record.longest_ms, record.total_ms),
        (900, first, first + 100)
    );
    // Once the tip is out of the gears, pulling is free and not counted.
    m.extruder_move(-40.0, 40.0);
    m.step(1500, &slot0(MotorCommand::Coast));
    m.step(500, &slot0(reverse(1000)));
    assert_eq!(m.max_pull_against_grip().total_ms, first + 100);
    // Two runs' records merge.
    let merged = record.merged(PullAgainstGrip {
        max_duty_permille: 100,
        longest_ms: 700,
        total_ms: 1,
    });
    assert_eq!(
        (merged.max_duty_permille, merged.longest_ms, merged.total_ms),
        (900, 700, first + 101)
    );
}

/// The extruder pushes (ramming) while the motor pulls back: a pull at no more than
/// `extruder_grip_duty_permille` loses, the motor dragged along and the push unslowed; a full
/// pull makes the gears slip and holds the tip back.
#[test]
fn a_weak_pull_loses_to_the_gripping_gears_and_a_full_one_makes_them_slip() {
    let grip = ModelConfig::default().extruder_grip_duty_permille;
    let pushed = |permille: u16| {
        let mut m = loaded(ModelConfig::default(), 5.0);
        let from = tip(&m);
        m.extruder_move(30.0, 10.0);
        m.step(3000, &slot0(reverse(permille)));
        tip(&m) - from
    };
    let weak = pushed(grip);
    assert!((weak - 30.0).abs() < 0.5, "the push went {weak} of 30 mm");
    let full = pushed(1000);
    assert!(full < 25.0, "a full pull held the push to {full} mm");
}
