//! Acceptance tests of the physical model: motion, stalls, slip, sensors, extruder, faults and
//! determinism.

use mmu_model::{Duty, Fault, FaultKind, Model, ModelConfig, MotorCommand, Rail, SensorId, SlotSamples};

const SLOTS: usize = 3;
const MID: u16 = 2048;

fn forward(permille: u16) -> MotorCommand {
    MotorCommand::forward(Duty::from_permille(permille))
}

fn reverse(permille: u16) -> MotorCommand {
    MotorCommand::reverse(Duty::from_permille(permille))
}

/// Slot 0 does `command`, the others coast.
fn only_slot0(command: MotorCommand) -> [MotorCommand; SLOTS] {
    [command, MotorCommand::Coast, MotorCommand::Coast]
}

fn model() -> Model {
    Model::new(ModelConfig::default(), SLOTS, 1)
}

fn tip(m: &Model, slot: usize) -> f32 {
    m.tip_mm(slot).expect("slot has filament")
}

fn median5(window: &[u16]) -> u16 {
    let mut w = [0u16; 5];
    w.copy_from_slice(&window[window.len() - 5..]);
    w.sort_unstable();
    w[2]
}

/// A simple revolution counter as the logic would build it: median of 5, then a Schmitt
/// trigger around mid-scale; counts rising crossings.
struct HallCounter {
    window: Vec<u16>,
    high: Option<bool>,
    periods: u32,
}

impl HallCounter {
    fn new() -> Self {
        HallCounter {
            window: Vec::new(),
            high: None,
            periods: 0,
        }
    }

    fn push(&mut self, raw: u16) {
        self.window.push(raw);
        if self.window.len() < 5 {
            return;
        }
        let v = median5(&self.window);
        self.window.remove(0);
        if v > MID + 300 {
            if self.high == Some(false) {
                self.periods += 1;
            }
            self.high = Some(true);
        } else if v < MID - 300 {
            self.high = Some(false);
        }
    }
}

/// Step slot 0 with `command` for `ms`, sampling its motor Hall every ms into `counter`.
fn run_counting(m: &mut Model, ms: u32, command: MotorCommand, counter: &mut HallCounter) {
    for _ in 0..ms {
        m.step(1, &only_slot0(command));
        counter.push(m.sample_slot(0).unwrap().motion);
    }
}

#[test]
fn full_duty_feed_reaches_configured_speed() {
    let mut m = model();
    let start = tip(&m, 0);
    assert_eq!(start, -15.0);
    m.step(40, &only_slot0(forward(1000)));
    // One time constant: 1 - 1/e of the target.
    let v = m.motor_speed_mm_s(0).unwrap();
    assert!((v - 150.0 * 0.632).abs() < 3.0, "speed after one tau {v}");
    m.step(160, &only_slot0(forward(1000)));
    let (t0, r0) = (tip(&m, 0), m.motor_revolutions(0).unwrap());
    m.step(200, &only_slot0(forward(1000)));
    let (t1, r1) = (tip(&m, 0), m.motor_revolutions(0).unwrap());
    let speed = (t1 - t0) / 0.2;
    assert!((speed - 150.0).abs() < 3.0, "tip speed {speed} mm/s");
    assert!(((r1 - r0) * 2.0 - (t1 - t0)).abs() < 0.01, "2 mm per revolution");
    // The other slots stayed parked.
    assert_eq!(tip(&m, 1), -15.0);
    assert_eq!(tip(&m, 2), -15.0);
    assert!(m.hub_filament_present());
    assert_eq!(m.loaded_slot(), Some(0));
}

#[test]
fn half_duty_is_half_speed_and_dead_band_does_not_move() {
    let mut m = model();
    m.step(300, &only_slot0(forward(500)));
    let v = m.motor_speed_mm_s(0).unwrap();
    assert!((v - 75.0).abs() < 1.0, "half duty speed {v}");

    let mut m = model();
    m.step(1000, &only_slot0(forward(50)));
    assert_eq!(tip(&m, 0), -15.0);
    assert_eq!(m.motor_revolutions(0), Some(0.0));
}

