//! The reference board: a NUCLEO-G071RB (STM32G071RB, Cortex-M0+, 64 MHz, 3.3 V) driving two
//! TB6612FNG dual H-bridges and nine analog Hall sensors, wired to a Prusa printer's MMU port,
//! on embassy-stm32's drivers: the ADC converting continuously into a DMA ring, `SimplePwm` on
//! TIM3, the printer UART (USART1) sent by DMA and received by a circular DMA transfer into a ring
//! (`uart_ring`), the blocking flash driver under the store, `IndependentWatchdog`, the CRC unit,
//! the button on EXTI, and embassy-time's driver on TIM2.
//!
//! With the feature `g071-n20` the same board drives N20 encoder gear motors (profile
//! `n20-quadrature`): TIM1, TIM2 and TIM3 count the lanes' encoders, the motor PWM moves to
//! TIM14, TIM16 and TIM17, embassy-time to TIM15, and the ADC converts the six slot filament and
//! hub sensors only (`n20`).
//!
//! The `pin_map!` table below (one per build) is the single source of truth for pins, timers,
//! DMA channels and the UART: the book's wiring tables mirror them (`scripts/check-pinmap.sh`
//! compares them), the emergency stop derives its pins from it, and the sensor scan order is
//! computed from the channels it names. Register code is left where the HAL has no driver: the
//! emergency stop (raw GPIO writes, usable in the fault handler), the reset flags, the flash's
//! ECC register and (`g071-n20`) PWM on a one-channel timer (`n20`); and where its drivers
//! cost too much on the M0+, each in one place: the ADC ring's and the UART ring's positions
//! read from the DMA (`Sampler::latest`, `uart_ring`), USART1's receiver and its error flags
//! (`uart_ring`), and USART1's interrupt enabled (`init`).

#[cfg(feature = "g071-n20")]
mod n20;
mod uart_ring;

use core::cell::UnsafeCell;
use core::ops::Range;
use core::sync::atomic::{AtomicBool, Ordering};

use embassy_stm32::adc::{self, Adc, AdcChannel as _, AdcConfig, AnyAdcChannel, Averaging, SampleTime};
use embassy_stm32::exti::{self, ExtiInput};
use embassy_stm32::flash::{self, Blocking, Flash};
#[cfg(not(feature = "g071-n20"))]
use embassy_stm32::gpio::OutputType;
use embassy_stm32::gpio::{AnyPin, Level, Output, Pin, Pull, Speed};
use embassy_stm32::interrupt::InterruptExt as _;
#[cfg(not(feature = "g071-n20"))]
use embassy_stm32::peripherals::TIM3;
use embassy_stm32::peripherals::{self, ADC1, DMA1_CH1};
#[cfg(feature = "g071-n20")]
use embassy_stm32::peripherals::{TIM14, TIM16, TIM17};
use embassy_stm32::rcc::{self, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk};
use embassy_stm32::time::khz;
#[cfg(not(feature = "g071-n20"))]
use embassy_stm32::timer::low_level::CountingMode;
#[cfg(not(feature = "g071-n20"))]
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm, SimplePwmChannel};
use embassy_stm32::usart::{self, UartTx};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{Peri, bind_interrupts, crc, dma, interrupt, pac};
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use mmu_firmware::persist::EntryCrc;
use mmu_hal_port::tb6612::Tb6612;
use mmu_hal_port::{HubSamples, Samples, SensorScan, SlotSamples};

use super::{Bridges, NotConnected};
#[cfg(feature = "g071-n20")]
use n20::{LaneEncoders, SingleChannelPwm};
use uart_ring::G071Ring;

/// The board, as the boot log names it.
pub const NAME: &str = "NUCLEO-G071RB";
/// The thesis build's sensors: an analog Hall per motor, the hub's sensors.
#[cfg(not(feature = "g071-n20"))]
pub const PROFILE: mmu_firmware::profile::Profile = mmu_firmware::profile::THESIS;
/// A quadrature encoder per motor (N20 gear motors), the hub's sensors as in the thesis build.
#[cfg(feature = "g071-n20")]
pub const PROFILE: mmu_firmware::profile::Profile = mmu_firmware::profile::N20_QUADRATURE;
/// Filament slots on this board.
pub const SLOTS: usize = 3;
/// PWM carrier of the motor bridges: above hearing, well below the TB6612FNG's 100 kHz limit.
const PWM_KHZ: u32 = 20;
/// Independent watchdog timeout. The control task feeds it every on-time step (1 ms); ~100
/// steps missed in a row and the MCU resets, which leaves every bridge off (see
/// [`emergency_stop`]). Longer than a page erase (40 ms), the longest the store stalls the CPU.
pub const WATCHDOG_TIMEOUT_US: u32 = 100_000;
/// The printer line's rate, 8N1.
const BAUD: u32 = 115_200;
/// ADC sample time per conversion (ADC clock 32 MHz): 2.5 µs, plenty for a Hall sensor output.
const SAMPLE_TIME: SampleTime = SampleTime::CYCLES79_5;

bind_interrupts!(struct Irqs {
    USART1 => usart::InterruptHandler<peripherals::USART1>;
    DMA1_CHANNEL1 => dma::InterruptHandler<peripherals::DMA1_CH1>;
    DMA1_CHANNEL2_3 => dma::InterruptHandler<peripherals::DMA1_CH2>, dma::InterruptHandler<peripherals::DMA1_CH3>;
    EXTI4_15 => exti::InterruptHandler<interrupt::typelevel::EXTI4_15>;
});

