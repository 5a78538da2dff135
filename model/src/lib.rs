//! A deterministic physical model of the multi-material unit and of the printer's extruder side.
//!
//! The unit logic is sans-IO: it is stepped with sensor samples and answers with motor
//! commands. To test it on the host (in virtual time, far faster than real time) and to run the
//! simulator, something has to turn those [`MotorCommand`]s into filament motion and the motion
//! back into noisy raw Hall samples. That is this crate: plain `std` Rust, no threads, no
//! `unsafe`, and bit-for-bit reproducible for a seed (its random source is in-crate, so a
//! dependency update can never change a recorded run).
//!
//! # What is modelled
//!
//! One coordinate, in mm along the filament path, relative to the hub filament sensor (0),
//! negative towards the spool (defaults in [`ModelConfig`]):
//!
//! ```text
//! spool → drive gear (−100) → slot sensor (−95) → park (≈ −15) → merge (−8) → hub sensor (0)
//!       → Bowden → printer fsensor (+360) → extruder gears (+364) → nozzle (+420)
//! ```
//!
//! Per slot the model tracks the filament's tip and tail, the slot motor's speed and angle, and
//! the hub buffer. The rules, in brief:
//!
//! - **Motor.** A drive duty sets a target speed (`duty/1000 × max_speed`, zero below the dead
//!   band) approached with a first-order lag; `Brake` runs down fast, `Coast` slowly. Reverse
//!   moves the filament back. The motor moves the filament only while its drive gear grips it
//!   (tip at or past the gear, tail behind it); otherwise it spins on air. A blocked filament
//!   stalls the motor: its speed and its Hall signal stop.
//! - **Front of the filament.** The tip is *free* while nothing holds it: it moves with the motor.
//!   It is *held* when the extruder grips it (tip inside the extruder gears), when it rests
//!   against a stop (idle extruder gears, a [`Fault::BowdenJam`]), or when it runs through a
//!   Bowden jam. A held tip moves with the extruder (or not at all).
//! - **Buffer (hub tension).** While the tip is held, the hub buffer takes up the difference:
//!   `buffer += extruder motion − motor-side motion`, limited to ±`buffer_limit_mm`
//!   (positive = taut). At the compressed limit a motor pushing further stalls (and an extruder
//!   retracting harder slips); at the taut limit an extruder pulling harder slips, and a motor
//!   pulling back against it stalls, unless its pull is weak (`extruder_grip_duty_permille`):
//!   then the gears win and drag it along (and an extruder retracting faster than it drives it
//!   back faster, where it would slip against a harder drive). A stop cannot pull, so the buffer at a stop is never taut.
//!   A coasting motor is back-driven: it follows the extruder and lets the buffer relax
//!   (time constant `buffer_relax_ms`). A free tip has no buffer.
//! - **Extruder.** [`Model::extruder_move`] and [`Model::set_printing`] turn the extruder; it
//!   moves the filament only when the tip is inside its gears. The tip never passes the nozzle:
//!   filament pushed further is extruded (used up).
//! - **Sensors.** Slot and hub filament sensors read `filament_level` when the filament passes
//!   their position, `rest_level` otherwise; the tension sensor reads
//!   `rest + tension_counts_per_mm × buffer`; the cutter sensor reads rest; the motor Hall reads
//!   `rest + hall_amplitude × sin(2π × revolutions)` (plus a per-slot start phase from the seed).
//!   Every sample gets Gaussian noise and, rarely, a spike; it is rounded and clamped to
//!   `0..=ADC_MAX`. The printer's own filament sensor is [`Model::fsensor_state`].
//! - **Faults** ([`Fault`]) can be injected and cleared at any time.
//!
//! # Time and sampling
//!
//! [`Model::step`] advances the physics by whole milliseconds in 1 ms sub-steps
//! ([`SUBSTEP_MS`]). Sampling ([`Model::samples`], [`Model::sample_slot`],
//! [`Model::sample_hub`]) takes `&mut self` and draws a *fresh* noisy reading on every call from
//! the state after the last step (the physics itself uses no randomness). The same seed, the
//! same sequence of calls and the same inputs give identical samples.
//!
//! No input panics: out-of-range slots are ignored (or give `None`), non-finite numbers are
//! rejected or replaced, motor commands missing for a slot mean `Coast`.

#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod config;
mod fault;
mod rng;

pub use config::ModelConfig;
pub use fault::{Fault, FaultKind, Rail, SensorId};
pub use mmu_hal_port::{Direction, Duty, HubSamples, MotionSensor, MotorCommand, Samples, SlotSamples};
pub use rng::Rng;

use mmu_hal_port::ADC_MAX;

/// Most slots a model has; [`Model::new`] clamps larger counts to this.
pub const MAX_SLOTS: usize = 32;

/// How taut the tube must be for a lane motor's pull to reach gripping extruder gears, mm
/// ([`Model::max_pull_against_grip`]): a slack tube passes no force on.
pub const GRIP_PULL_TAUT_MM: f64 = 1.0;

/// Length of one internal physics sub-step, ms.
pub const SUBSTEP_MS: u32 = 1;

