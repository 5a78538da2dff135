//! One slot's feeding system: its DC motor, the motor Hall sensor that measures how far it
//! turned, and the slot filament sensor at the slot entry.
//!
//! The feeder turns "move at v mm/s" into a duty cycle (open loop plus a correction that keeps
//! the odometry on schedule), counts millimetres from motor revolutions, and calls a motor
//! stalled when it is driven hard enough to turn but no revolution comes.

use mmu_hal_port::{Direction, Duty, MotorCommand, SlotSamples};

use crate::config::Config;
use crate::sensor::{PresenceSensor, RailLimits, RevolutionCounter, Thresholds};
use crate::time::Instant;

/// How long a braked motor stays braked before it may coast, ms: long enough to stop it, so a
/// parked tip does not drift on the motor's momentum.
const BRAKE_HOLD_MS: u64 = 200;

/// Duty added per millimetre the filament lags behind its schedule, per mille.
const CATCH_UP_GAIN: i32 = 25;

/// Thresholds no reading reaches, for a slot beyond the configured ones.
const DISABLED: Thresholds = Thresholds {
    on: u16::MAX,
    off: u16::MAX - 1,
};

/// A speed-controlled move in progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Drive {
    direction: Direction,
    speed: u16,
    since: Instant,
    from_centi: i32,
}

/// One slot: motor, motor Hall sensor, slot filament sensor.
#[derive(Debug, Clone, Copy, Default)]
pub struct Feeder {
    /// The motor Hall sensor and its revolution count.
    pub hall: RevolutionCounter,
    /// The slot filament sensor.
    pub filament: PresenceSensor,
    command: MotorCommand,
    drive: Option<Drive>,
    /// Where the motor moved the filament, in 1/100 mm, forward positive.
    odometry_centi: i32,
    /// Since when the motor has been driven at or above the stall duty.
    hard_drive_since: Option<Instant>,
    /// The direction revolutions are counted in (the extruder pulls forward while coasting).
    counting: Option<Direction>,
    /// When the motor was last braked.
    braked_at: Instant,
}

impl Feeder {
    /// Take the slot's raw samples at `now`.
    pub fn sense(
        &mut self,
        slot: usize,
        sample: SlotSamples,
        now: Instant,
        config: &Config,
        rails: &RailLimits,
    ) {
        let presence = config.slot_thresholds.get(slot).copied().unwrap_or(DISABLED);
        let edges = config.motor_thresholds.get(slot).copied().unwrap_or(DISABLED);
        self.filament
            .update(sample.filament, now, &config.presence_filter, rails, presence);
        let revolution = self
            .hall
            .update(sample.motor_hall, now, &config.motor_filter, rails, edges);
        if revolution {
            let step = i32::from(config.mm_per_rev_centi);
            self.odometry_centi = match self.counting.unwrap_or(Direction::Forward) {
                Direction::Forward => self.odometry_centi.saturating_add(step),
                Direction::Reverse => self.odometry_centi.saturating_sub(step),
            };
        }
    }

    /// Drive at `speed` mm/s in `direction`. Call every step; the duty follows the schedule.
    pub fn drive(&mut self, direction: Direction, speed: u16, now: Instant, config: &Config) {
        let drive = match self.drive {
            Some(drive) if drive.direction == direction && drive.speed == speed => drive,
            _ => Drive {
                direction,
                speed,
                since: now,
                from_centi: self.odometry_centi,
            },
        };
        self.drive = Some(drive);
        let elapsed_ms = i64::try_from(now.millis_since(drive.since)).unwrap_or(i64::MAX / 1000);
        let scheduled_centi = i64::from(speed).saturating_mul(elapsed_ms) / 10;
        let moved_centi = match direction {
            Direction::Forward => i64::from(self.odometry_centi) - i64::from(drive.from_centi),
            Direction::Reverse => i64::from(drive.from_centi) - i64::from(self.odometry_centi),
        };
        let lag_mm = ((scheduled_centi - moved_centi) / 100).clamp(-1000, 1000) as i32;
        let open_loop = i32::from(speed) * 1000 / i32::from(config.full_duty_speed.max(1));
        let duty = (open_loop + CATCH_UP_GAIN * lag_mm).clamp(0, i32::from(config.max_duty.min(1000)));
        self.set(
            MotorCommand::Drive {
                direction,
                duty: Duty::from_permille(duty as u16),
            },
            now,
            config,
        );
    }

    /// Drive at a fixed duty (the tension follower's assist).
    pub fn push(&mut self, duty: Duty, now: Instant, config: &Config) {
        self.drive = None;
        self.set(MotorCommand::forward(duty), now, config);
    }

    /// Let the motor turn freely.
    pub fn coast(&mut self, now: Instant, config: &Config) {
        self.drive = None;
        self.set(MotorCommand::Coast, now, config);
    }

    /// Hold the motor (short brake).
    pub fn brake(&mut self, now: Instant, config: &Config) {
        self.drive = None;
        if self.command != MotorCommand::Brake {
            self.braked_at = now;
        }
        self.set(MotorCommand::Brake, now, config);
    }

    /// Let the motor go: coast, once a brake has had time to stop it.
    pub fn release(&mut self, now: Instant, config: &Config) {
        if self.command == MotorCommand::Brake && now.millis_since(self.braked_at) < BRAKE_HOLD_MS {
            return;
        }
        self.coast(now, config);
    }

    fn set(&mut self, command: MotorCommand, now: Instant, config: &Config) {
        self.command = command;
        match command {
            MotorCommand::Drive { direction, duty } => {
                self.counting = Some(direction);
                let hard = duty.permille() >= config.stall_min_duty;
                self.hard_drive_since = match (hard, self.hard_drive_since) {
                    (true, Some(since)) => Some(since),
                    (true, None) => Some(now),
                    (false, _) => None,
                };
            }
            MotorCommand::Coast => {
                self.counting = Some(Direction::Forward);
                self.hard_drive_since = None;
            }
            MotorCommand::Brake => self.hard_drive_since = None,
        }
    }

    /// The command for the motor now.
    pub fn command(&self) -> MotorCommand {
        self.command
    }

    /// Where the motor has moved the filament since start, mm (forward positive).
    pub fn odometry_mm(&self) -> i32 {
        self.odometry_centi / 100
    }

    /// Filament speed from the motor's last revolution period, mm/s (0 when it stands still).
    pub fn speed_mm_s(&self, now: Instant, config: &Config) -> u16 {
        let speed = u64::from(self.hall.rpm(now)) * u64::from(config.mm_per_rev_centi) / 6000;
        speed.min(u64::from(u16::MAX)) as u16
    }

    /// The odometry in 1/100 mm.
    pub fn odometry_centi(&self) -> i32 {
        self.odometry_centi
    }

    /// True when the motor is driven hard enough to turn but has not turned for the stall timeout.
    pub fn stalled(&self, now: Instant, config: &Config) -> bool {
        let Some(since) = self.hard_drive_since else {
            return false;
        };
        let last_sign_of_life = since.max(self.hall.last_revolution());
        now.millis_since(last_sign_of_life) > u64::from(config.stall_timeout_ms)
    }
}
