//! The status LED: the BMCU-C's system WS2812B on PD1, lit green or dark.
//!
//! A WS2812B takes 24 bits (green, red, blue, most significant first), each a 1.25 µs period
//! whose high time says the bit (0.4 µs a 0, 0.8 µs a 1, ±0.15 µs; WS2812B datasheet), then a
//! low pause latches them. The bits are timed on the SysTick count (15 MHz: 67 ns a count),
//! interrupts left on: the SysTick's handler (the only one, about a microsecond) may stretch a
//! bit's high time into a 1 and show a wrong colour until the next update, at most 100 ms
//! later; a critical section's code did not fit the flash. Not the `smart-leds` traits: one LED
//! at two colours needs no colour type or buffer, and the lanes' LEDs are not driven (flash).

use core::convert::Infallible;

use ch32_metapac as pac;
use pac::gpio::vals::{Cnf, Mode};

use super::clock::systick_counts;
use super::{gpio_mode, time_driver};

/// The LED's data pin: PD1.
const PIN: usize = 1;
/// High time of a 0 and of a 1, and a bit's period, in SysTick counts.
const HIGH_0: u64 = systick_counts(400);
const HIGH_1: u64 = systick_counts(800);
const PERIOD: u64 = systick_counts(1_250);
/// The colour when lit: a dim green (G, R, B).
const LIT: u32 = 0x20_00_00;

/// The system LED.
pub struct Led;

impl Led {
    /// PD1 as a push-pull output, the LED dark.
    pub fn new() -> Self {
        pac::GPIOD.bcr().write(|w| w.set_br(PIN, true));
        gpio_mode(pac::GPIOD, PIN, Mode::OUTPUT_50MHZ, Cnf::ANALOG_IN__PUSH_PULL_OUT);
        let mut led = Led;
        led.send(0);
        led
    }

    /// Sends one LED's 24 bits.
    fn send(&mut self, grb: u32) {
        let gpiod = pac::GPIOD;
        for bit in (0..24).rev() {
            let high = if grb & (1 << bit) != 0 { HIGH_1 } else { HIGH_0 };
            let start = time_driver::counts();
            gpiod.bshr().write(|w| w.set_bs(PIN, true));
            time_driver::spin_until(start + high);
            gpiod.bcr().write(|w| w.set_br(PIN, true));
            time_driver::spin_until(start + PERIOD);
        }
    }
}

impl mmu_hal_port::StatusLed for Led {
    type Error = Infallible;

    /// The LED latches the colour after the line has stayed low for 50 µs: the next call comes
    /// much later (the status task blinks at most every 100 ms).
    fn set_lit(&mut self, lit: bool) -> Result<(), Infallible> {
        self.send(if lit { LIT } else { 0 });
        Ok(())
    }
}
