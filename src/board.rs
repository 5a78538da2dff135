//! The board the firmware runs on, one module per board, selected by feature: `g071` (the
//! reference board, a NUCLEO-G071RB with embassy-stm32, `cargo fw`; `g071-n20` is the same board
//! with N20 encoder gear motors, `cargo fw-n20`) or `pico` (a Raspberry Pi Pico with embassy-rp,
//! `cargo fw-pico`). Only these modules touch HAL types.
//!
//! Every board module implements [`Board`], the contract `main` and the tasks see a board
//! through (its `SLOTS` beside it), and the feature's board is [`ThisBoard`]. What both boards
//! share is here too: [`Parts`], the one `pin_map!`, and the motors on two TB6612FNG
//! ([`Bridges`], from mmu-hal-port).

/// Declares a board's pin map once and derives from it the `Parts` struct that takes every used
/// singleton out of the HAL's `Peripherals`, and the constants `STOP_STBY` and `STOP_OFF`: the
/// pins of the rows marked `stby` and of the rows marked `off`, as `$stop` makes them of their
/// names, for the board's `emergency_stop` to drive low in that order.
///
/// Row layout: `field: PIN, "function", "header pin", "wired to", safe-state;` where safe-state is
/// `stby` (standby pins, forced low first), `off` (PWM and IN pins, forced low next) or `-` (not
/// touched by the emergency stop). `scripts/check-pinmap.sh` holds the book's wiring tables to
/// the rows.
#[cfg(any(feature = "_stm32g071", feature = "pico"))]
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

/// Declares the board's type, `$board`, and its [`Board`] contract from the names every board
/// module defines: `NAME`, `STORE_RANGE`, `HAS_BUTTON`, `ResetCause` and the parts' types, `emergency_stop`,
/// `reset_cause`, `init` and `reset`.
macro_rules! board_contract {
    ($board:ident) => {
        /// This board's contract.
        pub struct $board;

        impl super::Board for $board {
            const NAME: &'static str = NAME;
            const PROFILE: &'static mmu_firmware::profile::Profile = &PROFILE;
            const STORE_RANGE: Range<u32> = STORE_RANGE;
            type ResetCause = ResetCause;
            type Sampler = Sampler;
            type Motors = Motors;
            type LinkRx = LinkRx;
            type LinkTx = LinkTx;
            type Led = Led;
            type ButtonPin = ButtonPin;
            const HAS_BUTTON: bool = HAS_BUTTON;
            type Watchdog = Watchdog;
            type StoreFlash = StoreFlash;
            type Crc = Crc;

            fn emergency_stop() {
                emergency_stop();
            }

            fn reset_cause() -> ResetCause {
                reset_cause()
            }

            fn init() -> super::Parts<Self> {
                init()
            }

            fn reset() -> ! {
                reset()
            }
        }
    };
}

#[cfg(feature = "_stm32g071")]
mod g071;
#[cfg(feature = "_stm32g071")]
pub use g071::{G071 as ThisBoard, SLOTS};

#[cfg(feature = "pico")]
mod pico;
#[cfg(feature = "pico")]
pub use pico::{Pico as ThisBoard, SLOTS};

#[cfg(feature = "bmcu")]
mod bmcu;
#[cfg(feature = "bmcu")]
pub use bmcu::{Bmcu as ThisBoard, SLOTS};

use core::ops::Range;

use embedded_storage::nor_flash::NorFlash;
use mmu_firmware::persist::EntryCrc;
use mmu_firmware::uart::Received;
#[cfg(any(feature = "_stm32g071", feature = "pico"))]
pub use mmu_hal_port::tb6612::Bridges;
use mmu_hal_port::{Button, Motors, SensorScan, StatusLed};

