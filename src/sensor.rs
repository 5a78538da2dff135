//! Analog Hall sensors: one filter pipeline for all of them, thresholds with hysteresis, rail
//! detection and the motor revolution counter.
//!
//! The sensors are noisy (thesis §6.2): every raw sample goes through a sliding median (kills
//! spikes), a moving average and exponential smoothing, and presence decisions use two thresholds
//! so a reading near one of them cannot flicker. A reading stuck at a supply rail means a
//! disconnected or shorted sensor: it is never fed to the filter, and after a short time the
//! sensor is reported faulty instead of being believed.
//!
//! Every sensor is filtered in every 1 ms step on a core without a divider (Cortex-M0+), where
//! a division is a library call of about a hundred instructions, so a sample costs as little as
//! the pipeline allows: medians of 3 and 5 by a few comparisons (a window still filling, or of
//! another length, by counting), the average from a running sum divided by a shift or a
//! reciprocal (`divide_small`), the smoothing in whole counts and thousandths (`Decay`: shifts
//! for the usual weights, [`div1000`] for the others), and the two filters' settings
//! ([`FilterKind`]) as constants the compiler folds. The results are exactly those of the sort
//! and divisions they replace (see the tests).

use crate::arith::{div1000, mul_high};
use crate::time::Instant;

/// The longest median or average window.
pub const MAX_WINDOW: usize = 9;

/// Window sizes and smoothing of one filter pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FilterConfig {
    /// Sliding median window, samples (1 = off), clamped to `1..=MAX_WINDOW`.
    pub median: u8,
    /// Moving average window, samples (1 = off), clamped to `1..=MAX_WINDOW`.
    pub average: u8,
    /// Weight of the newest value in the exponential smoothing, per mille (1000 = off).
    pub smoothing_permille: u16,
}

/// A pair of thresholds with hysteresis: a reading turns a sensor on at or above `on` and off at
/// or below `off`, and keeps its state in between.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Thresholds {
    /// The level that turns the sensor on.
    pub on: u16,
    /// The level that turns the sensor off; below `on`.
    pub off: u16,
}

impl Thresholds {
    /// True when `off < on` and both are inside the ADC range.
    pub const fn is_valid(self) -> bool {
        self.off < self.on && self.on <= mmu_hal_port::ADC_MAX
    }

    /// The new state of a sensor that was `was_on` and now reads `value`.
    pub const fn decide(self, was_on: bool, value: u16) -> bool {
        if was_on {
            value > self.off
        } else {
            value >= self.on
        }
    }
}

/// A fixed-capacity ring of the last samples.
#[derive(Debug, Clone, Copy)]
struct Window {
    values: [u16; MAX_WINDOW],
    len: usize,
    next: usize,
}

impl Window {
    const fn new() -> Self {
        Window {
            values: [0; MAX_WINDOW],
            len: 0,
            next: 0,
        }
    }

    /// Stores `value` in place of the oldest sample of a window of `capacity`; returns the
    /// sample it replaced, if that one was part of the window before.
    // The per-sample helpers are `inline(always)`: the firmware is built with `opt-level = "z"`,
    // which would call each of them for every sample of every sensor (frame setup included).
    #[inline(always)]
    fn push(&mut self, value: u16, capacity: usize) -> Option<u16> {
        let capacity = capacity.clamp(1, MAX_WINDOW);
        if self.next >= capacity {
            self.next = 0;
        }
        let replaced = self
            .values
            .get_mut(self.next)
            .map(|slot| core::mem::replace(slot, value))
            .filter(|_| self.next < self.len);
        self.next += 1;
        self.len = (self.len + 1).min(capacity);
        replaced
    }

    fn filled(&self) -> &[u16] {
        self.values.get(..self.len).unwrap_or(&[])
    }

    /// The median by copying and sorting: the reference for [`MedianWindow`].
    #[cfg(test)]
    fn median(&self) -> u16 {
        let mut sorted = [0u16; MAX_WINDOW];
        let values = self.filled();
        let sorted = &mut sorted[..values.len()];
        sorted.copy_from_slice(values);
        sorted.sort_unstable();
        sorted.get(sorted.len() / 2).copied().unwrap_or(0)
    }
}

/// A [`Window`] for the sliding median. The lengths the default filters use, 3 and 5, take their
/// median from the ring directly with a few comparisons ([`median_of_3`], [`median_of_5`]); any
/// other length (a window filling up, other settings) counts ([`MedianWindow::counted_median`]).
#[derive(Debug, Clone, Copy)]
struct MedianWindow {
    ring: Window,
}

