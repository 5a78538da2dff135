//! The unit's settings: geometry, speeds, bounds, sensor tuning and the version it reports.
//!
//! Every motion the logic makes is bounded by a distance and a time derived from these values.
//! The printer and the user change many of them at run time through registers
//! ([`crate::registers`]); the defaults are for the reference unit (a 360 mm Bowden tube).

use crate::MAX_SLOTS;
use crate::sensor::Thresholds;

/// The version reported through `S0`..`S3`. The printer checks major, minor and revision for
/// exact equality: 3.0.3 for Prusa-Firmware-Buddy 6.x (MK4, MK3.5, Core One), 3.0.2 for MK3S
/// firmware 3.13.3/3.14.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Version {
    /// `S0`.
    pub major: u8,
    /// `S1`.
    pub minor: u8,
    /// `S2`.
    pub revision: u8,
    /// `S3`: stored by the printer, never checked.
    pub build: u16,
}

/// The `S2` revisions of MMU firmware 3.0.x the unit speaks the wire of, newest first: 3.0.1
/// added register 0x22, 3.0.2 register 0x23, 3.0.3 nothing on the wire; requests, answers and
/// the printers' register use are the same (Prusa-Firmware-MMU tags v3.0.0..v3.0.3; research
/// notes `printer-truth.md` §5). A printer expecting any of them can talk to this unit.
pub const WIRE_COMPATIBLE_REVISIONS: [u8; 4] = [3, 2, 1, 0];

/// The revision to answer to the `repeat`-th `S2` in a row (0: the first): the configured one
/// (register 0x52), then every other wire-compatible revision, newest first, then round again.
/// Prusa's printer sends the same `S<n>` again at once on a mismatch, up to six mismatches per
/// handshake (`protocol_logic.cpp` `ProcessVersionResponse`, Buddy and MK3S firmware alike), so
/// every printer family finds its revision within one handshake.
pub fn offered_revision(configured: u8, repeat: u8) -> u8 {
    let mut others = WIRE_COMPATIBLE_REVISIONS
        .iter()
        .copied()
        .filter(|&r| r != configured);
    let offers = 1 + WIRE_COMPATIBLE_REVISIONS
        .iter()
        .filter(|&&r| r != configured)
        .count();
    match usize::from(repeat) % offers {
        0 => configured,
        k => others.nth(k - 1).unwrap_or(configured),
    }
}

/// Everything the unit logic can be tuned with.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// The MMU firmware version the unit claims to be compatible with.
    pub version: Version,
    /// Register 0x0b: mm pushed after the printer's sensor triggers (the printer writes 5).
    pub extra_load_mm: u16,
    /// Register 0x0c: mm of unloading within which the printer's sensor must clear.
    pub unload_check_mm: u16,
    /// Register 0x0d: unloading speed, mm/s.
    pub unload_speed: u16,
    /// Register 0x11: loading speed, mm/s.
    pub load_speed: u16,
    /// Register 0x14: slow feed speed near the printer's sensor, mm/s (the printer writes 20).
    pub slow_speed: u16,
    /// Register 0x22: Bowden tube length from the hub sensor to the printer's sensor, mm.
    pub bowden_mm: u16,
    /// How far before the hub sensor a parked tip rests, mm.
    pub park_mm: u16,
    /// How much of the Bowden tube is fed fast before slowing down for the printer's sensor, as mm
    /// left before its nominal position.
    pub bowden_slowdown_mm: u16,
    /// Longest feed searching for the printer's sensor (beyond the fast part), mm.
    pub fsensor_search_mm: u16,
    /// Longest feed from the slot entry to the hub sensor when preloading, mm.
    pub preload_max_mm: u16,
    /// Longest feed from the park position to the hub sensor, mm.
    pub hub_search_mm: u16,
    /// Longest reverse run of an eject, mm.
    pub eject_max_mm: u16,
    /// Filament moved per motor revolution, in 1/100 mm.
    pub mm_per_rev_centi: u16,
    /// Filament speed at full duty, mm/s: the open-loop part of the speed control.
    pub full_duty_speed: u16,
    /// The highest duty the logic commands, per mille.
    pub max_duty: u16,
    /// A motor driven at or above this duty must turn, per mille.
    pub stall_min_duty: u16,
    /// A motor driven at or above `stall_min_duty` without a revolution for this long is stalled, ms.
    pub stall_timeout_ms: u16,
    /// Slack added to every phase's time bound on top of twice its nominal duration, ms.
    pub phase_slack_ms: u16,
    /// Tension sensor reading with the Bowden tube at rest.
    pub tension_neutral: u16,
    /// Deviation from neutral the motor ignores while following the extruder, in ADC counts.
    pub tension_deadband: u16,
    /// Duty added per ADC count of tension above the deadband, per mille per count.
    pub tension_gain: u16,
    /// The most duty the tension follower applies, per mille.
    pub tension_max_duty: u16,
    /// Presence thresholds of the hub filament sensor.
    pub hub_thresholds: Thresholds,
    /// Presence thresholds of each slot's filament sensor.
    pub slot_thresholds: [Thresholds; MAX_SLOTS],
    /// Edge thresholds of each slot's motor Hall sine.
    pub motor_thresholds: [Thresholds; MAX_SLOTS],
}

impl Config {
    /// The reference unit's settings. A constant, so that building them copies them from flash
    /// (code storing each field took twice the room).
    pub const DEFAULT: Config = Config {
        version: Version {
            major: 3,
            minor: 0,
            revision: 3,
            build: 1,
        },
        extra_load_mm: 30,
        unload_check_mm: 40,
        unload_speed: 95,
        load_speed: 95,
        slow_speed: 20,
        bowden_mm: 360,
        park_mm: 15,
        bowden_slowdown_mm: 30,
        fsensor_search_mm: 90,
        preload_max_mm: 150,
        hub_search_mm: 45,
        eject_max_mm: 150,
        mm_per_rev_centi: 200,
        full_duty_speed: 150,
        max_duty: 1000,
        stall_min_duty: 250,
        stall_timeout_ms: 400,
        phase_slack_ms: 1000,
        tension_neutral: 2048,
        tension_deadband: 60,
        tension_gain: 2,
        tension_max_duty: 600,
        hub_thresholds: Thresholds { on: 2600, off: 2400 },
        slot_thresholds: [Thresholds { on: 2600, off: 2400 }; MAX_SLOTS],
        motor_thresholds: [Thresholds { on: 2300, off: 1800 }; MAX_SLOTS],
    };
}

impl Default for Config {
    fn default() -> Self {
        Self::DEFAULT
    }
}
