//! The whole unit in virtual time, and the printer that drives it.
//!
//! - [`Sim`]: the unchanged unit logic (the `App` the firmware steps) on the physical model
//!   (`mmu-model`), with the printer's mechanics and the harness faults (UART, power loss).
//!   Bytes in, bytes out, one millisecond per step: `mmu sim` serves it on stdio or a pty.
//! - [`printer`]: the printer's side of the protocol over any [`Link`]; [`SimLink`] is the
//!   in-process one (`mmu printer --sim`).
//! - [`Personality`]: which printer firmware both play (Buddy 6.5.3, Buddy 6.4, MK3S), with
//!   [`ExtruderGeometry`]: where its gears sit against its filament sensor; and
//!   [`mechanics`]: the printer's extruder as the simulator moves it around a tool change;
//!   [`scenario`]: Prusa's expected Buddy 6.5.3 exchange, replayed against the unit.
//! - [`soak`]: long runs of tool changes with random faults, and the figures they give;
//!   [`timing`]: the physical minimum a tool change is measured against; [`unload_faults`]: the
//!   unload faults users report, on this unit and on MMU 3.0.4's strict unload.

pub mod cut;
pub mod event;
pub mod fault;
pub mod firmware;
pub mod flash;
pub mod geometry;
pub mod link;
pub mod logic;
pub mod mechanics;
pub mod personality;
pub mod printer;
pub mod scenario;
pub mod scenarios;
pub mod sim;
pub mod soak;
pub mod timing;
pub mod unload_faults;

pub use event::{Event, EventKind};
pub use fault::{FAULT_HELP, ScheduledFault, SimFault, SimFaultKind};
pub use geometry::ExtruderGeometry;
pub use link::SimLink;
pub use personality::Personality;
pub use printer::{
    Decision, Link, LinkFault, Operator, Outcome, Printer, PrinterError, PrinterEvent, PrinterOptions,
};
pub use sim::{CommandRecord, PhaseCut, Sim, SimOptions};
