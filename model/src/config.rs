//! Every physical constant of the model, with realistic defaults.

use mmu_hal_port::MotionSensor;

/// The physical constants of a [`Model`](crate::Model).
///
/// Positions are filament-tip positions in mm along the filament path, relative to the hub
/// filament sensor (0); negative is towards the spool. The geometry is expected to increase
/// along the path (`drive_gear_mm < slot_sensor_mm < merge_mm < 0 < bowden_jam_mm <
/// bowden_length_mm < extruder_gears_mm < nozzle_mm`); other values never panic, they just
/// make little physical sense. Non-finite or negative times, speeds and levels are replaced
/// by their defaults when the model is built.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelConfig {
    /// Slot filament sensor position, mm. Default −95: just after the drive gear, so a reverse
    /// drive can pull the tip past it (that is how an eject knows it is done).
    pub slot_sensor_mm: f32,
    /// Slot drive gear (the motor's grip on the filament), mm. A filament whose tip is behind
    /// it is not gripped: the motor spins, the filament stays. Default −100.
    pub drive_gear_mm: f32,
    /// Where the slot paths merge into the single hub path, mm. While one slot's filament
    /// reaches past it, no other slot's tip can pass it (the motor stalls). Default −8 (between
    /// the logic's park position, about −15, and the hub sensor).
    pub merge_mm: f32,
    /// Where every slot's tip rests at start, mm. Default −15 (parked).
    pub start_tip_mm: f32,
    /// Bowden length = the printer filament sensor's position, mm. Default 360.
    pub bowden_length_mm: f32,
    /// The printer's extruder gears, mm. Idle gears stop a tip pushed into them; turning
    /// forward they grip it. Default 364: a few mm below the filament sensor, as on an MK4, so
    /// the printer's extra load push after its sensor triggers reaches them.
    pub extruder_gears_mm: f32,
    /// The nozzle, mm. The tip never passes it: filament pushed further is extruded (used up).
    /// Default 420.
    pub nozzle_mm: f32,
    /// Where a [`Fault::BowdenJam`](crate::Fault::BowdenJam) blocks the Bowden tube, mm.
    /// Default 200.
    pub bowden_jam_mm: f32,
    /// Filament on each spool behind the tip at start (and after insertion or a cleared
    /// runout), mm. Default 100 000 (100 m).
    pub spool_filament_mm: f32,

    /// Filament speed at full duty, mm/s (`target = duty/1000 × this`). Default 150.
    pub max_speed_mm_s: f32,
    /// First-order time constant of a driven motor, ms. Default 40.
    pub motor_tau_ms: f32,
    /// Time constant of a braked motor running down, ms. Default 5.
    pub brake_tau_ms: f32,
    /// Time constant of a coasting motor running down (spool drag, gearbox friction), ms.
    /// Default 60.
    pub coast_tau_ms: f32,
    /// Duties below this (per mille) do not overcome the spool drag: the motor stays still.
    /// Default 80 (8 %).
    pub dead_band_permille: u16,
    /// Filament moved per motor revolution, mm (per turn of the sensed shaft: the drive gear for
    /// an angle sensor). Default 2.0.
    pub mm_per_rev: f32,
    /// What each lane's motion sensor reads. Default the Hall wave.
    pub motion_sensor: MotionSensor,
    /// Each lane has its own tension sensor (read from that lane's buffer). Default false.
    pub lane_tension: bool,

    /// A motor pulling back at this duty or less loses to extruder gears that grip the filament
    /// (per mille): at the taut limit it is dragged along with them, where a harder pull makes
    /// the gears slip. Default 300 (an assumption, not a measurement: extruder gears hold
    /// kilograms, a small gear motor at a third of its duty pulls a fraction of that).
    pub extruder_grip_duty_permille: u16,
    /// Travel of the hub's tension buffer each way from its rest, mm. Default 6.
    pub buffer_limit_mm: f32,
    /// Time constant with which a coasting (back-driven) motor lets the buffer relax while
    /// the extruder holds the filament, ms. Default 100.
    pub buffer_relax_ms: f32,
    /// How taut an extruder pulling the filament through the Bowden tube holds the buffer against
    /// a coasting lane, per metre of tube, mm: the tube's friction, which the extruder alone must
    /// overcome (the buffer's deflection stands for the force). Default 0: no friction was
    /// measured, so none is modelled unless asked.
    pub bowden_drag_mm_per_m: f32,

    /// Rest reading of every Hall sensor (no filament, no tension, cutter idle, motor Hall
    /// centre), counts. Default 2048.
    pub rest_level: u16,
    /// Reading of a slot or hub filament sensor with filament present, counts. Default 3000.
    pub filament_level: u16,
    /// Peak amplitude of the motor Hall sine, counts. Default 700.
    pub hall_amplitude: f32,
    /// Tension sensor gain, counts per mm of buffer (taut = higher). Default 150.
    pub tension_counts_per_mm: f32,
    /// Gaussian noise on every sample, σ in counts. Default 15.
    pub noise_sigma: f32,
    /// Probability per sample of a spike. Default 0.002.
    pub spike_probability: f32,
    /// Size of a spike (random sign), counts. Default 600.
    pub spike_counts: f32,
}