// ================================ PIN MAP (single source of truth) ================================
//
// TB6612 #1 drives slots 0 (bridge A) and 1 (bridge B); TB6612 #2 drives slot 2 (bridge A, bridge
// B unused). Arduino names are the NUCLEO-G071RB's (UM2324); every pin is also on the ST morpho
// headers CN7/CN10. Pins the NUCLEO itself uses are avoided: PA2/PA3 (ST-LINK VCP, USART2),
// PA13/PA14 (SWD), PC14/PC15 (32 kHz crystal), PF0-PF2 (HSE/NRST); and so are the USB-C PD pins
// (PA8, PA9, PA10, PB15, PD0-PD3), whose dead-battery pull-downs are active until the HAL starts.
//
// Logic levels: the STM32G0 runs at 3.3 V. The printer UART is USART1 (PB6/PB7), not USART3: the
// G071's USART3 has no FIFO (RM0444, "USART implementation": FIFO mode on USART1 and USART2 only)
// while embassy-stm32 0.6.0 sets FIFOEN on every USART of the family (usart/mod.rs, `configure`),
// a reserved bit on USART3. A 5 V printer port (MK3S Einsy) drives the unit's RX through a level
// shifter or a divider (the book's wiring page), whatever the pin's tolerance. ADC pins are NOT
// 5 V tolerant (analog pins of the G0 are 3.6 V tolerant): power the Hall sensors from 3.3 V.
#[cfg(not(feature = "g071-n20"))]
pin_map! {
    hal embassy_stm32;
    stop StopPins = StopPins::of;
    peripherals {
        pwm_timer: TIM3, "Motor PWM, 20 kHz, channels 1-3 (TIM2 is embassy-time's driver)";
        adc: ADC1, "All nine Hall sensors, scanned continuously (a scan about every 210 µs)";
        adc_dma: DMA1_CH1, "The ADC scan's DMA channel";
        printer_uart: USART1, "Printer MMU port, 115200 8N1: a USART with FIFO (USART2 stays on the ST-LINK VCP)";
        printer_rx_dma: DMA1_CH2, "The printer UART's receive ring";
        printer_tx_dma: DMA1_CH3, "The printer UART's transmit DMA";
        button_exti: EXTI13, "The button's edge interrupt";
        watchdog: IWDG, "Independent watchdog, fed by the control task";
        flash: FLASH, "Internal flash: the persisted state in its last 16 pages (STORE_RANGE)";
        crc: CRC, "CRC unit: the CRC-32 of the persisted state's entries (HardwareCrc)";
    }
    pins {
        // field         pin    function      NUCLEO header   wired to                                   safe
        stby1:           PC2,  "GPIO out",   "morpho",       "TB6612 #1 STBY (10k pull-down to GND)",   stby;
        stby2:           PC3,  "GPIO out",   "morpho",       "TB6612 #2 STBY (10k pull-down to GND)",   stby;
        slot0_pwm:       PC6,  "TIM3_CH1",   "morpho",       "TB6612 #1 PWMA (10k pull-down to GND)",   off;
        slot0_in1:       PB3,  "GPIO out",   "Arduino D3",   "TB6612 #1 AIN1",                          off;
        slot0_in2:       PB5,  "GPIO out",   "Arduino D4",   "TB6612 #1 AIN2",                          off;
        slot1_pwm:       PC7,  "TIM3_CH2",   "Arduino D9",   "TB6612 #1 PWMB (10k pull-down to GND)",   off;
        slot1_in1:       PB4,  "GPIO out",   "Arduino D5",   "TB6612 #1 BIN1",                          off;
        slot1_in2:       PB14, "GPIO out",   "Arduino D6",   "TB6612 #1 BIN2",                          off;
        slot2_pwm:       PC8,  "TIM3_CH3",   "morpho",       "TB6612 #2 PWMA (10k pull-down to GND)",   off;
        slot2_in1:       PC0,  "GPIO out",   "morpho",       "TB6612 #2 AIN1",                          off;
        slot2_in2:       PC1,  "GPIO out",   "morpho",       "TB6612 #2 AIN2",                          off;
        slot0_hall:      PA0,  "ADC1_IN0",   "Arduino A0",   "slot 0 motor Hall sensor output",         -;
        slot0_filament:  PA1,  "ADC1_IN1",   "Arduino A1",   "slot 0 filament sensor output",           -;
        slot1_hall:      PA4,  "ADC1_IN4",   "Arduino A2",   "slot 1 motor Hall sensor output",         -;
        slot1_filament:  PB1,  "ADC1_IN9",   "Arduino A3",   "slot 1 filament sensor output",           -;
        slot2_hall:      PB11, "ADC1_IN15",  "Arduino A4",   "slot 2 motor Hall sensor output",         -;
        slot2_filament:  PB12, "ADC1_IN16",  "Arduino A5",   "slot 2 filament sensor output",           -;
        hub_filament:    PA6,  "ADC1_IN6",   "Arduino D12",  "hub filament sensor output",              -;
        hub_tension:     PA7,  "ADC1_IN7",   "Arduino D11",  "hub tension sensor output",               -;
        hub_cutter:      PB0,  "ADC1_IN8",   "Arduino D10",  "hub cutter sensor output",                -;
        printer_tx:      PB6,  "USART1_TX",  "morpho",       "printer MMU port RX (3.3 V push-pull)",   -;
        printer_rx:      PB7,  "USART1_RX",  "morpho",       "printer MMU port TX (via the level shifter)", -;
        status_led:      PA5,  "GPIO out",   "LD4 (on board)", "green user LED",                        -;
        button:          PC13, "GPIO in",    "B1 (on board)", "blue user button, active low: Middle",   -;
    }
}