#[test]
fn brake_stops_quickly_coast_runs_on() {
    let mut braked = model();
    braked.step(300, &only_slot0(forward(1000)));
    let mut coasted = braked.clone();
    let t = tip(&braked, 0);
    braked.step(300, &only_slot0(MotorCommand::Brake));
    coasted.step(300, &only_slot0(MotorCommand::Coast));
    let brake_run = tip(&braked, 0) - t;
    let coast_run = tip(&coasted, 0) - t;
    assert!(brake_run < 1.0, "brake run-out {brake_run}");
    assert!(coast_run > 5.0 * brake_run, "coast run-out {coast_run}");
    assert!(braked.motor_speed_mm_s(0).unwrap().abs() < 0.01);
}

#[test]
fn reverse_retracts_and_a_full_eject_loses_the_grip() {
    let c = ModelConfig::default();
    // The slot sensor sits just after the drive gear, so a reverse drive pulls the tip past it
    // while the gear still grips the filament.
    assert!(c.drive_gear_mm < c.slot_sensor_mm);
    let mut m = model();
    let mut ms = 0;
    while m.slot_filament_present(0) == Some(true) {
        assert!(ms < 1000, "the slot sensor never cleared");
        m.step(1, &only_slot0(reverse(1000)));
        ms += 1;
    }
    let cleared = tip(&m, 0);
    assert!(
        cleared < c.slot_sensor_mm && cleared > c.slot_sensor_mm - 0.5,
        "clears as the tip passes the slot sensor: {cleared}"
    );
    assert!(cleared > c.drive_gear_mm, "still in the gear: {cleared}");
    // Still gripped: the motor keeps pulling the filament back at full speed.
    m.step(1, &only_slot0(reverse(1000)));
    ms += 1;
    assert!(tip(&m, 0) < cleared - 0.1, "still pulled back: {}", tip(&m, 0));
    let v = m.motor_speed_mm_s(0).unwrap();
    assert!((v + 150.0).abs() < 3.0, "full reverse speed {v}");
    // Then the tip leaves the gear and the grip is lost just behind it.
    m.step(1000 - ms, &only_slot0(reverse(1000)));
    let t = tip(&m, 0);
    assert!(
        t < c.drive_gear_mm && t > c.drive_gear_mm - 1.0,
        "stops just behind the drive gear: {t}"
    );
    assert_eq!(m.slot_filament_present(0), Some(false), "past the slot sensor");
    // The motor spins but can no longer move the filament in either direction.
    let revs = m.motor_revolutions(0).unwrap();
    m.step(500, &only_slot0(forward(1000)));
    assert_eq!(tip(&m, 0), t);
    assert!(m.motor_revolutions(0).unwrap() - revs > 30.0);
    // Re-inserted to the gear, it is gripped again and fed back past the slot sensor.
    assert!(m.insert_filament(0, c.drive_gear_mm + 1.0));
    m.step(300, &only_slot0(forward(1000)));
    assert!(tip(&m, 0) > c.drive_gear_mm + 30.0, "tip {}", tip(&m, 0));
    assert_eq!(m.slot_filament_present(0), Some(true));
}

#[test]
fn jam_stalls_the_motor() {
    // Control: the same counter sees about 75 periods per second of free feeding.
    let mut free = model();
    let mut counter = HallCounter::new();
    run_counting(&mut free, 1000, forward(1000), &mut counter);
    let revs = free.motor_revolutions(0).unwrap();
    assert!(revs > 65.0);
    assert!(
        (counter.periods as f32 - revs).abs() <= 2.0,
        "{} vs {revs}",
        counter.periods
    );

    let mut m = model();
    assert!(m.inject(Fault::Jam { slot: 0 }));
    let mut counter = HallCounter::new();
    run_counting(&mut m, 1000, forward(1000), &mut counter);
    assert_eq!(counter.periods, 0);
    assert_eq!(tip(&m, 0), -15.0);
    assert!(m.motor_revolutions(0).unwrap().abs() < 0.01);
    // It can be pulled back, and pushed up to the jam again but not past it.
    m.step(100, &only_slot0(reverse(1000)));
    assert!(tip(&m, 0) < -20.0);
    m.step(500, &only_slot0(forward(1000)));
    assert!((tip(&m, 0) + 15.0).abs() < 1e-3);
    // Cleared, it moves.
    assert!(m.clear(FaultKind::Jam(0)));
    m.step(200, &only_slot0(forward(1000)));
    assert!(tip(&m, 0) > 0.0);
}