/// One sub-step in seconds.
const DT: f64 = SUBSTEP_MS as f64 / 1000.0;
/// Position tolerance for "at a stop", mm.
const EPS: f64 = 1e-6;
/// How far past the slot sensor a runout leaves the filament's tail, mm.
const RUNOUT_MARGIN_MM: f64 = 0.1;
/// The longest [`Fault::TipCatch`], mm.
pub const MAX_TIP_CATCH_MM: f32 = 100.0;
/// The slowest [`Fault::SlowRetract`], as a fraction of the commanded speed.
pub const MIN_RETRACT_FACTOR: f32 = 0.01;
/// Within this distance of the nozzle the tip counts as "in the nozzle", mm.
const NOZZLE_TOLERANCE_MM: f64 = 1e-3;

/// The sanitized configuration in the units the physics uses (mm, s, f64).
#[derive(Debug, Clone, Copy)]
struct Params {
    slot_sensor: f64,
    gear: f64,
    merge: f64,
    fsensor: f64,
    gears: f64,
    nozzle: f64,
    bowden_jam: f64,
    spool: f64,
    max_speed: f64,
    alpha_drive: f64,
    alpha_brake: f64,
    alpha_coast: f64,
    relax_factor: f64,
    /// Where a coasting lane lets the buffer settle while the extruder pulls: the tube's drag.
    drag: f64,
    dead_band: u16,
    grip_duty: u16,
    mm_per_rev: f64,
    buffer_limit: f64,
    rest: f64,
    filament_level: f64,
    hall_amplitude: f64,
    tension_gain: f64,
    sigma: f64,
    spike_probability: f64,
    spike_counts: f64,
}

/// Per sub-step smoothing factor of a first-order lag with time constant `tau_ms`.
fn lag_alpha(tau_ms: f32) -> f64 {
    let tau = f64::from(tau_ms) / 1000.0;
    if tau > 0.0 { 1.0 - (-DT / tau).exp() } else { 1.0 }
}

impl Params {
    fn new(c: &ModelConfig) -> Self {
        let relax = f64::from(c.buffer_relax_ms) / 1000.0;
        Params {
            slot_sensor: c.slot_sensor_mm.into(),
            gear: c.drive_gear_mm.into(),
            merge: c.merge_mm.into(),
            fsensor: c.bowden_length_mm.into(),
            gears: c.extruder_gears_mm.into(),
            nozzle: c.nozzle_mm.into(),
            bowden_jam: c.bowden_jam_mm.into(),
            spool: c.spool_filament_mm.into(),
            max_speed: c.max_speed_mm_s.into(),
            alpha_drive: lag_alpha(c.motor_tau_ms),
            alpha_brake: lag_alpha(c.brake_tau_ms),
            alpha_coast: lag_alpha(c.coast_tau_ms),
            relax_factor: if relax > 0.0 { (-DT / relax).exp() } else { 0.0 },
            drag: f64::from(c.bowden_drag_mm_per_m) * f64::from(c.bowden_length_mm.max(0.0)) / 1000.0,
            dead_band: c.dead_band_permille,
            grip_duty: c.extruder_grip_duty_permille,
            mm_per_rev: c.mm_per_rev.into(),
            buffer_limit: c.buffer_limit_mm.into(),
            rest: c.rest_level.into(),
            filament_level: c.filament_level.into(),
            hall_amplitude: c.hall_amplitude.into(),
            tension_gain: c.tension_counts_per_mm.into(),
            sigma: c.noise_sigma.into(),
            spike_probability: c.spike_probability.into(),
            spike_counts: c.spike_counts.into(),
        }
    }
}

/// The state of one slot: its filament and its motor.
#[derive(Debug, Clone)]
struct Slot {
    /// The slot holds a filament at all.
    present: bool,
    /// Tip position, mm (never past the nozzle).
    tip: f64,
    /// Tail position (the spool end), mm.
    tail: f64,
    /// Hub buffer, mm: positive = taut. Zero while the tip is free.
    buffer: f64,
    /// Motor surface speed, mm of filament per second (positive = forward).
    motor_speed: f64,
    /// Motor revolutions since start (signed).
    motor_revs: f64,
    /// Motor revolutions since start, either way (what one channel of pulses counts).
    turned_revs: f64,
    /// Start phase of the Hall magnet, revolutions.
    hall_phase: f64,
    /// Cumulative filament motion at the drive gear side, mm (the reference of `jam_limit`).
    rear_travel: f64,
    /// `Fault::Jam`: `rear_travel` may not exceed this.
    jam_limit: Option<f64>,
    /// Filament motion per motor motion (1 = no slip).
    slip: f64,
    /// `Fault::MotorDead`.
    dead: bool,
    /// `Fault::SpoolRunout`.
    runout: bool,
    /// `Fault::TipCatch`: how far behind the extruder's gears the tip must be before they let
    /// the filament go, mm (0: at the gears).
    catch_mm: f64,
    /// The gears hold this filament by its caught tip (it has been in them since the fault).
    caught: bool,
    /// How long this slot's motor has been pulling against the gripping gears without a break,
    /// ms.
    grip_pull_ms: u64,
}

impl Slot {
    /// Where the tip would be with a relaxed buffer: the filament's extent on the slot side.
    fn rear(&self) -> f64 {
        self.tip - self.buffer
    }

    /// The filament passes `x`, a point upstream of the hub buffer.
    fn covers_upstream(&self, x: f64) -> bool {
        self.present && self.tail <= x && self.rear() >= x
    }

    /// The motor turns freely at `speed` (no filament gripped).
    fn spin_free(&mut self, speed: f64, p: &Params) {
        self.motor_speed = speed;
        self.motor_revs += speed * DT / p.mm_per_rev;
        self.turned_revs += (speed * DT / p.mm_per_rev).abs();
    }

