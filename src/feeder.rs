//! What one slot's feeding system senses: how far its filament moved (odometry in mm, speed,
//! from whichever motion sensor the profile has), the slot filament sensor at the slot entry,
//! and, where the profile has one per lane, the lane's tension. Its motor is driven by
//! [`crate::drive`].

use mmu_hal_port::{Direction, SlotSamples};

use crate::config::Config;
use crate::odometer::Odometer;
use crate::profile::{Profile, TensionAt};
use crate::sensor::{AnalogSensor, FilterKind, PresenceSensor, Thresholds};
use crate::time::Instant;

/// Thresholds no reading reaches, for a slot beyond the configured ones.
const DISABLED: Thresholds = Thresholds {
    on: u16::MAX,
    off: u16::MAX - 1,
};

/// One slot's sensors.
#[derive(Debug, Clone, Copy)]
pub struct Feeder {
    /// The lane's motion: odometry, speed and the motion sensor's health.
    pub motion: Odometer,
    /// The slot filament sensor.
    pub filament: PresenceSensor,
    /// The lane's own tension sensor (a profile with [`TensionAt::Lane`]).
    pub tension: AnalogSensor,
}

impl Default for Feeder {
    fn default() -> Self {
        Self::NEW
    }
}

impl Feeder {
    /// A slot that has seen no sample.
    pub const NEW: Feeder = Feeder {
        motion: Odometer::NEW,
        filament: PresenceSensor::NEW,
        tension: AnalogSensor::NEW,
    };

    /// Take the slot's raw samples at `now`, read as `profile` says; a motion sensor that cannot
    /// tell the direction counts the way the motor was last driven (`counting`). Returns true
    /// when the lane's motion made a mark ([`crate::odometer`]).
    pub fn sense(
        &mut self,
        slot: usize,
        sample: SlotSamples,
        counting: Direction,
        now: Instant,
        config: &Config,
        profile: &Profile,
    ) -> bool {
        let presence = config.slot_thresholds.get(slot).copied().unwrap_or(DISABLED);
        let edges = config.motor_thresholds.get(slot).copied().unwrap_or(DISABLED);
        self.filament
            .update(sample.filament, now, profile.presence, presence);
        if profile.tension == TensionAt::Lane {
            self.tension.update(sample.tension, now, FilterKind::Presence);
        }
        self.motion.sense(
            profile.motion,
            sample.motion,
            counting,
            edges,
            config.mm_per_rev_centi,
            now,
        )
    }

    /// Where the motor has moved the filament since start, mm (forward positive; wraps with the
    /// odometry, see [`Odometer::centi`]).
    pub fn odometry_mm(&self) -> i32 {
        self.motion.centi() / 100
    }

    /// Filament speed over the lane's last marks, mm/s (0 when it stands still).
    pub fn speed_mm_s(&self, now: Instant) -> u16 {
        self.motion.speed_mm_s(now).min(u32::from(u16::MAX)) as u16
    }

    /// The odometry in 1/100 mm. It wraps: a distance is the `wrapping_sub` of two readings
    /// (see [`distance_centi`]).
    pub fn odometry_centi(&self) -> i32 {
        self.motion.centi()
    }

    /// Start the odometry from `centi` instead of 0: for tests (a slot that has fed kilometres)
    /// and a restart that keeps it. Only differences of two readings are distances, so any
    /// start behaves as 0 does.
    pub fn set_odometry_centi(&mut self, centi: i32) {
        self.motion.set_centi(centi);
    }
}

/// The filament moved from odometry reading `from` to reading `to`, 1/100 mm (forward positive):
/// their wrapping difference, exact for any move shorter than 21.47 km, wherever the odometry is.
pub const fn distance_centi(from: i32, to: i32) -> i32 {
    to.wrapping_sub(from)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_are_wrapping_differences_across_the_end_of_the_odometry() {
        assert_eq!(distance_centi(100, 350), 250);
        assert_eq!(distance_centi(350, 100), -250);
        assert_eq!(distance_centi(i32::MAX - 50, i32::MIN + 50), 101);
        assert_eq!(distance_centi(i32::MIN + 50, i32::MAX - 50), -101);
    }
}
