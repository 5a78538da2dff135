//! The unit logic of a DC-motor multi-material unit that speaks the Prusa MMU3 protocol.
//!
//! `no_std`, no allocation, no clock and no hardware: the board (or a test, or the simulator)
//! calls [`App::step`] with the current [`Instant`], the raw sensor [`Samples`] and the bytes
//! received from the printer, and carries out the [`Outputs`]: motor commands, bytes to send and
//! board actions. The same code runs on the MCU and on the host.

#![no_std]
#![warn(missing_docs)]

pub mod app;
pub mod arbiter;
pub mod commands;
pub mod config;
pub mod control;
pub mod drive;
pub mod feeder;
pub mod follower;
pub mod guards;
pub mod lanes;
pub mod odometer;
pub mod persist;
pub mod phases;
pub mod port;
pub mod profile;
pub mod registers;
pub mod runner;
pub mod sensor;
pub mod session;
pub mod spool_end;
pub mod tally;
#[cfg(feature = "tasks")]
pub mod tasks;
pub mod time;
pub mod tip;
pub mod uart;
pub mod unit;

pub use app::{App, BoardAction, Outputs, TX_CAPACITY};
pub use config::Config;
pub use mmu_hal_port::{Direction, Duty, HubSamples, MotorCommand, Samples, SlotSamples};
pub use time::Instant;

/// The largest unit: the printer addresses slots T0 to T4.
pub const MAX_SLOTS: usize = 5;
/// The reference unit's slot count.
pub const DEFAULT_SLOTS: usize = 3;