    /// The motor surface moves `d_m` mm in this sub-step.
    fn turn(&mut self, d_m: f64, p: &Params) {
        self.motor_speed = d_m / DT;
        self.motor_revs += d_m / p.mm_per_rev;
        self.turned_revs += (d_m / p.mm_per_rev).abs();
    }

    /// Apply a spool runout: the tail moves just past the slot sensor.
    fn apply_runout(&mut self, p: &Params) {
        if !self.present {
            return;
        }
        let new_tail = p.slot_sensor + RUNOUT_MARGIN_MM;
        if new_tail > self.tail {
            if new_tail < self.rear() {
                self.tail = new_tail;
            } else {
                // The whole remaining piece lies behind the sensor: the slot is empty.
                self.present = false;
                self.buffer = 0.0;
            }
        }
    }
}

/// What holds the front of the filament during one sub-step.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Front {
    /// Nothing: the tip moves with the slot side.
    Free,
    /// The tip moves `d_f` (extruder motion, or 0 at a stop / in a jam). `can_pull` is false at
    /// a stop, which blocks forward motion but cannot hold the tip back.
    Held { d_f: f64, can_pull: bool },
}

/// The printer's extruder.
#[derive(Debug, Clone, Default)]
struct Extruder {
    /// Signed distance left of the current move, mm.
    remaining: f64,
    /// Speed of the current move, mm/s (> 0).
    speed: f64,
    /// Continuous pull while printing, mm/s.
    printing: Option<f64>,
    /// Commanded extruder position (E axis), mm.
    position: f64,
    /// `Fault::SlowRetract`: retracts run at this fraction of their commanded speed.
    retract_factor: Option<f64>,
}

impl Extruder {
    /// Advance one sub-step; the extruder's commanded motion, mm.
    fn substep(&mut self) -> f64 {
        let d = if self.remaining != 0.0 {
            let factor = if self.remaining < 0.0 {
                self.retract_factor.unwrap_or(1.0)
            } else {
                1.0
            };
            let step = (self.speed * factor * DT)
                .min(self.remaining.abs())
                .copysign(self.remaining);
            self.remaining -= step;
            if self.remaining.abs() < 1e-9 {
                self.remaining = 0.0;
            }
            step
        } else if let Some(rate) = self.printing {
            rate * DT
        } else {
            0.0
        };
        self.position += d;
        d
    }
}

/// The physical model of a unit with some slots, its hub, and the printer's extruder side.
///
/// See the [crate documentation](crate) for the rules.
#[derive(Debug, Clone)]
pub struct Model {
    config: ModelConfig,
    p: Params,
    slots: Vec<Slot>,
    extruder: Extruder,
    faults: Vec<Fault>,
    bowden_jam: bool,
    noise_override: Option<f64>,
    rng: Rng,
    time_ms: u64,
    /// `Fault::FsensorLate`: the printer's sensor reads filament this long after it left, ms.
    fsensor_late_ms: Option<u64>,
    /// The last time the printer's sensor had filament under it, ms.
    fsensor_seen_ms: Option<u64>,
    /// The hardest and longest pulls against gripping gears so far.
    grip_pull: PullAgainstGrip,
}

/// The pulls of lane motors against the extruder's gears while they grip the filament (its tip,
/// or a [`Fault::TipCatch`]'s caught tip, inside them) and the extruder is not turning it back
/// faster than the motor would pull it: the force the unit puts on a filament the extruder
/// holds. See [`Model::max_pull_against_grip`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PullAgainstGrip {
    /// The highest reverse duty, per mille (0: no such pull).
    pub max_duty_permille: u16,
    /// The longest such pull without a break, ms.
    pub longest_ms: u64,
    /// Every such millisecond added up, ms.
    pub total_ms: u64,
}

impl PullAgainstGrip {
    /// The harder and longer of both, and their milliseconds added (two runs' figures).
    pub fn merged(self, other: PullAgainstGrip) -> PullAgainstGrip {
        PullAgainstGrip {
            max_duty_permille: self.max_duty_permille.max(other.max_duty_permille),
            longest_ms: self.longest_ms.max(other.longest_ms),
            total_ms: self.total_ms.saturating_add(other.total_ms),
        }
    }
}

impl Model {
    /// A model of a unit with `slots` slots (clamped to [`MAX_SLOTS`]) whose noise is fixed by
    /// `seed`. Invalid configuration values are replaced by their defaults (see
    /// [`ModelConfig`]). Every slot starts with filament parked at
    /// [`ModelConfig::start_tip_mm`], nothing loaded, motors at rest, no faults.
    pub fn new(config: ModelConfig, slots: usize, seed: u64) -> Self {
        let config = config.sanitized();
        let p = Params::new(&config);
        let mut rng = Rng::new(seed);
        let start = f64::from(config.start_tip_mm);
        let slots = (0..slots.min(MAX_SLOTS))
            .map(|_| Slot {
                present: true,
                tip: start,
                tail: start - p.spool,
                buffer: 0.0,
                motor_speed: 0.0,
                motor_revs: 0.0,
                turned_revs: 0.0,
                hall_phase: rng.uniform(),
                rear_travel: 0.0,
                jam_limit: None,
                slip: 1.0,
                dead: false,
                runout: false,
                catch_mm: 0.0,
                caught: false,
                grip_pull_ms: 0,
            })
            .collect();
        Model {
            config,
            p,
            slots,
            extruder: Extruder::default(),
            faults: Vec::new(),
            bowden_jam: false,
            noise_override: None,
            rng,
            time_ms: 0,
            fsensor_late_ms: None,
            fsensor_seen_ms: None,
            grip_pull: PullAgainstGrip::default(),
        }
    }

