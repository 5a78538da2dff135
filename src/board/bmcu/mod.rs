//! The third board, the one a maker can buy as a kit: the BMCU-C ("BMCU 370C Hall"), a WCH
//! CH32V203C8T6 (RISC-V QingKe V4B, run at 120 MHz from the HSI, 64 KB flash, 20 KB RAM) driving four
//! AT8236 H-bridges, with an AS5600 angle sensor on each lane's drive gear, an opto for presence
//! and a Hall slider for tension per lane, WS2812 LEDs, and the printer on USART3 (header H1).
//!
//! No CH32 HAL is on crates.io, so the drivers are this module's, on `ch32-metapac`'s registers
//! (CH32V20x reference manual, CH32FV2x_V3xRM; the chip's registers follow the STM32F103's): the
//! clocks ([`clock`]), embassy-time's driver on SysTick ([`time_driver`]), the bridges' PWM
//! ([`motors`]), the ADC scan and the angle sensors ([`sensors`], [`as5600`]), the printer UART
//! ([`uart`]), the store's flash ([`flash`]), the status LED ([`ws2812`]) and the watchdog (here).
//!
//! Pins are those the BMCU-C's published sources give (`../shared/docs/bmcu-c.md` names them).
//! Nothing here has run on a real BMCU-C yet: the book says what that leaves unproven.
//!
//! The pins, the board's one table of them (the drivers' constants follow it; the book's wiring
//! table mirrors it, `scripts/check-pinmap.sh`). Lanes are numbered 0-3 as the printer's slots
//! are; the BMCU's sources number them 1-4 in the same order.
//!
//! | pin | function | wired to |
//! |---|---|---|
//! | PB8 | TIM4_CH3 PWM | lane 0 AT8236 IN1 |
//! | PB9 | TIM4_CH4 PWM | lane 0 AT8236 IN2 |
//! | PB6 | TIM4_CH1 PWM | lane 1 AT8236 IN1 |
//! | PB7 | TIM4_CH2 PWM | lane 1 AT8236 IN2 |
//! | PB4 | TIM3_CH1 PWM (partial remap) | lane 2 AT8236 IN1 |
//! | PB5 | TIM3_CH2 PWM (partial remap) | lane 2 AT8236 IN2 |
//! | PA15 | TIM2_CH1 PWM (full remap) | lane 3 AT8236 IN1 |
//! | PB3 | TIM2_CH2 PWM (full remap) | lane 3 AT8236 IN2 |
//! | PA7 | ADC_IN7 | lane 0 presence (ITR9606 opto) |
//! | PA6 | ADC_IN6 | lane 0 tension (49E Hall slider) |
//! | PA5 | ADC_IN5 | lane 1 presence |
//! | PA4 | ADC_IN4 | lane 1 tension |
//! | PA3 | ADC_IN3 | lane 2 presence |
//! | PA2 | ADC_IN2 | lane 2 tension |
//! | PA1 | ADC_IN1 | lane 3 presence |
//! | PA0 | ADC_IN0 | lane 3 tension |
//! | PB15 | I2C SCL (bit-banged) | lane 0 AS5600 |
//! | PD0 | I2C SDA (bit-banged, PD0 remapped from OSC_IN) | lane 0 AS5600 |
//! | PB14 | I2C SCL (bit-banged) | lane 1 AS5600 |
//! | PC15 | I2C SDA (bit-banged) | lane 1 AS5600 |
//! | PB13 | I2C SCL (bit-banged) | lane 2 AS5600 |
//! | PC14 | I2C SDA (bit-banged) | lane 2 AS5600 |
//! | PB12 | I2C SCL (bit-banged) | lane 3 AS5600 |
//! | PC13 | I2C SDA (bit-banged) | lane 3 AS5600 |
//! | PD1 | WS2812 data (bit-banged, PD1 remapped from OSC_OUT) | system LED |
//! | PB10 | USART3_TX | header H1 TX: printer RX |
//! | PB11 | USART3_RX | header H1 RX: printer TX |
//! | PA12 | output, held low | RS-485 transceiver DE (driver off) |

mod as5600;
mod clock;
mod flash;
mod motors;
mod sensors;
mod time_driver;
mod uart;
mod ws2812;

use core::convert::Infallible;
use core::ops::Range;

use ch32_metapac as pac;
use mmu_firmware::persist::BitwiseCrc;

pub use flash::StoreFlash;
pub use motors::Motors;
pub use sensors::Sampler;
pub use uart::{LinkRx, LinkTx};
pub use ws2812::Led;

