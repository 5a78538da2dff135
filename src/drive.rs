//! The drive owner: the only code that turns decisions into [`MotorCommand`]s.
//!
//! Command phases and the tension follower never set a motor themselves: they ask the slot's
//! [`SlotDrive`] for a [`Motion`] under a [`Budget`] (distance, time, and the stall rule, which
//! always applies). The drive turns the motion into a duty, counts the budget from where the
//! motion began, and refuses to go on past it: the motor is braked and the budget's error is
//! returned. So whoever asks, no motor runs unsupervised.

use mmu_hal_port::{Direction, Duty, MotorCommand};
use mmu_protocol::ErrorCode;

use crate::config::Config;
use crate::feeder::{Feeder, distance_centi};
use crate::time::Instant;

/// How long a braked motor stays braked before it may coast, ms: long enough to stop it, so a
/// parked tip does not drift on the motor's momentum.
const BRAKE_HOLD_MS: u64 = 200;

/// The duty of a feel ([`SlotDrive::feel`]), per mille: above the drag of a spool, a sixth of
/// the highest duty, below the stall rule's duty (nothing a feel meets counts as a stall). Not
/// measured against real extruder gears; the simulator records every pull against its gears.
pub const FEEL_DUTY: Duty = Duty::from_permille(160);

/// Duty added per millimetre the filament lags behind its schedule, per mille.
const CATCH_UP_GAIN: i32 = 25;

/// How far and how long a supervised motion may go, and what going past it means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Budget {
    /// Filament the motor may move, mm (either direction).
    pub max_mm: u16,
    /// Time the motor may be driven, ms (`u32::MAX`: no limit).
    pub max_ms: u32,
    /// The longest the motor may be driven, at any duty, without a revolution, ms: a motor too
    /// weakly driven to count as stalled still has to move the filament.
    pub max_still_ms: u32,
    /// The error reported past any bound.
    pub error: ErrorCode,
}

/// What a slot's motor should do this step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// Move the filament at `speed` mm/s in `direction`; the duty follows a schedule.
    Run {
        /// The direction.
        direction: Direction,
        /// The filament speed, mm/s.
        speed: u16,
    },
    /// Forward at `speed` mm/s, corrected by the Bowden tension (see [`follow_duty`]).
    Follow {
        /// The filament speed, mm/s (0: assist the extruder only).
        speed: u16,
    },
}

/// A speed-controlled move in progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct SpeedSchedule {
    direction: Direction,
    speed: u16,
    since: Instant,
    from_centi: i32,
    /// [`open_loop_duty`] of `speed`, and the `full_duty_speed` it was computed for: computed when
    /// the move starts (or the setting changes), not every step of it.
    open_loop: i32,
    full_duty_speed: u16,
}

/// The budget of the motion in progress and where it began.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct DriveLease {
    budget: Budget,
    started: Instant,
    from_centi: i32,
}

/// One slot's motor.
#[derive(Debug, Clone, Copy)]
pub struct SlotDrive {
    command: MotorCommand,
    schedule: Option<SpeedSchedule>,
    lease: Option<DriveLease>,
    /// Since when the motor has been driven at or above the stall duty with no revolution
    /// since: a dip below the stall duty does not start the count again (see
    /// [`SlotDrive::stalled`]).
    hard_drive_since: Option<Instant>,
    /// The direction revolutions count in (the extruder pulls forward while the motor coasts).
    counting: Option<Direction>,
    /// When the motor was last braked.
    braked_at: Instant,
}

impl Default for SlotDrive {
    fn default() -> Self {
        Self::NEW
    }
}

impl SlotDrive {
    /// A motor that coasts, with no motion in progress.
    pub const NEW: SlotDrive = SlotDrive {
        command: MotorCommand::Coast,
        schedule: None,
        lease: None,
        hard_drive_since: None,
        counting: None,
        braked_at: Instant::ZERO,
    };