    /// The (sanitized) configuration in use.
    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// Number of slots.
    pub fn slot_count(&self) -> usize {
        self.slots.len()
    }

    /// Virtual time since start, ms.
    pub fn time_ms(&self) -> u64 {
        self.time_ms
    }

    /// Advance the physics by `dt_ms` milliseconds (in 1 ms sub-steps) with the slot motors
    /// doing `motors[slot]` throughout. Slots without an entry coast; extra entries are ignored.
    pub fn step(&mut self, dt_ms: u32, motors: &[MotorCommand]) {
        for _ in 0..dt_ms / SUBSTEP_MS {
            self.measure_grip_pull(motors);
            self.substep(motors);
            self.time_ms = self.time_ms.saturating_add(u64::from(SUBSTEP_MS));
            if self.raw_fsensor_state() != 0 {
                self.fsensor_seen_ms = Some(self.time_ms);
            }
        }
    }

    /// Record, for one sub-step about to run with `motors`, each lane motor that pulls back its
    /// filament while the extruder's gears grip it and do not turn it back faster.
    fn measure_grip_pull(&mut self, motors: &[MotorCommand]) {
        let p = self.p;
        let extruder_back = if self.extruder.remaining < 0.0 {
            self.extruder.speed * self.extruder.retract_factor.unwrap_or(1.0)
        } else {
            0.0
        };
        for (i, s) in self.slots.iter_mut().enumerate() {
            let in_gears = s.present && s.tail <= p.gears && (s.tip > p.gears + EPS || s.caught);
            let pull = match motors.get(i).copied().unwrap_or_default() {
                MotorCommand::Drive {
                    direction: Direction::Reverse,
                    duty,
                } if duty.permille() >= p.dead_band => Some(duty.permille()),
                _ => None,
            };
            // Against the gears: the tube between them taut, so the pull reaches them.
            let taut = s.buffer > GRIP_PULL_TAUT_MM;
            match pull.filter(|&permille| {
                in_gears && taut && !s.dead && extruder_back < f64::from(permille) / 1000.0 * p.max_speed
            }) {
                Some(permille) => {
                    s.grip_pull_ms += u64::from(SUBSTEP_MS);
                    let g = &mut self.grip_pull;
                    g.max_duty_permille = g.max_duty_permille.max(permille);
                    g.longest_ms = g.longest_ms.max(s.grip_pull_ms);
                    g.total_ms += u64::from(SUBSTEP_MS);
                }
                None => s.grip_pull_ms = 0,
            }
        }
    }

    /// The hardest reverse duty any lane motor had while the extruder's gears gripped its
    /// filament (the tip inside them, the extruder not turning it back faster than the motor),
    /// and for how long, since the model was built.
    pub fn max_pull_against_grip(&self) -> PullAgainstGrip {
        self.grip_pull
    }

    fn substep(&mut self, motors: &[MotorCommand]) {
        let d_e = self.extruder.substep();
        for i in 0..self.slots.len() {
            let command = motors.get(i).copied().unwrap_or_default();
            self.slot_substep(i, command, d_e);
        }
    }

    /// Where a forward move of a free tip from `from` to `to` ends, given the stops ahead.
    fn clamp_forward(&self, from: f64, to: f64, tail: f64) -> f64 {
        let p = &self.p;
        let mut end = to;
        let jam = (self.bowden_jam && tail < p.bowden_jam).then_some(p.bowden_jam);
        let gears = (tail <= p.gears).then_some(p.gears);
        for stop in [jam, gears].into_iter().flatten() {
            if from <= stop + EPS && end > stop {
                end = stop.max(from);
            }
        }
        end
    }

    /// What holds the tip of `s` this sub-step, with the extruder moving `d_e`.
    fn front(&self, s: &Slot, d_e: f64) -> Front {
        let p = &self.p;
        let jammed = self.bowden_jam && s.tail < p.bowden_jam;
        if jammed && s.tip > p.bowden_jam + EPS {
            return Front::Held {
                d_f: 0.0,
                can_pull: true,
            };
        }
        if s.tail <= p.gears {
            if s.tip > p.gears + EPS || s.caught || (s.tip >= p.gears - EPS && d_e > 0.0) {
                return Front::Held {
                    d_f: d_e,
                    can_pull: true,
                };
            }
            if s.tip >= p.gears - EPS {
                return Front::Held {
                    d_f: 0.0,
                    can_pull: false,
                };
            }
        }
        if jammed && s.tip >= p.bowden_jam - EPS {
            return Front::Held {
                d_f: 0.0,
                can_pull: false,
            };
        }
        Front::Free
    }

    /// The motor's surface speed after this sub-step if nothing constrained it, mm/s.
    fn free_speed(&self, s: &Slot, command: MotorCommand) -> f64 {
        let p = &self.p;
        if s.dead {
            return 0.0;
        }
        let (target, alpha) = match command {
            MotorCommand::Drive { direction, duty } => {
                let permille = duty.permille();
                let magnitude = if permille < p.dead_band {
                    0.0
                } else {
                    f64::from(permille.min(1000)) / 1000.0 * p.max_speed
                };
                let target = match direction {
                    Direction::Forward => magnitude,
                    Direction::Reverse => -magnitude,
                };
                (target, p.alpha_drive)
            }
            MotorCommand::Brake => (0.0, p.alpha_brake),
            MotorCommand::Coast => (0.0, p.alpha_coast),
        };
        s.motor_speed + (target - s.motor_speed) * alpha
    }