#[test]
fn slip_moves_the_filament_by_the_ratio() {
    let mut m = model();
    assert!(m.inject(Fault::Slip { slot: 0, ratio: 0.5 }));
    let mut counter = HallCounter::new();
    run_counting(&mut m, 500, forward(1000), &mut counter);
    let moved = tip(&m, 0) + 15.0;
    let motor_mm = m.motor_revolutions(0).unwrap() * 2.0;
    assert!(
        (moved / motor_mm - 0.5).abs() < 0.01,
        "moved {moved} for {motor_mm} of motor"
    );
    let counted_mm = counter.periods as f32 * 2.0;
    assert!((moved / counted_mm - 0.5).abs() < 0.05, "counted {counted_mm}");
}

#[test]
fn motor_dead_neither_moves_nor_changes_hall() {
    let mut m = model();
    assert!(m.inject(Fault::MotorDead { slot: 0 }));
    let mut counter = HallCounter::new();
    run_counting(&mut m, 500, forward(1000), &mut counter);
    assert_eq!(counter.periods, 0);
    assert_eq!(tip(&m, 0), -15.0);
    assert_eq!(m.motor_revolutions(0), Some(0.0));
    assert!(m.clear(Fault::MotorDead { slot: 0 }));
    m.step(200, &only_slot0(forward(1000)));
    assert!(tip(&m, 0) > 0.0);
}

#[test]
fn rest_noise_never_crosses_a_mid_threshold() {
    // Without spikes, raw samples stay far below the threshold.
    let config = ModelConfig {
        spike_probability: 0.0,
        ..ModelConfig::default()
    };
    let mut m = Model::new(config, SLOTS, 3);
    let (mut sum, mut sum_sq) = (0.0f64, 0.0f64);
    for _ in 0..10_000 {
        let s = m.sample_hub().filament;
        assert!(s < 2400, "raw {s}");
        let x = f64::from(s) - f64::from(MID);
        sum += x;
        sum_sq += x * x;
    }
    let sigma = (sum_sq / 10_000.0 - (sum / 10_000.0).powi(2)).sqrt();
    assert!((sigma - 15.0).abs() < 1.5, "sigma {sigma}");

    // With the default spikes, raw samples do spike, but a median of 5 never crosses.
    let mut m = model();
    let mut window = Vec::new();
    let mut spikes = 0;
    for _ in 0..10_000 {
        let s = m.sample_hub().filament;
        if s.abs_diff(MID) > 400 {
            spikes += 1;
        }
        window.push(s);
        if window.len() >= 5 {
            assert!(median5(&window) < 2400);
            window.remove(0);
        }
    }
    assert!((5..=60).contains(&spikes), "spikes {spikes}");
}

#[test]
fn sensor_noise_fault_raises_sigma() {
    let mut m = model();
    assert!(m.inject(Fault::SensorNoise { sigma: 200.0 }));
    let wide = (0..2000)
        .filter(|_| m.sample_hub().cutter.abs_diff(MID) > 150)
        .count();
    assert!(wide > 500, "{wide}");
    assert!(!m.inject(Fault::SensorNoise { sigma: f32::NAN }));
    assert!(m.clear(FaultKind::SensorNoise));
    let wide = (0..2000)
        .filter(|_| m.sample_hub().cutter.abs_diff(MID) > 150)
        .count();
    assert!(wide < 20, "{wide}");
}