// The `g071-n20` build: the thesis map with the three motor Hall inputs gone and an encoder per
// lane in their place. Only TIM1, TIM2 and TIM3 have encoder mode, so each counts one lane
// (channels 1 and 2: encoder A and B) and the PWM moves to the one-channel timers TIM14, TIM16 and
// TIM17; embassy-time runs on TIM15, which needs no pin. Pins and alternate functions as the
// STM32G071RB datasheet's AF tables give them (embassy-stm32's pin traits check the encoder pins at
// compile time; the PWM pins' AF numbers are in `PWM_ALTERNATE_FUNCTIONS`): TIM2_CH1 PA0 AF2, TIM2_CH2 PC5 AF2,
// TIM3_CH1 PC6 AF1, TIM3_CH2 PC7 AF1, TIM1_CH1 PC8 AF2, TIM1_CH2 PC9 AF2, TIM14_CH1 PA4 AF4,
// TIM16_CH1 PB8 AF2, TIM17_CH1 PB9 AF2. The other timer pins of TIM1-TIM3 are taken (the printer
// UART, the analog inputs, the bridges' IN pins), on the ST-LINK VCP (PA2/PA3) or USB-C PD
// (PA8-PA10, PB15). Power the encoders from 3.3 V: the inputs then never see more than VDD,
// whatever their pins' 5 V tolerance (an N20 magnetic encoder runs from 3.3 V to 5 V).
#[cfg(feature = "g071-n20")]
pin_map! {
    hal embassy_stm32;
    stop StopPins = StopPins::of;
    peripherals {
        slot0_pwm_timer: TIM14, "Slot 0 motor PWM, 20 kHz, channel 1 (TIM15 is embassy-time's driver)";
        slot1_pwm_timer: TIM16, "Slot 1 motor PWM, 20 kHz, channel 1";
        slot2_pwm_timer: TIM17, "Slot 2 motor PWM, 20 kHz, channel 1";
        slot0_encoder: TIM2, "Slot 0 motor encoder, encoder mode 3 (every edge of A and B)";
        slot1_encoder: TIM3, "Slot 1 motor encoder, encoder mode 3";
        slot2_encoder: TIM1, "Slot 2 motor encoder, encoder mode 3";
        adc: ADC1, "The six slot filament and hub sensors, scanned continuously (a scan about every 140 µs)";
        adc_dma: DMA1_CH1, "The ADC scan's DMA channel";
        printer_uart: USART1, "Printer MMU port, 115200 8N1: a USART with FIFO (USART2 stays on the ST-LINK VCP)";
        printer_rx_dma: DMA1_CH2, "The printer UART's receive ring";
        printer_tx_dma: DMA1_CH3, "The printer UART's transmit DMA";
        button_exti: EXTI13, "The button's edge interrupt";
        watchdog: IWDG, "Independent watchdog, fed by the control task";
        flash: FLASH, "Internal flash: the persisted state in its last 16 pages (STORE_RANGE)";
        crc: CRC, "CRC unit: the CRC-32 of the persisted state's entries (HardwareCrc)";
    }
    pins {
        // field         pin    function      NUCLEO header   wired to                                   safe
        stby1:           PC2,  "GPIO out",   "morpho",       "TB6612 #1 STBY (10k pull-down to GND)",   stby;
        stby2:           PC3,  "GPIO out",   "morpho",       "TB6612 #2 STBY (10k pull-down to GND)",   stby;
        slot0_pwm:       PA4,  "TIM14_CH1",  "Arduino A2",   "TB6612 #1 PWMA (10k pull-down to GND)",   off;
        slot0_in1:       PB3,  "GPIO out",   "Arduino D3",   "TB6612 #1 AIN1",                          off;
        slot0_in2:       PB5,  "GPIO out",   "Arduino D4",   "TB6612 #1 AIN2",                          off;
        slot1_pwm:       PB8,  "TIM16_CH1",  "Arduino D15",  "TB6612 #1 PWMB (10k pull-down to GND)",   off;
        slot1_in1:       PB4,  "GPIO out",   "Arduino D5",   "TB6612 #1 BIN1",                          off;
        slot1_in2:       PB14, "GPIO out",   "Arduino D6",   "TB6612 #1 BIN2",                          off;
        slot2_pwm:       PB9,  "TIM17_CH1",  "Arduino D14",  "TB6612 #2 PWMA (10k pull-down to GND)",   off;
        slot2_in1:       PC0,  "GPIO out",   "morpho",       "TB6612 #2 AIN1",                          off;
        slot2_in2:       PC1,  "GPIO out",   "morpho",       "TB6612 #2 AIN2",                          off;
        slot0_encoder_a: PA0,  "TIM2_CH1",   "Arduino A0",   "slot 0 motor encoder A (encoder at 3.3 V)", -;
        slot0_encoder_b: PC5,  "TIM2_CH2",   "morpho",       "slot 0 motor encoder B (encoder at 3.3 V)", -;
        slot1_encoder_a: PC6,  "TIM3_CH1",   "morpho",       "slot 1 motor encoder A (encoder at 3.3 V)", -;
        slot1_encoder_b: PC7,  "TIM3_CH2",   "Arduino D9",   "slot 1 motor encoder B (encoder at 3.3 V)", -;
        slot2_encoder_a: PC8,  "TIM1_CH1",   "morpho",       "slot 2 motor encoder A (encoder at 3.3 V)", -;
        slot2_encoder_b: PC9,  "TIM1_CH2",   "morpho",       "slot 2 motor encoder B (encoder at 3.3 V)", -;
        slot0_filament:  PA1,  "ADC1_IN1",   "Arduino A1",   "slot 0 filament sensor output",           -;
        slot1_filament:  PB1,  "ADC1_IN9",   "Arduino A3",   "slot 1 filament sensor output",           -;
        slot2_filament:  PB12, "ADC1_IN16",  "Arduino A5",   "slot 2 filament sensor output",           -;
        hub_filament:    PA6,  "ADC1_IN6",   "Arduino D12",  "hub filament sensor output",              -;
        hub_tension:     PA7,  "ADC1_IN7",   "Arduino D11",  "hub tension sensor output",               -;
        hub_cutter:      PB0,  "ADC1_IN8",   "Arduino D10",  "hub cutter sensor output",                -;
        printer_tx:      PB6,  "USART1_TX",  "morpho",       "printer MMU port RX (3.3 V push-pull)",   -;
        printer_rx:      PB7,  "USART1_RX",  "morpho",       "printer MMU port TX (via the level shifter)", -;
        status_led:      PA5,  "GPIO out",   "LD4 (on board)", "green user LED",                        -;
        button:          PC13, "GPIO in",    "B1 (on board)", "blue user button, active low: Middle",   -;
    }
}

