//! The sensor scan: the lanes' presence optos and tension sliders on ADC1, and their angle
//! sensors ([`super::as5600`], a byte of their transaction each scan).
//!
//! ADC1 scans its eight inputs (PA0-PA7) without pause, 239.5 sampling cycles each at 10 MHz
//! (25 µs a conversion, 202 µs a round), and DMA1 channel 1 copies each result into
//! [`CONVERSIONS`], circularly: the control step reads the newest conversion of every input
//! there, at most one round old. The scan order is lane by lane, presence then tension. The
//! ADC's DMA request is enabled only after its calibration, whose result lands in the data
//! register (WCH's `Get_CalibrationValue`), so that it never takes a slot of the ring. No offset
//! correction is applied to the conversions (the BMCU-C's own firmware applies none either).

use core::cell::UnsafeCell;
use core::convert::Infallible;
use core::ptr;

use ch32_metapac as pac;
use mmu_hal_port::{HubSamples, Samples, SensorScan, SlotSamples};
use pac::adc::vals::{Extsel, SampleTime};
use pac::dma::vals::{Pl, Size};
use pac::gpio::vals::{Cnf, Mode};

use super::SLOTS;
use super::as5600::AngleSensors;
use super::{circular_dma, gpio_mode};

/// ADC inputs: a presence and a tension sensor per lane.
const INPUTS: usize = 2 * SLOTS;
/// Each lane's presence and tension inputs (ADC channel = PAn), in scan order.
const CHANNELS: [[u8; 2]; SLOTS] = [[7, 6], [5, 4], [3, 2], [1, 0]];
/// DMA1's channel for ADC1 (CH32V20x reference manual, DMA1 request map: ADC1 on channel 1).
const DMA_CHANNEL: usize = 0;

/// The conversions, as the DMA writes them: read only through volatile reads.
struct Conversions(UnsafeCell<[u16; INPUTS]>);

// SAFETY: the CPU only reads it (volatile), the DMA only writes it.
unsafe impl Sync for Conversions {}

static CONVERSIONS: Conversions = Conversions(UnsafeCell::new([0; INPUTS]));

/// The scan: ADC1 running on its own, the angle sensors read at each scan.
pub struct Sampler {
    angles: AngleSensors,
}

impl Sampler {
    /// Calibrates ADC1 and starts its endless scan into [`CONVERSIONS`].
    pub fn new() -> Self {
        let rcc = pac::RCC;
        rcc.ahbpcenr().modify(|w| w.set_dma1en(true));
        rcc.apb2pcenr().modify(|w| w.set_adc1en(true));
        for pin in 0..8 {
            gpio_mode(pac::GPIOA, pin, Mode::INPUT, Cnf::ANALOG_IN__PUSH_PULL_OUT);
        }
        let adc = pac::ADC1;
        adc.ctlr1().modify(|w| w.set_scan(true));
        adc.ctlr2().modify(|w| {
            w.set_adon(true);
            w.set_cont(true);
            w.set_extsel(Extsel::SWSTART);
            w.set_exttrig(true);
        });
        for (position, &channel) in CHANNELS.iter().flatten().enumerate() {
            if position < 6 {
                adc.rsqr3().modify(|w| w.set_sq(position, channel));
            } else {
                adc.rsqr2().modify(|w| w.set_sq(position - 6, channel));
            }
            adc.samptr2()
                .modify(|w| w.set_smp(usize::from(channel), SampleTime::CYCLES239_5));
        }
        adc.rsqr1().modify(|w| w.set_l(INPUTS as u8 - 1));
        adc.ctlr2().modify(|w| w.set_rstcal(true));
        while adc.ctlr2().read().rstcal() {}
        adc.ctlr2().modify(|w| w.set_cal(true));
        while adc.ctlr2().read().cal() {}
        let _calibration = adc.rdatar().read();
        adc.ctlr2().modify(|w| w.set_dma(true));

        circular_dma(
            DMA_CHANNEL,
            adc.rdatar().as_ptr() as u32,
            CONVERSIONS.0.get() as u32,
            INPUTS as u16,
            Size::BITS16,
            Pl::HIGH,
        );
        adc.ctlr2().modify(|w| w.set_swstart(true));
        Sampler {
            angles: AngleSensors::new(),
        }
    }
}

/// The newest conversion of scan position `position`, 12 bits.
fn conversion(position: usize) -> u16 {
    // SAFETY: `position < INPUTS` (the callers'), inside the static; a volatile read, as the
    // DMA writes it.
    unsafe { ptr::read_volatile(CONVERSIONS.0.get().cast::<u16>().add(position)) & 0x0FFF }
}

impl SensorScan<SLOTS> for Sampler {
    type Error = Infallible;

    async fn scan(&mut self) -> Result<Samples<SLOTS>, Infallible> {
        self.angles.advance();
        let angles = self.angles.latest();
        Ok(Samples {
            slots: core::array::from_fn(|lane| SlotSamples {
                motion: angles[lane],
                filament: conversion(2 * lane),
                tension: conversion(2 * lane + 1),
            }),
            // No hub sensor on the BMCU-C (the profile says so; the logic reads none).
            hub: HubSamples::default(),
        })
    }
}