    /// Start a supervised motion under `budget`: distance and time count from here.
    pub fn begin(&mut self, budget: Budget, feeder: &Feeder, now: Instant) {
        self.lease = Some(DriveLease {
            budget,
            started: now,
            from_centi: feeder.odometry_centi(),
        });
    }

    /// Drive as `motion` this step, within the budget given to [`SlotDrive::begin`]. Past the
    /// budget, or stalled, the motor is braked and the error returned; without a budget the motor
    /// is braked and [`ErrorCode::INTERNAL`] returned.
    pub fn run(
        &mut self,
        motion: Motion,
        feeder: &Feeder,
        tension: Option<u16>,
        now: Instant,
        config: &Config,
    ) -> Result<(), ErrorCode> {
        let Some(lease) = self.lease else {
            self.brake(now);
            return Err(ErrorCode::INTERNAL);
        };
        match motion {
            Motion::Run { direction, speed } => self.follow_schedule(direction, speed, feeder, now, config),
            Motion::Follow { speed } => {
                self.schedule = None;
                self.set(
                    MotorCommand::forward(follow_duty(speed, tension, config)),
                    feeder,
                    now,
                    config,
                );
            }
        }
        let still_since = lease.started.max(feeder.motion.last_mark());
        let still_too_long = self.command.is_driving()
            && millis_u32(now.millis_since(still_since)) > lease.budget.max_still_ms;
        let too_far = distance_centi(lease.from_centi, feeder.odometry_centi()).unsigned_abs() / 100
            > u32::from(lease.budget.max_mm);
        let too_long = millis_u32(now.millis_since(lease.started)) > lease.budget.max_ms;
        let verdict = if self.stalled(feeder, now, config) {
            Err(ErrorCode::STALLED_PULLEY)
        } else if still_too_long || too_far || too_long {
            Err(lease.budget.error)
        } else {
            Ok(())
        };
        if verdict.is_err() {
            self.brake(now);
        }
        verdict
    }

    /// Hold the motor (short brake); ends the motion in progress.
    pub fn brake(&mut self, now: Instant) {
        self.end();
        if self.command != MotorCommand::Brake {
            self.braked_at = now;
        }
        self.command = MotorCommand::Brake;
        self.hard_drive_since = None;
    }

    /// Let the motor go: coast, once a brake has had time to stop it. Ends the motion in progress.
    pub fn release(&mut self, now: Instant) {
        self.end();
        if self.command == MotorCommand::Brake && now.millis_since(self.braked_at) < BRAKE_HOLD_MS {
            return;
        }
        self.command = MotorCommand::Coast;
        self.counting = Some(Direction::Forward);
        self.hard_drive_since = None;
    }

    /// Pull back at [`FEEL_DUTY`], outside any budget (the phase that feels bounds the time):
    /// too weak to move a filament the extruder's gears grip, it brings back one they let go.
    /// Ends the motion in progress.
    pub fn feel(&mut self) {
        self.end();
        self.command = MotorCommand::reverse(FEEL_DUTY);
        self.counting = Some(Direction::Reverse);
        self.hard_drive_since = None;
    }

    /// True while a motion under a budget is in progress.
    pub fn is_supervising(&self) -> bool {
        self.lease.is_some()
    }

    /// True while the motor turns freely (not driven, not braked): whatever turns it now is the
    /// filament, pulled or pushed by the printer's extruder or a hand.
    pub fn is_coasting(&self) -> bool {
        self.command == MotorCommand::Coast
    }

    /// The command for the motor now.
    pub fn command(&self) -> MotorCommand {
        self.command
    }

    /// The speed the move in progress is scheduled at, mm/s (`None`: no speed-controlled move).
    pub fn scheduled_speed(&self) -> Option<u16> {
        self.schedule.map(|schedule| schedule.speed)
    }

    /// The direction the motor's revolutions move the filament.
    pub fn counting(&self) -> Direction {
        self.counting.unwrap_or(Direction::Forward)
    }

    fn end(&mut self) {
        self.schedule = None;
        self.lease = None;
    }

