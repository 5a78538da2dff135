//! What the unit keeps across restarts, and how it is kept in flash.
//!
//! Four records, each written only when it changed: the lane state (where each slot's filament
//! is) and the settings at once, so a power cut leaves the last known position and setting; the
//! counters at most every [`SLOW_RECORD_PERIOD_MS`] (and before a reset); the identity (the
//! registers that decide whether a printer talks to the unit: the revision `S2` reports) apart
//! from the settings, so that `X42` and a damaged store keep it. [`Store`] keeps them in a log
//! built for the STM32G0's flash, where a power cut can tear any program or erase; [`Keeper`] is
//! the policy the firmware and the simulator share: restore at boot, save as the App changes,
//! recover from a flash that fails, and never erase more than [`ERASES_PER_HOUR`] (plus a burst,
//! earned while running: a boot starts with [`ERASES_AT_BOOT`]).

mod crc;
mod entry;
#[cfg(test)]
mod format;
mod keeper;
#[cfg(test)]
pub(crate) mod ram_flash;
mod records;
mod settings;
mod store;

use heapless::Vec;

use crate::lanes::LaneFigures;
use crate::unit::Lane;

pub use crc::{BitwiseCrc, EntryCrc, SoftwareCrc, iso_hdlc};
pub use keeper::{
    Boot, ERASE_BURST, ERASES_AT_BOOT, ERASES_PER_HOUR, FULL_CHECK_MS, Health, Keeper, RETRY_MAX_MS,
};
pub use store::{Damage, Progress, SLOW_RECORD_PERIOD_MS, Store};

/// Settings registers a unit has at most (plain settings and two thresholds per sensor).
pub const MAX_SETTINGS: usize = 64;
/// The registers kept by `X42` and a store repair: the revision `S2` reports (0x52), which decides
/// whether an MK3S (it wants 3.0.2) talks to the unit at all.
pub const IDENTITY_REGISTERS: [u8; 1] = [0x52];

/// Setting registers and their values.
pub type Settings = Vec<(u8, u16), MAX_SETTINGS>;

fn is_identity(address: u8) -> bool {
    IDENTITY_REGISTERS.contains(&address)
}

/// Counters of the unit's life.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Counters<const N: usize> {
    /// Errors raised (register 0x04).
    pub drive_errors: u16,
    /// Completed tool changes per slot.
    pub tool_changes: [u16; N],
    /// Errors raised while driving each slot.
    pub failures: [u16; N],
    /// Filament fed or pulled by each slot's completed moves, mm.
    pub fed_mm: [u32; N],
    /// Each lane's filament used and health figures ([`crate::lanes`]).
    pub lanes: [LaneFigures; N],
}

/// As derived, the lane figures left out while they are blank: the store's format tests compare
/// a hash of what an earlier firmware (without them) restored (`persist/format.rs`).
impl<const N: usize> core::fmt::Debug for Counters<N> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let mut out = f.debug_struct("Counters");
        out.field("drive_errors", &self.drive_errors)
            .field("tool_changes", &self.tool_changes)
            .field("failures", &self.failures)
            .field("fed_mm", &self.fed_mm);
        if self.lanes.iter().any(|lane| *lane != LaneFigures::default()) {
            out.field("lanes", &self.lanes);
        }
        out.finish()
    }
}

impl<const N: usize> Default for Counters<N> {
    fn default() -> Self {
        Counters {
            drive_errors: 0,
            tool_changes: [0; N],
            failures: [0; N],
            fed_mm: [0; N],
            lanes: [LaneFigures::default(); N],
        }
    }
}

/// Everything the unit keeps across a restart.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Snapshot<const N: usize> {
    /// Where each slot's filament is.
    pub lanes: [Lane; N],
    /// The counters.
    pub counters: Counters<N>,
    /// Every writable setting register that differs from its default, and its value (the
    /// identity registers among them).
    pub settings: Settings,
}

impl<const N: usize> Default for Snapshot<N> {
    fn default() -> Self {
        Snapshot {
            lanes: [Lane::Unknown; N],
            counters: Counters::default(),
            settings: Vec::new(),
        }
    }
}

/// Why a flash operation of the store failed. The unit carries on with what it has in RAM.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// The region or the flash does not suit the store (not page aligned, under three pages).
    Layout,
    /// The flash refused a program or an erase (or the power went).
    Flash,
    /// A record did not fit the page (a fresh page is opened next).
    Full,
    /// The erase budget is spent: the save waits (see [`Keeper`]).
    EraseBudget,
}