impl MedianWindow {
    const fn new() -> Self {
        MedianWindow { ring: Window::new() }
    }

    /// Adds a sample to a window of `capacity`; returns the new median (the upper one of an even
    /// count).
    #[inline(always)]
    fn push(&mut self, value: u16, capacity: usize) -> u16 {
        self.ring.push(value, capacity);
        let [a, b, c, d, e, ..] = self.ring.values;
        match self.ring.len {
            1 => value,
            3 => median_of_3(a, b, c),
            5 => median_of_5(a, b, c, d, e),
            _ => self.counted_median(),
        }
    }

    /// The median of the window by counting, for each sample, the samples below it and those
    /// not above it: no sorted copy, no sort routine in the image, nothing indexed (a window of
    /// at most [`MAX_WINDOW`] samples takes at most 162 comparisons, and only while a window
    /// fills or for settings other than the sensors' own).
    #[inline(never)]
    fn counted_median(&self) -> u16 {
        let filled = self.ring.filled();
        let middle = filled.len() / 2;
        filled
            .iter()
            .copied()
            .find(|&x| {
                let below = filled.iter().filter(|&&v| v < x).count();
                let not_above = filled.iter().filter(|&&v| v <= x).count();
                below <= middle && middle < not_above
            })
            .unwrap_or(0)
    }
}

/// The median of three values.
#[inline(always)]
fn median_of_3(a: u16, b: u16, c: u16) -> u16 {
    let (low, high) = if a < b { (a, b) } else { (b, a) };
    low.max(high.min(c))
}

/// The median of five values in six comparisons: the smaller of two ordered pairs' lows is below
/// three others, so it is not the median, which is then the second lowest of the other four.
#[inline(always)]
fn median_of_5(a: u16, b: u16, c: u16, d: u16, e: u16) -> u16 {
    let (a, b) = if a < b { (a, b) } else { (b, a) };
    let (c, d) = if c < d { (c, d) } else { (d, c) };
    // Drop the lowest of a, b, c, d; the other pair's low joins e.
    let (low, high, x) = if a < c { (c, d, b) } else { (a, b, d) };
    let (x, y) = if x < e { (x, e) } else { (e, x) };
    // The second lowest of the ordered pairs (low, high) and (x, y).
    if low < x { high.min(x) } else { low.min(y) }
}

/// A [`Window`] with the running sum of its samples, for the moving average: a sample adds
/// itself and takes off the one it replaced, instead of the window being summed every sample.
#[derive(Debug, Clone, Copy)]
struct AverageWindow {
    ring: Window,
    /// The sum of `ring.filled()`.
    sum: u32,
}

impl AverageWindow {
    const fn new() -> Self {
        AverageWindow {
            ring: Window::new(),
            sum: 0,
        }
    }

    /// Adds a sample to a window of `capacity`; returns the new mean, rounded down.
    #[inline(always)]
    fn push(&mut self, value: u16, capacity: usize) -> u16 {
        if capacity <= 1 {
            // A window of one sample (the motor sensors'): the state the ring's bookkeeping
            // would reach, set directly.
            self.ring.values[0] = value;
            self.ring.len = 1;
            self.ring.next = 1;
            self.sum = value.into();
            return value;
        }
        let len_before = self.ring.len;
        let replaced = self.ring.push(value, capacity);
        let len = self.ring.len;
        self.sum = match replaced {
            // The same window with one sample replaced (a window that changed length may have
            // lost several: summed again).
            Some(old) if len == len_before => self.sum.wrapping_sub(old.into()).wrapping_add(value.into()),
            _ => self.ring.filled().iter().map(|&v| u32::from(v)).sum(),
        };
        divide_small(self.sum, len) as u16
    }
}

/// `⌈2³² / d⌉` for every window length `d` from 2 to [`MAX_WINDOW`] (index `d`).
const RECIPROCALS: [u32; MAX_WINDOW + 1] = {
    let mut table = [0; MAX_WINDOW + 1];
    let mut d = 2;
    while d <= MAX_WINDOW {
        table[d] = u32::MAX / d as u32 + 1;
        d += 1;
    }
    table
};