    /// The duty that keeps the odometry on a schedule of `speed` mm/s from when this move began.
    fn follow_schedule(
        &mut self,
        direction: Direction,
        speed: u16,
        feeder: &Feeder,
        now: Instant,
        config: &Config,
    ) {
        let odometry = feeder.odometry_centi();
        let mut schedule = match self.schedule {
            Some(schedule) if schedule.direction == direction && schedule.speed == speed => schedule,
            _ => SpeedSchedule {
                direction,
                speed,
                since: now,
                from_centi: odometry,
                open_loop: open_loop_duty(speed, config.full_duty_speed),
                full_duty_speed: config.full_duty_speed,
            },
        };
        if schedule.full_duty_speed != config.full_duty_speed {
            schedule.open_loop = open_loop_duty(speed, config.full_duty_speed);
            schedule.full_duty_speed = config.full_duty_speed;
        }
        self.schedule = Some(schedule);
        let moved_centi = match direction {
            Direction::Forward => distance_centi(schedule.from_centi, odometry),
            Direction::Reverse => distance_centi(odometry, schedule.from_centi),
        };
        let lag_mm = schedule_lag_mm(speed, now.millis_since(schedule.since), moved_centi);
        let duty =
            (schedule.open_loop + CATCH_UP_GAIN * lag_mm).clamp(0, i32::from(config.max_duty.min(1000)));
        self.set(
            MotorCommand::Drive {
                direction,
                duty: Duty::from_permille(duty as u16),
            },
            feeder,
            now,
            config,
        );
    }

    /// Drive as `command`; a hard drive (at or above the stall duty) starts the stall count
    /// unless one runs with no revolution since it began.
    fn set(&mut self, command: MotorCommand, feeder: &Feeder, now: Instant, config: &Config) {
        self.command = command;
        if let MotorCommand::Drive { direction, duty } = command {
            self.counting = Some(direction);
            let turned_since = |since: Instant| feeder.motion.last_mark() > since;
            if duty.permille() >= config.stall_min_duty && self.hard_drive_since.is_none_or(turned_since) {
                self.hard_drive_since = Some(now);
            }
        }
    }

    /// True when the motor, driven hard enough to turn (at or above the stall duty) now, has not
    /// turned for the stall timeout since it was first driven that hard. A duty that dips below
    /// the stall duty on the way (a follower's, hovering at it on a noisy tension reading) does
    /// not start the count again, or every dip would put the stop off by the time before it. A
    /// brake or a release ends the count; so does a revolution, the count starting again at the
    /// next hard drive.
    fn stalled(&self, feeder: &Feeder, now: Instant, config: &Config) -> bool {
        let Some(since) = self.hard_drive_since else {
            return false;
        };
        let hard_now = matches!(self.command, MotorCommand::Drive { duty, .. } if duty.permille() >= config.stall_min_duty);
        let last_sign_of_life = since.max(feeder.motion.last_mark());
        hard_now && now.millis_since(last_sign_of_life) > u64::from(config.stall_timeout_ms)
    }
}

/// A duration in 32 bits, saturated (49 days): past a budget's every bound but `u32::MAX`, which
/// is none.
pub(crate) fn millis_u32(ms: u64) -> u32 {
    u32::try_from(ms).unwrap_or(u32::MAX)
}

/// Every motor of a unit stopped (coasting): what the board applies before the logic's first
/// step and before a reset.
pub const fn stopped<const N: usize>() -> [MotorCommand; N] {
    [MotorCommand::Coast; N]
}

/// How far the filament is behind its schedule after `elapsed_ms` at `speed` mm/s, in whole mm
/// (truncated toward zero), within ±1000: `(speed × elapsed / 10 − moved_centi) / 100`.
fn schedule_lag_mm(speed: u16, elapsed_ms: u64, moved_centi: i32) -> i32 {
    // In 32 bits up to a schedule of 4.29 km: hours into a move, a metre behind is exact enough.
    let Ok(scheduled) = u32::try_from(elapsed_ms.saturating_mul(u64::from(speed))) else {
        return 1000;
    };
    let lag_centi = i64::from(scheduled / 10) - i64::from(moved_centi);
    lag_centi.clamp(-100_000, 100_000) as i32 / 100
}