/// The datasheet's alternate function numbers of the `g071-n20` PWM pins (STM32G071RB AF tables:
/// PA4 AF4 TIM14_CH1, PB8 AF2 TIM16_CH1, PB9 AF2 TIM17_CH1).
#[cfg(feature = "g071-n20")]
const PWM_ALTERNATE_FUNCTIONS: [u8; SLOTS] = [4, 2, 2];

// ==================================================================================================

/// GPIO ports of the STM32G071RB that the HAL numbers: A (0) to F (5).
const GPIO_PORTS: usize = 6;

/// A set of pins to force low, as one bit mask of pin numbers per GPIO port.
struct StopPins([u16; GPIO_PORTS]);

impl StopPins {
    /// The pins named (`"PC2"`: port C, pin 2), numbered as the HAL numbers them: the port from
    /// the letter (GPIOA = 0, its register blocks 0x400 apart), the pin from the digits
    /// (embassy-stm32 0.6.0 `build.rs`, `pin_port = port_num * 16 + pin_num`). A name that is not
    /// a pin fails the build.
    const fn of(names: &[Option<&str>]) -> Self {
        let mut masks = [0u16; GPIO_PORTS];
        let mut i = 0;
        while i < names.len() {
            if let Some(name) = names[i] {
                let name = name.as_bytes();
                assert!(name.len() >= 3 && name[0] == b'P' && name[1] >= b'A');
                let port = (name[1] - b'A') as usize;
                assert!(port < GPIO_PORTS);
                let mut pin = 0u32;
                let mut digit = 2;
                while digit < name.len() {
                    assert!(name[digit].is_ascii_digit());
                    pin = pin * 10 + (name[digit] - b'0') as u32;
                    digit += 1;
                }
                assert!(pin < 16);
                masks[port] |= 1 << pin;
            }
            i += 1;
        }
        StopPins(masks)
    }

    /// Drives every pin of the set low as a push-pull output through raw register writes, one
    /// port at a time: its clock on (RCC_IOPENR), the output latches low (GPIOx_BSRR, the BRy
    /// bits: atomic), then output mode (GPIOx_MODER = 01 for each pin; OTYPER is left at
    /// push-pull, its reset value and what the HAL sets; RM0444, RCC and GPIO register
    /// descriptions). Works before and after the HAL starts.
    #[inline(never)]
    fn force_low(&self) {
        for (port, &mask) in self.0.iter().enumerate() {
            if mask == 0 {
                continue;
            }
            let pins = u32::from(mask);
            // MODER has two bits per pin: 01 (output) in each pin's pair, both bits cleared first.
            let mut moder_output = 0u32;
            for pin in 0..16 {
                moder_output |= ((pins >> pin) & 1) << (2 * pin);
            }
            let moder_mask = moder_output * 0b11;
            // SAFETY: only the port's register block is taken, never a pin driver.
            let gpio = unsafe { AnyPin::steal(16 * port as u8) }.block();
            pac::RCC.gpioenr().modify(|w| w.0 |= 1 << port);
            gpio.bsrr().write_value(pac::gpio::regs::Bsrr(pins << 16));
            gpio.moder().modify(|w| w.0 = (w.0 & !moder_mask) | moder_output);
        }
    }
}

/// Turns every motor bridge off at once, without the HAL and without allocation: both TB6612 STBY
/// pins low (outputs high impedance), then every PWM and IN pin low (duty 0, coast).
///
/// Called first thing at boot, from the panic handler and the HardFault handler, and before any
/// reset. The pins float while the MCU is held in reset (STM32G0 pins reset to analog mode), so
/// STBY and PWM need external pull-downs to keep the bridges off then.
///
/// It does not take ownership: the HAL drivers that own these pins must not be used afterwards
/// (every caller resets or halts).
pub fn emergency_stop() {
    STOP_STBY.force_low();
    STOP_OFF.force_low();
}

/// Why the MCU last started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum ResetCause {
    /// The independent watchdog expired: the control loop stalled.
    Watchdog,
    /// The window watchdog (unused).
    WindowWatchdog,
    /// `SCB::sys_reset`: an `X0`/`X42` request.
    Software,
    /// Illegal low-power mode entry.
    LowPower,
    /// Option bytes reloaded.
    OptionBytes,
    /// Power-on or brown-out.
    PowerOn,
    /// The NRST pin (reset button, ST-LINK, or the printer's reset line).
    Pin,
    /// No flag set.
    Unknown,
}

/// Reads and clears the reset flags (RCC_CSR). Call once at boot.
pub fn reset_cause() -> ResetCause {
    let csr = pac::RCC.csr().read();
    // Every internal reset also pulses NRST, so PINRSTF is checked last.
    let cause = if csr.iwdgrstf() {
        ResetCause::Watchdog
    } else if csr.wwdgrstf() {
        ResetCause::WindowWatchdog
    } else if csr.sftrstf() {
        ResetCause::Software
    } else if csr.lpwrrstf() {
        ResetCause::LowPower
    } else if csr.oblrstf() {
        ResetCause::OptionBytes
    } else if csr.pwrrstf() {
        ResetCause::PowerOn
    } else if csr.pinrstf() {
        ResetCause::Pin
    } else {
        ResetCause::Unknown
    };
    pac::RCC.csr().modify(|w| w.set_rmvf(true));
    cause
}

/// The persisted state's region, as offsets from the flash base (0x0800_0000): the last 16 pages
/// (2 KiB each) of the 128 KiB, 0x0801_8000..0x0802_0000. memory.x ends FLASH before it, so no
/// code or data is ever linked there, and `probe-rs` (which only erases the pages it programs)
/// leaves it alone when the firmware is flashed again.
pub const STORE_RANGE: Range<u32> = 0x1_8000..0x2_0000;
/// The board has a button.
pub const HAS_BUTTON: bool = true;