/// `sum / len` for a sum of at most [`MAX_WINDOW`] `u16` values, without a division: a shift for
/// the lengths that are powers of two, else exact for `sum < 2³² / MAX_WINDOW`, which such a sum
/// always is (`len` 0 counts as 1).
#[inline(always)]
fn divide_small(sum: u32, len: usize) -> u32 {
    match len {
        0 | 1 => sum,
        2 => sum >> 1,
        4 => sum >> 2,
        8 => sum >> 3,
        _ => RECIPROCALS
            .get(len)
            .map_or(sum, |&reciprocal| mul_high(sum, reciprocal)),
    }
}

/// One step of the exponential smoothing for one weight `w`, prepared once per weight:
/// `next = ⌊(previous × (1000 − w) + mean × 1000 × w) / 1000⌋` in 1/1000 counts, as the
/// divisions computed it. A smoothed value is kept as whole counts and thousandths
/// ([`Smoothed`]). When `1000 − w` is a multiple of 125 (w = 500 keeps four eighths) the step
/// needs no division at all (see [`Decay::next`]); other weights take two [`div1000`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Decay {
    /// The weight prepared for, per mille (0: none yet).
    weight: u16,
    /// `1000 − weight`.
    keep: u32,
    /// `keep / 125`, when that divides evenly: `keep / 1000` is this many eighths.
    eighths: Option<u32>,
}

/// A smoothed value `counts + thousandths / 1000`, `thousandths < 1000` (a smoothed value is
/// never above the largest sample).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Smoothed {
    counts: u16,
    thousandths: u16,
}

impl Decay {
    /// Prepared for `weight`, taken as `1..=1000`.
    const fn new(weight: u16) -> Self {
        let weight = if weight > 1000 {
            1000
        } else if weight < 1 {
            1
        } else {
            weight
        };
        let keep = 1000 - weight as u32;
        // Without a division: other weights prepare it every sample.
        let mut eighths = None;
        let mut k = 0;
        while k < 8 {
            if k * 125 == keep {
                eighths = Some(k);
            }
            k += 1;
        }
        Decay {
            weight,
            keep,
            eighths,
        }
    }

    /// The smoothed value after `previous` took in `mean`, for values of samples up to
    /// [`mmu_hal_port::ADC_MAX`].
    ///
    /// With `keep = 125 k` and `previous = 1000 q + r`: `⌊previous × k / 8⌋ = 125 k q + ⌊r k / 8⌋`
    /// and `mean × w = 1000 mean − 125 k mean`, so with `d = k (q − mean)` the next value is
    /// `1000 (mean + ⌊d / 8⌋) + 125 (d mod 8) + ⌊r k / 8⌋`, whose last two terms are below 2000:
    /// shifts, masks and at most one carry.
    #[inline(always)]
    fn next(&self, previous: Smoothed, mean: u16) -> Smoothed {
        let (counts, thousandths) = (u32::from(previous.counts), u32::from(previous.thousandths));
        let mean = u32::from(mean);
        let (counts, thousandths) = match self.eighths {
            Some(k) => {
                let d = (counts.wrapping_sub(mean) as i32).wrapping_mul(k as i32);
                let counts = mean.wrapping_add((d >> 3) as u32);
                let thousandths = 125 * (d & 7) as u32 + ((thousandths * k) >> 3);
                if thousandths >= 1000 {
                    (counts + 1, thousandths - 1000)
                } else {
                    (counts, thousandths)
                }
            }
            None => {
                let previous = counts * 1000 + thousandths;
                let next = mean * u32::from(self.weight) + div1000(previous.wrapping_mul(self.keep));
                let counts = div1000(next);
                (counts, next - counts * 1000)
            }
        };
        // Below the largest sample, so within 16 bits.
        Smoothed {
            counts: counts as u16,
            thousandths: thousandths as u16,
        }
    }
}

/// The filter of the filament presence, tension and cutter sensors.
const PRESENCE_FILTER: FilterConfig = FilterConfig {
    median: 5,
    average: 4,
    smoothing_permille: 500,
};
const PRESENCE_DECAY: Decay = Decay::new(PRESENCE_FILTER.smoothing_permille);
/// The filter of the motor Hall sensors: a revolution's edges need little delay.
const MOTOR_FILTER: FilterConfig = FilterConfig {
    median: 3,
    average: 1,
    smoothing_permille: 1000,
};
const MOTOR_DECAY: Decay = Decay::new(MOTOR_FILTER.smoothing_permille);

