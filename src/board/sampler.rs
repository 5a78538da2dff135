//! The nine Hall sensors through the ADC: one scan a control step.
//!
//! Embassy's driver sets the ADC up (regulator, calibration, clock, oversampling); the scan is
//! register code: the channels are selected once ([`start_scan`]), and each scan starts the
//! sequence and reads each result as it completes. Embassy's `read` reprograms the channels and a
//! DMA transfer at every call (1.3 KB more of the 32 KiB flash, measured), and does not wait for
//! CCRDY after writing ADC_CHSELR, which RM0444 requires before a conversion starts.

use embassy_stm32::Peri;
use embassy_stm32::adc::{self, Adc, AdcConfig, AnyAdcChannel, Averaging, SampleTime};
use embassy_stm32::pac;
use embassy_stm32::peripherals::ADC1;
use mmu_hal_port::{HubSamples, Samples, SlotSamples};

use super::SLOTS;

/// ADC sample time per conversion (ADC clock 32 MHz): 2.5 µs, plenty for a Hall sensor output.
const SAMPLE_TIME: SampleTime = SampleTime::CYCLES79_5;

/// Analog inputs: two per slot and three on the hub, in this order: slot `s`'s motor Hall sensor
/// at `2 s`, its filament sensor at `2 s + 1`, then the hub's filament, tension and cutter
/// sensors from [`HUB_INPUTS`].
pub(super) const ANALOG_INPUTS: usize = 2 * SLOTS + 3;
/// The first hub input.
const HUB_INPUTS: usize = 2 * SLOTS;

/// The ADC half of the board: one scan of all nine Hall sensors per call.
pub struct Sampler {
    _adc: Adc<'static, ADC1>,
    /// The channels' pins, in analog mode for as long as the board runs.
    _inputs: [AnyAdcChannel<'static, ADC1>; ANALOG_INPUTS],
    /// Where each input's conversion lands in a scan's results. The G0 ADC converts the selected
    /// channels (CHSELR) in ascending channel number whatever order they are listed in (RM0444,
    /// ADC: CHSELRMOD = 0, SCANDIR = 0), so it is the number of inputs on a lower channel.
    scan_positions: [u8; ANALOG_INPUTS],
}

impl Sampler {
    /// Sets the ADC up for [`Sampler::sample`]: Embassy's driver for the regulator, calibration,
    /// clock (64 MHz system clock / 2 = 32 MHz, the G0 allows 35) and 8x hardware oversampling,
    /// then the scan's channels ([`start_scan`]). `inputs` in the order of [`ANALOG_INPUTS`].
    pub(super) fn start(
        adc: Peri<'static, ADC1>,
        inputs: [AnyAdcChannel<'static, ADC1>; ANALOG_INPUTS],
    ) -> Self {
        let config = AdcConfig {
            clock: Some(adc::Clock::Async {
                div: adc::Presc::DIV2,
            }),
            averaging: Some(Averaging::Samples8),
            ..AdcConfig::default()
        };
        let adc = Adc::new_with_config(adc, config);
        let mut scan_positions = [0u8; ANALOG_INPUTS];
        for (position, own) in scan_positions.iter_mut().zip(&inputs) {
            for other in &inputs {
                *position += u8::from(other.get_hw_channel() < own.get_hw_channel());
            }
        }
        start_scan(&inputs);
        Sampler {
            _adc: adc,
            _inputs: inputs,
            scan_positions,
        }
    }

    /// One scan of every sensor, about 210 µs (9 channels x 8 oversampled conversions of
    /// 2.9 µs): ADSTART, then each conversion's result from ADC_DR once EOC is set (reading DR
    /// clears EOC; RM0444, ADC_ISR and ADC_DR). A scan that never completes stalls the control
    /// loop, and the watchdog resets the MCU.
    pub fn sample(&mut self) -> Samples<SLOTS> {
        let adc = pac::ADC1;
        let mut raw = [0u16; ANALOG_INPUTS];
        // Flags left by an earlier scan cleared. A scan held up past a conversion (23 µs: a probe
        // halted the core) loses the results that overran (OVRMOD = 0 keeps the unread one) and
        // never delivers nine: the loop below waits and the watchdog resets the MCU, as the
        // doc above says; it cannot go on with results shifted by one channel.
        adc.isr().write(|w| {
            w.set_eoc(true);
            w.set_eos(true);
            w.set_ovr(true);
        });
        adc.cr().modify(|w| w.set_adstart(true));
        for value in &mut raw {
            while !adc.isr().read().eoc() {}
            *value = adc.dr().read().data();
        }
        let positions = &self.scan_positions;
        let input = |index: usize| {
            let position = positions.get(index).map_or(usize::MAX, |&at| usize::from(at));
            raw.get(position).copied().unwrap_or_default()
        };
        Samples {
            slots: core::array::from_fn(|slot| SlotSamples {
                motor_hall: input(2 * slot),
                filament: input(2 * slot + 1),
            }),
            hub: HubSamples {
                filament: input(HUB_INPUTS),
                tension: input(HUB_INPUTS + 1),
                cutter: input(HUB_INPUTS + 2),
            },
        }
    }
}

/// Prepares the scan [`Sampler::sample`] starts: the ADC enabled (ADEN, then ADRDY), every input
/// selected in ADC_CHSELR with the sample time SMP1 ([`SAMPLE_TIME`]; SMPSEL = 0 for all), single
/// conversion mode, no DMA (ADC_CFGR1 as reset), then CCRDY awaited: RM0444 (ADC_ISR, CCRDY)
/// ignores a start issued before the channel configuration is applied.
fn start_scan(inputs: &[AnyAdcChannel<'static, ADC1>; ANALOG_INPUTS]) {
    let adc = pac::ADC1;
    if !adc.cr().read().aden() {
        adc.isr().write(|w| w.set_adrdy(true));
        adc.cr().modify(|w| w.set_aden(true));
        while !adc.isr().read().adrdy() {}
    }
    adc.smpr().write(|w| w.set_sample_time(0, SAMPLE_TIME));
    adc.chselr().write(|w| {
        for input in inputs {
            w.set_chsel(usize::from(input.get_hw_channel()), true);
        }
    });
    while !adc.isr().read().ccrdy() {}
}