/// The STM32G0's CRC unit computing the store's CRC-32/ISO-HDLC (`persist::iso_hdlc`, RM0444
/// "Cyclic redundancy check calculation unit"): polynomial 0x04C11DB7 on 32 bits, initial value
/// 0xFFFFFFFF, input bit-reversed by byte, output bit-reversed, the final XOR in software. No
/// 1 KiB table in flash, and one register write per byte instead of a table lookup.
///
/// Untested on a board so far (the host tests check the software CRC, and a model of the unit set
/// up as here, against CRC-32/ISO-HDLC). `main` checks it on the catalogue's check value at boot
/// (`mmu_firmware::port::CheckedCrc`) and falls back to the software CRC if it computes another
/// CRC, so the store stays readable by every build.
pub struct HardwareCrc(crc::Crc<'static>);

impl HardwareCrc {
    /// Set up as `persist::iso_hdlc` says (the host tests check a model of the unit with the
    /// same values).
    fn new(unit: Peri<'static, peripherals::CRC>) -> Self {
        use crc::{Config, InputReverseConfig, PolySize};
        use mmu_firmware::persist::iso_hdlc::{INIT, POLY, REVERSE_INPUT_BYTES, REVERSE_OUTPUT};
        let reverse_input = if REVERSE_INPUT_BYTES {
            InputReverseConfig::Byte
        } else {
            InputReverseConfig::None
        };
        // The polynomial is odd: the only thing the configuration refuses is an even one.
        let config = defmt::unwrap!(Config::new(
            reverse_input,
            REVERSE_OUTPUT,
            PolySize::Width32,
            INIT,
            POLY
        ));
        HardwareCrc(crc::Crc::new(unit, config))
    }
}

impl EntryCrc for HardwareCrc {
    /// Loads `CRC_INIT` into the data register.
    fn start(&mut self) {
        self.0.reset();
    }

    /// A 32-bit write of the data register per four bytes, the rest one 8-bit write each. With
    /// the input bit-reversed by byte the unit takes a word's bytes from its most significant
    /// (RM0444, CRC: "the data ... processed MSB first"), so a word is the bytes in big-endian
    /// order; `CheckedCrc` checks the unit this way at boot.
    fn add(&mut self, bytes: &[u8]) {
        let (words, rest) = bytes.as_chunks::<4>();
        for &word in words {
            self.0.feed_word(u32::from_be_bytes(word));
        }
        self.0.feed_bytes(rest);
    }

    fn value(&mut self) -> u32 {
        self.0.read() ^ mmu_firmware::persist::iso_hdlc::FINAL_XOR
    }
}

/// Set by [`on_flash_double_ecc_error`] when a read of the store met a double ECC error;
/// [`EccFlash`]'s read turns it into an error, which costs the store one entry.
static STORE_ECC_ERROR: AtomicBool = AtomicBool::new(false);

/// A flash read hit a double ECC error (the NMI; RM0444 §3.3.9). On this part a double-word
/// program cut by a power loss leaves one in the store: the read that met it is in
/// [`EccFlash`]'s read, which is told so and returns an error (the store then skips that
/// entry, see `mmu_firmware::persist`). Anywhere else (code, constants) the MCU cannot go on:
/// motors off, reset.
pub fn on_flash_double_ecc_error() {
    let eccr = pac::FLASH.eccr().read();
    // ADDR_ECC: the failing double word's offset from the flash base, in double words.
    let offset = u32::from(eccr.addr_ecc()) * 8;
    if eccr.eccd() && !eccr.sysf_ecc() && STORE_RANGE.contains(&offset) {
        pac::FLASH.eccr().modify(|w| w.set_eccd(true));
        STORE_ECC_ERROR.store(true, Ordering::SeqCst);
        return;
    }
    emergency_stop();
    cortex_m::peripheral::SCB::sys_reset()
}

/// Stops every motor and restarts the MCU.
pub fn reset() -> ! {
    emergency_stop();
    cortex_m::peripheral::SCB::sys_reset()
}

/// The internal flash under the store, turning a double ECC error in the store into a failed
/// read ([`on_flash_double_ecc_error`]).
///
/// The STM32G071RB has a single flash bank: while a page is erased (22 ms typical, 40 ms at most)
/// or a double word programmed (85 µs typical), every fetch from flash stalls, so the CPU stops
/// altogether: no task, no interrupt (the vectors are in flash too). The motors keep the last
/// command applied, the DMA keeps receiving the printer's bytes into its ring, the timers and the
/// ADC carry on. It never feeds the watchdog: `main` wraps it in
/// `mmu_firmware::port::WatchedFlash`.
pub struct EccFlash(Flash<'static, Blocking>);

impl ErrorType for EccFlash {
    type Error = flash::Error;
}

impl ReadNorFlash for EccFlash {
    const READ_SIZE: usize = <Flash<'static, Blocking> as ReadNorFlash>::READ_SIZE;

    /// A double word with a double ECC error (a program cut by a power loss) makes the read
    /// fail (see [`on_flash_double_ecc_error`]).
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), flash::Error> {
        STORE_ECC_ERROR.store(false, Ordering::SeqCst);
        self.0.blocking_read(offset, bytes)?;
        // The NMI of a failing load is taken before the barrier completes.
        cortex_m::asm::dsb();
        cortex_m::asm::isb();
        if STORE_ECC_ERROR.load(Ordering::SeqCst) {
            STORE_ECC_ERROR.store(false, Ordering::SeqCst);
            return Err(flash::Error::Prog);
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.0.capacity()
    }
}

impl NorFlash for EccFlash {
    const WRITE_SIZE: usize = <Flash<'static, Blocking> as NorFlash>::WRITE_SIZE;
    const ERASE_SIZE: usize = <Flash<'static, Blocking> as NorFlash>::ERASE_SIZE;

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), flash::Error> {
        self.0.blocking_write(offset, bytes)
    }

    fn erase(&mut self, from: u32, to: u32) -> Result<(), flash::Error> {
        self.0.blocking_erase(from, to)
    }
}

/// The NMI: on this part a double ECC error reading the flash (see [`on_flash_double_ecc_error`]:
/// in the store it fails the read, elsewhere it resets).
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    on_flash_double_ecc_error()
}