#[test]
fn disconnected_sensors_read_at_the_rail() {
    let mut m = model();
    assert!(m.inject(Fault::SensorDisconnected {
        sensor: SensorId::HubFilament,
        rail: Rail::High
    }));
    assert!(m.inject(Fault::SensorDisconnected {
        sensor: SensorId::MotorHall(1),
        rail: Rail::Low
    }));
    assert!(m.inject(Fault::SensorDisconnected {
        sensor: SensorId::SlotFilament(2),
        rail: Rail::High
    }));
    assert!(!m.inject(Fault::SensorDisconnected {
        sensor: SensorId::MotorHall(3),
        rail: Rail::Low
    }));
    for _ in 0..1000 {
        m.step(1, &[forward(1000); SLOTS]);
        let s = m.samples::<SLOTS>();
        assert_eq!(s.hub.filament, 4095);
        assert_eq!(s.slots[1].motion, 0);
        assert_eq!(s.slots[2].filament, 4095);
        assert_ne!(s.hub.tension, 0);
    }
    assert_eq!(m.active_faults().len(), 3);
    assert!(m.clear(FaultKind::SensorDisconnected(SensorId::HubFilament)));
    assert!(!m.clear(FaultKind::SensorDisconnected(SensorId::HubFilament)));
    let hub = m.sample_hub().filament;
    assert!(hub > 2600 && hub < 4095, "filament at the hub: {hub}");
    m.clear_all();
    assert!(m.active_faults().is_empty());
    assert!(m.sample_slot(1).unwrap().motion > 0);
}

#[test]
fn extruder_pulls_a_gripped_filament_and_back_drives_a_coasting_motor() {
    let c = ModelConfig::default();
    // Inside the extruder gears, far enough from the nozzle for the whole 20 mm move.
    let start = c.extruder_gears_mm + 16.0;
    assert!(start + 20.0 < c.nozzle_mm);
    let mut m = model();
    assert!(m.insert_filament(0, start));
    assert_eq!(m.fsensor_state(), 1);
    m.extruder_move(20.0, 10.0);
    assert!(m.extruder_busy());
    let mut max_tension = 0.0f32;
    for _ in 0..2500 {
        m.step(1, &only_slot0(MotorCommand::Coast));
        max_tension = max_tension.max(m.tension_mm().abs());
    }
    assert!(!m.extruder_busy());
    assert!((tip(&m, 0) - (start + 20.0)).abs() < 0.01, "tip {}", tip(&m, 0));
    let revs = m.motor_revolutions(0).unwrap();
    assert!((revs - 10.0).abs() < 0.2, "back-driven revolutions {revs}");
    assert!(max_tension < 0.5, "coasting motor follows: {max_tension}");

    // A braked motor holds: the extruder pulls the buffer taut, then its gears slip.
    let mut m = model();
    m.insert_filament(0, start);
    m.extruder_move(20.0, 10.0);
    m.step(2500, &only_slot0(MotorCommand::Brake));
    assert!(
        (tip(&m, 0) - (start + c.buffer_limit_mm)).abs() < 0.01,
        "tip {}",
        tip(&m, 0)
    );
    assert!((m.tension_mm() - c.buffer_limit_mm).abs() < 1e-3);
    assert_eq!(m.motor_revolutions(0), Some(0.0));
    let tension = m.sample_hub().tension;
    assert!(tension > 2048 + 800, "taut reads high: {tension}");
    assert_eq!(m.extruder_position_mm(), 20.0);
}

