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
        Instant(div_rem_u64(us, 1000).0)
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

/// `n / d` and `n % d` for a divisor below 2^16, by 32-bit divisions only: long division, one
/// 16-bit digit of `n` at a time. A `/` or `%` of 64-bit numbers pulls a 1 KB library routine
/// into the firmware (RV32 and the M0+ have no 64-bit division); the firmware's 64-bit times and
/// distances are divided here instead. Panics when `d` is 0, as `/` does.
pub const fn div_rem_u64(n: u64, d: u16) -> (u64, u64) {
    let d = d as u32;
    let mut quotient = 0;
    let mut remainder = 0;
    let mut shift = 64;
    while shift > 0 {
        shift -= 16;
        // The remainder is below `d`, so the digit after it fits 32 bits.
        let part = (remainder << 16) | ((n >> shift) as u32 & 0xffff);
        quotient |= ((part / d) as u64) << shift;
        remainder = part % d;
    }
    (quotient, remainder as u64)
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

    #[test]
    fn div_rem_u64_divides_as_the_operators_do() {
        let numbers = [
            0,
            1,
            999,
            1000,
            65_535,
            1 << 32,
            u64::from(u32::MAX) * 15 + 14,
            u64::MAX - 1,
            u64::MAX,
        ];
        for n in numbers {
            for d in [1, 2, 15, 250, 1000, 4096, 60_000, u16::MAX] {
                assert_eq!(
                    div_rem_u64(n, d),
                    (n / u64::from(d), n % u64::from(d)),
                    "{n} / {d}"
                );
            }
        }
    }
}
