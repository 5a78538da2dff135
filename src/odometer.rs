//! A lane's motion as distance and direction, whatever counts it ([`MotionSensor`]).
//!
//! Every source becomes signed counts of a sensed shaft's turn: a revolution edge of the Hall
//! wave, the difference of two quadrature counts, the unwrapped difference of two angles. The
//! counts become odometry exactly (the division's remainder is carried, so no distance is lost
//! over kilometres), and every [`MARK_CENTI`] of it, or every revolution of a Hall wave, is a
//! *mark*: the sign of life the stall rules wait for and the period the speed comes from.

use mmu_hal_port::Direction;

use crate::profile::{ANGLE_COUNTS, ANGLE_FAULT, MotionSensor};
use crate::sensor::{AnalogSensor, FilterKind, Thresholds};
use crate::time::{Instant, div_rem_u64};

/// The filament motion between two marks of a counting source, 1/100 mm: the thesis build's
/// distance per revolution, so the stall rules wait as long on every build.
pub const MARK_CENTI: u16 = 200;

/// One lane's odometry.
#[derive(Debug, Clone, Copy)]
pub struct Odometer {
    /// The motion sensor as the diagnostics show it: the Hall wave filtered, a count or an
    /// angle as read.
    pub sensor: AnalogSensor,
    /// A Hall wave above its "on" threshold.
    high: bool,
    /// The last count or angle read (`None` before the first, or after a fault).
    last_count: Option<u16>,
    /// Where the filament moved, 1/100 mm, forward positive (wraps; see [`Odometer::centi`]).
    centi: i32,
    /// Counts × distance per turn not yet a whole 1/100 mm, carried to the next count.
    remainder: i32,
    /// The odometry at the last mark.
    mark_centi: i32,
    /// Marks counted since start (wraps).
    marks: u32,
    last_mark: Instant,
    /// Speed over the last two marks, mm/s, and the time between them, ms.
    mark_speed: Option<(u32, u64)>,
}

impl Default for Odometer {
    fn default() -> Self {
        Self::NEW
    }
}

impl Odometer {
    /// A lane that has seen no sample.
    pub const NEW: Odometer = Odometer {
        sensor: AnalogSensor::NEW,
        high: false,
        last_count: None,
        centi: 0,
        remainder: 0,
        mark_centi: 0,
        marks: 0,
        last_mark: Instant::ZERO,
        mark_speed: None,
    };

    /// Take the lane's motion sample `raw` from `source` at `now`. A Hall revolution counts the
    /// way the motor was last driven (`counting`); `edges` are the Hall wave's thresholds and
    /// `mm_per_rev_centi` the filament's motion per turn of the sensed shaft. Returns the marks
    /// this sample made (0 or 1).
    pub fn sense(
        &mut self,
        source: MotionSensor,
        raw: u16,
        counting: Direction,
        edges: Thresholds,
        mm_per_rev_centi: u16,
        now: Instant,
    ) -> bool {
        let counts = match source {
            MotionSensor::HallWave => self.hall_edge(raw, edges, now, counting),
            MotionSensor::Quadrature { .. } => {
                self.sensor.measure(raw, Some(raw), now);
                self.count_since_last(Some(raw), |from, to| i32::from(to.wrapping_sub(from) as i16))
            }
            MotionSensor::Pulses { .. } => {
                self.sensor.measure(raw, Some(raw), now);
                let pulses = self.count_since_last(Some(raw), |from, to| i32::from(to.wrapping_sub(from)));
                match counting {
                    Direction::Forward => pulses,
                    Direction::Reverse => -pulses,
                }
            }
            MotionSensor::Angle => {
                let angle = (raw & ANGLE_FAULT == 0).then_some(raw % ANGLE_COUNTS);
                self.sensor.measure(raw, angle, now);
                self.count_since_last(angle, unwrap_angle)
            }
        };
        if counts == 0 {
            return false;
        }
        let per_rev = source.counts_per_rev().max(1);
        let (step, remainder) = scale(counts, mm_per_rev_centi, self.remainder, per_rev);
        self.centi = self.centi.wrapping_add(step);
        self.remainder = remainder;
        let moved = self.centi.wrapping_sub(self.mark_centi).unsigned_abs();
        let mark = match source {
            MotionSensor::HallWave => true,
            _ => moved >= u32::from(MARK_CENTI),
        };
        if mark {
            let period = now.millis_since(self.last_mark);
            // A period over 2³² ms (49 days) is no speed at all.
            self.mark_speed = u32::try_from(period)
                .ok()
                .filter(|&period| self.marks > 0 && period > 0)
                .map(|period32| (moved.saturating_mul(10) / period32, period));
            self.marks = self.marks.wrapping_add(1);
            self.last_mark = now;
            self.mark_centi = self.centi;
        }
        mark
    }