/// A Bowden tube with drag (`bowden_drag_mm_per_m`): an extruder pulling the filament through it
/// holds the buffer taut by the drag against a coasting lane (more for a longer tube); once it
/// stops, the lane lets the buffer back to rest.
#[test]
fn a_tube_s_drag_holds_the_buffer_taut_while_the_extruder_pulls() {
    let settled = |tube_mm: f32| {
        let c = ModelConfig {
            bowden_drag_mm_per_m: 1.0,
            ..ModelConfig::default()
        }
        .with_bowden_length(tube_mm);
        let mut m = Model::new(c.clone(), SLOTS, 1);
        assert!(m.insert_filament(0, c.extruder_gears_mm + 16.0));
        m.set_printing(Some(5.0));
        m.step(2000, &only_slot0(MotorCommand::Coast));
        let pulling = m.tension_mm();
        m.set_printing(None);
        m.step(2000, &only_slot0(MotorCommand::Coast));
        (pulling, m.tension_mm())
    };
    let (two_m, two_m_after) = settled(2000.0);
    let (five_m, _) = settled(5000.0);
    assert!((two_m - 2.0).abs() < 0.05, "2 m of tube: {two_m} mm");
    assert!((five_m - 5.0).abs() < 0.05, "5 m of tube: {five_m} mm");
    assert!(
        two_m_after.abs() < 0.05,
        "at rest once the extruder stops: {two_m_after} mm"
    );
}

/// A drive gear that slips cannot hold the filament against the extruder: the printer's retract
/// pulls it back through the braked, slipping lane (a gear that slips under the unit's own motor
/// slips under the extruder's pull too). The slipping gear used to hold like a sound one, and
/// left the tip in the printer's gears once the fault cleared.
#[test]
fn a_slipping_drive_gives_way_to_the_extruder() {
    let c = ModelConfig::default();
    let start = c.extruder_gears_mm + 30.0;
    let mut m = model();
    assert!(m.insert_filament(0, start));
    assert!(m.inject(Fault::Slip { slot: 0, ratio: 0.5 }));
    m.extruder_move(-20.0, 10.0);
    m.step(2500, &only_slot0(MotorCommand::Brake));
    assert!(!m.extruder_busy());
    assert!((tip(&m, 0) - (start - 20.0)).abs() < 0.5, "tip {}", tip(&m, 0));
    // Sound again, the braked lane holds: the extruder's gears slip instead.
    assert!(m.clear(Fault::Slip { slot: 0, ratio: 0.5 }));
    let held = tip(&m, 0);
    m.extruder_move(-20.0, 10.0);
    m.step(2500, &only_slot0(MotorCommand::Brake));
    assert!(
        held - tip(&m, 0) <= c.buffer_limit_mm + 0.01,
        "tip {}",
        tip(&m, 0)
    );
}

#[test]
fn extruder_on_a_tip_before_its_gears_turns_on_air() {
    let c = ModelConfig::default();
    let mut m = model();
    m.extruder_move(50.0, 20.0);
    m.step(3000, &only_slot0(MotorCommand::Coast));
    assert_eq!(tip(&m, 0), c.start_tip_mm);
    assert!(!m.extruder_busy());
    assert_eq!(m.extruder_position_mm(), 50.0);

    // Also in the Bowden, past the printer's filament sensor, just before the gears.
    let before_gears = c.extruder_gears_mm - 2.0;
    assert!(before_gears > c.bowden_length_mm);
    let mut m = model();
    m.insert_filament(0, before_gears);
    assert_eq!(m.fsensor_state(), 1);
    m.set_printing(Some(5.0));
    m.extruder_move(-30.0, 20.0);
    m.step(3000, &only_slot0(MotorCommand::Brake));
    assert_eq!(tip(&m, 0), before_gears);
    assert_eq!(m.tension_mm(), 0.0);
}

