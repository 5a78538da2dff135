//! One of the unit's own moves of a slot, tallied while it runs and folded into the lane's drag
//! and slip when it ends.

use mmu_hal_port::MotorCommand;

use super::figures::{LaneFigures, roll, roll_signed};
use crate::config::Config;
use crate::drive::SlotDrive;
use crate::feeder::{Feeder, distance_centi};
use crate::time::Instant;

/// Moves shorter than this (commanded) give no slip figure, 1/100 mm.
const MIN_COMMANDED_CENTI: u32 = 5_000;
/// A speed under this gives no drag sample, mm/s (the motor is starting or stopping).
const MIN_SPEED: u16 = 5;

/// What one move did so far.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct MotionTally {
    /// The schedule's speed times the time driven: the distance commanded, mm·ms.
    commanded_mm_ms: u32,
    /// The distance the odometry counted meanwhile, 1/100 mm.
    counted_centi: u32,
    /// The duty applied, summed over the drag samples (one a revolution), per mille.
    duty_sum: u32,
    /// The speed measured, summed over the same samples, mm/s.
    speed_sum: u32,
    /// The odometry at the last step, 1/100 mm (`None` before the move's first step).
    last_centi: Option<i32>,
}

impl MotionTally {
    /// One step of a move the running command drives, `dt_ms` after the last.
    pub(super) fn add(&mut self, drive: &SlotDrive, feeder: &Feeder, dt_ms: u32, now: Instant) {
        let odometry = feeder.odometry_centi();
        let moved = self
            .last_centi
            .replace(odometry)
            .map_or(0, |last| distance_centi(last, odometry));
        let (MotorCommand::Drive { duty, .. }, Some(speed)) = (drive.command(), drive.scheduled_speed())
        else {
            return;
        };
        self.commanded_mm_ms = self.commanded_mm_ms.saturating_add(u32::from(speed) * dt_ms);
        self.counted_centi = self.counted_centi.saturating_add(moved.unsigned_abs());
        // Sampled where the lane moved (the speed is measured from its marks).
        if moved == 0 {
            return;
        }
        let measured = feeder.motion.speed_mm_s(now);
        if measured >= u32::from(MIN_SPEED) {
            self.duty_sum = self.duty_sum.saturating_add(u32::from(duty.permille()));
            self.speed_sum = self.speed_sum.saturating_add(measured);
        }
    }

    /// The move ended (or none runs): fold what it did into `lane`, and start again.
    pub(super) fn fold(&mut self, lane: &mut LaneFigures, config: &Config) {
        let mut tally = core::mem::take(self);
        let (mut commanded, mut counted) = (tally.commanded_mm_ms / 10, tally.counted_centi);
        if commanded >= MIN_COMMANDED_CENTI {
            // Both scaled under 2²¹ (a 21 m move), the shortfall limited to the commanded
            // distance: `short × 1000` fits.
            while commanded >= 1 << 21 {
                (commanded, counted) = (commanded >> 1, counted >> 1);
            }
            let short = (commanded as i32 - counted.min(2 * commanded) as i32)
                .clamp(-(commanded as i32), commanded as i32);
            let permille = (short * 1000 / commanded as i32) as i16;
            let first = lane.slip_permille == 0 && lane.drag_pct == 0;
            lane.slip_permille = roll_signed(lane.slip_permille, permille, first);
        }
        if tally.speed_sum > 0 {
            // A free lane needs `speed × 1000 / full_duty_speed` per mille for `speed`: the duty
            // applied over it, %, is `duty × full_duty_speed / (speed × 10)`. Both sums scaled
            // under 2²¹ so that the products fit (`full_duty_speed` is at most 2000, 2¹¹).
            while tally.duty_sum >= 1 << 21 || tally.speed_sum >= 1 << 21 {
                (tally.duty_sum, tally.speed_sum) = (tally.duty_sum >> 1, tally.speed_sum >> 1);
            }
            let applied = tally.duty_sum * u32::from(config.full_duty_speed.clamp(1, 2000));
            let pct = (applied / (tally.speed_sum.max(1) * 10)).min(u32::from(u16::MAX)) as u16;
            lane.drag_pct = roll(lane.drag_pct, pct.max(1));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn folded(tally: MotionTally) -> LaneFigures {
        let mut lane = LaneFigures::default();
        let mut tally = tally;
        tally.fold(&mut lane, &Config::default());
        lane
    }

    #[test]
    fn slip_and_drag_come_out_of_any_move_without_overflow() {
        // 400 mm commanded at 100 mm/s, 380 counted: 50 ‰ short; 667 ‰ duty for 100 mm/s
        // where a free lane needs 100 × 1000 / 150 = 667: 100 %.
        let lane = folded(MotionTally {
            commanded_mm_ms: 400_000,
            counted_centi: 38_000,
            duty_sum: 667 * 200,
            speed_sum: 100 * 200,
            last_centi: None,
        });
        assert_eq!((lane.slip_permille, lane.drag_pct), (50, 100));
        // A 60 m move, counted long, and sums at their limits.
        let lane = folded(MotionTally {
            commanded_mm_ms: 60_000_000,
            counted_centi: u32::MAX,
            duty_sum: u32::MAX,
            speed_sum: u32::MAX / 1000,
            last_centi: None,
        });
        assert_eq!(lane.slip_permille, -1000);
        assert!(lane.drag_pct > 0);
        // Too short for a slip figure; no speed sample: no drag figure.
        let lane = folded(MotionTally {
            commanded_mm_ms: 40_000,
            counted_centi: 0,
            duty_sum: 0,
            speed_sum: 0,
            last_centi: None,
        });
        assert_eq!(lane, LaneFigures::default());
    }
}
