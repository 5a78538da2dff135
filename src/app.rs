//! The App: one stepped state machine for the whole unit (stub: API only, logic follows).

use heapless::Vec;
use mmu_hal_port::{MotorCommand, Samples};

use crate::time::Instant;

/// Room for the bytes one step may send (several complete responses).
pub const TX_CAPACITY: usize = 96;

/// Something only the board can do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BoardAction {
    /// Restart the MCU (`X0`).
    Reset,
    /// Erase persisted data, then restart (`X42`).
    EraseAndReset,
}

/// What one step asks of the board.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Outputs<const N: usize> {
    /// Per slot motor command, to apply now.
    pub motors: [MotorCommand; N],
    /// Bytes to send to the printer, in order.
    pub tx: Vec<u8, TX_CAPACITY>,
    /// A reset or erase to carry out after sending `tx`.
    pub action: Option<BoardAction>,
    /// The status LED: lit while a command runs, blinking in an error state.
    pub status_led: bool,
}

/// The unit logic for `N` slots.
pub struct App<const N: usize> {
    _private: (),
}

impl<const N: usize> App<N> {
    /// A freshly started unit.
    pub fn new() -> Self {
        App { _private: () }
    }

    /// Advance the unit to `now` with the latest sensor samples and the bytes received since the
    /// last step.
    pub fn step(&mut self, _now: Instant, _samples: &Samples<N>, _rx: &[u8]) -> Outputs<N> {
        Outputs { motors: [MotorCommand::Coast; N], tx: Vec::new(), action: None, status_led: false }
    }

    /// A physical button on the unit was pressed.
    pub fn press_button(&mut self, _button: mmu_protocol::ButtonCode) {}
}

impl<const N: usize> Default for App<N> {
    fn default() -> Self {
        Self::new()
    }
}