#[test]
fn load_to_nozzle_print_and_unload() {
    let c = ModelConfig::default();
    // An extruder move from the gears that reaches 10 mm past the nozzle.
    let past_nozzle = c.nozzle_mm - c.extruder_gears_mm + 10.0;
    let mut m = model();
    // The slot motor pushes the tip to the idle extruder gears: it stops there, compresses the
    // buffer and stalls.
    m.step(4000, &only_slot0(forward(1000)));
    assert!(
        (tip(&m, 0) - c.extruder_gears_mm).abs() < 1e-3,
        "tip {}",
        tip(&m, 0)
    );
    assert!(
        (m.tension_mm() + c.buffer_limit_mm).abs() < 1e-3,
        "compressed {}",
        m.tension_mm()
    );
    assert!(m.motor_speed_mm_s(0).unwrap().abs() < 5.0);
    assert_eq!(m.fsensor_state(), 1);
    let tension = m.sample_hub().tension;
    assert!(tension < 2048 - 800, "compressed reads low: {tension}");

    // The extruder takes it to the nozzle while the motor coasts and the buffer relaxes.
    m.extruder_move(past_nozzle, 20.0);
    m.step(4000, &only_slot0(MotorCommand::Coast));
    assert!(!m.extruder_busy());
    assert_eq!(tip(&m, 0), c.nozzle_mm);
    assert_eq!(m.fsensor_state(), 2);
    assert!(m.tension_mm().abs() < 0.1);

    // Printing uses filament; the tip stays at the nozzle, the slot side follows.
    let tail = m.tail_mm(0).unwrap();
    m.set_printing(Some(5.0));
    m.step(10_000, &only_slot0(MotorCommand::Coast));
    assert_eq!(tip(&m, 0), c.nozzle_mm);
    assert!((m.tail_mm(0).unwrap() - tail - 50.0).abs() < 0.5);
    m.set_printing(None);

    // Unload: the extruder retracts the tip out of its gears (the rest of its move turns on
    // air), then the motor pulls back to park.
    m.extruder_move(-past_nozzle, 40.0);
    m.step(2000, &only_slot0(MotorCommand::Coast));
    assert!(!m.extruder_busy());
    assert!(
        (tip(&m, 0) - c.extruder_gears_mm).abs() < 1e-3,
        "tip {}",
        tip(&m, 0)
    );
    assert_eq!(m.fsensor_state(), 1);
    m.step(2800, &only_slot0(reverse(1000)));
    let parked = tip(&m, 0);
    assert!(
        parked < c.start_tip_mm && parked > c.slot_sensor_mm,
        "tip {parked}"
    );
    assert_eq!(m.slot_filament_present(0), Some(true), "not ejected");
    assert_eq!(m.fsensor_state(), 0);
    assert_eq!(m.loaded_slot(), None);
}

#[test]
fn bowden_jam_stops_the_tip_and_compresses_the_buffer() {
    let mut m = model();
    assert!(m.inject(Fault::BowdenJam));
    m.step(3000, &only_slot0(forward(1000)));
    assert!((tip(&m, 0) - 200.0).abs() < 1e-3, "tip {}", tip(&m, 0));
    assert!((m.tension_mm() + 6.0).abs() < 1e-3);
    let revs = m.motor_revolutions(0).unwrap();
    m.step(500, &only_slot0(forward(1000)));
    assert!((m.motor_revolutions(0).unwrap() - revs).abs() < 0.05, "stalled");
    // Pulling back works.
    m.step(500, &only_slot0(reverse(1000)));
    assert!(tip(&m, 0) < 180.0);
    assert_eq!(m.tension_mm(), 0.0);
}

#[test]
fn only_one_filament_passes_the_merge() {
    let mut m = model();
    m.step(500, &only_slot0(forward(1000)));
    assert!(tip(&m, 0) > 0.0);
    m.step(500, &[MotorCommand::Brake, forward(1000), MotorCommand::Coast]);
    assert!(
        (tip(&m, 1) + 8.0).abs() < 1e-3,
        "slot 1 stops at the merge: {}",
        tip(&m, 1)
    );
    assert_eq!(m.loaded_slot(), Some(0));
}