/// The board, as the boot log names it.
pub const NAME: &str = "BMCU-C (CH32V203)";
/// The BMCU-C's lanes: an AS5600 on each drive gear, opto presence, a tension slider per lane,
/// no hub sensor.
pub const PROFILE: mmu_firmware::profile::Profile = mmu_firmware::profile::BMCU_C;
/// Filament lanes on this board.
pub const SLOTS: usize = 4;
/// The store's region, as offsets from the flash base (0x0800_0000): the last 4 KB of the rated
/// 64 KB. src/board/bmcu/memory.x ends FLASH before it.
pub const STORE_RANGE: Range<u32> = 0xF000..0x1_0000;
/// No button on the BMCU-C (see [`ButtonPin`]).
pub const HAS_BUTTON: bool = false;

/// Watchdog timeout, ms: a flash erase (four 256-byte fast erases of a store page) and a step
/// fit well inside it.
const WATCHDOG_TIMEOUT_MS: u32 = 500;
/// The independent watchdog's clock, the LSI: 40 kHz (CH32V20x datasheet).
const LSI_HZ: u32 = 40_000;
/// IWDG prescaler register value 3: LSI / 32.
const IWDG_PRESCALER: u8 = 3;
const IWDG_DIVIDER: u32 = 32;
const _: () = assert!(WATCHDOG_TIMEOUT_MS * (LSI_HZ / 1000) / IWDG_DIVIDER <= 0xFFF);

/// Every bridge off: the eight PWM pins driven low as plain outputs, whatever the timers were
/// doing (both inputs of an AT8236 low: its outputs open, the motor coasts). Raw register writes
/// only, so it runs at boot before anything is set up and in the panic and exception handlers.
pub fn emergency_stop() {
    motors::stop_all();
}

/// Why the CH32V203 last started (RCC_RSTSCKR).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ResetCause {
    /// The independent watchdog expired: the control task stalled.
    Watchdog,
    /// A software reset: `X0`/`X42`, a panic or a fault.
    Software,
    /// Power-on, the reset pin, or anything else.
    Other,
}

/// Why the CH32V203 last started; clears the flags for the next start.
pub fn reset_cause() -> ResetCause {
    let flags = pac::RCC.rstsckr().read();
    pac::RCC.rstsckr().modify(|w| w.set_rmvf(true));
    if flags.iwdgrstf() {
        ResetCause::Watchdog
    } else if flags.sftrstf() {
        ResetCause::Software
    } else {
        ResetCause::Other
    }
}

/// Stops every motor and restarts the MCU (PFIC_CFGR's system reset, with its key).
pub fn reset() -> ! {
    emergency_stop();
    const KEY: u32 = 0xBEEF << 16;
    const SYSRESET: u32 = 1 << 7;
    pac::PFIC
        .cfgr()
        .write_value(pac::pfic::regs::Cfgr(KEY | SYSRESET));
    loop {
        core::hint::spin_loop();
    }
}

/// The CH32V203's CRC unit computes CRC-32/MPEG-2 over whole words (no reflection, no final
/// XOR), not the store's CRC-32/ISO-HDLC over bytes: the software CRC, bit by bit, without the
/// table's 1 KiB of flash, which the image cannot spare; slower, within the real-time contract
/// (the book's firmware-in-the-loop figures).
pub type Crc = BitwiseCrc;

/// The BMCU-C has no button: the printer's menu and `mmu` do what the others' button does.
pub struct ButtonPin;

impl embedded_hal::digital::ErrorType for ButtonPin {
    type Error = Infallible;
}

impl embedded_hal::digital::InputPin for ButtonPin {
    fn is_high(&mut self) -> Result<bool, Infallible> {
        Ok(true)
    }

    fn is_low(&mut self) -> Result<bool, Infallible> {
        Ok(false)
    }
}

impl embedded_hal_async::digital::Wait for ButtonPin {
    async fn wait_for_high(&mut self) -> Result<(), Infallible> {
        Ok(())
    }

    async fn wait_for_low(&mut self) -> Result<(), Infallible> {
        core::future::pending().await
    }

    async fn wait_for_rising_edge(&mut self) -> Result<(), Infallible> {
        core::future::pending().await
    }

    async fn wait_for_falling_edge(&mut self) -> Result<(), Infallible> {
        core::future::pending().await
    }

    async fn wait_for_any_edge(&mut self) -> Result<(), Infallible> {
        core::future::pending().await
    }
}

/// The independent watchdog, started by [`init`].
pub struct Watchdog;