    fn slot_substep(&mut self, i: usize, command: MotorCommand, d_e: f64) {
        let p = self.p;
        let merge_blocked = self
            .slots
            .iter()
            .enumerate()
            .any(|(j, other)| j != i && other.present && other.tail < p.merge && other.rear() > p.merge);
        let Some(mut s) = self.slots.get(i).cloned() else {
            return;
        };
        let free_speed = self.free_speed(&s, command);
        if !s.present {
            s.spin_free(free_speed, &p);
            self.slots[i] = s;
            return;
        }

        let mut front = self.front(&s, d_e);
        if front == Front::Free && s.buffer != 0.0 {
            // Released: the buffer's spring moves the tip to the slot side (up to a stop).
            let rear = s.rear();
            let tip = if rear > s.tip {
                self.clamp_forward(s.tip, rear, s.tail)
            } else {
                rear
            };
            s.tip = tip;
            s.buffer = tip - rear;
            front = self.front(&s, d_e);
        }

        let rear = s.rear();
        let gripped = s.tail < p.gear && rear >= p.gear;
        // How far the slot side may move forward (jam in the slot path, occupied merge).
        let mut rear_forward_max = f64::INFINITY;
        if let Some(limit) = s.jam_limit {
            rear_forward_max = rear_forward_max.min((limit - s.rear_travel).max(0.0));
        }
        if merge_blocked && rear <= p.merge {
            rear_forward_max = rear_forward_max.min(p.merge - rear);
        }
        let driven = matches!(command, MotorCommand::Drive { .. } | MotorCommand::Brake);

        match front {
            Front::Free => {
                if !gripped {
                    s.spin_free(free_speed, &p);
                } else if s.dead {
                    s.motor_speed = 0.0;
                } else {
                    let d_m_free = free_speed * DT;
                    let want = d_m_free * s.slip;
                    let d_r = want.min(rear_forward_max);
                    let d_r = self.clamp_forward(s.tip, s.tip + d_r, s.tail) - s.tip;
                    let d_m = if (d_r - want).abs() > 1e-12 && s.slip > 0.0 {
                        d_r / s.slip
                    } else {
                        d_m_free
                    };
                    s.turn(d_m, &p);
                    s.tip += d_r;
                    s.tail += d_r;
                    s.rear_travel += d_r;
                }
            }
            Front::Held { mut d_f, can_pull } => {
                // A coasting motor lets the buffer relax, to the tube's drag while the extruder
                // pulls the filament through it.
                let rest = if d_f > 0.0 { p.drag } else { 0.0 };
                let follow = d_f + (s.buffer - rest) - (s.buffer - rest) * p.relax_factor;
                let (want, d_m_free) = if gripped && s.dead {
                    (0.0, None)
                } else if gripped && driven && s.slip < 1.0 && d_f < 0.0 && follow < free_speed * DT * s.slip
                {
                    // A drive gear that slips under its own motor slips under the extruder's
                    // retract too: the filament follows the extruder back, the motor turns as
                    // driven.
                    (follow, Some(free_speed * DT))
                } else if gripped && driven {
                    let d_m = free_speed * DT;
                    (d_m * s.slip, Some(d_m))
                } else {
                    // A coasting motor is back-driven; a tail past the gear just follows.
                    (follow, None)
                };
                let mut d_r = want.min(rear_forward_max);
                let limit = p.buffer_limit;
                let mut buffer = s.buffer + d_f - d_r;
                if !can_pull && buffer > 0.0 {
                    // A stop cannot pull: the tip follows the slot side back.
                    d_f -= buffer;
                    buffer = 0.0;
                }
                let weak_pull = matches!(
                    command,
                    MotorCommand::Drive { direction: Direction::Reverse, duty } if duty.permille() <= p.grip_duty
                );
                if buffer > limit && weak_pull {
                    // Taut under a pull the gripping gears win against: the motor is dragged.
                    d_r += buffer - limit;
                } else if buffer > limit {
                    // Taut: the extruder's gears slip, then a motor pulling back stalls.
                    let mut excess = buffer - limit;
                    if d_f > 0.0 {
                        let cut = excess.min(d_f);
                        d_f -= cut;
                        excess -= cut;
                    }
                    if excess > 0.0 && d_r < 0.0 {
                        d_r += excess.min(-d_r);
                    }
                } else if buffer < -limit && weak_pull {
                    // Compressed by an extruder retracting faster than a weak pull: it drives the
                    // motor back faster.
                    d_r -= -limit - buffer;
                } else if buffer < -limit {
                    // Compressed: a motor pushing stalls, then an extruder retracting slips.
                    let mut deficit = -limit - buffer;
                    if d_r > 0.0 {
                        let cut = deficit.min(d_r);
                        d_r -= cut;
                        deficit -= cut;
                    }
                    if deficit > 0.0 && d_f < 0.0 {
                        d_f += deficit.min(-d_f);
                    }
                }
                let upper = if can_pull { limit } else { 0.0 };
                buffer = (s.buffer + d_f - d_r).clamp(-limit, upper.max(-limit));

                if !gripped {
                    s.spin_free(free_speed, &p);
                } else if s.dead {
                    s.motor_speed = 0.0;
                } else if let Some(d_m_free) = d_m_free {
                    let d_m = if (d_r - want).abs() > 1e-12 && s.slip > 0.0 {
                        d_r / s.slip
                    } else {
                        d_m_free
                    };
                    s.turn(d_m, &p);
                } else {
                    s.turn(d_r, &p);
                }
                s.tip += d_f;
                s.tail += d_r;
                s.rear_travel += d_r;
                s.buffer = buffer;
            }
        }
        // Filament pushed past the nozzle is extruded.
        if s.tip > p.nozzle {
            s.tip = p.nozzle;
        }
        if s.tip <= s.tail {
            s.present = false;
            s.buffer = 0.0;
        }
        // A caught tip stays in the gears until it is `catch_mm` behind them.
        s.caught = s.catch_mm > 0.0
            && s.present
            && s.tail <= p.gears
            && (s.tip > p.gears + EPS || (s.caught && s.tip > p.gears - s.catch_mm));
        self.slots[i] = s;
    }