#[test]
fn spool_runout_clears_the_slot_sensor() {
    let c = ModelConfig::default();
    let mut m = model();
    let before = m.sample_slot(0).unwrap().filament;
    assert!(before > 2600, "filament present reads high: {before}");
    assert!(m.inject(Fault::SpoolRunout { slot: 0 }));
    assert_eq!(m.slot_filament_present(0), Some(false));
    let mut window = Vec::new();
    for _ in 0..100 {
        window.push(m.sample_slot(0).unwrap().filament);
    }
    let mut sorted = window.clone();
    sorted.sort_unstable();
    assert!(sorted[50] < 2200, "median {}", sorted[50]);
    // The slot sensor sits just after the drive gear, so the tail left just past the sensor
    // has already left the gear: there is nothing to push, the motor spins on air.
    assert!(c.slot_sensor_mm > c.drive_gear_mm);
    let revs = m.motor_revolutions(0).unwrap();
    m.step(1000, &only_slot0(forward(1000)));
    assert_eq!(tip(&m, 0), c.start_tip_mm, "nothing left to push");
    assert!(
        m.motor_revolutions(0).unwrap() > revs + 60.0,
        "motor spins on air"
    );
    assert_eq!(m.slot_filament_present(0), Some(false));
    // A refilled spool is gripped again.
    assert!(m.clear(Fault::SpoolRunout { slot: 0 }));
    assert_eq!(m.slot_filament_present(0), Some(true));
    m.step(300, &only_slot0(forward(1000)));
    assert!(tip(&m, 0) > c.start_tip_mm + 10.0, "tip {}", tip(&m, 0));
}

#[test]
fn spool_runout_with_the_sensor_behind_the_gear_pushes_the_rest() {
    // A slot sensor 20 mm behind the drive gear: the runout leaves the tail 0.1 mm past the
    // sensor, still behind the gear, so the motor can push the rest of the filament until its
    // tail leaves the gear.
    let d = ModelConfig::default();
    let c = ModelConfig {
        slot_sensor_mm: d.drive_gear_mm - 20.0,
        ..d
    };
    let mut m = Model::new(c.clone(), SLOTS, 1);
    assert_eq!(m.slot_filament_present(0), Some(true));
    assert!(m.inject(Fault::SpoolRunout { slot: 0 }));
    assert_eq!(m.slot_filament_present(0), Some(false));
    m.step(1000, &only_slot0(forward(1000)));
    let t = tip(&m, 0);
    assert!((t - (c.start_tip_mm + 20.0 - 0.1)).abs() < 0.2, "tip {t}");
    let revs = m.motor_revolutions(0).unwrap();
    m.step(500, &only_slot0(forward(1000)));
    assert_eq!(tip(&m, 0), t, "nothing left to push");
    assert!(
        m.motor_revolutions(0).unwrap() > revs + 30.0,
        "motor spins on air"
    );
    assert_eq!(m.slot_filament_present(0), Some(false));
    // A refilled spool is gripped again.
    assert!(m.clear(Fault::SpoolRunout { slot: 0 }));
    assert_eq!(m.slot_filament_present(0), Some(true));
}

#[test]
fn same_seed_same_samples() {
    fn script(seed: u64) -> Vec<[SlotSamples; SLOTS]> {
        let mut m = Model::new(ModelConfig::default(), SLOTS, seed);
        let mut out = Vec::new();
        for i in 0..3000u32 {
            let cmd = match i / 500 {
                0 | 2 => forward(800),
                1 => reverse(600),
                3 => MotorCommand::Brake,
                _ => MotorCommand::Coast,
            };
            m.step(1, &[cmd, forward(300), MotorCommand::Coast]);
            if i == 1000 {
                m.inject(Fault::Slip { slot: 0, ratio: 0.7 });
            }
            let s = m.samples::<SLOTS>();
            out.push(s.slots);
            out.push([
                SlotSamples {
                    motion: s.hub.filament,
                    filament: s.hub.tension,
                    tension: 0,
                },
                SlotSamples {
                    motion: s.hub.cutter,
                    filament: 0,
                    tension: 0,
                },
                SlotSamples::default(),
            ]);
        }
        out
    }
    assert_eq!(script(42), script(42));
    assert_ne!(script(42), script(43));
}

