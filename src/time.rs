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

    /// The whole milliseconds in an uptime of `us` microseconds: `us / 1000` without the 64-bit
    /// division, a library call of about 200 instructions on a core without a divider (two of
    /// them every control step). The high word is folded into the low one (2³² = 4 294 967 ×
    /// 1000 + 296) until it is gone, which takes no round at all for the first 71 minutes of
    /// uptime and at most four after them; the low word takes [`crate::arith::div1000`].
    pub fn from_micros(us: u64) -> Self {
        let (mut x, mut ms) = (us, 0u64);
        while x >> 32 != 0 {
            let high = x >> 32;
            ms += high * 4_294_967;
            x = high * 296 + (x & 0xffff_ffff);
        }
        Instant(ms + u64::from(crate::arith::div1000(x as u32)))
    }

    /// Milliseconds since the start.
    pub const fn as_millis(self) -> u64 {
        self.0
    }

    /// Milliseconds from `earlier` to `self`, 0 if `earlier` is later.
    // Inlined: a dozen calls a step, each a call's overhead around four instructions (the
    // step-cost benchmark: about 100 instructions a millisecond, for about 0.2 KiB of flash).
    #[inline(always)]
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn from_micros_at_the_word_boundaries() {
        for us in [
            0,
            999,
            1000,
            u64::from(u32::MAX),
            u64::from(u32::MAX) + 1,
            (1 << 32) + 703,
            (1 << 32) + 704,
            (1 << 41) - 1,
            (1 << 41) + 999,
            u64::MAX - 1000,
            u64::MAX,
        ] {
            assert_eq!(Instant::from_micros(us).as_millis(), us / 1000, "{us}");
        }
    }

    proptest! {
        #[test]
        fn from_micros_divides_by_1000(us: u64, small in 0u64..1 << 40) {
            prop_assert_eq!(Instant::from_micros(us).as_millis(), us / 1000);
            prop_assert_eq!(Instant::from_micros(small).as_millis(), small / 1000);
        }
    }
}
