//! Division by a constant without a divider. The Cortex-M0+ has no divide instruction and no
//! 32 × 32 → 64 multiply: a `/` is a library call of 80 to 140 instructions, a `u64` product
//! another call. The control step divides by 10, 100 and 1000 every millisecond (hundredths of a
//! millimetre to millimetres, microseconds to milliseconds); here each is a multiplication by a
//! reciprocal, exact for every `u32`, checked when it is built ([`Divisor::new`], at compile time).

/// The high 32 bits of the 64-bit product `a × b`, from 16-bit halves: four single-cycle
/// multiplications on the Cortex-M0+ instead of the 64-bit multiplication routine
/// (`__aeabi_lmul`), which LLVM would otherwise turn this back into (hence the `black_box`).
// Out of line: a dozen callers (smaller than inlined; the idle step no costlier, measured).
#[inline(never)]
pub fn mul_high(a: u32, b: u32) -> u32 {
    let (a0, a1) = (a & 0xffff, a >> 16);
    let (b0, b1) = (b & 0xffff, core::hint::black_box(b >> 16));
    let (low, cross1, cross2) = (a0 * b0, a0 * b1, a1 * b0);
    let carry = ((low >> 16) + (cross1 & 0xffff) + (cross2 & 0xffff)) >> 16;
    a1 * b1 + (cross1 >> 16) + (cross2 >> 16) + carry
}

/// A constant divisor `d`, as its reciprocal: `⌊x / d⌋ = ⌊x × m / 2³²⁺ˢ⌋` for every `u32` `x`
/// when `m = ⌈2³²⁺ˢ / d⌉` fits in 32 bits and `m × d − 2³²⁺ˢ ≤ 2ˢ` (Granlund and Montgomery,
/// "Division by invariant integers using multiplication", 1994, theorem 4.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Divisor {
    multiplier: u32,
    shift: u32,
}

impl Divisor {
    /// `d`'s reciprocal with the smallest shift that makes it exact. Fails to build (a panic in
    /// a `const`) for a divisor without one: 0, 1 and some large ones.
    pub const fn new(d: u32) -> Self {
        match Self::exact(d) {
            Some(divisor) => divisor,
            None => panic!("no exact 32-bit reciprocal for this divisor"),
        }
    }

    /// `d`'s reciprocal with the smallest shift that makes it exact, if there is one.
    pub const fn exact(d: u32) -> Option<Self> {
        if d < 2 {
            return None;
        }
        let mut shift = 0;
        while shift < 32 {
            let power = 1u64 << (32 + shift);
            let multiplier = power.div_ceil(d as u64);
            if multiplier > u32::MAX as u64 {
                break;
            }
            if multiplier * d as u64 - power <= 1 << shift {
                return Some(Divisor {
                    multiplier: multiplier as u32,
                    shift,
                });
            }
            shift += 1;
        }
        None
    }

    /// `d`'s reciprocal for a divisor known only at run time (a setting), exact for every `x`
    /// below 2³¹; `None` for 0 and 1. With `2ˢ⁻¹ < d ≤ 2ˢ`, `m = ⌈2³¹⁺ˢ / d⌉` fits in 32 bits, and
    /// `x m / 2³¹⁺ˢ` exceeds `x / d` by less than `x / 2³¹⁺ˢ < 2⁻ˢ ≤ 1 / d`: too little to reach
    /// the next whole quotient. Built with one 64-bit division.
    pub const fn for_dividends_below_2_31(d: u32) -> Option<Self> {
        if d < 2 {
            return None;
        }
        let s = u32::BITS - (d - 1).leading_zeros();
        let multiplier = (1u64 << (31 + s)).div_ceil(d as u64);
        if multiplier > u32::MAX as u64 {
            return None;
        }
        Some(Divisor {
            multiplier: multiplier as u32,
            shift: s - 1,
        })
    }

    /// `x / d`, for every `x` (below 2³¹ for [`Divisor::for_dividends_below_2_31`]).
    #[inline(always)]
    pub fn divide(self, x: u32) -> u32 {
        mul_high(x, self.multiplier) >> self.shift
    }

    /// `x / d` truncated toward zero, as Rust's `/` on `i32`, for every `x`.
    #[inline(always)]
    pub fn divide_signed(self, x: i32) -> i32 {
        // |i32::MIN| / d fits an i32 for every d > 1.
        let quotient = self.divide(x.unsigned_abs()) as i32;
        if x < 0 { -quotient } else { quotient }
    }
}

/// Tenths.
pub const BY_10: Divisor = Divisor::new(10);
/// Hundredths: 1/100 mm to mm.
pub const BY_100: Divisor = Divisor::new(100);
/// Thousandths: µs to ms, per mille.
pub const BY_1000: Divisor = Divisor::new(1000);

/// `x / 1000` for any `u32`.
#[inline(always)]
pub fn div1000(x: u32) -> u32 {
    BY_1000.divide(x)
}

/// Whole millimetres in `centi` hundredths, truncated toward zero (as `centi / 100`).
#[inline(always)]
pub fn centi_to_mm(centi: i32) -> i32 {
    BY_100.divide_signed(centi)
}