impl Default for ModelConfig {
    fn default() -> Self {
        ModelConfig {
            slot_sensor_mm: -95.0,
            drive_gear_mm: -100.0,
            merge_mm: -8.0,
            start_tip_mm: -15.0,
            bowden_length_mm: 360.0,
            extruder_gears_mm: 364.0,
            nozzle_mm: 420.0,
            bowden_jam_mm: 200.0,
            spool_filament_mm: 100_000.0,
            max_speed_mm_s: 150.0,
            motor_tau_ms: 40.0,
            brake_tau_ms: 5.0,
            coast_tau_ms: 60.0,
            dead_band_permille: 80,
            mm_per_rev: 2.0,
            motion_sensor: MotionSensor::HallWave,
            lane_tension: false,
            extruder_grip_duty_permille: 300,
            buffer_limit_mm: 6.0,
            buffer_relax_ms: 100.0,
            bowden_drag_mm_per_m: 0.0,
            rest_level: 2048,
            filament_level: 3000,
            hall_amplitude: 700.0,
            tension_counts_per_mm: 150.0,
            noise_sigma: 15.0,
            spike_probability: 0.002,
            spike_counts: 600.0,
        }
    }
}

impl ModelConfig {
    /// This configuration with a Bowden tube of `mm` to the printer's filament sensor (a unit
    /// outside an enclosure: 1 to 5 m): the extruder's gears and nozzle move with the sensor,
    /// keeping their distances to it.
    pub fn with_bowden_length(&self, mm: f32) -> ModelConfig {
        let shift = mm - self.bowden_length_mm;
        ModelConfig {
            bowden_length_mm: mm,
            extruder_gears_mm: self.extruder_gears_mm + shift,
            nozzle_mm: self.nozzle_mm + shift,
            ..self.clone()
        }
    }

    /// This configuration with every non-finite value (and every negative time, speed, length
    /// or level) replaced by its default, so the physics stays finite.
    pub(crate) fn sanitized(&self) -> ModelConfig {
        let d = ModelConfig::default();
        let finite = |v: f32, def: f32| if v.is_finite() { v } else { def };
        let non_neg = |v: f32, def: f32| if v.is_finite() && v >= 0.0 { v } else { def };
        let positive = |v: f32, def: f32| if v.is_finite() && v > 0.0 { v } else { def };
        ModelConfig {
            slot_sensor_mm: finite(self.slot_sensor_mm, d.slot_sensor_mm),
            drive_gear_mm: finite(self.drive_gear_mm, d.drive_gear_mm),
            merge_mm: finite(self.merge_mm, d.merge_mm),
            start_tip_mm: finite(self.start_tip_mm, d.start_tip_mm),
            bowden_length_mm: finite(self.bowden_length_mm, d.bowden_length_mm),
            extruder_gears_mm: finite(self.extruder_gears_mm, d.extruder_gears_mm),
            nozzle_mm: finite(self.nozzle_mm, d.nozzle_mm),
            bowden_jam_mm: finite(self.bowden_jam_mm, d.bowden_jam_mm),
            spool_filament_mm: non_neg(self.spool_filament_mm, d.spool_filament_mm),
            max_speed_mm_s: non_neg(self.max_speed_mm_s, d.max_speed_mm_s),
            motor_tau_ms: non_neg(self.motor_tau_ms, d.motor_tau_ms),
            brake_tau_ms: non_neg(self.brake_tau_ms, d.brake_tau_ms),
            coast_tau_ms: non_neg(self.coast_tau_ms, d.coast_tau_ms),
            dead_band_permille: self.dead_band_permille,
            mm_per_rev: positive(self.mm_per_rev, d.mm_per_rev),
            motion_sensor: self.motion_sensor,
            lane_tension: self.lane_tension,
            extruder_grip_duty_permille: self.extruder_grip_duty_permille,
            buffer_limit_mm: non_neg(self.buffer_limit_mm, d.buffer_limit_mm),
            buffer_relax_ms: non_neg(self.buffer_relax_ms, d.buffer_relax_ms),
            bowden_drag_mm_per_m: non_neg(self.bowden_drag_mm_per_m, d.bowden_drag_mm_per_m),
            rest_level: self.rest_level,
            filament_level: self.filament_level,
            hall_amplitude: non_neg(self.hall_amplitude, d.hall_amplitude),
            tension_counts_per_mm: finite(self.tension_counts_per_mm, d.tension_counts_per_mm),
            noise_sigma: non_neg(self.noise_sigma, d.noise_sigma),
            spike_probability: non_neg(self.spike_probability, d.spike_probability).min(1.0),
            spike_counts: non_neg(self.spike_counts, d.spike_counts),
        }
    }
}