    /// One Hall wave sample: ±1 count on a rising edge through both thresholds.
    fn hall_edge(&mut self, raw: u16, edges: Thresholds, now: Instant, counting: Direction) -> i32 {
        self.sensor.update(raw, now, FilterKind::Motor);
        let Some(value) = self.sensor.reading() else {
            return 0;
        };
        let was_high = self.high;
        self.high = edges.decide(was_high, value);
        match (self.high && !was_high, counting) {
            (false, _) => 0,
            (true, Direction::Forward) => 1,
            (true, Direction::Reverse) => -1,
        }
    }

    /// The counts from the last reading to `count` by `difference`. A reading missed for less
    /// than the fault timeout is bridged; none is counted across a fault.
    fn count_since_last(&mut self, count: Option<u16>, difference: fn(u16, u16) -> i32) -> i32 {
        let Some(to) = count else {
            if self.sensor.fault().is_some() {
                self.last_count = None;
            }
            return 0;
        };
        let counts = self.last_count.map_or(0, |from| difference(from, to));
        self.last_count = Some(to);
        counts
    }

    /// Where the filament moved since start, 1/100 mm, forward positive. It wraps (at ±21.47
    /// km): a distance is only ever the `wrapping_sub` of two readings, exact while the filament
    /// moved less than 21.47 km between them, so a lane past the end behaves as a fresh one.
    pub const fn centi(&self) -> i32 {
        self.centi
    }

    /// Start the odometry from `centi` instead of 0 (tests, a restart that keeps it).
    pub fn set_centi(&mut self, centi: i32) {
        self.centi = centi;
        self.mark_centi = centi;
    }

    /// When the last mark came: the filament's last sign of life.
    pub const fn last_mark(&self) -> Instant {
        self.last_mark
    }

    /// Marks since start (wraps).
    pub const fn marks(&self) -> u32 {
        self.marks
    }

    /// Filament speed over the last two marks, mm/s; 0 when the lane has not marked for twice
    /// that period (or has marked less than twice).
    pub fn speed_mm_s(&self, now: Instant) -> u32 {
        match self.mark_speed {
            Some((speed, period)) if now.millis_since(self.last_mark) <= period.saturating_mul(2) => speed,
            _ => 0,
        }
    }
}

/// `counts` of a turn of `per_rev` counts, each turn `mm_per_rev_centi`, with the `remainder`
/// carried from before: the whole 1/100 mm and the new remainder. In 32 bits as long as it fits
/// (every sample of a moving lane), else in 64: a count's difference is up to 65 535.
fn scale(counts: i32, mm_per_rev_centi: u16, remainder: i32, per_rev: u16) -> (i32, i32) {
    match counts
        .checked_mul(i32::from(mm_per_rev_centi))
        .and_then(|scaled| scaled.checked_add(remainder))
    {
        Some(scaled) => (scaled / i32::from(per_rev), scaled % i32::from(per_rev)),
        None => {
            let scaled = i64::from(counts) * i64::from(mm_per_rev_centi) + i64::from(remainder);
            // Divided by size; the quotient and the remainder take the sign of `scaled`, as `/`
            // and `%` give them. The odometry wraps; the remainder is below `per_rev`.
            let (quotient, rest) = div_rem_u64(scaled.unsigned_abs(), per_rev);
            let (quotient, rest) = (quotient as i32, rest as i32);
            if scaled < 0 {
                (quotient.wrapping_neg(), -rest)
            } else {
                (quotient, rest)
            }
        }
    }
}