/// Which of the unit's two filters a sensor takes. Their settings are fixed at build time (no
/// register changes them), so the compiler folds them into the pipeline: its clamps, window
/// dispatch and smoothing preparation, a fifth of a sample's instructions, and no general copy
/// of the pipeline for other settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FilterKind {
    /// Filament presence, tension and cutter sensors ([`FilterKind::config`]: median of 5,
    /// average of 4, smoothing 500 ‰).
    Presence,
    /// Motor Hall sensors (median of 3, no average, no smoothing).
    Motor,
}

impl FilterKind {
    /// The settings of this filter.
    pub const fn config(self) -> FilterConfig {
        match self {
            FilterKind::Presence => PRESENCE_FILTER,
            FilterKind::Motor => MOTOR_FILTER,
        }
    }
}

/// Sliding median, then moving average, then exponential smoothing.
#[derive(Debug, Clone, Copy)]
pub struct Filter {
    medians: MedianWindow,
    averages: AverageWindow,
    /// The smoothed value (`None` before the first sample).
    smoothed: Option<Smoothed>,
    /// The smoothed value rounded to counts (0 before the first sample).
    value: u16,
}

impl Default for Filter {
    fn default() -> Self {
        Self::new()
    }
}

impl Filter {
    /// An empty filter. Out of line: inlined into the per-sample code (for the reset after a
    /// fault) it cost every idle step 12 instructions.
    #[inline(never)]
    pub const fn new() -> Self {
        Filter {
            medians: MedianWindow::new(),
            averages: AverageWindow::new(),
            smoothed: None,
            value: 0,
        }
    }

    /// Feed one raw sample through the filter `kind`; returns the filtered value.
    #[inline(always)]
    pub fn push(&mut self, raw: u16, kind: FilterKind) -> u16 {
        match kind {
            FilterKind::Presence => self.push_with(raw, PRESENCE_FILTER, PRESENCE_DECAY),
            FilterKind::Motor => self.push_with(raw, MOTOR_FILTER, MOTOR_DECAY),
        }
    }

    /// [`Self::push`] with any settings: the same pipeline, for the tests to reach every window
    /// length and weight.
    #[cfg(test)]
    fn push_config(&mut self, raw: u16, config: &FilterConfig) -> u16 {
        self.push_with(raw, *config, Decay::new(config.smoothing_permille))
    }

    /// [`Self::push`] with the settings `config`; `decay` is its smoothing prepared.
    #[inline(always)]
    fn push_with(&mut self, raw: u16, config: FilterConfig, decay: Decay) -> u16 {
        let median = self.medians.push(raw, config.median.into());
        let mean = self.averages.push(median, config.average.into());
        let weight = config.smoothing_permille.clamp(1, 1000);
        // At w = 1000 (or on the first sample) the smoothed value is the mean itself.
        let smoothed = match self.smoothed {
            Some(previous) if weight < 1000 => decay.next(previous, mean),
            _ => Smoothed {
                counts: mean,
                thousandths: 0,
            },
        };
        self.smoothed = Some(smoothed);
        // Rounded half up.
        self.value = smoothed.counts + u16::from(smoothed.thousandths >= 500);
        self.value
    }

    /// The current filtered value (0 before the first sample).
    pub fn value(&self) -> u16 {
        self.value
    }

    /// Forget every sample.
    pub fn clear(&mut self) {
        *self = Self::new();
    }
}

/// Which rail a faulty sensor is stuck at. Counted from 1, so that `Option::<Rail>::None` is a
/// zero byte (see [`crate::unit::Unit::default`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Rail {
    /// Ground: typically a disconnected signal or supply.
    Low = 1,
    /// Supply: typically a short or a disconnected ground.
    High = 2,
}

/// A raw reading at or below this is a sensor stuck at the low rail. The rail limits are the
/// same for every sensor and fixed at build time (no register changes them).
pub const RAIL_LOW: u16 = 40;
/// A raw reading at or above this is a sensor stuck at the high rail.
pub const RAIL_HIGH: u16 = 4055;
/// How long a reading must stay at a rail before the sensor is reported faulty, ms.
pub const RAIL_TIMEOUT_MS: u64 = 50;

/// One analog sensor: its latest raw sample, its filtered value and its health.
#[derive(Debug, Clone, Copy)]
pub struct AnalogSensor {
    filter: Filter,
    raw: u16,
    /// Samples filtered since start or the last fault, counted up to [`WARM_UP_SAMPLES`].
    samples: u16,
    at_rail_since: Option<(Rail, Instant)>,
    fault: Option<Rail>,
}

