//! The unit's sensors: one filter pipeline for every analog one, thresholds with hysteresis,
//! rail detection, and digital readings taken as they are.
//!
//! The sensors are noisy (thesis §6.2): every raw sample goes through a sliding median (kills
//! spikes), a moving average and exponential smoothing, and presence decisions use two thresholds
//! so a reading near one of them cannot flicker. A reading stuck at a supply rail means a
//! disconnected or shorted sensor: it is never fed to the filter, and after a short time the
//! sensor is reported faulty instead of being believed.

use crate::profile::PresenceInput;
use crate::time::Instant;

/// The longest median or average window.
pub const MAX_WINDOW: usize = 5;

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

/// The last samples of a sliding window of `LEN` samples (at most [`MAX_WINDOW`]), which its
/// first sample fills: a window is always full.
#[derive(Debug, Clone, Copy)]
struct Window {
    values: [u16; MAX_WINDOW],
    /// Where the next sample goes.
    next: usize,
}

impl Window {
    const fn new() -> Self {
        Window {
            values: [0; MAX_WINDOW],
            next: 0,
        }
    }

    /// Every place of the window holds `value`.
    fn fill(&mut self, value: u16) {
        self.values = [value; MAX_WINDOW];
        self.next = 0;
    }

    /// Stores `value` in place of the oldest sample.
    fn push<const LEN: usize>(&mut self, value: u16) {
        if let Some(oldest) = self.values.get_mut(self.next) {
            *oldest = value;
        }
        self.next = if self.next + 1 >= LEN { 0 } else { self.next + 1 };
    }

    fn samples<const LEN: usize>(&self) -> &[u16] {
        self.values.get(..LEN).unwrap_or(&self.values)
    }

    /// The middle sample (the upper one of an even count).
    fn median<const LEN: usize>(&self) -> u16 {
        // An insertion sort of a copy: a window is a handful of samples.
        let mut sorted = [0u16; MAX_WINDOW];
        for (filled, &value) in self.samples::<LEN>().iter().enumerate() {
            let mut at = filled;
            while at > 0 && sorted[at - 1] > value {
                sorted[at] = sorted[at - 1];
                at -= 1;
            }
            sorted[at] = value;
        }
        sorted[LEN / 2]
    }

    /// The mean of the samples, rounded down.
    fn mean<const LEN: usize>(&self) -> u16 {
        let sum: u32 = self.samples::<LEN>().iter().map(|&v| u32::from(v)).sum();
        (sum / LEN as u32) as u16
    }
}

/// Which of the unit's two filters a sensor takes. Their settings are fixed at build time (no
/// register changes them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FilterKind {
    /// Filament presence, tension and cutter sensors: median of 5, average of 4, smoothing that
    /// weighs the newest average 1/2.
    Presence,
    /// Motor Hall sensors, whose revolution edges need little delay: median of 3 only.
    Motor,
}

/// The presence filter's median and average windows, samples.
const PRESENCE_MEDIAN: usize = 5;
const PRESENCE_AVERAGE: usize = 4;

/// Fractional bits of a smoothed value.
const FRACTION_BITS: u32 = 8;

/// Sliding median, then moving average, then exponential smoothing.
#[derive(Debug, Clone, Copy)]
pub struct Filter {
    medians: Window,
    averages: Window,
    /// The smoothed value in 1/2^[`FRACTION_BITS`] counts (`None` before the first sample).
    smoothed: Option<u32>,
    /// The smoothed value rounded to counts (0 before the first sample).
    value: u16,
}

impl Default for Filter {
    fn default() -> Self {
        Self::new()
    }
}

impl Filter {
    /// An empty filter.
    pub const fn new() -> Self {
        Filter {
            medians: Window::new(),
            averages: Window::new(),
            smoothed: None,
            value: 0,
        }
    }

    /// Feed one raw sample through the filter `kind`; returns the filtered value.
    pub fn push(&mut self, raw: u16, kind: FilterKind) -> u16 {
        match kind {
            FilterKind::Presence => self.push_with::<PRESENCE_MEDIAN, PRESENCE_AVERAGE, 1>(raw),
            FilterKind::Motor => self.push_with::<3, 1, 0>(raw),
        }
    }

