//! The reference board: a NUCLEO-G071RB (STM32G071RB, Cortex-M0+, 64 MHz, 3.3 V) driving two
//! TB6612FNG dual H-bridges and nine analog Hall sensors, wired to a Prusa printer's MMU port.
//!
//! This is the only module (with its submodules) that touches Embassy HAL types. The `pin_map!` table below is the
//! single source of truth for pins, timers, ADC channels and the UART: the README wiring table
//! mirrors it (`scripts/check-pinmap.sh` compares the two), the emergency stop derives its pins
//! from it, and the sensor scan order is computed from the channels it names.
//!
//! What the rest of the firmware gets:
//! - [`emergency_stop`]: every bridge off through raw register writes, usable at any time (boot,
//!   panic, fault, reset) without the HAL;
//! - [`init`]: clocks and peripherals, returning the [`Control`] half (motors, printer UART, LED,
//!   button, watchdog), the [`Sampler`] half (ADC) and the [`StoreFlash`] (the persisted state's
//!   region of the internal flash, [`STORE_RANGE`]);
//! - [`uptime_us`] and [`wait_until`]: the clock that paces the control loop (TIM2);
//! - [`reset_cause`], [`reset`].
//!
//! Three parts are plain register code rather than Embassy's, each in a module of its own, for
//! the 32 KiB flash target (each measured on the linked image): the printer UART
//! (`printer_uart`; the ring logic is `mmu_firmware::uart`, with host tests; embassy-stm32's
//! `BufferedUart` took 1.8 KB more), the clock (`clock`: one free-running 32-bit counter instead
//! of embassy-time's driver, queue and the executor, 1.9 KB more) and the ADC scan (`sampler`:
//! Embassy still sets the ADC up; its DMA `read` took 1.3 KB more).

mod clock;
mod printer_uart;
mod sampler;

use core::convert::Infallible;
use core::ops::Range;
use core::sync::atomic::{AtomicBool, Ordering};

use embassy_stm32::adc::AdcChannel as _;
use embassy_stm32::crc;
use embassy_stm32::flash::{self, Blocking, Flash};
use embassy_stm32::gpio::{AnyPin, Flex, Input, Level, Output, OutputType, Pin, Pull, Speed};
use embassy_stm32::pac;
use embassy_stm32::peripherals::{self, TIM3};
use embassy_stm32::rcc::{self, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk};
use embassy_stm32::time::khz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm, SimplePwmChannel};
use embassy_stm32::{Peri, bind_interrupts};
use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use mmu_firmware::persist::EntryCrc;
use mmu_firmware::uart::Port;
use mmu_hal_port::tb6612::{Channel, Tb6612};
use mmu_hal_port::{Button as _, MotorCommand, StatusLed as _};

use clock::start_clock;
pub use clock::{uptime_us, wait_until};
use printer_uart::{PRINTER_UART, PrinterUartInterrupt, PrinterUsart, RX_RING, TX_RING, start_printer_uart};
pub use sampler::Sampler;

/// Filament slots on this board.
pub const SLOTS: usize = 3;

/// PWM carrier of the motor bridges: above hearing, well below the TB6612FNG's 100 kHz limit.
const PWM_KHZ: u32 = 20;
/// Independent watchdog timeout. The control loop feeds it every on-time step (1 ms); ~100 steps
/// missed in a row and the MCU resets, which leaves every bridge off (see [`emergency_stop`]).
pub const WATCHDOG_TIMEOUT_US: u32 = 100_000;

bind_interrupts!(struct Irqs {
    USART3_4_LPUART1 => PrinterUartInterrupt;
});