    // ----- sensors -------------------------------------------------------------------------

    fn disconnected(&self, sensor: SensorId) -> Option<Rail> {
        self.faults.iter().find_map(|fault| match *fault {
            Fault::SensorDisconnected { sensor: s, rail } if s == sensor => Some(rail),
            _ => None,
        })
    }

    /// One noisy reading of `sensor` whose noise-free value is `ideal` counts. The random draws
    /// happen even for a disconnected sensor, so a fault never shifts other sensors' noise.
    fn read(&mut self, sensor: SensorId, ideal: f64) -> u16 {
        let sigma = self.noise_override.unwrap_or(self.p.sigma);
        let noise = self.rng.normal() * sigma;
        let roll = self.rng.uniform();
        let spike = if roll < self.p.spike_probability {
            if roll < self.p.spike_probability / 2.0 {
                -self.p.spike_counts
            } else {
                self.p.spike_counts
            }
        } else {
            0.0
        };
        match self.disconnected(sensor) {
            Some(rail) => rail.counts(),
            None => to_counts(ideal + noise + spike),
        }
    }

    /// One fresh sample of `slot`'s sensors (noisy where they are analog); `None` for an unknown
    /// slot. A lane without its own tension sensor reads 0 there.
    pub fn sample_slot(&mut self, slot: usize) -> Option<SlotSamples> {
        let s = self.slots.get(slot)?;
        let p = &self.p;
        let turns = s.hall_phase + s.motor_revs;
        let filament = if s.covers_upstream(p.slot_sensor) {
            p.filament_level
        } else {
            p.rest
        };
        let tension = p.rest + p.tension_gain * s.buffer;
        let sensor = SensorId::MotorHall(slot);
        let motion = match self.config.motion_sensor {
            MotionSensor::HallWave => {
                let hall = p.rest + p.hall_amplitude * (core::f64::consts::TAU * turns.rem_euclid(1.0)).sin();
                self.read(sensor, hall)
            }
            // A disconnected encoder's channels stay put: the count stops.
            MotionSensor::Quadrature { counts_per_rev } => match self.disconnected(sensor) {
                Some(_) => 0,
                None => ((turns * f64::from(counts_per_rev)).floor() as i64).rem_euclid(65_536) as u16,
            },
            // Edges of one channel count up whichever way it turns: the distance turned.
            MotionSensor::Pulses { counts_per_rev } => match self.disconnected(sensor) {
                Some(_) => 0,
                None => {
                    ((s.turned_revs * f64::from(counts_per_rev)).floor() as i64).rem_euclid(65_536) as u16
                }
            },
            MotionSensor::Angle => match self.disconnected(sensor) {
                Some(_) => mmu_hal_port::ANGLE_FAULT,
                None => {
                    let counts = f64::from(mmu_hal_port::ANGLE_COUNTS);
                    ((turns.rem_euclid(1.0) * counts).floor() as u16) % mmu_hal_port::ANGLE_COUNTS
                }
            },
        };
        let filament = self.read(SensorId::SlotFilament(slot), filament);
        let tension = if self.config.lane_tension {
            self.read(SensorId::LaneTension(slot), tension)
        } else {
            0
        };
        Some(SlotSamples {
            motion,
            filament,
            tension,
        })
    }

    /// One fresh noisy sample of the hub's three sensors.
    pub fn sample_hub(&mut self) -> HubSamples {
        let p = self.p;
        let filament = if self.hub_filament_present() {
            p.filament_level
        } else {
            p.rest
        };
        let tension = p.rest + p.tension_gain * f64::from(self.tension_mm());
        HubSamples {
            filament: self.read(SensorId::HubFilament, filament),
            tension: self.read(SensorId::HubTension, tension),
            cutter: self.read(SensorId::HubCutter, p.rest),
        }
    }

    /// One fresh noisy sampling round of every sensor (slots in order, then the hub). Slots the
    /// model does not have (`slot >= slot_count()`) read 0, like unconnected inputs.
    pub fn samples<const N: usize>(&mut self) -> Samples<N> {
        let mut out = Samples::<N>::default();
        for (i, slot) in out.slots.iter_mut().enumerate() {
            if let Some(sample) = self.sample_slot(i) {
                *slot = sample;
            }
        }
        out.hub = self.sample_hub();
        out
    }

    // ----- physical truth ------------------------------------------------------------------