    /// The pipeline with a median of `MEDIAN` samples, an average of `AVERAGE` medians, and
    /// smoothing that weighs the newest average 1/2^`SMOOTHING`.
    fn push_with<const MEDIAN: usize, const AVERAGE: usize, const SMOOTHING: u32>(
        &mut self,
        raw: u16,
    ) -> u16 {
        const { assert!(MEDIAN >= 1 && MEDIAN <= MAX_WINDOW && AVERAGE >= 1 && AVERAGE <= MAX_WINDOW) };
        let raw = raw.min(mmu_hal_port::ADC_MAX);
        let first = self.smoothed.is_none();
        if first {
            self.medians.fill(raw);
        } else {
            self.medians.push::<MEDIAN>(raw);
        }
        let median = self.medians.median::<MEDIAN>();
        if first {
            self.averages.fill(median);
        } else {
            self.averages.push::<AVERAGE>(median);
        }
        let mean = u32::from(self.averages.mean::<AVERAGE>()) << FRACTION_BITS;
        let smoothed = match self.smoothed {
            // Moves 1/2^SMOOTHING of the way to the mean.
            Some(previous) => previous + (mean >> SMOOTHING) - (previous >> SMOOTHING),
            None => mean,
        };
        self.smoothed = Some(smoothed);
        // Rounded half up.
        self.value = ((smoothed + (1 << (FRACTION_BITS - 1))) >> FRACTION_BITS) as u16;
        self.value
    }

    /// The current filtered value (0 before the first sample).
    pub fn value(&self) -> u16 {
        self.value
    }

    /// Hold `value` as it is, as if every sample had been it.
    pub fn set(&mut self, value: u16) {
        self.medians.fill(value);
        self.averages.fill(value);
        self.smoothed = Some(u32::from(value) << FRACTION_BITS);
        self.value = value;
    }

    /// Forget every sample.
    pub fn clear(&mut self) {
        *self = Self::new();
    }
}

/// Which rail a faulty sensor is stuck at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Rail {
    /// Ground: typically a disconnected signal or supply.
    Low,
    /// Supply: typically a short or a disconnected ground.
    High,
}

/// Why a sensor is not believed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SensorFault {
    /// An analog reading stuck at a rail.
    Rail(Rail),
    /// A digital sensor that could not measure (an angle sensor without its magnet, a sensor
    /// that does not answer on its bus).
    NoSignal,
}

/// A raw reading at or below this is a sensor stuck at the low rail. The rail limits are the
/// same for every sensor and fixed at build time (no register changes them).
pub const RAIL_LOW: u16 = 40;
/// A raw reading at or above this is a sensor stuck at the high rail.
pub const RAIL_HIGH: u16 = 4055;
/// How long a reading must stay at a rail (or a digital sensor fail to measure) before the
/// sensor is reported faulty, ms.
pub const RAIL_TIMEOUT_MS: u64 = 50;

/// One sensor: its latest raw sample, its filtered value and its health. An analog sensor's
/// samples go through the filter ([`AnalogSensor::update`]); a digital one's are taken as they
/// are ([`AnalogSensor::measure`]).
#[derive(Debug, Clone, Copy)]
pub struct AnalogSensor {
    filter: Filter,
    raw: u16,
    /// Samples filtered since start or the last fault, counted up to [`WARM_UP_SAMPLES`].
    samples: u16,
    /// What has looked wrong, and since when, before it is called a fault.
    suspect_since: Option<(SensorFault, Instant)>,
    fault: Option<SensorFault>,
}