/// The duty that moves the filament at `speed` mm/s without feedback, per mille (not limited):
/// `speed × 1000 / full_duty_speed` (a setting of 0 taken as 1).
fn open_loop_duty(speed: u16, full_duty_speed: u16) -> i32 {
    i32::from(speed) * 1000 / i32::from(full_duty_speed.max(1))
}

/// Duty that moves the filament at `speed` while keeping the Bowden tube at rest: more when the
/// extruder pulls it taut, less when it is compressed. Without a healthy tension sensor it is the
/// open-loop duty for `speed`.
pub fn follow_duty(speed: u16, tension: Option<u16>, config: &Config) -> Duty {
    let open_loop = open_loop_duty(speed, config.full_duty_speed);
    let correction = tension.map_or(0, |value| {
        let deviation = i32::from(value) - i32::from(config.tension_neutral);
        let deadband = i32::from(config.tension_deadband);
        let beyond = if deviation > deadband {
            deviation - deadband
        } else if deviation < -deadband {
            deviation + deadband
        } else {
            0
        };
        beyond * i32::from(config.tension_gain)
    });
    let limit = i32::from(config.tension_max_duty.min(config.max_duty));
    Duty::from_permille((open_loop + correction).clamp(0, limit) as u16)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A motion under `max_ms`, `now_ms` after it began, motor stopped (no stall, no distance).
    fn timed_run(max_ms: u32, now_ms: u64) -> Result<(), ErrorCode> {
        let (config, feeder, mut drive) = (Config::default(), Feeder::default(), SlotDrive::NEW);
        let budget = Budget {
            max_mm: u16::MAX,
            max_ms,
            max_still_ms: max_ms,
            error: ErrorCode::MOVE_PULLEY_FAILED,
        };
        drive.begin(budget, &feeder, Instant::ZERO);
        drive.run(
            Motion::Follow { speed: 0 },
            &feeder,
            None,
            Instant::from_millis(now_ms),
            &config,
        )
    }

    /// The open-loop part of the duty is `speed × 1000 / full_duty_speed` whatever came before:
    /// a new speed, a new setting (`full_duty_speed` written by the printer mid-move), a switch between following and a
    /// schedule. Motor still, no tension reading: the duty is that part.
    #[test]
    fn the_open_loop_duty_follows_every_change_of_speed_and_setting() {
        let (mut config, feeder, mut drive) = (Config::default(), Feeder::default(), SlotDrive::NEW);
        let budget = Budget {
            max_mm: u16::MAX,
            max_ms: u32::MAX,
            max_still_ms: u32::MAX,
            error: ErrorCode::MOVE_PULLEY_FAILED,
        };
        drive.begin(budget, &feeder, Instant::ZERO);
        let follow = |speed| Motion::Follow { speed };
        let run = |speed| Motion::Run {
            direction: Direction::Forward,
            speed,
        };
        // (motion, full_duty_speed, duty ‰): each step at the same instant, so a schedule has
        // no lag to catch up and its duty is the open-loop one.
        let steps = [
            (follow(50), 200, 250),
            (follow(50), 200, 250),
            (follow(50), 100, 500),
            (follow(30), 100, 300),
            (run(30), 100, 300),
            (run(30), 150, 200),
            (run(45), 150, 300),
            (follow(45), 150, 300),
            (follow(0), 150, 0),
            (follow(45), 90, 500),
            (run(0), 90, 0),
        ];
        for (i, (motion, full_duty_speed, duty)) in steps.into_iter().enumerate() {
            config.full_duty_speed = full_duty_speed;
            drive
                .run(motion, &feeder, None, Instant::from_millis(1), &config)
                .unwrap();
            let permille = match drive.command() {
                MotorCommand::Drive { duty, .. } => duty.permille(),
                _ => 0,
            };
            assert_eq!(
                permille, duty,
                "step {i}: {motion:?} at full duty speed {full_duty_speed}"
            );
        }
    }

    #[test]
    fn a_budget_runs_out_after_its_time_and_u32_max_is_none() {
        for max_ms in [0, 1, 3000, 131_135_535, u32::MAX - 1] {
            assert_eq!(timed_run(max_ms, u64::from(max_ms)), Ok(()), "{max_ms}");
            for late in [u64::from(max_ms) + 1, u64::from(u32::MAX) + 1, 1 << 40, u64::MAX] {
                assert_eq!(
                    timed_run(max_ms, late),
                    Err(ErrorCode::MOVE_PULLEY_FAILED),
                    "{max_ms}"
                );
            }
        }
        // The follower's budget: a print of any length.
        for now_ms in [0, u64::from(u32::MAX), u64::from(u32::MAX) + 1, 1 << 40, u64::MAX] {
            assert_eq!(timed_run(u32::MAX, now_ms), Ok(()), "{now_ms}");
        }
    }

    /// A follower's duty hovering at the stall duty (a noisy tension reading: 250 ‰ one step, 248
    /// the next) on a motor that never turns: stopped once the stall timeout has passed since it
    /// was first driven that hard, at the first hard step after it. Each dip used to start the
    /// count again, and this motor was never stopped by the stall rule.
    #[test]
    fn a_duty_hovering_at_the_stall_duty_stalls_within_the_timeout_of_the_first_hard_step() {
        let (config, feeder, mut drive) = (Config::default(), Feeder::default(), SlotDrive::NEW);
        let budget = Budget {
            max_mm: u16::MAX,
            max_ms: u32::MAX,
            max_still_ms: u32::MAX,
            error: ErrorCode::MOVE_PULLEY_FAILED,
        };
        // Neutral 2048, dead band 60, gain 2: 2233 gives 250 ‰, 2232 gives 248 ‰.
        let hard = config.tension_neutral + config.tension_deadband + config.stall_min_duty / 2;
        assert_eq!(
            follow_duty(0, Some(hard), &config).permille(),
            config.stall_min_duty
        );
        drive.begin(budget, &feeder, Instant::ZERO);
        let timeout = u64::from(config.stall_timeout_ms);
        for ms in 1..=timeout + 3 {
            let tension = if ms % 2 == 1 { hard } else { hard - 1 };
            let verdict = drive.run(
                Motion::Follow { speed: 0 },
                &feeder,
                Some(tension),
                Instant::from_millis(ms),
                &config,
            );
            // First hard at 1 ms: past the timeout from 402 ms, the next hard step is 403 ms.
            let expected = if ms == timeout + 3 {
                Err(ErrorCode::STALLED_PULLEY)
            } else {
                Ok(())
            };
            assert_eq!(verdict, expected, "at {ms} ms");
        }
        assert_eq!(drive.command(), MotorCommand::Brake);
    }

    /// The lag the drive catches up: whole millimetres behind the schedule, truncated toward
    /// zero, ahead of it negative, and never more than a metre either way (hours into a move).
    #[test]
    fn the_schedule_lag_is_whole_millimetres_within_a_metre() {
        // 100 mm/s for 1 s is 10 000 centi scheduled.
        for (moved_centi, lag_mm) in [(0, 100), (9_901, 0), (9_900, 1), (10_099, 0), (10_100, -1)] {
            assert_eq!(schedule_lag_mm(100, 1000, moved_centi), lag_mm, "{moved_centi}");
        }
        assert_eq!(schedule_lag_mm(0, u64::MAX, 0), 0);
        for elapsed_ms in [1 << 40, u64::MAX] {
            assert_eq!(schedule_lag_mm(65_535, elapsed_ms, i32::MAX), 1000);
        }
        assert_eq!(schedule_lag_mm(1, 0, i32::MAX), -1000);
    }
}