/// Samples a filter needs before its output means anything.
const WARM_UP_SAMPLES: u16 = MAX_WINDOW as u16 * 2;

impl Default for AnalogSensor {
    fn default() -> Self {
        Self::NEW
    }
}

impl AnalogSensor {
    /// A sensor that has seen no sample.
    pub const NEW: AnalogSensor = AnalogSensor {
        filter: Filter::new(),
        raw: 0,
        samples: 0,
        at_rail_since: None,
        fault: None,
    };

    /// Take a new raw sample at `now`.
    pub fn update(&mut self, raw: u16, now: Instant, filter: FilterKind) {
        self.raw = raw;
        let rail = if raw <= RAIL_LOW {
            Some(Rail::Low)
        } else if raw >= RAIL_HIGH {
            Some(Rail::High)
        } else {
            None
        };
        match (rail, self.at_rail_since) {
            (Some(rail), Some((seen, since))) if rail == seen => {
                if now.millis_since(since) >= RAIL_TIMEOUT_MS {
                    self.fault = Some(rail);
                }
            }
            (Some(rail), _) => self.at_rail_since = Some((rail, now)),
            (None, _) => {
                if self.at_rail_since.is_some() {
                    self.at_rail_since = None;
                }
                if self.fault.is_some() {
                    // Back from a fault: old samples say nothing about the reconnected sensor.
                    self.fault = None;
                    self.filter.clear();
                    self.samples = 0;
                }
                self.filter.push(raw, filter);
                // Counted up to the warm-up only: all that is asked of the count.
                if self.samples < WARM_UP_SAMPLES {
                    self.samples += 1;
                }
            }
        }
    }

    /// The latest raw sample, whatever it was.
    pub fn raw(&self) -> u16 {
        self.raw
    }

    /// The filtered value (held while the raw reading sits at a rail).
    pub fn filtered(&self) -> u16 {
        self.filter.value()
    }

    /// The rail the sensor is stuck at, if it is faulty.
    pub fn fault(&self) -> Option<Rail> {
        self.fault
    }

    /// The filtered value, if the sensor is healthy and has seen enough samples to mean it.
    pub fn reading(&self) -> Option<u16> {
        self.fresh_reading()
    }

    /// [`Self::reading`], inlined into the per-sample updates below (a call per sensor and step
    /// otherwise).
    #[inline(always)]
    fn fresh_reading(&self) -> Option<u16> {
        (self.fault.is_none() && self.samples >= WARM_UP_SAMPLES).then(|| self.filter.value())
    }
}

/// A filament presence sensor: an analog sensor with a hysteresis decision.
#[derive(Debug, Clone, Copy)]
pub struct PresenceSensor {
    /// The analog part.
    pub analog: AnalogSensor,
    present: bool,
}

impl Default for PresenceSensor {
    fn default() -> Self {
        Self::NEW
    }
}

impl PresenceSensor {
    /// A sensor that has seen no sample.
    pub const NEW: PresenceSensor = PresenceSensor {
        analog: AnalogSensor::NEW,
        present: false,
    };

    /// Take a new raw sample at `now` and decide presence.
    pub fn update(&mut self, raw: u16, now: Instant, filter: FilterKind, thresholds: Thresholds) {
        self.analog.update(raw, now, filter);
        if let Some(value) = self.analog.fresh_reading() {
            self.present = thresholds.decide(self.present, value);
        }
    }

    /// Filament present, or `None` while the sensor is faulty or warming up.
    pub fn present(&self) -> Option<bool> {
        self.analog.reading().map(|_| self.present)
    }
}

/// Counts motor revolutions from the filtered Hall sine: one rising edge through both thresholds
/// is one revolution, so noise between the thresholds cannot add counts.
#[derive(Debug, Clone, Copy)]
pub struct RevolutionCounter {
    /// The analog part.
    pub analog: AnalogSensor,
    high: bool,
    revolutions: u32,
    last_revolution: Instant,
    /// Time between the last two revolutions, ms.
    period_ms: Option<u64>,
}

impl Default for RevolutionCounter {
    fn default() -> Self {
        Self::NEW
    }
}

impl RevolutionCounter {
    /// A counter that has seen no sample.
    pub const NEW: RevolutionCounter = RevolutionCounter {
        analog: AnalogSensor::NEW,
        high: false,
        revolutions: 0,
        last_revolution: Instant::ZERO,
        period_ms: None,
    };