/// What a board gives the firmware, checked by the compiler.
pub trait Board {
    /// The board, as the boot log names it.
    const NAME: &'static str;
    /// What senses each lane on this build ([`crate::profile`]).
    const PROFILE: &'static mmu_firmware::profile::Profile;
    /// The store's region of the flash, as offsets from its base.
    const STORE_RANGE: Range<u32>;
    /// Why the MCU last started, for the boot log.
    type ResetCause: Loggable;
    /// The sensor scan.
    type Sampler: SensorScan<SLOTS>;
    /// The slot motors.
    type Motors: Motors<SLOTS>;
    /// The printer UART's receive side: its DMA ring.
    type LinkRx: Received;
    /// The printer UART's transmit side.
    type LinkTx: embedded_io_async::Write;
    /// The status LED.
    type Led: StatusLed;
    /// The unit's button, with its edges.
    type ButtonPin: Button + embedded_hal_async::digital::Wait;
    /// Whether the board has a button at all: without one, no button task runs.
    const HAS_BUTTON: bool = true;
    /// The watchdog.
    type Watchdog: mmu_hal_port::Watchdog;
    /// The flash holding the store.
    type StoreFlash: NorFlash;
    /// The CRC the store's entries are checked with.
    type Crc: EntryCrc;

    /// Every bridge off by raw register writes: at boot before anything else, and in the fault
    /// handler.
    fn emergency_stop();
    /// Why the MCU last started (read once, at boot).
    fn reset_cause() -> Self::ResetCause;
    /// Clocks, the watchdog started, every driver.
    fn init() -> Parts<Self>;
    /// Every bridge off, then the MCU restarted.
    fn reset() -> !;
}

/// What the boot log can print: defmt's `Format` where the board logs with defmt (not the
/// BMCU-C, which has no log).
#[cfg(feature = "_cortex_m")]
pub trait Loggable: defmt::Format {}
#[cfg(feature = "_cortex_m")]
impl<T: defmt::Format> Loggable for T {}
/// What the boot log can print: anything, on a board without a log.
#[cfg(not(feature = "_cortex_m"))]
pub trait Loggable {}
#[cfg(not(feature = "_cortex_m"))]
impl<T> Loggable for T {}

/// What a board's `init` hands to `main`.
pub struct Parts<B: Board + ?Sized> {
    /// The sensor scan.
    pub sampler: B::Sampler,
    /// The slot motors.
    pub motors: B::Motors,
    /// The printer UART's receive side (DMA ring).
    pub link_rx: B::LinkRx,
    /// The printer UART's transmit side.
    pub link_tx: B::LinkTx,
    /// The status LED.
    pub led: B::Led,
    /// The unit's button.
    pub button: B::ButtonPin,
    /// The watchdog, already running.
    pub watchdog: B::Watchdog,
    /// The flash holding the store ([`Board::STORE_RANGE`]).
    pub flash: B::StoreFlash,
    /// The CRC the store's entries are checked with.
    pub crc: B::Crc,
}

/// An IN (or PWM) input of the unused bridge: not wired to the MCU.
#[cfg(any(feature = "_stm32g071", feature = "pico"))]
pub struct NotConnected;

#[cfg(any(feature = "_stm32g071", feature = "pico"))]
impl embedded_hal::digital::ErrorType for NotConnected {
    type Error = core::convert::Infallible;
}

#[cfg(any(feature = "_stm32g071", feature = "pico"))]
impl embedded_hal::digital::OutputPin for NotConnected {
    fn set_low(&mut self) -> Result<(), core::convert::Infallible> {
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), core::convert::Infallible> {
        Ok(())
    }
}

#[cfg(feature = "g071-n20")]
impl embedded_hal::pwm::ErrorType for NotConnected {
    type Error = core::convert::Infallible;
}

/// The unused bridge's PWM input, where a board has no timer channel left for it: duty 0 always.
#[cfg(feature = "g071-n20")]
impl embedded_hal::pwm::SetDutyCycle for NotConnected {
    fn max_duty_cycle(&self) -> u16 {
        1
    }

    fn set_duty_cycle(&mut self, _duty: u16) -> Result<(), core::convert::Infallible> {
        Ok(())
    }
}