/// Samples a filter needs before its output means anything: twice the presence filter's median
/// and average windows together.
const WARM_UP_SAMPLES: u16 = 2 * (PRESENCE_MEDIAN + PRESENCE_AVERAGE) as u16;

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
        suspect_since: None,
        fault: None,
    };

    /// Take a new raw analog sample at `now`.
    pub fn update(&mut self, raw: u16, now: Instant, filter: FilterKind) {
        self.raw = raw;
        let rail = if raw <= RAIL_LOW {
            Some(Rail::Low)
        } else if raw >= RAIL_HIGH {
            Some(Rail::High)
        } else {
            None
        };
        if self.suspect(rail.map(SensorFault::Rail), now) {
            self.filter.push(raw, filter);
            // Counted up to the warm-up only: all that is asked of the count.
            if self.samples < WARM_UP_SAMPLES {
                self.samples += 1;
            }
        }
    }

    /// Take a digital sensor's sample `raw` at `now`: its `reading`, taken as it is, or `None`
    /// when the sensor could not measure.
    pub fn measure(&mut self, raw: u16, reading: Option<u16>, now: Instant) {
        self.raw = raw;
        let wrong = match reading {
            Some(_) => None,
            None => Some(SensorFault::NoSignal),
        };
        if self.suspect(wrong, now)
            && let Some(value) = reading
        {
            self.filter.set(value);
            self.samples = WARM_UP_SAMPLES;
        }
    }

    /// Tracks what looks `wrong` now; true when the sample is good to take. Something wrong for
    /// [`RAIL_TIMEOUT_MS`] becomes the fault; a good sample after a fault starts the sensor
    /// afresh (old samples say nothing about a reconnected sensor).
    fn suspect(&mut self, wrong: Option<SensorFault>, now: Instant) -> bool {
        match (wrong, self.suspect_since) {
            (Some(wrong), Some((seen, since))) if wrong == seen => {
                if now.millis_since(since) >= RAIL_TIMEOUT_MS {
                    self.fault = Some(wrong);
                }
                false
            }
            (Some(wrong), _) => {
                self.suspect_since = Some((wrong, now));
                false
            }
            (None, _) => {
                self.suspect_since = None;
                if self.fault.is_some() {
                    self.fault = None;
                    self.filter.clear();
                    self.samples = 0;
                }
                true
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

    /// Why the sensor is faulty, if it is.
    pub fn fault(&self) -> Option<SensorFault> {
        self.fault
    }

    /// The filtered value, if the sensor is healthy and has seen enough samples to mean it.
    pub fn reading(&self) -> Option<u16> {
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

    /// Take a new raw sample at `now`, read as `input`, and decide presence.
    pub fn update(&mut self, raw: u16, now: Instant, input: PresenceInput, thresholds: Thresholds) {
        match input {
            PresenceInput::Analog => self.analog.update(raw, now, FilterKind::Presence),
            PresenceInput::Digital => self.analog.measure(raw, Some(raw), now),
        }
        if let Some(value) = self.analog.reading() {
            self.present = thresholds.decide(self.present, value);
        }
    }

    /// Filament present, or `None` while the sensor is faulty or warming up.
    pub fn present(&self) -> Option<bool> {
        self.analog.reading().map(|_| self.present)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const THRESHOLDS: Thresholds = Thresholds { on: 2600, off: 2400 };

    #[test]
    fn the_motor_filter_removes_a_single_spike_and_follows_a_step_at_once() {
        let mut filter = Filter::new();
        for _ in 0..3 {
            filter.push(2000, FilterKind::Motor);
        }
        assert_eq!(filter.push(4000, FilterKind::Motor), 2000);
        assert_eq!(filter.push(2000, FilterKind::Motor), 2000);
        filter.push(3000, FilterKind::Motor);
        assert_eq!(filter.push(3000, FilterKind::Motor), 3000, "two of three");
    }

    #[test]
    fn the_presence_filter_removes_spikes_and_converges_to_a_step() {
        let mut filter = Filter::new();
        for _ in 0..10 {
            filter.push(1000, FilterKind::Presence);
        }
        assert_eq!(filter.value(), 1000);
        // Two spikes in five samples are no step.
        for raw in [4000, 1000, 4000, 1000, 1000] {
            assert_eq!(filter.push(raw, FilterKind::Presence), 1000, "spike {raw}");
        }
        let mut last = 1000;
        let mut steps = 0;
        while filter.push(3000, FilterKind::Presence) != 3000 {
            assert!(
                (last..=3000).contains(&filter.value()),
                "{last} then {}",
                filter.value()
            );
            last = filter.value();
            steps += 1;
            assert!(steps < 30, "converges");
        }
        assert!(steps >= 3, "the median and the average hold a step back: {steps}");
    }

    #[test]
    fn a_filter_takes_any_sample_without_overflow() {
        let mut filter = Filter::new();
        for raw in [
            u16::MAX,
            0,
            u16::MAX,
            u16::MAX,
            u16::MAX,
            u16::MAX,
            u16::MAX,
            u16::MAX,
        ] {
            filter.push(raw, FilterKind::Presence);
        }
        assert!(filter.value() <= mmu_hal_port::ADC_MAX);
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
            sensor.update(2048, now, PresenceInput::Analog, THRESHOLDS);
            now = now + 1;
        }
        assert_eq!(sensor.present(), Some(false));
        // 50 ms at the rail: suspicious, held, not yet called faulty.
        for _ in 0..50 {
            sensor.update(4095, now, PresenceInput::Analog, THRESHOLDS);
            now = now + 1;
            assert_eq!(
                sensor.present(),
                Some(false),
                "the rail value is never taken as presence"
            );
        }
        sensor.update(4095, now, PresenceInput::Analog, THRESHOLDS);
        assert_eq!(sensor.analog.fault(), Some(SensorFault::Rail(Rail::High)));
        assert_eq!(sensor.present(), None);
    }
}
