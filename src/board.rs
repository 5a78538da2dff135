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

/// Declares a board's pin map once and derives from it the `Parts` struct that takes every used
/// singleton out of the HAL's `Peripherals`, and the constants `STOP_STBY` and `STOP_OFF`: the
/// pins of the rows marked `stby` and of the rows marked `off`, as `$stop` makes them of their
/// names, for the board's `emergency_stop` to drive low in that order.
///
/// Row layout: `field: PIN, "function", "header pin", "wired to", safe-state;` where safe-state is
/// `stby` (standby pins, forced low first), `off` (PWM and IN pins, forced low next) or `-` (not
/// touched by the emergency stop). `scripts/check-pinmap.sh` holds the book's wiring tables to
/// the rows.
macro_rules! pin_map {
    (
        hal $hal:ident;
        stop $stop_ty:ty = $stop:path;
        peripherals { $( $pfield:ident : $periph:ident, $pdoc:literal; )* }
        pins { $( $field:ident : $pin:ident, $func:literal, $header:literal, $to:literal, $safe:tt; )* }
    ) => {
        /// Every singleton this board uses, named by role.
        struct Parts {
            $( #[doc = $pdoc] $pfield: $hal::Peri<'static, $hal::peripherals::$periph>, )*
            $( #[doc = concat!(stringify!($pin), " (", $func, ", ", $header, "): ", $to)]
               $field: $hal::Peri<'static, $hal::peripherals::$pin>, )*
        }

        impl Parts {
            fn take(p: $hal::Peripherals) -> Self {
                Parts { $( $pfield: p.$periph, )* $( $field: p.$pin, )* }
            }
        }

        /// The TB6612 standby pins, forced low first (see `emergency_stop`).
        const STOP_STBY: $stop_ty = $stop(&[$( pin_map!(@stop stby $safe $pin) ),*]);
        /// The PWM and IN pins, forced low next.
        const STOP_OFF: $stop_ty = $stop(&[$( pin_map!(@stop off $safe $pin) ),*]);
    };
    (@stop stby stby $pin:ident) => { Some(stringify!($pin)) };
    (@stop off off $pin:ident) => { Some(stringify!($pin)) };
    (@stop $pass:ident $safe:tt $pin:ident) => { None };
}

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