impl Watchdog {
    /// Starts the IWDG (it cannot be stopped again) with [`WATCHDOG_TIMEOUT_MS`].
    fn start() -> Self {
        let iwdg = pac::IWDG;
        iwdg.ctlr().write(|w| w.set_key(0x5555));
        iwdg.pscr().write(|w| w.set_pr(IWDG_PRESCALER));
        iwdg.rldr()
            .write(|w| w.set_rl((WATCHDOG_TIMEOUT_MS * (LSI_HZ / 1000) / IWDG_DIVIDER) as u16));
        iwdg.ctlr().write(|w| w.set_key(0xAAAA));
        iwdg.ctlr().write(|w| w.set_key(0xCCCC));
        Watchdog
    }
}

impl mmu_hal_port::Watchdog for Watchdog {
    fn feed(&mut self) {
        pac::IWDG.ctlr().write(|w| w.set_key(0xAAAA));
    }
}

/// Clocks at 120 MHz, the time driver, the watchdog, then every driver.
pub fn init() -> super::Parts<Bmcu> {
    clock::init();
    time_driver::init();
    let watchdog = Watchdog::start();
    let rcc = pac::RCC;
    rcc.apb2pcenr().modify(|w| {
        w.set_afioen(true);
        w.set_iopaen(true);
        w.set_iopben(true);
        w.set_iopcen(true);
        w.set_iopden(true);
    });
    // One write of every remap, never modified after: on early CH32V203 dies PCFR1's bits from
    // 13 up read back one place too high (WCH's `GPIO_PinRemapConfig` shifts them back), so a
    // read-modify-write would clear PD01_RM. PD0 and PD1 are OSC_IN/OSC_OUT: remapped to GPIO
    // (no crystal on the BMCU-C). TIM2 full remap (CH1 PA15, CH2 PB3; its CH3/CH4 would be on
    // USART3's PB10/PB11, but stay disabled), TIM3 partial remap (CH1 PB4, CH2 PB5), TIM4 not
    // remapped (PB6-PB9). The debug port is PA13/PA14 only: PA15, PB3 and PB4 need no release.
    pac::AFIO.pcfr1().write(|w| {
        w.set_pd01_rm(true);
        w.set_tim2_rm(0b11);
        w.set_tim3_rm(0b10);
    });
    hold_rs485_quiet();
    super::Parts {
        sampler: Sampler::new(),
        motors: Motors::new(),
        link_rx: uart::start_rx(),
        link_tx: LinkTx::new(),
        led: Led::new(),
        button: ButtonPin,
        watchdog,
        flash: StoreFlash::new(),
        crc: BitwiseCrc::default(),
    }
}

/// PA12, the RS-485 transceiver's DE, as an output held low: the transceiver never drives the
/// Bambu bus pair on the power connector (this firmware speaks to a Prusa printer on H1).
fn hold_rs485_quiet() {
    let gpioa = pac::GPIOA;
    gpioa.bcr().write(|w| w.set_br(12, true));
    gpio_mode(
        gpioa,
        12,
        pac::gpio::vals::Mode::OUTPUT_2MHZ,
        pac::gpio::vals::Cnf::ANALOG_IN__PUSH_PULL_OUT,
    );
}

/// Starts DMA1 channel `channel` (0 = channel 1) copying `count` items of `size` from the
/// peripheral register at `from` into the ring at `into`, circularly, with `priority`: the ADC's
/// scan and USART3's receive ring.
fn circular_dma(
    channel: usize,
    from: u32,
    into: u32,
    count: u16,
    size: pac::dma::vals::Size,
    priority: pac::dma::vals::Pl,
) {
    let dma = pac::DMA1.ch(channel);
    dma.par().write_value(from);
    dma.mar().write_value(into);
    dma.ndtr().write(|w| w.set_ndt(count));
    dma.cr().write(|w| {
        w.set_dir(pac::dma::vals::Dir::FROMPERIPHERAL);
        w.set_circ(true);
        w.set_minc(true);
        w.set_psize(size);
        w.set_msize(size);
        w.set_pl(priority);
        w.set_en(true);
    });
}

/// Sets pin `pin` of `port` to `mode` and `cnf` (GPIOx_CFGLR for pins 0-7, CFGHR for 8-15).
fn gpio_mode(port: pac::gpio::Gpio, pin: usize, mode: pac::gpio::vals::Mode, cnf: pac::gpio::vals::Cnf) {
    if pin < 8 {
        port.cfglr().modify(|w| {
            w.set_mode(pin, mode);
            w.set_cnf(pin, cnf);
        });
    } else {
        port.cfghr().modify(|w| {
            w.set_mode(pin - 8, mode);
            w.set_cnf(pin - 8, cnf);
        });
    }
}

board_contract!(Bmcu);