    /// The printer's filament sensor as the printer reports it with `f`: 0 = no filament (tip
    /// before the fsensor), 1 = filament at the fsensor, 2 = tip in the nozzle.
    pub fn fsensor_state(&self) -> u8 {
        let raw = self.raw_fsensor_state();
        let late = match (self.fsensor_late_ms, self.fsensor_seen_ms) {
            // Seen at the end of the sub-step `seen`: the filament left during the next one.
            (Some(delay), Some(seen)) => self.time_ms < seen.saturating_add(u64::from(SUBSTEP_MS) + delay),
            _ => false,
        };
        if raw == 0 && late { 1 } else { raw }
    }

    /// The printer's filament sensor as the filament is under it, without a
    /// [`Fault::FsensorLate`].
    fn raw_fsensor_state(&self) -> u8 {
        let p = &self.p;
        self.slots
            .iter()
            .find(|s| s.present && s.tail <= p.fsensor && s.tip >= p.fsensor)
            .map_or(0, |s| {
                if s.tip >= p.nozzle - NOZZLE_TOLERANCE_MM {
                    2
                } else {
                    1
                }
            })
    }

    /// Tip position of `slot`'s filament, mm from the hub sensor; `None` for an unknown slot
    /// or a slot without filament.
    pub fn tip_mm(&self, slot: usize) -> Option<f32> {
        self.slots.get(slot).filter(|s| s.present).map(|s| s.tip as f32)
    }

    /// Tail (spool end) position of `slot`'s filament, mm; `None` for an unknown slot or a slot
    /// without filament.
    pub fn tail_mm(&self, slot: usize) -> Option<f32> {
        self.slots.get(slot).filter(|s| s.present).map(|s| s.tail as f32)
    }

    /// The first slot whose filament tip is at or past the hub sensor.
    pub fn loaded_slot(&self) -> Option<usize> {
        self.slots.iter().position(|s| s.present && s.tip >= 0.0)
    }

    /// Motor revolutions of `slot` since start (signed, forward positive); `None` for an
    /// unknown slot.
    pub fn motor_revolutions(&self, slot: usize) -> Option<f32> {
        self.slots.get(slot).map(|s| s.motor_revs as f32)
    }

    /// Motor surface speed of `slot`, mm of filament per second (forward positive).
    pub fn motor_speed_mm_s(&self, slot: usize) -> Option<f32> {
        self.slots.get(slot).map(|s| s.motor_speed as f32)
    }

    /// The hub buffer, mm: positive = taut, negative = compressed, 0 at rest. (Normally one
    /// filament at most is held; if several are, e.g. after [`Model::insert_filament`] put two
    /// past the merge, their buffers add up within the buffer's travel.)
    pub fn tension_mm(&self) -> f32 {
        let limit = self.p.buffer_limit;
        self.slots
            .iter()
            .map(|s| s.buffer)
            .sum::<f64>()
            .clamp(-limit, limit) as f32
    }

    /// Noise-free truth: `slot`'s filament passes its slot sensor.
    pub fn slot_filament_present(&self, slot: usize) -> Option<bool> {
        self.slots
            .get(slot)
            .map(|s| s.covers_upstream(self.p.slot_sensor))
    }

    /// Noise-free truth: some filament passes the hub sensor.
    pub fn hub_filament_present(&self) -> bool {
        self.slots.iter().any(|s| s.covers_upstream(0.0))
    }

    /// A user inserts a fresh filament into `slot` with its tip at `tip_mm` (any previous
    /// filament of that slot is replaced; an active [`Fault::SpoolRunout`] applies to it).
    /// False for an unknown slot or a non-finite position.
    pub fn insert_filament(&mut self, slot: usize, tip_mm: f32) -> bool {
        let p = self.p;
        let Some(s) = self.slots.get_mut(slot) else {
            return false;
        };
        if !tip_mm.is_finite() {
            return false;
        }
        let tip = f64::from(tip_mm).min(p.nozzle);
        s.present = true;
        s.tip = tip;
        s.tail = tip - p.spool;
        s.buffer = 0.0;
        if s.runout {
            s.apply_runout(&p);
        }
        true
    }

    /// A user pulls `slot`'s filament out entirely. False for an unknown slot.
    pub fn remove_filament(&mut self, slot: usize) -> bool {
        let Some(s) = self.slots.get_mut(slot) else {
            return false;
        };
        s.present = false;
        s.buffer = 0.0;
        true
    }

    // ----- extruder ------------------------------------------------------------------------

    /// Start an extruder move of `mm` (positive feeds, negative retracts) at `speed_mm_s`,
    /// replacing any move in progress. A non-finite distance or a speed that is not finite and
    /// positive just stops the current move.
    pub fn extruder_move(&mut self, mm: f32, speed_mm_s: f32) {
        if mm.is_finite() && speed_mm_s.is_finite() && speed_mm_s > 0.0 {
            self.extruder.remaining = mm.into();
            self.extruder.speed = speed_mm_s.into();
        } else {
            self.extruder.remaining = 0.0;
        }
    }

    /// An extruder move is in progress (printing alone is not busy).
    pub fn extruder_busy(&self) -> bool {
        self.extruder.remaining != 0.0
    }

    /// Pull continuously at `mm_s` while printing, or stop with `None`. Moves take precedence
    /// while they run. A rate that is not finite and positive means `None`.
    pub fn set_printing(&mut self, mm_s: Option<f32>) {
        self.extruder.printing = mm_s.filter(|r| r.is_finite() && *r > 0.0).map(f64::from);
    }