    /// Take a new raw sample at `now`; returns true when it completed a revolution.
    pub fn update(&mut self, raw: u16, now: Instant, filter: FilterKind, edges: Thresholds) -> bool {
        self.analog.update(raw, now, filter);
        let Some(value) = self.analog.fresh_reading() else {
            return false;
        };
        let was_high = self.high;
        self.high = edges.decide(was_high, value);
        if self.high && !was_high {
            self.period_ms = (self.revolutions > 0).then(|| now.millis_since(self.last_revolution));
            self.revolutions = self.revolutions.wrapping_add(1);
            self.last_revolution = now;
            true
        } else {
            false
        }
    }

    /// Revolutions counted since start (wraps).
    pub fn revolutions(&self) -> u32 {
        self.revolutions
    }

    /// When the last revolution completed.
    pub fn last_revolution(&self) -> Instant {
        self.last_revolution
    }

    /// Revolutions per minute from the last full period; 0 when the motor has not turned for
    /// longer than that period (or has turned less than twice).
    pub fn rpm(&self, now: Instant) -> u32 {
        self.live_period_ms(now).map_or(0, |period| 60_000 / period)
    }

    /// The speed of what a revolution moves by `centi_per_rev` 1/100 mm, mm/s, from the last
    /// full period (`centi_per_rev × 10 / period`: one division); 0 when [`Self::rpm`] is.
    pub fn speed_mm_s(&self, now: Instant, centi_per_rev: u16) -> u32 {
        self.live_period_ms(now)
            .map_or(0, |period| u32::from(centi_per_rev) * 10 / period)
    }

    /// The last full period, ms, unless the motor has not turned for longer than it (or has
    /// turned less than twice). In 32 bits (a period over 2³² ms is no speed at all): the 64-bit
    /// division costs twice.
    fn live_period_ms(&self, now: Instant) -> Option<u32> {
        self.period_ms
            .filter(|&period| {
                period > 0 && now.millis_since(self.last_revolution) <= period.saturating_mul(2)
            })
            .and_then(|period| u32::try_from(period).ok())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const THRESHOLDS: Thresholds = Thresholds { on: 2600, off: 2400 };

    #[test]
    fn median_removes_a_single_spike() {
        let mut filter = Filter::new();
        let config = FilterConfig {
            median: 5,
            average: 1,
            smoothing_permille: 1000,
        };
        for _ in 0..5 {
            filter.push_config(2000, &config);
        }
        assert_eq!(filter.push_config(4000, &config), 2000);
        assert_eq!(filter.push_config(2000, &config), 2000);
    }

    #[test]
    fn smoothing_converges_to_a_step() {
        let mut filter = Filter::new();
        let config = FilterConfig {
            median: 1,
            average: 1,
            smoothing_permille: 500,
        };
        filter.push_config(1000, &config);
        assert_eq!(filter.push_config(3000, &config), 2000);
        for _ in 0..20 {
            filter.push_config(3000, &config);
        }
        assert_eq!(filter.value(), 3000);
    }

    #[test]
    fn reciprocal_divisions_equal_the_divisions_they_replace() {
        // Every sum a window of up to MAX_WINDOW u16 samples can have, by every length.
        for len in 0..=MAX_WINDOW {
            for sum in 0..=MAX_WINDOW as u32 * u32::from(u16::MAX) {
                assert_eq!(divide_small(sum, len), sum / len.max(1) as u32, "{sum} / {len}");
            }
        }
        // Every u32 near the multiples of 1000 and the ends, and a dense sweep of the rest.
        let mut x: u32 = 0;
        loop {
            for probe in [x, x.saturating_add(1), x.saturating_sub(1)] {
                assert_eq!(div1000(probe), probe / 1000, "{probe} / 1000");
            }
            match x.checked_add(997) {
                Some(next) => x = next,
                None => break,
            }
        }
        for probe in [u32::MAX, u32::MAX - 1, 4_294_967_000, 4_294_966_999] {
            assert_eq!(div1000(probe), probe / 1000);
        }
    }

    /// The next number of a linear congruential sequence (noise for the equivalence tests).
    fn next_random(seed: u32) -> u32 {
        seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223)
    }

    /// The pipeline as it was, with divisions: the reference for the division-free one.
    struct DividingFilter {
        medians: Window,
        averages: Window,
        smoothed: Option<u32>,
    }

    impl DividingFilter {
        fn new() -> Self {
            DividingFilter {
                medians: Window::new(),
                averages: Window::new(),
                smoothed: None,
            }
        }

