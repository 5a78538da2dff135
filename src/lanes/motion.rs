//! One of the unit's own moves of a slot, tallied while it runs and folded into the lane's drag
//! and slip when it ends.

use mmu_hal_port::MotorCommand;

use super::figures::{LaneFigures, roll, roll_signed};
use crate::config::Config;
use crate::drive::SlotDrive;
use crate::feeder::Feeder;
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
}

impl MotionTally {
    /// One step of a move the running command drives: `moved` 1/100 mm counted since the last
    /// step, `dt_ms` after it.
    pub(super) fn add(
        &mut self,
        drive: &SlotDrive,
        feeder: &Feeder,
        moved: i32,
        dt_ms: u32,
        now: Instant,
        config: &Config,
    ) {
        let (MotorCommand::Drive { duty, .. }, Some(speed)) = (drive.command(), drive.scheduled_speed())
        else {
            return;
        };
        self.commanded_mm_ms = self.commanded_mm_ms.saturating_add(u32::from(speed) * dt_ms);
        self.counted_centi = self.counted_centi.saturating_add(moved.unsigned_abs());
        // Sampled at each revolution (the speed is measured from its period): a 64-bit division
        // a revolution, not one a step.
        if moved == 0 {
            return;
        }
        let measured = feeder.speed_mm_s(now, config);
        if measured >= MIN_SPEED {
            self.duty_sum = self.duty_sum.saturating_add(u32::from(duty.permille()));
            self.speed_sum = self.speed_sum.saturating_add(u32::from(measured));
        }
    }

    /// Whether a move was tallied since the last fold.
    pub(super) fn is_open(&self) -> bool {
        self.commanded_mm_ms != 0 || self.speed_sum != 0
    }

    /// The move ended (or none runs): fold what it did into `lane`, and start again.
    pub(super) fn fold(&mut self, lane: &mut LaneFigures, config: &Config) {
        let tally = core::mem::take(self);
        let commanded_centi = tally.commanded_mm_ms / 10;
        if commanded_centi >= MIN_COMMANDED_CENTI {
            let short = i64::from(commanded_centi) - i64::from(tally.counted_centi);
            let permille = (short * 1000 / i64::from(commanded_centi)).clamp(-1000, 1000) as i16;
            let first = lane.slip_permille == 0 && lane.drag_pct == 0;
            lane.slip_permille = roll_signed(lane.slip_permille, permille, first);
        }
        if tally.speed_sum > 0 {
            // A free lane needs `speed × 1000 / full_duty_speed` per mille for `speed`.
            let needed = u64::from(tally.speed_sum) * 1000;
            let applied = u64::from(tally.duty_sum) * u64::from(config.full_duty_speed.max(1));
            let pct = (applied * 100 / needed).min(u64::from(u16::MAX)) as u16;
            lane.drag_pct = roll(lane.drag_pct, pct.max(1));
        }
    }
}