/// The board's flash for the store.
pub type StoreFlash = EccFlash;
/// The board's CRC for the store's entries.
pub type Crc = HardwareCrc;
/// The PWM input of one bridge.
#[cfg(not(feature = "g071-n20"))]
type Pwm = SimplePwmChannel<'static, TIM3>;
/// The slot motors.
#[cfg(not(feature = "g071-n20"))]
pub type Motors = Bridges<
    Tb6612<Pwm, Output<'static>, Output<'static>, Pwm, Output<'static>, Output<'static>, Output<'static>>,
    Tb6612<Pwm, Output<'static>, Output<'static>, Pwm, NotConnected, NotConnected, Output<'static>>,
>;
/// The slot motors: each bridge's PWM on its own one-channel timer.
#[cfg(feature = "g071-n20")]
pub type Motors = Bridges<
    Tb6612<
        SingleChannelPwm<TIM14>,
        Output<'static>,
        Output<'static>,
        SingleChannelPwm<TIM16>,
        Output<'static>,
        Output<'static>,
        Output<'static>,
    >,
    Tb6612<
        SingleChannelPwm<TIM17>,
        Output<'static>,
        Output<'static>,
        NotConnected,
        NotConnected,
        NotConnected,
        Output<'static>,
    >,
>;
/// The printer UART's receive side.
pub type LinkRx = mmu_firmware::uart::ReceiveRing<G071Ring, { mmu_firmware::uart::G071_DMA_RING }>;
/// The printer UART's transmit side.
pub type LinkTx = UartTx<'static, embassy_stm32::mode::Async>;
/// LD4.
pub type Led = Output<'static>;
/// B1.
pub type ButtonPin = ExtiInput<'static, embassy_stm32::mode::Async>;