/// Whether `⌊dividend / divisor⌋ < x` (`divisor` 0 counts as 1), without the division, which a
/// bound checked every millisecond would pay each time: `⌊a / d⌋ < x` exactly when `a < x × d`,
/// the product compared in 64 bits from [`mul_high`] and the low word.
pub fn quotient_below(dividend: u32, divisor: u32, x: u32) -> bool {
    let divisor = divisor.max(1);
    mul_high(x, divisor) != 0 || dividend < x.wrapping_mul(divisor)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const EDGES: [u32; 8] = [0, 1, 99, 100, 999, 1000, u32::MAX - 1, u32::MAX];

    #[test]
    fn a_run_time_reciprocal_is_exact_at_the_edges_and_absent_for_0_and_1() {
        assert_eq!(Divisor::for_dividends_below_2_31(0), None);
        assert_eq!(Divisor::for_dividends_below_2_31(1), None);
        let dividends = [0, 1, 999, 1000, 65_535_000, (1 << 31) - 2, (1 << 31) - 1];
        for d in [
            2,
            3,
            7,
            150,
            1000,
            1 << 16,
            (1 << 16) + 1,
            u32::MAX / 2,
            u32::MAX - 1,
            u32::MAX,
        ] {
            let divisor = Divisor::for_dividends_below_2_31(d).unwrap();
            let around_d = [d - 1, d, d.saturating_add(1)].map(|x| x.min((1 << 31) - 1));
            for x in dividends.into_iter().chain(around_d) {
                assert_eq!(divisor.divide(x), x / d, "{x} / {d}");
            }
        }
    }

    #[test]
    fn a_quotient_below_x_is_the_division_compared() {
        for a in EDGES {
            for d in EDGES {
                for x in EDGES
                    .into_iter()
                    .chain([a / d.max(1), (a / d.max(1)).saturating_add(1)])
                {
                    assert_eq!(quotient_below(a, d, x), a / d.max(1) < x, "{a} / {d} < {x}");
                }
            }
        }
    }

    #[test]
    fn the_reciprocals_are_those_of_the_literature() {
        // ⌈2³⁸ / 1000⌉ and ⌈2³⁵ / 10⌉, as compilers emit them.
        assert_eq!(
            BY_1000,
            Divisor {
                multiplier: 0x1062_4dd3,
                shift: 6
            }
        );
        assert_eq!(
            BY_10,
            Divisor {
                multiplier: 0xcccc_cccd,
                shift: 3
            }
        );
    }

    #[test]
    fn every_divisor_in_use_is_exact_at_the_edges() {
        for (divisor, d) in [(BY_10, 10), (BY_100, 100), (BY_1000, 1000)] {
            for x in EDGES.into_iter().chain((0..4).map(|k| d * k + d - 1)) {
                assert_eq!(divisor.divide(x), x / d, "{x} / {d}");
            }
            for x in [
                i32::MIN,
                i32::MIN + 1,
                -1000,
                -101,
                -100,
                -99,
                -1,
                0,
                1,
                99,
                100,
                i32::MAX,
            ] {
                assert_eq!(divisor.divide_signed(x), x / d as i32, "{x} / {d}");
            }
        }
        assert_eq!(Divisor::exact(1), None);
        assert_eq!(
            Divisor::exact(100_000),
            None,
            "metres take two steps: by 100, then by 1000"
        );
    }

    proptest! {
        #[test]
        fn a_quotient_below_x_is_the_division_compared_anywhere(a: u32, d: u32, x: u32) {
            prop_assert_eq!(quotient_below(a, d, x), a / d.max(1) < x);
            // Near the quotient, where the answer turns.
            let q = a / d.max(1);
            prop_assert!(!quotient_below(a, d, q));
            prop_assert_eq!(quotient_below(a, d, q.saturating_add(1)), q < u32::MAX);
        }

        #[test]
        fn a_run_time_reciprocal_divides_every_dividend_below_2_31(x in 0u32..1 << 31, d in 2u32..) {
            let divisor = Divisor::for_dividends_below_2_31(d).unwrap();
            prop_assert_eq!(divisor.divide(x), x / d);
            // The largest dividend, and the multiple of d just below it and the one before.
            let top = (1 << 31) - 1;
            for x in [top, top / d * d, (top / d * d).saturating_sub(1)] {
                prop_assert_eq!(divisor.divide(x), x / d);
            }
        }

        #[test]
        fn a_reciprocal_divides_as_the_division_does(x: u32, d in 2u32..1 << 20) {
            // Divisors without an exact 32-bit reciprocal have none, never a wrong one.
            if let Some(divisor) = Divisor::exact(d) {
                prop_assert_eq!(divisor.divide(x), x / d);
                let signed = x as i32;
                prop_assert_eq!(divisor.divide_signed(signed), signed / d as i32);
            }
        }

        #[test]
        fn centi_to_mm_truncates_as_the_division_does(centi: i32) {
            prop_assert_eq!(centi_to_mm(centi), centi / 100);
        }
    }
}