        fn push(&mut self, raw: u16, config: &FilterConfig) -> u16 {
            self.medians.push(raw, config.median.into());
            self.averages.push(self.medians.median(), config.average.into());
            let values = self.averages.filled();
            let sum: u32 = values.iter().map(|&v| u32::from(v)).sum();
            let averaged = sum / values.len().max(1) as u32 * 1000;
            let weight = u32::from(config.smoothing_permille.clamp(1, 1000));
            let next = match self.smoothed {
                None => averaged,
                Some(previous) => (previous * (1000 - weight) + averaged * weight) / 1000,
            };
            self.smoothed = Some(next);
            ((next + 500) / 1000) as u16
        }
    }

    /// The division-free filter and its dividing reference, fed the same samples.
    struct Twins {
        filter: Filter,
        reference: DividingFilter,
    }

    impl Twins {
        fn new() -> Self {
            Twins {
                filter: Filter::new(),
                reference: DividingFilter::new(),
            }
        }

        /// Push `raw` (sample `i`) through both; they must agree.
        fn push(&mut self, raw: u16, config: &FilterConfig, i: u32) {
            assert_eq!(
                self.filter.push_config(raw, config),
                self.reference.push(raw, config),
                "{config:?} at {i}"
            );
        }

        /// Push `raw` (sample `i`) through the filter `kind`, as the sensors do, and through the
        /// reference with that filter's settings; they must agree.
        fn push_kind(&mut self, raw: u16, kind: FilterKind, i: u32) {
            assert_eq!(
                self.filter.push(raw, kind),
                self.reference.push(raw, &kind.config()),
                "{kind:?} at {i}"
            );
        }

        fn clear(&mut self) {
            self.filter.clear();
            self.reference = DividingFilter::new();
        }
    }

    #[test]
    fn the_filter_computes_what_the_divisions_did() {
        for (median, average, permille) in [(5, 4, 500), (3, 1, 1000), (1, 1, 1), (9, 9, 333), (2, 7, 999)] {
            let config = FilterConfig {
                median,
                average,
                smoothing_permille: permille,
            };
            let mut twins = Twins::new();
            // Noisy levels switching between off and on, over the 12-bit ADC range.
            let mut seed: u32 = 7;
            for i in 0..4000u32 {
                seed = next_random(seed);
                let noise = (seed >> 20) as u16 % 400;
                let raw = if i % 500 < 250 { 1800 + noise } else { 3600 + noise };
                twins.push(raw, &config, i);
            }
        }
    }

    #[test]
    fn the_filter_follows_window_changes_as_the_divisions_did() {
        // Window lengths changing between samples (a `set` of the filter registers), growing and
        // shrinking while the windows are partly and fully filled, and a clear in between.
        let mut twins = Twins::new();
        let mut seed: u32 = 11;
        for i in 0..6000u32 {
            seed = next_random(seed);
            let raw = (seed >> 20) as u16; // 0..4096, every value possible
            let config = FilterConfig {
                median: [5, 9, 1, 3, 9, 2, 0, 12][(i / 37 % 8) as usize],
                average: [4, 1, 9, 2][(i / 53 % 4) as usize],
                smoothing_permille: 400,
            };
            if i % 1000 == 999 {
                twins.clear();
            }
            twins.push(raw, &config, i);
        }
    }