#[test]
fn out_of_range_and_garbage_inputs_never_panic() {
    let c = ModelConfig::default();
    let mut m = Model::new(ModelConfig::default(), SLOTS, 9);
    assert_eq!(m.tip_mm(SLOTS), None);
    assert_eq!(m.motor_revolutions(99), None);
    assert_eq!(m.sample_slot(SLOTS), None);
    assert!(!m.inject(Fault::Jam { slot: SLOTS }));
    assert!(!m.inject(Fault::Slip {
        slot: 0,
        ratio: f32::NAN
    }));
    assert!(!m.insert_filament(0, f32::INFINITY));
    assert!(!m.insert_filament(7, 0.0));
    assert!(!m.remove_filament(7));
    assert!(!m.clear(FaultKind::BowdenJam));
    // More sample slots than the model has: the extra read 0.
    let s = m.samples::<8>();
    assert_eq!(s.slots[SLOTS], SlotSamples::default());
    // Fewer: fine.
    let _ = m.samples::<1>();
    let _ = m.samples::<0>();

    // A pseudo-random soak over commands, faults and extruder moves.
    let mut x: u64 = 0x1234_5678;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for _ in 0..3000 {
        let r = next();
        let slot = (r % 5) as usize;
        match (r >> 8) % 16 {
            0 => {
                m.inject(Fault::Jam { slot });
            }
            1 => {
                m.inject(Fault::BowdenJam);
            }
            2 => {
                m.inject(Fault::Slip {
                    slot,
                    ratio: ((r >> 20) % 300) as f32 / 100.0 - 1.0,
                });
            }
            3 => {
                m.inject(Fault::MotorDead { slot });
            }
            4 => {
                m.inject(Fault::SpoolRunout { slot });
            }
            5 => {
                m.inject(Fault::SensorDisconnected {
                    sensor: SensorId::SlotFilament(slot),
                    rail: Rail::Low,
                });
            }
            6 => m.clear_all(),
            7 => m.extruder_move(((r >> 20) % 200) as f32 - 100.0, ((r >> 30) % 60) as f32 - 5.0),
            8 => m.set_printing(Some(((r >> 20) % 10) as f32 - 2.0)),
            9 => {
                m.insert_filament(slot, ((r >> 20) % 700) as f32 - 200.0);
            }
            10 => {
                m.remove_filament(slot);
            }
            11 => m.extruder_move(f32::NAN, 10.0),
            _ => {}
        }
        let pick = |v: u64| match v % 5 {
            0 => MotorCommand::Coast,
            1 => MotorCommand::Brake,
            2 => forward((v >> 3) as u16 % 1200),
            _ => reverse((v >> 3) as u16 % 1200),
        };
        let cmds = [pick(next()), pick(next()), pick(next()), pick(next())];
        m.step((next() % 20) as u32, &cmds[..(next() % 5) as usize]);
        let s = m.samples::<4>();
        for slot in &s.slots {
            assert!(slot.motion <= 4095 && slot.filament <= 4095);
        }
        assert!(m.fsensor_state() <= 2);
        for i in 0..SLOTS {
            if let Some(t) = m.tip_mm(i) {
                assert!(t.is_finite() && t <= c.nozzle_mm, "tip {t}");
            }
        }
        assert!(m.tension_mm().abs() <= c.buffer_limit_mm + 1e-3);
    }

    // A hostile configuration is sanitized.
    let config = ModelConfig {
        motor_tau_ms: f32::NAN,
        mm_per_rev: 0.0,
        noise_sigma: -1.0,
        max_speed_mm_s: f32::INFINITY,
        ..ModelConfig::default()
    };
    let mut m = Model::new(config, usize::MAX, 0);
    assert_eq!(m.slot_count(), mmu_model::MAX_SLOTS);
    m.step(100, &[forward(1000)]);
    assert!(m.tip_mm(0).unwrap().is_finite());
    let _ = m.samples::<4>();
}