/// The turn from angle `from` to angle `to`, counts, the short way round: an angle sensor read
/// every millisecond sees less than half a turn between two readings.
fn unwrap_angle(from: u16, to: u16) -> i32 {
    let half = i32::from(ANGLE_COUNTS / 2);
    (i32::from(to) - i32::from(from) + half).rem_euclid(i32::from(ANGLE_COUNTS)) - half
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::SensorFault;

    const EDGES: Thresholds = Thresholds { on: 2300, off: 1800 };

    fn feed(odometer: &mut Odometer, source: MotionSensor, samples: &[u16], now: &mut Instant, per_rev: u16) {
        for &raw in samples {
            odometer.sense(source, raw, Direction::Forward, EDGES, per_rev, *now);
            *now = *now + 1;
        }
    }

    #[test]
    fn a_hall_wave_counts_full_periods_only() {
        let mut odometer = Odometer::NEW;
        let mut now = Instant::ZERO;
        // Warm up at rest, then wobble between the thresholds: no revolution.
        let wobble: [u16; 100] = core::array::from_fn(|i| if i % 2 == 0 { 2100 } else { 2250 });
        feed(&mut odometer, MotionSensor::HallWave, &wobble, &mut now, 200);
        assert_eq!(odometer.centi(), 0);
        for _ in 0..3 {
            feed(
                &mut odometer,
                MotionSensor::HallWave,
                &[2400, 2500, 2000, 1700, 1600, 2000],
                &mut now,
                200,
            );
        }
        assert_eq!((odometer.marks(), odometer.centi()), (3, 600));
        // A revolution (2 mm) every 6 ms is 333 mm/s; long after the last one the lane is still.
        assert_eq!(odometer.speed_mm_s(now), 333);
        assert_eq!(odometer.speed_mm_s(now + 100), 0);
    }

    #[test]
    fn quadrature_counts_both_ways_across_the_counters_wrap_without_losing_a_fraction() {
        let source = MotionSensor::Quadrature { counts_per_rev: 2800 };
        let mut odometer = Odometer::NEW;
        let mut now = Instant::ZERO;
        // 23.56 mm a turn: 2800 counts forward from just below the counter's wrap.
        let forward: [u16; 29] = core::array::from_fn(|i| 65_500u16.wrapping_add(100 * i as u16));
        feed(&mut odometer, source, &forward, &mut now, 2356);
        assert_eq!(odometer.centi(), 2356);
        // Back 1400 counts: half a turn.
        feed(
            &mut odometer,
            source,
            &[(65_500u16).wrapping_add(1400)],
            &mut now,
            2356,
        );
        assert_eq!(odometer.centi(), 1178);
        // 7 counts at a time, 400 times: 2800 counts, still exactly a turn.
        let start = 65_500u16.wrapping_add(1400);
        let creep: [u16; 400] = core::array::from_fn(|i| start.wrapping_add(7 * (i as u16 + 1)));
        feed(&mut odometer, source, &creep, &mut now, 2356);
        assert_eq!(odometer.centi(), 1178 + 2356);
        assert!(odometer.marks() > 10);
    }

    #[test]
    fn any_count_and_distance_per_turn_scale_without_overflow_or_a_lost_fraction() {
        // Past i32: in 64 bits, the odometry wrapping as it does.
        assert_eq!(scale(65_535, u16::MAX, 1, 1), (-131_070, 0));
        assert_eq!(scale(-65_535, u16::MAX, 0, 4096), (-1_048_544, -1));
        assert_eq!(scale(3, 2356, 100, 2800), (2, 1_568));
    }

    #[test]
    fn pulses_count_the_way_the_motor_was_driven_across_the_counters_wrap() {
        let source = MotionSensor::Pulses { counts_per_rev: 700 };
        let mut odometer = Odometer::NEW;
        let mut now = Instant::ZERO;
        // 700 pulses a turn of 23.56 mm, from just below the wrap, driven forward then back.
        let forward: [u16; 8] = core::array::from_fn(|i| 65_400u16.wrapping_add(100 * i as u16));
        feed(&mut odometer, source, &forward, &mut now, 2356);
        assert_eq!(odometer.centi(), 2356);
        let back = [forward[7].wrapping_add(350)];
        odometer.sense(source, back[0], Direction::Reverse, EDGES, 2356, now);
        assert_eq!(odometer.centi(), 2356 - 1178);
    }

    #[test]
    fn an_angle_unwraps_through_zero_and_a_lost_magnet_is_a_fault_that_counts_nothing() {
        let mut odometer = Odometer::NEW;
        let mut now = Instant::ZERO;
        // Forward through 0: 4000 -> 100 is 196 counts; back again.
        feed(
            &mut odometer,
            MotionSensor::Angle,
            &[4000, 4050, 4095, 50, 100],
            &mut now,
            4096,
        );
        assert_eq!(odometer.centi(), 196);
        feed(&mut odometer, MotionSensor::Angle, &[4000], &mut now, 4096);
        assert_eq!(odometer.centi(), 0);
        // The magnet is lost for longer than the fault timeout, then comes back at another angle.
        let lost = [ANGLE_FAULT | 123; 60];
        feed(&mut odometer, MotionSensor::Angle, &lost, &mut now, 4096);
        assert_eq!(odometer.sensor.fault(), Some(SensorFault::NoSignal));
        feed(&mut odometer, MotionSensor::Angle, &[2000, 2010], &mut now, 4096);
        assert_eq!(odometer.sensor.fault(), None);
        assert_eq!(odometer.centi(), 10, "only the turn seen since it came back");
    }
}
