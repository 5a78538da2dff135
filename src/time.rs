//! Explicit time: the logic is given the current instant at every step and never reads a clock,
//! so host tests and the simulator run it in virtual time.

use core::ops::Add;

/// A point in time, in milliseconds since the unit started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Instant(u64);

impl Instant {
    /// The unit's start.
    pub const ZERO: Instant = Instant(0);

    /// `ms` milliseconds after the start.
    pub const fn from_millis(ms: u64) -> Self {
        Instant(ms)
    }

    /// The whole milliseconds in an uptime of `us` microseconds.
    pub const fn from_micros(us: u64) -> Self {
        Instant(us / 1000)
    }

    /// Milliseconds since the start.
    pub const fn as_millis(self) -> u64 {
        self.0
    }

    /// Milliseconds from `earlier` to `self`, 0 if `earlier` is later.
    pub const fn millis_since(self, earlier: Instant) -> u64 {
        self.0.saturating_sub(earlier.0)
    }
}

impl Add<u64> for Instant {
    type Output = Instant;

    /// `ms` milliseconds later.
    fn add(self, ms: u64) -> Instant {
        Instant(self.0.saturating_add(ms))
    }
}