    /// The printing pull rate, mm/s, if printing.
    pub fn printing(&self) -> Option<f32> {
        self.extruder.printing.map(|r| r as f32)
    }

    /// The extruder's commanded position (E axis) since start, mm; it also counts motion on air
    /// and while its gears slip.
    pub fn extruder_position_mm(&self) -> f32 {
        self.extruder.position as f32
    }

    // ----- faults --------------------------------------------------------------------------

    /// Inject `fault`, replacing an active fault of the same kind. False (and no change) for an
    /// unknown slot or sensor or a non-finite parameter.
    pub fn inject(&mut self, fault: Fault) -> bool {
        let slots = self.slots.len();
        if fault.kind().slot().is_some_and(|slot| slot >= slots) {
            return false;
        }
        let p = self.p;
        let fault = match fault {
            Fault::Jam { slot } | Fault::SpoolFastened { slot } => {
                let s = &mut self.slots[slot];
                s.jam_limit = Some(s.rear_travel);
                fault
            }
            Fault::BowdenJam => {
                self.bowden_jam = true;
                fault
            }
            Fault::Slip { slot, ratio } => {
                if !ratio.is_finite() {
                    return false;
                }
                let ratio = ratio.clamp(0.0, 1.0);
                self.slots[slot].slip = ratio.into();
                Fault::Slip { slot, ratio }
            }
            Fault::MotorDead { slot } => {
                let s = &mut self.slots[slot];
                s.dead = true;
                s.motor_speed = 0.0;
                fault
            }
            Fault::SensorNoise { sigma } => {
                if !sigma.is_finite() {
                    return false;
                }
                let sigma = sigma.abs().min(f32::from(ADC_MAX));
                self.noise_override = Some(sigma.into());
                Fault::SensorNoise { sigma }
            }
            Fault::SensorDisconnected { .. } => fault,
            Fault::SpoolRunout { slot } => {
                let s = &mut self.slots[slot];
                s.runout = true;
                s.apply_runout(&p);
                fault
            }
            Fault::FsensorLate { delay_ms } => {
                self.fsensor_late_ms = Some(u64::from(delay_ms));
                fault
            }
            Fault::TipCatch { slot, mm } => {
                if !mm.is_finite() {
                    return false;
                }
                let mm = mm.clamp(0.0, MAX_TIP_CATCH_MM);
                let s = &mut self.slots[slot];
                s.catch_mm = mm.into();
                s.caught = s.present && s.tail <= p.gears && s.tip > p.gears + EPS;
                Fault::TipCatch { slot, mm }
            }
            Fault::SlowRetract { factor } => {
                if !factor.is_finite() {
                    return false;
                }
                let factor = factor.clamp(MIN_RETRACT_FACTOR, 1.0);
                self.extruder.retract_factor = Some(factor.into());
                Fault::SlowRetract { factor }
            }
        };
        let kind = fault.kind();
        self.faults.retain(|f| f.kind() != kind);
        self.faults.push(fault);
        true
    }

    /// Clear the active fault of this kind (pass a [`FaultKind`], a [`Fault`] or a reference to
    /// either). True if one was active. Clearing a [`Fault::Jam`] frees the path; clearing a
    /// [`Fault::SpoolRunout`] refills the spool behind the filament still in the slot.
    pub fn clear(&mut self, kind: impl Into<FaultKind>) -> bool {
        let kind = kind.into();
        let Some(index) = self.faults.iter().position(|f| f.kind() == kind) else {
            return false;
        };
        self.faults.remove(index);
        let p = self.p;
        match kind {
            FaultKind::Jam(slot) | FaultKind::SpoolFastened(slot) => {
                if let Some(s) = self.slots.get_mut(slot) {
                    s.jam_limit = None;
                }
            }
            FaultKind::BowdenJam => self.bowden_jam = false,
            FaultKind::Slip(slot) => {
                if let Some(s) = self.slots.get_mut(slot) {
                    s.slip = 1.0;
                }
            }
            FaultKind::MotorDead(slot) => {
                if let Some(s) = self.slots.get_mut(slot) {
                    s.dead = false;
                }
            }
            FaultKind::SensorNoise => self.noise_override = None,
            FaultKind::SensorDisconnected(_) => {}
            FaultKind::FsensorLate => self.fsensor_late_ms = None,
            FaultKind::TipCatch(slot) => {
                if let Some(s) = self.slots.get_mut(slot) {
                    s.catch_mm = 0.0;
                    s.caught = false;
                }
            }
            FaultKind::SlowRetract => self.extruder.retract_factor = None,
            FaultKind::SpoolRunout(slot) => {
                if let Some(s) = self.slots.get_mut(slot) {
                    s.runout = false;
                    if s.present {
                        s.tail = s.tail.min(s.rear() - p.spool);
                    }
                }
            }
        }
        true
    }

    /// Clear every active fault.
    pub fn clear_all(&mut self) {
        while let Some(fault) = self.faults.last().copied() {
            self.clear(fault);
        }
    }

    /// The active faults, in injection order.
    pub fn active_faults(&self) -> &[Fault] {
        &self.faults
    }
}

/// Round and clamp a value to a raw 12-bit sample.
fn to_counts(value: f64) -> u16 {
    if value.is_nan() {
        0
    } else {
        value.round().clamp(0.0, f64::from(ADC_MAX)) as u16
    }
}
