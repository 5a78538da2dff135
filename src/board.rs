//! The board the firmware runs on, one module per board, selected by feature: `g071` (the
//! reference board, a NUCLEO-G071RB with embassy-stm32, `cargo fw`) or `pico` (a Raspberry Pi
//! Pico with embassy-rp, `cargo fw-pico`). Only these modules touch HAL types.
//!
//! Every board module provides the same names, which `main` uses:
//! - `NAME`, `SLOTS`, `STORE_RANGE` (the store's region of the flash, as offsets);
//! - `emergency_stop()` (every bridge off by raw register writes, usable in the fault handler),
//!   `reset_cause()`, `reset()`;
//! - `init() -> Parts<...>`: clocks, the watchdog started, every driver;
//! - the types of the parts: `Sampler` (a [`SensorScan`](mmu_hal_port::SensorScan)), `Motors`
//!   ([`Bridges`] over the board's TB6612 pins), `LinkRx` (the UART's DMA ring, a
//!   [`ReceiveRing`](mmu_firmware::uart::ReceiveRing)), `LinkTx` (embedded-io-async), `Led`,
//!   `ButtonPin`, `Watchdog`, `StoreFlash` (NOR flash) and `Crc`
//!   ([`EntryCrc`](mmu_firmware::persist::EntryCrc)).
//!
//! What both boards share is here: [`Parts`], and the motors on two TB6612FNG ([`Bridges`],
//! from mmu-hal-port).

#[cfg(feature = "g071")]
mod g071;
#[cfg(feature = "g071")]
pub use g071::*;

#[cfg(feature = "pico")]
mod pico;
#[cfg(feature = "pico")]
pub use pico::*;

use core::convert::Infallible;

use embedded_hal::digital::OutputPin;
pub use mmu_hal_port::tb6612::Bridges;

/// What a board's `init` hands to `main`.
pub struct Parts<Sampler, Motors, LinkRx, LinkTx, Led, ButtonPin, Watchdog, StoreFlash, Crc> {
    /// The sensor scan.
    pub sampler: Sampler,
    /// The slot motors.
    pub motors: Motors,
    /// The printer UART's receive side (DMA ring).
    pub link_rx: LinkRx,
    /// The printer UART's transmit side.
    pub link_tx: LinkTx,
    /// The status LED.
    pub led: Led,
    /// The unit's button.
    pub button: ButtonPin,
    /// The watchdog, already running.
    pub watchdog: Watchdog,
    /// The flash holding the store ([`STORE_RANGE`]).
    pub flash: StoreFlash,
    /// The CRC the store's entries are checked with.
    pub crc: Crc,
}

/// An IN input of the unused bridge: not wired to the MCU.
pub struct NotConnected;

impl embedded_hal::digital::ErrorType for NotConnected {
    type Error = Infallible;
}

impl OutputPin for NotConnected {
    fn set_low(&mut self) -> Result<(), Infallible> {
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}