/// The independent watchdog, as the hal-port trait.
pub struct Watchdog(IndependentWatchdog<'static, peripherals::IWDG>);

impl mmu_hal_port::Watchdog for Watchdog {
    fn feed(&mut self) {
        self.0.pet();
    }
}

/// Analog inputs of each slot: the motor Hall sensor and the filament sensor (thesis build).
#[cfg(not(feature = "g071-n20"))]
const INPUTS_PER_SLOT: usize = 2;
/// Analog inputs of each slot: the filament sensor only (the encoder is counted by a timer).
#[cfg(feature = "g071-n20")]
const INPUTS_PER_SLOT: usize = 1;
/// Analog inputs: [`INPUTS_PER_SLOT`] per slot and three on the hub, in this order: slot `s`'s
/// motor Hall sensor at `2 s` (thesis build only), its filament sensor last of the slot's
/// ([`filament_input`]), then the hub's filament, tension and cutter sensors from [`HUB_INPUTS`].
const ANALOG_INPUTS: usize = INPUTS_PER_SLOT * SLOTS + 3;
/// The first hub input.
const HUB_INPUTS: usize = INPUTS_PER_SLOT * SLOTS;

/// Where slot `slot`'s filament sensor is among the analog inputs.
const fn filament_input(slot: usize) -> usize {
    INPUTS_PER_SLOT * slot + INPUTS_PER_SLOT - 1
}

/// Conversions in the ADC's DMA ring: 24 whole scans, about 5 ms of continuous conversion. A
/// step reads the newest whole scan, which the DMA reaches again only a lap (5 ms) later; the
/// DMA's half- and full-ring interrupts (embassy-stm32's ring sets them) come every 2.5 ms. (In
/// the `g071-n20` build a lap is 3.3 ms, its interrupts 1.7 ms apart.)
const ADC_RING: usize = 24 * ANALOG_INPUTS;

/// The ADC's DMA ring, written only by the DMA (embassy-stm32's ring set the transfer up, then
/// was forgotten: [`Sampler::new`]), read only through volatile reads of the one [`Sampler`].
struct AdcRing(UnsafeCell<[u16; ADC_RING]>);

// SAFETY: see above: the CPU never writes it, and reads only whole scans the DMA has written.
unsafe impl Sync for AdcRing {}

static ADC_RING_BUFFER: AdcRing = AdcRing(UnsafeCell::new([0; ADC_RING]));

/// The ADC: the nine Hall sensors converted over and over (continuous mode, a scan every 207 µs:
/// 9 channels x 8 oversampled conversions of (79.5 + 12.5) / 32 MHz) into a DMA ring; a scan
/// takes the newest whole one. In the `g071-n20` build the six filament and hub sensors (a scan
/// every 138 µs), and each lane's motion is its encoder timer's count, read with the scan.
///
/// Why: a DMA `read` per step reconfigured the sequence and the DMA channel and woke the control
/// task at its end, and the samples of one scan are what a step wants, whenever it runs. So the
/// driver configures the ADC and starts the
/// circular transfer (`into_ring_buffered`, `start`) and is then forgotten, the DMA running on;
/// the scan reads the DMA channel's count (CNDTR) and the ring itself, in this one place.
pub struct Sampler {
    /// Where each input's conversion lands in a scan's results. The G0 ADC converts the selected
    /// channels (CHSELR) in ascending channel number whatever order they are listed in (RM0444,
    /// ADC: CHSELRMOD = 0, SCANDIR = 0), so it is the number of inputs on a lower channel.
    scan_positions: [u8; ANALOG_INPUTS],
    /// The DMA's place in the ring at the last scan, to tell a stopped ADC from a running one.
    last_position: usize,
    /// A whole scan has been written since the start (the ring's tail holds none before).
    scanned: bool,
    /// The lanes' encoder counters, read with each scan.
    #[cfg(feature = "g071-n20")]
    encoders: LaneEncoders,
}

/// The DMA1 channel of the ADC's ring (`DMA1_CH1`), as `pac::DMA1.ch` numbers it.
const ADC_DMA_CHANNEL: usize = 0;

impl Sampler {
    /// Embassy's driver for the regulator, calibration, clock (64 MHz system clock / 2 = 32 MHz,
    /// the G0 allows 35) and 8x hardware oversampling, then the continuous conversion into the
    /// ring. `inputs` in the order of [`ANALOG_INPUTS`].
    fn new(
        adc: Peri<'static, ADC1>,
        dma: Peri<'static, DMA1_CH1>,
        inputs: [AnyAdcChannel<'static, ADC1>; ANALOG_INPUTS],
        #[cfg(feature = "g071-n20")] encoders: LaneEncoders,
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
        // SAFETY: the only reference ever made to the ring, given to the driver, which is
        // forgotten below: nothing uses it after that; the scan reads through raw pointers.
        let buffer = unsafe { &mut *ADC_RING_BUFFER.0.get() };
        let mut driver = adc.into_ring_buffered(
            dma,
            buffer,
            Irqs,
            inputs.into_iter().map(|input| (input, SAMPLE_TIME)),
            adc::CONTINUOUS,
            adc::Exten::DISABLED,
        );
        driver.start();
        // Dropped, it would stop the ADC and the DMA.
        core::mem::forget(driver);
        Sampler {
            scan_positions,
            last_position: usize::MAX,
            scanned: false,
            #[cfg(feature = "g071-n20")]
            encoders,
        }
    }

    /// The newest whole scan in the ring, in scan (channel) order; `None` if the DMA has not
    /// moved since the last look (the ADC stopped).
    fn latest(&mut self) -> Option<[u16; ANALOG_INPUTS]> {
        let remaining = usize::from(pac::DMA1.ch(ADC_DMA_CHANNEL).ndtr().read().ndt());
        // Where the DMA writes next (CNDTR counts down from the ring's length, reloaded at 0).
        let position = match ADC_RING.saturating_sub(remaining) {
            ADC_RING => 0,
            position => position,
        };
        if position == self.last_position {
            return None;
        }
        self.last_position = position;
        self.scanned |= position >= ANALOG_INPUTS;
        if !self.scanned {
            return None;
        }
        // The DMA wrote scans from the ring's start, whole scans back to back: the newest whole
        // one ends at the last multiple of a scan at or before `position`. (`u8`: a division by
        // a constant the compiler makes a multiplication, not a library call.)
        let partial = usize::from(position as u8 % ANALOG_INPUTS as u8);
        let end = position - partial;
        let start = if end >= ANALOG_INPUTS { end } else { end + ADC_RING } - ANALOG_INPUTS;
        // `start + ANALOG_INPUTS <= ADC_RING`: `end` is a multiple of a scan below `ADC_RING`.
        Some(core::array::from_fn(|k| {
            // SAFETY: `start + k < ADC_RING`: inside the ring; a volatile read, as the DMA
            // writes it.
            unsafe { core::ptr::read_volatile(ADC_RING_BUFFER.0.get().cast::<u16>().add(start + k)) }
        }))
    }
}

// The ring's offsets fit the `u8` of [`Sampler::latest`], and it holds whole scans.
const _: () = assert!(ADC_RING <= 255 && ADC_RING.is_multiple_of(ANALOG_INPUTS));

/// The ADC's DMA has not moved since the last scan (the ADC stopped), or no whole scan exists yet.
/// An overrun would stop it for good (embassy-stm32 leaves OVRMOD at 0: the ADC then makes no DMA
/// request until OVR is cleared), and nothing here restarts it: the stale samples stop the
/// watchdog's feed and the reset restarts it. The DMA has the highest priority and reads a
/// result every 2.9 µs: none happened in the emulated scenarios (fil/g071).
#[derive(Debug)]
pub struct AdcStopped;

impl SensorScan<SLOTS> for Sampler {
    type Error = AdcStopped;

    /// The newest whole scan (at most 207 µs old when the step begins).
    async fn scan(&mut self) -> Result<Samples<SLOTS>, AdcStopped> {
        let raw = self.latest().ok_or(AdcStopped)?;
        let positions = &self.scan_positions;
        let input = |index: usize| {
            let position = positions.get(index).map_or(usize::MAX, |&at| usize::from(at));
            raw.get(position).copied().unwrap_or_default()
        };
        // The thesis build's motion is the motor Hall sensor's level; the encoder build's is the
        // lane's timer count, read right after the scan it goes with.
        #[cfg(not(feature = "g071-n20"))]
        let motion = |slot: usize| input(2 * slot);
        #[cfg(feature = "g071-n20")]
        let counts = self.encoders.counts();
        #[cfg(feature = "g071-n20")]
        let motion = |slot: usize| counts.get(slot).copied().unwrap_or_default();
        Ok(Samples {
            slots: core::array::from_fn(|slot| SlotSamples {
                motion: motion(slot),
                filament: input(filament_input(slot)),
                tension: 0,
            }),
            hub: HubSamples {
                filament: input(HUB_INPUTS),
                tension: input(HUB_INPUTS + 1),
                cutter: input(HUB_INPUTS + 2),
            },
        })
    }
}

/// A GPIO output, low from the start.
fn low(pin: Peri<'static, impl Pin>) -> Output<'static> {
    Output::new(pin, Level::Low, Speed::Low)
}

board_contract!(G071);

/// Starts the clocks and every peripheral of the board. The watchdog first, right after the
/// clocks; the bridges come up in standby with both inputs low and duty 0.
fn init() -> super::Parts<G071> {
    let mut config = embassy_stm32::Config::default();
    // 64 MHz from the internal 16 MHz oscillator: VCO 16 x 8 = 128 MHz, R / 2.
    config.rcc.pll = Some(Pll {
        source: PllSource::HSI,
        prediv: PllPreDiv::DIV1,
        mul: PllMul::MUL8,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2),
    });
    config.rcc.sys = Sysclk::PLL1_R;
    config.rcc.mux.adcsel = rcc::mux::Adcsel::SYS;
    let parts = Parts::take(embassy_stm32::init(config));

    // The watchdog first: from here on a stalled init resets the MCU too.
    let mut watchdog = IndependentWatchdog::new(parts.watchdog, WATCHDOG_TIMEOUT_US);
    watchdog.unleash();

    // Motors: duty 0 on every channel before the pins switch to the timer, STBY and IN low.
    #[cfg(not(feature = "g071-n20"))]
    let motors = {
        let pwm = SimplePwm::new(
            parts.pwm_timer,
            Some(PwmPin::new(parts.slot0_pwm, OutputType::PushPull)),
            Some(PwmPin::new(parts.slot1_pwm, OutputType::PushPull)),
            Some(PwmPin::new(parts.slot2_pwm, OutputType::PushPull)),
            None,
            khz(PWM_KHZ),
            CountingMode::EdgeAlignedUp,
        );
        let mut pwm = pwm.split();
        for channel in [&mut pwm.ch1, &mut pwm.ch2, &mut pwm.ch3] {
            channel.set_duty_cycle_fully_off();
            channel.enable();
        }
        let chip1 = Tb6612::new(
            pwm.ch1,
            low(parts.slot0_in1),
            low(parts.slot0_in2),
            pwm.ch2,
            low(parts.slot1_in1),
            low(parts.slot1_in2),
            low(parts.stby1),
        );
        let chip2 = Tb6612::new(
            pwm.ch3,
            low(parts.slot2_in1),
            low(parts.slot2_in2),
            pwm.ch4,
            NotConnected,
            NotConnected,
            low(parts.stby2),
        );
        // Every error of these drivers is `Infallible`.
        let (Ok(chip1), Ok(chip2)) = (chip1, chip2);
        Bridges::new(chip1, chip2)
    };
    #[cfg(feature = "g071-n20")]
    let motors = {
        let [slot0_af, slot1_af, slot2_af] = PWM_ALTERNATE_FUNCTIONS;
        let chip1 = Tb6612::new(
            SingleChannelPwm::new(parts.slot0_pwm_timer, parts.slot0_pwm, slot0_af, khz(PWM_KHZ)),
            low(parts.slot0_in1),
            low(parts.slot0_in2),
            SingleChannelPwm::with_break_unit(parts.slot1_pwm_timer, parts.slot1_pwm, slot1_af, khz(PWM_KHZ)),
            low(parts.slot1_in1),
            low(parts.slot1_in2),
            low(parts.stby1),
        );
        let chip2 = Tb6612::new(
            SingleChannelPwm::with_break_unit(parts.slot2_pwm_timer, parts.slot2_pwm, slot2_af, khz(PWM_KHZ)),
            low(parts.slot2_in1),
            low(parts.slot2_in2),
            NotConnected,
            NotConnected,
            NotConnected,
            low(parts.stby2),
        );
        // Every error of these drivers is `Infallible`.
        let (Ok(chip1), Ok(chip2)) = (chip1, chip2);
        Bridges::new(chip1, chip2)
    };

    // The printer UART: 115 200 8N1, sent by embassy-stm32's `UartTx` (which configures
    // USART1), received by DMA into a ring the CPU need not attend (`uart_ring`).
    let mut uart_config = usart::Config::default();
    uart_config.baudrate = BAUD;
    let link_tx = defmt::unwrap!(UartTx::new(
        parts.printer_uart,
        parts.printer_tx,
        parts.printer_tx_dma,
        Irqs,
        uart_config,
    ));
    // embassy-stm32 0.6's `UartTx::new` leaves USART1's interrupt disabled in the NVIC (only the
    // receiver's constructors enable it), and its async `flush` waits for the transmission-complete
    // interrupt: without this the first flush never returns and nothing more is sent (found on
    // the emulated G071: the second answer stayed in the transmit buffer).
    interrupt::USART1.unpend();
    // SAFETY: its handler is bound (`Irqs`); no critical section relies on it being masked.
    unsafe { interrupt::USART1.enable() };
    let link_rx = G071Ring::start(parts.printer_rx, parts.printer_rx_dma);

    // In the order of `ANALOG_INPUTS`.
    #[cfg(not(feature = "g071-n20"))]
    let sampler = Sampler::new(
        parts.adc,
        parts.adc_dma,
        [
            parts.slot0_hall.degrade_adc(),
            parts.slot0_filament.degrade_adc(),
            parts.slot1_hall.degrade_adc(),
            parts.slot1_filament.degrade_adc(),
            parts.slot2_hall.degrade_adc(),
            parts.slot2_filament.degrade_adc(),
            parts.hub_filament.degrade_adc(),
            parts.hub_tension.degrade_adc(),
            parts.hub_cutter.degrade_adc(),
        ],
    );
    #[cfg(feature = "g071-n20")]
    let sampler = Sampler::new(
        parts.adc,
        parts.adc_dma,
        [
            parts.slot0_filament.degrade_adc(),
            parts.slot1_filament.degrade_adc(),
            parts.slot2_filament.degrade_adc(),
            parts.hub_filament.degrade_adc(),
            parts.hub_tension.degrade_adc(),
            parts.hub_cutter.degrade_adc(),
        ],
        LaneEncoders::new(
            (parts.slot0_encoder, parts.slot0_encoder_a, parts.slot0_encoder_b),
            (parts.slot1_encoder, parts.slot1_encoder_a, parts.slot1_encoder_b),
            (parts.slot2_encoder, parts.slot2_encoder_a, parts.slot2_encoder_b),
        ),
    );

    super::Parts {
        sampler,
        motors,
        link_rx,
        link_tx,
        led: low(parts.status_led),
        button: ExtiInput::new(parts.button, parts.button_exti, Pull::Up, Irqs),
        watchdog: Watchdog(watchdog),
        flash: EccFlash(Flash::new_blocking(parts.flash)),
        crc: HardwareCrc::new(parts.crc),
    }
}