/// Declares the board's pin map once and derives from it: the [`Parts`] struct that takes every
/// used singleton out of the HAL's `Peripherals`, and the constants [`STOP_STBY`] and [`STOP_OFF`]:
/// the pins of the rows marked `stby` and of the rows marked `off`, for [`emergency_stop`] to
/// drive low in that order.
///
/// Row layout: `field: PIN, "function", "NUCLEO header", "wired to", safe-state;`
/// where safe-state is `stby` (standby pins, forced low first), `off` (PWM and IN pins, forced low
/// next) or `-` (not touched by the emergency stop).
macro_rules! pin_map {
    (
        peripherals { $( $pfield:ident : $periph:ident, $pdoc:literal; )* }
        pins { $( $field:ident : $pin:ident, $func:literal, $header:literal, $to:literal, $safe:tt; )* }
    ) => {
        /// Every singleton this board uses, named by role.
        struct Parts {
            $( #[doc = $pdoc] $pfield: Peri<'static, peripherals::$periph>, )*
            $( #[doc = concat!(stringify!($pin), " (", $func, ", ", $header, "): ", $to)]
               $field: Peri<'static, peripherals::$pin>, )*
        }

        impl Parts {
            fn take(p: embassy_stm32::Peripherals) -> Self {
                Parts { $( $pfield: p.$periph, )* $( $field: p.$pin, )* }
            }
        }

        /// The TB6612 standby pins, forced low first (see [`emergency_stop`]).
        const STOP_STBY: StopPins = StopPins::of(&[$( pin_map!(@stop stby $safe $pin) ),*]);
        /// The PWM and IN pins, forced low next.
        const STOP_OFF: StopPins = StopPins::of(&[$( pin_map!(@stop off $safe $pin) ),*]);
    };
    (@stop stby stby $pin:ident) => { Some(stringify!($pin)) };
    (@stop off off $pin:ident) => { Some(stringify!($pin)) };
    (@stop $pass:ident $safe:tt $pin:ident) => { None };
}

// ================================ PIN MAP (single source of truth) ================================
//
// TB6612 #1 drives slots 0 (bridge A) and 1 (bridge B); TB6612 #2 drives slot 2 (bridge A, bridge
// B unused). Arduino names are the NUCLEO-G071RB's (UM2324); every pin is also on the ST morpho
// headers CN7/CN10. Pins the NUCLEO itself uses are avoided: PA2/PA3 (ST-LINK VCP, USART2),
// PA13/PA14 (SWD), PC14/PC15 (32 kHz crystal), PF0-PF2 (HSE/NRST); and so are the USB-C PD pins
// (PA8, PA9, PA10, PB15, PD0-PD3), whose dead-battery pull-downs are active until the HAL starts.
//
// Logic levels: the STM32G0 runs at 3.3 V. The unit's receive pin PC11 (the printer's TX) has no
// analog function, so it is a 5 V tolerant (FT) pin: an MK3S Einsy drives it with 5 V. ADC pins
// are NOT 5 V tolerant (analog pins of the G0 are 3.6 V tolerant): power the Hall sensors from 3.3 V.
pin_map! {
    peripherals {
        pwm_timer: TIM3, "Motor PWM, 20 kHz, channels 1-3";
        clock_timer: TIM2, "The uptime clock, 1 MHz, 32 bits (uptime_us)";
        adc: ADC1, "All nine Hall sensors, one scan per millisecond";
        printer_uart: USART3, "Printer MMU port, 115200 8N1 (USART2 stays on the ST-LINK VCP)";
        watchdog: IWDG, "Independent watchdog, fed by the control loop";
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
        printer_tx:      PC10, "USART3_TX",  "morpho",       "printer MMU port RX (3.3 V push-pull)",   -;
        printer_rx:      PC11, "USART3_RX",  "morpho",       "printer MMU port TX (FT pin: 5 V ok)",    -;
        status_led:      PA5,  "GPIO out",   "LD4 (on board)", "green user LED",                        -;
        button:          PC13, "GPIO in",    "B1 (on board)", "blue user button, active low: Middle",   -;
    }
}
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

/// What `mmu_firmware::persist::Store` keeps the persisted state with: the flash (blocking NOR
/// flash, see [`WatchedFlash`]) and the CRC unit that checks its entries ([`HardwareCrc`]).
pub struct StoreFlash {
    /// The internal flash.
    pub flash: WatchedFlash,
    /// The CRC unit.
    pub crc: HardwareCrc,
}

/// The STM32G0's CRC unit computing the store's CRC-32/ISO-HDLC (`persist::iso_hdlc`, RM0444
/// "Cyclic redundancy check calculation unit"): polynomial 0x04C11DB7 on 32 bits, initial value
/// 0xFFFFFFFF, input bit-reversed by byte, output bit-reversed, the final XOR in software. No
/// 1 KiB table in flash, and one register write per byte instead of a table lookup.
///
/// Untested on a board so far (the host tests check the software CRC, and a model of the unit set
/// up as here, against CRC-32/ISO-HDLC). Should the unit compute another CRC, the store stays
/// consistent all the same (every entry is written and checked by the same unit), but a store
/// written by a build with the software CRC would read as empty (the unit would start as new).
pub struct HardwareCrc(crc::Crc<'static>);

impl HardwareCrc {
    /// Set up as `persist::iso_hdlc` says (the host tests check a model of the unit with the
    /// same values), then checked on the catalogue's check value: a unit that computes another
    /// CRC is reported at boot (its store stays consistent, see above).
    fn new(unit: Peri<'static, peripherals::CRC>) -> Self {
        use crc::{Config, InputReverseConfig, PolySize};
        use mmu_firmware::persist::iso_hdlc::{CHECK, INIT, POLY, REVERSE_INPUT_BYTES, REVERSE_OUTPUT};
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
        let mut crc = HardwareCrc(crc::Crc::new(unit, config));
        crc.start();
        crc.add(b"123456789");
        let check = crc.value();
        if check != CHECK {
            defmt::error!(
                "CRC unit: {=u32:#x} for the check value, not {=u32:#x}: CRC-32/ISO-HDLC set up wrong",
                check,
                CHECK
            );
        }
        crc
    }
}

impl EntryCrc for HardwareCrc {
    /// Loads `CRC_INIT` into the data register.
    fn start(&mut self) {
        self.0.reset();
    }

    /// One 8-bit write of the data register per byte.
    fn add(&mut self, bytes: &[u8]) {
        self.0.feed_bytes(bytes);
    }

    fn value(&mut self) -> u32 {
        self.0.read() ^ mmu_firmware::persist::iso_hdlc::FINAL_XOR
    }
}

/// The internal flash, reloading the watchdog before each program or erase it starts.
///
/// The STM32G071RB has a single flash bank: while a page is erased (22 ms typical, 40 ms at most)
/// or a double word programmed (85 µs typical), every fetch from flash stalls, so the CPU stops
/// altogether: no task, no interrupt (the vectors are in flash too). The motors keep the last
/// command applied; UART bytes that arrive meanwhile, past the receiver's own buffer, are lost
/// (overrun; the printer's protocol retries); the timers and the ADC carry on. One control
/// step of a save programs at most 8 double words or erases one page (a save erases at most two,
/// see `mmu_firmware::persist`); a save before a reset runs whole, and erasing the whole store
/// erases all its pages in a row. Each erase is shorter
/// than [`WATCHDOG_TIMEOUT_US`], so reloading before each operation keeps a long run of them from
/// resetting the MCU, while a stall outside the flash (the control loop itself) still does.
pub struct WatchedFlash(Flash<'static, Blocking>);

/// Reloads the independent watchdog (IWDG_KR = 0xAAAA): the register write of embassy-stm32's
/// `IndependentWatchdog::pet`, for [`Control`] and for the flash.
fn reload_watchdog() {
    pac::IWDG.kr().write(|w| w.set_key(pac::iwdg::vals::Key::RESET));
}

/// The IWDG prescaler register value (PR) and reload value (RLR) for [`WATCHDOG_TIMEOUT_US`],
/// computed at compile time exactly as embassy-stm32 0.6.0's `IndependentWatchdog::new` computes
/// them at run time (`wdg/mod.rs`: `get_timeout_us`, `reload_value`): the smallest prescaler
/// 2^p, p = 2..=8, whose longest period (reload 0xFFF) reaches the timeout, then the reload for
/// it, with the LSI at the HAL's nominal `LSI_FREQ` (32 kHz on the G0). For 100 ms: PR 0
/// (prescaler 4), RLR 799.
const WATCHDOG_PR_RLR: (u8, u16) = {
    const MAX_RL: u16 = 0xFFF;
    let lsi = embassy_stm32::rcc::LSI_FREQ.0;
    let mut psc_power = 2;
    while psc_power <= 8 {
        let psc = 1u32 << psc_power;
        if WATCHDOG_TIMEOUT_US <= 1_000_000 * (MAX_RL as u32 + 1) / (lsi / psc) {
            break;
        }
        psc_power += 1;
    }
    assert!(psc_power <= 8, "the watchdog timeout is beyond the IWDG's range");
    let psc = 1u32 << psc_power;
    let rl = (WATCHDOG_TIMEOUT_US / psc * lsi / 1_000_000) as u16 - 1;
    ((psc_power - 2) as u8, rl)
};
const _: () = assert!(WATCHDOG_PR_RLR.0 == 0 && WATCHDOG_PR_RLR.1 == 799);

/// Starts the independent watchdog with [`WATCHDOG_PR_RLR`]: the register writes of embassy-stm32
/// 0.6.0's `IndependentWatchdog::new` and `unleash`, in their order (IWDG_KR = 0x5555 to unlock PR
/// and RLR, PR, RLR, then IWDG_KR = 0xCCCC to start; RM0444, IWDG chapter). Once started, only a
/// reset stops it. Taking the peripheral keeps anything else from configuring it.
fn start_watchdog(_iwdg: Peri<'static, peripherals::IWDG>) {
    use pac::iwdg::vals::{Key, Pr};
    let (pr, rl) = WATCHDOG_PR_RLR;
    pac::IWDG.kr().write(|w| w.set_key(Key::ENABLE));
    pac::IWDG.pr().write(|w| w.set_pr(Pr::from_bits(pr)));
    pac::IWDG.rlr().write(|w| w.set_rl(rl));
    pac::IWDG.kr().write(|w| w.set_key(Key::START));
}

impl ErrorType for WatchedFlash {
    type Error = flash::Error;
}

impl ReadNorFlash for WatchedFlash {
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

impl NorFlash for WatchedFlash {
    const WRITE_SIZE: usize = <Flash<'static, Blocking> as NorFlash>::WRITE_SIZE;
    const ERASE_SIZE: usize = <Flash<'static, Blocking> as NorFlash>::ERASE_SIZE;

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), flash::Error> {
        reload_watchdog();
        self.0.blocking_write(offset, bytes)
    }

    /// One page at a time, the watchdog reloaded before each.
    fn erase(&mut self, from: u32, to: u32) -> Result<(), flash::Error> {
        for page in (from..to).step_by(Self::ERASE_SIZE) {
            reload_watchdog();
            self.0.blocking_erase(page, page + Self::ERASE_SIZE as u32)?;
        }
        Ok(())
    }
}

/// Set by [`on_flash_double_ecc_error`] when a read of the store met a double ECC error;
/// [`WatchedFlash`]'s read turns it into an error, which costs the store one entry.
static STORE_ECC_ERROR: AtomicBool = AtomicBool::new(false);

/// A flash read hit a double ECC error (the NMI; RM0444 §3.3.9). On this part a double-word
/// program cut by a power loss leaves one in the store: the read that met it is in
/// [`WatchedFlash::read`], which is told so and returns an error (the store then skips that
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

/// The PWM input of one bridge.
type Pwm = SimplePwmChannel<'static, TIM3>;
/// TB6612 #1: slot 0 on bridge A, slot 1 on bridge B.
type Chip1 =
    Tb6612<Pwm, Output<'static>, Output<'static>, Pwm, Output<'static>, Output<'static>, Output<'static>>;
/// TB6612 #2: slot 2 on bridge A; bridge B is not connected (TIM3 channel 4 has no pin).
type Chip2 = Tb6612<Pwm, Output<'static>, Output<'static>, Pwm, NotConnected, NotConnected, Output<'static>>;

/// An IN input of the unused bridge: not wired to the MCU.
pub struct NotConnected;

impl embedded_hal::digital::ErrorType for NotConnected {
    type Error = Infallible;
}

impl embedded_hal::digital::OutputPin for NotConnected {
    fn set_low(&mut self) -> Result<(), Infallible> {
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// Every error of these drivers is `Infallible`.
fn infallible<T>(result: Result<T, mmu_hal_port::tb6612::Error<Infallible, Infallible>>) -> T {
    match result {
        Ok(value) => value,
        Err(mmu_hal_port::tb6612::Error::Pwm(never) | mmu_hal_port::tb6612::Error::Pin(never)) => {
            match never {}
        }
    }
}

/// The control half of the board: motors, printer UART, status LED, button and watchdog.
pub struct Control {
    chip1: Chip1,
    chip2: Chip2,
    /// Whether each chip is in standby (STBY low): while none of its motors is driven or braked.
    chip_standby: [bool; 2],
    uart: Port<'static, PrinterUsart, RX_RING, TX_RING>,
    /// PC11 (RX) and PC10 (TX) in their USART3 function, for as long as the board runs.
    _uart_pins: [Flex<'static>; 2],
    led: Output<'static>,
    button: Input<'static>,
}

impl Control {
    /// Carries out one step's motor commands. A chip whose motors all coast is put in standby
    /// (STBY low), so a bridge is only powered while the logic drives or brakes it.
    pub fn apply(&mut self, motors: &[MotorCommand; SLOTS]) {
        let coast = MotorCommand::Coast;
        if motors[0] == coast && motors[1] == coast {
            if !self.chip_standby[0] {
                infallible(self.chip1.standby());
                self.chip_standby[0] = true;
            }
        } else {
            infallible(self.chip1.apply(Channel::A, motors[0]));
            infallible(self.chip1.apply(Channel::B, motors[1]));
            self.chip_standby[0] = false;
        }
        if motors[2] == coast {
            if !self.chip_standby[1] {
                infallible(self.chip2.standby());
                self.chip_standby[1] = true;
            }
        } else {
            infallible(self.chip2.apply(Channel::A, motors[2]));
            self.chip_standby[1] = false;
        }
    }

    /// Moves the oldest bytes received from the printer into `buf`, at most
    /// `control::MAX_RX_PER_STEP` (the rest wait for the next steps), without waiting; returns
    /// how many. The USART interrupt fills a 256-byte ring in the background.
    pub fn receive(&mut self, buf: &mut [u8]) -> usize {
        let limit = buf.len().min(mmu_firmware::control::MAX_RX_PER_STEP);
        match buf.get_mut(..limit) {
            Some(buf) => self.uart.receive(buf),
            None => 0,
        }
    }

    /// Queues `bytes` for the printer without waiting. Returns false (nothing queued) when the
    /// transmit ring has no room for all of them, so a response is never sent in part.
    pub fn send(&mut self, bytes: &[u8]) -> bool {
        self.uart.send(bytes)
    }

    /// Waits until every queued byte has left the UART, at most `timeout_us`.
    pub fn flush(&mut self, timeout_us: u64) {
        let deadline = uptime_us() + timeout_us;
        while !self.uart.sent() && uptime_us() < deadline {}
    }

    /// What went wrong on the printer's receive line since start-up.
    pub fn line_errors(&self) -> mmu_firmware::uart::LineErrors {
        PRINTER_UART.errors()
    }

    /// Lights or clears LD4.
    pub fn set_status_led(&mut self, lit: bool) {
        let Ok(()) = self.led.set_lit(lit);
    }

    /// True while B1 is held down.
    pub fn button_down(&mut self) -> bool {
        let Ok(down) = self.button.is_pressed();
        down
    }

    /// Reloads the independent watchdog.
    pub fn feed_watchdog(&mut self) {
        reload_watchdog();
    }
}

/// A GPIO output, low from the start.
fn low(pin: Peri<'static, impl Pin>) -> Output<'static> {
    Output::new(pin, Level::Low, Speed::Low)
}

/// Starts the clocks and every peripheral of the board. The bridges come up in standby with both
/// inputs low and duty 0; the watchdog is running when this returns.
///
/// Out of line, so that its frame is gone before `main`'s `new_logic` builds the unit logic
/// (the deepest boot path, `scripts/firmware-size.sh`).
#[inline(never)]
pub fn init() -> (Control, Sampler, StoreFlash) {
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
    start_watchdog(parts.watchdog);
    start_clock(parts.clock_timer);

    // Motors: duty 0 on every channel before the pins switch to the timer, STBY and IN low.
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
    let chip1 = infallible(Tb6612::new(
        pwm.ch1,
        low(parts.slot0_in1),
        low(parts.slot0_in2),
        pwm.ch2,
        low(parts.slot1_in1),
        low(parts.slot1_in2),
        low(parts.stby1),
    ));
    let chip2 = infallible(Tb6612::new(
        pwm.ch3,
        low(parts.slot2_in1),
        low(parts.slot2_in2),
        pwm.ch4,
        NotConnected,
        NotConnected,
        low(parts.stby2),
    ));

    let (uart, _uart_pins) = start_printer_uart(parts.printer_uart, parts.printer_rx, parts.printer_tx);

    let control = Control {
        chip1,
        chip2,
        chip_standby: [true; 2],
        uart,
        _uart_pins,
        led: Output::new(parts.status_led, Level::Low, Speed::Low),
        button: Input::new(parts.button, Pull::Up),
    };
    // In the order of `sampler::ANALOG_INPUTS`.
    let sampler = Sampler::start(
        parts.adc,
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
    let store = StoreFlash {
        flash: WatchedFlash(Flash::new_blocking(parts.flash)),
        crc: HardwareCrc::new(parts.crc),
    };
    (control, sampler, store)
}
