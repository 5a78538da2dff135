//! What one slot's feeding system senses: the motor Hall sensor that measures how far the motor
//! turned (odometry in mm, speed) and the slot filament sensor at the slot entry. Its motor is
//! driven by [`crate::drive`].

use mmu_hal_port::{Direction, SlotSamples};

use crate::config::Config;
use crate::sensor::{FilterKind, PresenceSensor, RevolutionCounter, Thresholds};
use crate::time::Instant;

/// Thresholds no reading reaches, for a slot beyond the configured ones.
const DISABLED: Thresholds = Thresholds {
    on: u16::MAX,
    off: u16::MAX - 1,
};

/// One slot's sensors: motor Hall sensor and slot filament sensor.
#[derive(Debug, Clone, Copy)]
pub struct Feeder {
    /// The motor Hall sensor and its revolution count.
    pub hall: RevolutionCounter,
    /// The slot filament sensor.
    pub filament: PresenceSensor,
    /// Where the motor moved the filament, in 1/100 mm, forward positive. It wraps (at ±21.47 km):
    /// a distance is only ever the `wrapping_sub` of two readings, exact while the filament moved
    /// less than 21.47 km between them, so a slot past the end behaves as a fresh one.
    odometry_centi: i32,
}

impl Default for Feeder {
    fn default() -> Self {
        Self::NEW
    }
}

impl Feeder {
    /// A slot that has seen no sample.
    pub const NEW: Feeder = Feeder {
        hall: RevolutionCounter::NEW,
        filament: PresenceSensor::NEW,
        odometry_centi: 0,
    };

    /// Take the slot's raw samples at `now`; a revolution moves the filament in `counting`.
    pub fn sense(
        &mut self,
        slot: usize,
        sample: SlotSamples,
        counting: Direction,
        now: Instant,
        config: &Config,
    ) {
        let presence = config.slot_thresholds.get(slot).copied().unwrap_or(DISABLED);
        let edges = config.motor_thresholds.get(slot).copied().unwrap_or(DISABLED);
        self.filament
            .update(sample.filament, now, FilterKind::Presence, presence);
        let revolution = self.hall.update(sample.motor_hall, now, FilterKind::Motor, edges);
        if revolution {
            let step = i32::from(config.mm_per_rev_centi);
            self.odometry_centi = match counting {
                Direction::Forward => self.odometry_centi.wrapping_add(step),
                Direction::Reverse => self.odometry_centi.wrapping_sub(step),
            };
        }
    }

    /// Where the motor has moved the filament since start, mm (forward positive; wraps with the
    /// odometry, see [`Feeder::odometry_centi`]).
    pub fn odometry_mm(&self) -> i32 {
        self.odometry_centi / 100
    }

    /// Filament speed from the motor's last revolution period, mm/s (0 when it stands still).
    pub fn speed_mm_s(&self, now: Instant, config: &Config) -> u16 {
        let speed = self.hall.speed_mm_s(now, config.mm_per_rev_centi);
        speed.min(u32::from(u16::MAX)) as u16
    }

    /// The odometry in 1/100 mm. It wraps: a distance is the `wrapping_sub` of two readings
    /// (see [`distance_centi`]).
    pub fn odometry_centi(&self) -> i32 {
        self.odometry_centi
    }

    /// Start the odometry from `centi` instead of 0: for tests (a slot that has fed kilometres)
    /// and a restart that keeps it. Only differences of two readings are distances, so any
    /// start behaves as 0 does.
    pub fn set_odometry_centi(&mut self, centi: i32) {
        self.odometry_centi = centi;
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
