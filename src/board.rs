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
//!   ([`Bridges`] over the board's TB6612 pins), `LinkRx`/`LinkTx` (embedded-io-async), `Led`,
//!   `ButtonPin`, `Watchdog`, `StoreFlash` (NOR flash) and `Crc`
//!   ([`EntryCrc`](mmu_firmware::persist::EntryCrc));
//! - `line_error(&error)`: what a receive error of the link counts as.
//!
//! What both boards share is here: the motors on two TB6612FNG ([`Bridges`]) and [`Parts`].

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
use embedded_hal::pwm::SetDutyCycle;
pub use mmu_firmware::tasks::LineError;
use mmu_hal_port::MotorCommand;
use mmu_hal_port::tb6612::{Channel, Error, Tb6612};

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

/// The three slot motors on two TB6612FNG: chip 1 drives slots 0 (bridge A) and 1 (bridge B),
/// chip 2 slot 2 (bridge A; bridge B unused). A chip whose motors all coast is put in standby
/// (STBY low), so a bridge is only powered while the logic drives or brakes it.
pub struct Bridges<C1, C2> {
    chip1: C1,
    chip2: C2,
    /// Whether each chip is in standby.
    standby: [bool; 2],
}

impl<PA, A1, A2, PB, B1, B2, S1, QA, C1, C2, QB, D1, D2, S2, E>
    Bridges<Tb6612<PA, A1, A2, PB, B1, B2, S1>, Tb6612<QA, C1, C2, QB, D1, D2, S2>>
where
    PA: SetDutyCycle<Error = E>,
    PB: SetDutyCycle<Error = E>,
    QA: SetDutyCycle<Error = E>,
    QB: SetDutyCycle<Error = E>,
    A1: OutputPin<Error = Infallible>,
    A2: OutputPin<Error = Infallible>,
    B1: OutputPin<Error = Infallible>,
    B2: OutputPin<Error = Infallible>,
    S1: OutputPin<Error = Infallible>,
    C1: OutputPin<Error = Infallible>,
    C2: OutputPin<Error = Infallible>,
    D1: OutputPin<Error = Infallible>,
    D2: OutputPin<Error = Infallible>,
    S2: OutputPin<Error = Infallible>,
{
    /// Both chips, in standby (as `Tb6612::new` leaves them).
    pub fn new(chip1: Tb6612<PA, A1, A2, PB, B1, B2, S1>, chip2: Tb6612<QA, C1, C2, QB, D1, D2, S2>) -> Self {
        Bridges {
            chip1,
            chip2,
            standby: [true; 2],
        }
    }
}

impl<PA, A1, A2, PB, B1, B2, S1, QA, C1, C2, QB, D1, D2, S2, E> mmu_hal_port::Motors<3>
    for Bridges<Tb6612<PA, A1, A2, PB, B1, B2, S1>, Tb6612<QA, C1, C2, QB, D1, D2, S2>>
where
    PA: SetDutyCycle<Error = E>,
    PB: SetDutyCycle<Error = E>,
    QA: SetDutyCycle<Error = E>,
    QB: SetDutyCycle<Error = E>,
    A1: OutputPin<Error = Infallible>,
    A2: OutputPin<Error = Infallible>,
    B1: OutputPin<Error = Infallible>,
    B2: OutputPin<Error = Infallible>,
    S1: OutputPin<Error = Infallible>,
    C1: OutputPin<Error = Infallible>,
    C2: OutputPin<Error = Infallible>,
    D1: OutputPin<Error = Infallible>,
    D2: OutputPin<Error = Infallible>,
    S2: OutputPin<Error = Infallible>,
{
    /// A PWM or pin error (none on either HAL: their errors are `Infallible`) leaves that
    /// bridge's state unknown to its driver, which rewrites it at the next command.
    fn apply(&mut self, motors: &[MotorCommand; 3]) {
        let coast = MotorCommand::Coast;
        if motors[0] == coast && motors[1] == coast {
            if !self.standby[0] {
                ignore(self.chip1.standby());
                self.standby[0] = true;
            }
        } else {
            ignore(self.chip1.apply(Channel::A, motors[0]));
            ignore(self.chip1.apply(Channel::B, motors[1]));
            self.standby[0] = false;
        }
        if motors[2] == coast {
            if !self.standby[1] {
                ignore(self.chip2.standby());
                self.standby[1] = true;
            }
        } else {
            ignore(self.chip2.apply(Channel::A, motors[2]));
            self.standby[1] = false;
        }
    }
}

/// A driver error: nothing to do about it here (see [`Bridges`]'s `apply`).
fn ignore<E>(_: Result<(), Error<E, Infallible>>) {}