    #[test]
    fn medians_of_3_and_5_are_the_middle_of_the_sorted_values() {
        // Every tuple over six levels: all orders, and every pattern of ties.
        let levels = [0, 1, 2, 3, 2048, u16::MAX];
        for &a in &levels {
            for &b in &levels {
                for &c in &levels {
                    let mut sorted = [a, b, c];
                    sorted.sort_unstable();
                    assert_eq!(median_of_3(a, b, c), sorted[1], "{a} {b} {c}");
                    for &d in &levels {
                        for &e in &levels {
                            let mut sorted = [a, b, c, d, e];
                            sorted.sort_unstable();
                            assert_eq!(median_of_5(a, b, c, d, e), sorted[2], "{a} {b} {c} {d} {e}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn every_window_and_weight_filters_as_the_divisions_did() {
        // The weights whose kept part is a multiple of 125 (a shift) and some that are not, over
        // every median and average length.
        let weights = [0, 1, 125, 250, 375, 400, 500, 625, 750, 875, 999, 1000, 1001];
        for median in 1..=MAX_WINDOW as u8 {
            for average in 1..=MAX_WINDOW as u8 {
                for permille in weights {
                    let config = FilterConfig {
                        median,
                        average,
                        smoothing_permille: permille,
                    };
                    let mut twins = Twins::new();
                    let mut seed = u32::from(median) * 31 + u32::from(average);
                    for i in 0..300u32 {
                        seed = next_random(seed);
                        let raw = if i % 100 < 50 {
                            40 + (seed >> 28) as u16
                        } else {
                            (seed >> 20) as u16
                        };
                        twins.push(raw, &config, i);
                    }
                }
            }
        }
    }

    #[test]
    fn the_sensors_filters_filter_as_the_divisions_did() {
        // The sensors' two filters take their settings folded in (`Filter::push`): each gives
        // what the divisions gave with its settings, over noisy levels switching off and on.
        for kind in [FilterKind::Presence, FilterKind::Motor] {
            let mut twins = Twins::new();
            let mut seed: u32 = 3;
            for i in 0..4000u32 {
                seed = next_random(seed);
                let noise = (seed >> 20) as u16 % 400;
                let raw = if i % 500 < 250 { 1800 + noise } else { 3600 + noise };
                twins.push_kind(raw, kind, i);
            }
        }
    }

    #[test]
    fn switching_between_the_sensors_filters_and_others_filters_as_the_divisions_did() {
        // The folded filters and the general pipeline share one state: switching between them
        // mid-stream, with partly and fully filled windows, gives what the divisions gave.
        let others = [
            FilterConfig {
                median: 5,
                average: 4,
                smoothing_permille: 400,
            },
            FilterConfig {
                median: 9,
                average: 2,
                smoothing_permille: 500,
            },
            FilterConfig {
                median: 3,
                average: 1,
                smoothing_permille: 250,
            },
        ];
        let mut twins = Twins::new();
        let mut seed: u32 = 5;
        for i in 0..5000u32 {
            seed = next_random(seed);
            let raw = (seed >> 20) as u16;
            match (i / 29) as usize % 6 {
                0 | 3 => twins.push_kind(raw, FilterKind::Presence, i),
                1 | 5 => twins.push_kind(raw, FilterKind::Motor, i),
                k => twins.push(raw, &others[k % others.len()], i),
            }
        }
    }

    #[test]
    fn hysteresis_holds_between_thresholds() {
        assert!(!THRESHOLDS.decide(false, 2500));
        assert!(THRESHOLDS.decide(false, 2600));
        assert!(THRESHOLDS.decide(true, 2500));
        assert!(!THRESHOLDS.decide(true, 2400));
    }

    #[test]
    fn a_sensor_at_a_rail_is_faulty_and_never_believed() {
        let mut sensor = PresenceSensor::default();
        let mut now = Instant::ZERO;
        for _ in 0..30 {
            sensor.update(2048, now, FilterKind::Presence, THRESHOLDS);
            now = now + 1;
        }
        assert_eq!(sensor.present(), Some(false));
        // 50 ms at the rail: suspicious, held, not yet called faulty.
        for _ in 0..50 {
            sensor.update(4095, now, FilterKind::Presence, THRESHOLDS);
            now = now + 1;
            assert_eq!(
                sensor.present(),
                Some(false),
                "the rail value is never taken as presence"
            );
        }
        sensor.update(4095, now, FilterKind::Presence, THRESHOLDS);
        assert_eq!(sensor.analog.fault(), Some(Rail::High));
        assert_eq!(sensor.present(), None);
    }

    #[test]
    fn revolutions_count_full_periods_only() {
        let edges = Thresholds { on: 2300, off: 1800 };
        let mut counter = RevolutionCounter::default();
        let mut now = Instant::ZERO;
        // Warm up at rest, then wobble between the thresholds: no revolution.
        for i in 0..100u32 {
            counter.update(
                if i % 2 == 0 { 2100 } else { 2250 },
                now,
                FilterKind::Motor,
                edges,
            );
            now = now + 1;
        }
        assert_eq!(counter.revolutions(), 0);
        for _ in 0..3 {
            for value in [2400, 2500, 2000, 1700, 1600, 2000] {
                counter.update(value, now, FilterKind::Motor, edges);
                now = now + 1;
            }
        }
        assert_eq!(counter.revolutions(), 3);
        // One revolution every 6 ms is 10 000 rpm; long after the last one the motor is still.
        assert_eq!(counter.rpm(now), 10_000);
        assert_eq!(counter.rpm(now + 100), 0);
    }
}
