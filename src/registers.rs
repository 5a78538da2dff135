//! The register map read by `R`/`S` and written by `W`, as one table.
//!
//! `0x00`-`0x22` follow the MMU3 map where a register means something on this hardware (the
//! others answer `R`). The unit's own settings and diagnostics live from `0x40`; `0x80`-`0x82`
//! stay free because the MK4 intercepts them printer-side. Writes are validated: an unknown or
//! read-only register, a value out of range, or one that would leave a configuration the guards
//! refuse ([`crate::guards`]: each write is applied to a copy of the settings, and the whole copy
//! is checked) answers `R` and changes nothing.
//!
//! Every register is a row of [`REGISTERS`]: its address (a block of addresses for per-sensor and
//! per-slot registers), its name, whether it can be written, and how it is read and written. The
//! App answers `R`/`W` from it and the host tool names registers from it ([`describe`],
//! [`lookup`]), so the two cannot disagree.

use core::fmt;

use mmu_protocol::{ErrorCode, ProgressCode};

use crate::config::Config;
use crate::feeder::Feeder;
use crate::guards::{self, Rule};
use crate::lanes::{LaneFigures, left_mm};
use crate::phases::UnloadStuck;
use crate::profile::{MotionSensor, Profile};
use crate::runner::Status;
use crate::sensor::{AnalogSensor, Thresholds};
use crate::time::Instant;
use crate::unit::{Hub, Lane, SensorId};

/// Sensor diagnostic blocks hold up to 16 sensors ([`crate::unit::SENSOR_INDICES`]).
const SENSOR_BLOCK: u8 = crate::unit::SENSOR_INDICES as u8;
/// Per-slot blocks hold up to 8 slots.
const SLOT_BLOCK: u8 = 8;
/// Lane blocks (filament left, lane health) hold 5 slots, packed where 8 do not fit.
const LANE_BLOCK: u8 = crate::MAX_SLOTS as u8;

/// What a register read sees of the unit: plain borrowed state, the same for every slot count.
pub struct View<'a> {
    /// What senses each lane.
    pub profile: &'a Profile,
    /// The settings in force.
    pub config: &'a Config,
    /// The hub's sensors.
    pub hub: &'a Hub,
    /// What FINDA reads: the hub sensor, or empty while a spool end is reported
    /// ([`crate::spool_end`]).
    pub finda: bool,
    /// Every slot's feeding system (none in a view of the settings alone: [`settings_view`]).
    pub feeders: &'a [Feeder],
    /// The unit's slots (the sensors' diagnostic indices depend on them).
    pub slots: usize,
    /// Where each slot's filament is.
    pub lanes: &'a [Lane],
    /// The printer's filament sensor as last reported.
    pub fsensor: u8,
    /// The slot owning the hub path, or else the slot last asked for.
    pub path_slot: Option<usize>,
    /// The slot whose motor the running command drives.
    pub driving_slot: Option<usize>,
    /// Where the current command stands.
    pub status: Status,
    /// Errors raised since the counters were last cleared.
    pub drive_errors: u16,
    /// Completed tool changes per slot.
    pub tool_changes: &'a [u16],
    /// Errors raised while driving each slot.
    pub failures: &'a [u16],
    /// Filament fed or pulled by each slot, mm.
    pub fed_mm: &'a [u32],
    /// Responses dropped because a step's transmit buffer was full.
    pub dropped_responses: u16,
    /// The Bowden length the last Retry of FSENSOR TOO EARLY learned since start, mm (0: none).
    pub bowden_learned_mm: u16,
    /// The build number `S3` reports now (register 0x03).
    pub build: u16,
    /// Each lane's kept figures ([`crate::lanes`]).
    pub lane_figures: &'a [LaneFigures],
    /// Filament taken off each slot's spool, 1/100 mm.
    pub used_centi: &'a [i32],
    /// Per slot, its last load distance drifted (bit k of register 0x5e).
    pub lanes_drifted: u8,
    /// The rule the last refusal broke (register 0x8f).
    pub refused_rule: Option<Rule>,
    /// Why the unload stopped, while its `8004` waits ([`UNLOAD_STUCK`]).
    pub unload_stuck: Option<UnloadStuck>,
    /// The time of the current step.
    pub now: Instant,
}

impl View<'_> {
    fn sensor_of(&self, id: SensorId) -> Option<&AnalogSensor> {
        crate::unit::sensor_in(self.profile, self.hub, self.feeders, id)
    }

    fn sensor(&self, index: usize) -> Option<&AnalogSensor> {
        self.sensor_of(SensorId::from_index(index, self.slots))
    }
}

/// What a register write may change.
pub struct Target<'a> {
    /// What senses each lane.
    pub profile: &'a Profile,
    /// The unit's slots.
    pub slots: usize,
    /// The settings.
    pub config: &'a mut Config,
    /// The printer's filament sensor state (register 0x09, as `f`).
    pub fsensor: &'a mut u8,
    /// What the presence sensors show now, for the guards ([`Rule::OnAtFilamentSeen`]).
    pub filament_readings: FilamentReadings,
    /// Filament taken off each slot's spool, 1/100 mm (register `0x59 + k` sets what is left).
    pub used_centi: &'a mut [i32],
}

pub use crate::guards::{FilamentReadings, NO_FILAMENT_READINGS};

impl<'a> Target<'a> {
    /// What a write may change of the settings `config` alone, on a unit with `slots` slots of
    /// `profile`: no presence sensor known to see filament, no spool ledger.
    pub fn of_settings(
        profile: &'a Profile,
        slots: usize,
        config: &'a mut Config,
        fsensor: &'a mut u8,
    ) -> Self {
        Target {
            profile,
            slots,
            config,
            fsensor,
            filament_readings: NO_FILAMENT_READINGS,
            used_centi: &mut [],
        }
    }
}

/// Why a write was answered `R`. Whatever the reason, it changed nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Refused {
    /// The unit has no such register.
    Unknown,
    /// The register is read only.
    ReadOnly,
    /// The value is outside the register's range (or names a slot the unit lacks).
    OutOfRange,
    /// The settings with the value would break a guard's rule ([`crate::guards`]).
    Broke(Rule),
}

/// Whether the printer may write a register.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Read only: a write answers `R`.
    Read,
    /// Read and write.
    ReadWrite,
}

/// How many addresses a row covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Span {
    /// One address.
    One,
    /// One address per sensor, in the diagnostic order of [`SensorId::index`].
    Sensors,
    /// One address per slot.
    Slots,
    /// One address per slot, in a block of 5 ([`LANE_BLOCK`]).
    Lanes,
}

/// What one address of a block register is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Subject {
    /// A sensor.
    Sensor(SensorId),
    /// A slot.
    Slot(usize),
}

/// One row of the register table: plain data (6 B in the firmware image); the code that reads
/// and writes its register is an arm of `read_row` and `write_row` (made by `registers!`).
pub struct Row {
    /// The (first) address.
    pub address: u8,
    /// The name tools show, e.g. `bowden_mm`; block registers add their subject (`raw.hub.filament`).
    /// Empty in the firmware image, which never shows it.
    pub name: Name,
    /// The lowest and highest value a write accepts; a read-only row's accepts none (lowest
    /// above highest: 2 B a row less than an `Option`).
    accepts: (u16, u16),
    handler: Handler,
}

/// What a read-only row accepts: nothing.
const READ_ONLY: (u16, u16) = (1, 0);

impl Row {
    /// Whether the printer may write it: a register with a range of values to accept.
    pub const fn access(&self) -> Access {
        match self.range() {
            Some(_) => Access::ReadWrite,
            None => Access::Read,
        }
    }

    /// The values a write accepts, lowest and highest (`None`: read only).
    pub const fn range(&self) -> Option<(u16, u16)> {
        let (min, max) = self.accepts;
        if min <= max { Some(self.accepts) } else { None }
    }

    /// How many addresses the row covers.
    pub const fn span(&self) -> Span {
        self.handler.span()
    }

    /// Its value at `index` of the block, as `view` reads it.
    fn read(&self, view: &View, index: usize) -> Option<u16> {
        read_row(self.handler, view, self.address, index)
    }

    /// The index inside the block that `address` names, if it is one of this row's addresses.
    const fn index_of(&self, address: u8) -> Option<usize> {
        let Some(offset) = address.checked_sub(self.address) else {
            return None;
        };
        let size = match self.span() {
            Span::One => 1,
            Span::Sensors => SENSOR_BLOCK,
            Span::Slots => SLOT_BLOCK,
            Span::Lanes => LANE_BLOCK,
        };
        if offset < size {
            Some(offset as usize)
        } else {
            None
        }
    }
}

/// A register's name. Only tools show names: in the firmware image (feature `mcu`) it is empty
/// and takes no space in the table (6 B a row).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Name(#[cfg(not(feature = "mcu"))] &'static str);

impl Name {
    /// The name tools show (empty in the firmware image).
    pub const fn as_str(self) -> &'static str {
        #[cfg(not(feature = "mcu"))]
        return self.0;
        #[cfg(feature = "mcu")]
        ""
    }
}

macro_rules! name {
    ($name:literal) => {{
        #[cfg(not(feature = "mcu"))]
        let name = Name($name);
        #[cfg(feature = "mcu")]
        let name = Name();
        name
    }};
}

/// The [`Config`] field of each plain setting, by address: [`setting_field`] and
/// [`setting_field_mut`] (the same machine code, folded into one by the linker).
macro_rules! settings {
    ($($address:literal => $field:ident,)*) => {
        /// The field of the plain setting at `address`.
        fn setting_field(config: &Config, address: u8) -> Option<&u16> {
            match address {
                $($address => Some(&config.$field),)*
                _ => None,
            }
        }

        /// The field of the plain setting at `address`, to write.
        fn setting_field_mut(config: &mut Config, address: u8) -> Option<&mut u16> {
            match address {
                $($address => Some(&mut config.$field),)*
                _ => None,
            }
        }

        /// The name of the field of the plain setting at `address`.
        #[cfg(test)]
        fn setting_field_name(address: u8) -> Option<&'static str> {
            match address {
                $($address => Some(stringify!($field)),)*
                _ => None,
            }
        }
    };
}

settings! {
    0x0b => extra_load_mm,
    0x0c => unload_check_mm,
    0x0d => unload_speed,
    0x11 => load_speed,
    0x14 => slow_speed,
    0x22 => bowden_mm,
    0x41 => park_mm,
    0x42 => mm_per_rev_centi,
    0x43 => max_duty,
    0x44 => stall_min_duty,
    0x45 => stall_timeout_ms,
    0x46 => preload_max_mm,
    0x47 => hub_search_mm,
    0x48 => fsensor_search_mm,
    0x49 => eject_max_mm,
    0x4a => bowden_slowdown_mm,
    0x4b => full_duty_speed,
    0x4c => tension_neutral,
    0x4d => tension_deadband,
    0x4e => tension_gain,
    0x4f => tension_max_duty,
    0x5f => lane_to_hub_mm,
}

fn read_setting(v: &View, address: u8, _: usize) -> Option<u16> {
    setting_field(v.config, address).copied()
}

/// Write a plain setting (what it must agree with is the guards' to check, on the whole
/// configuration: [`write`]).
fn write_setting(t: &mut Target, address: u8, _: usize, value: u16) -> bool {
    match setting_field_mut(t.config, address) {
        Some(field) => {
            *field = value;
            true
        }
        None => false,
    }
}

/// The register table, one row per entry, in address order (but the lane rows, last):
///
/// - `setting(address, name, min..=max)`: a plain setting, a `u16` field of [`Config`] listed in
///   [`settings!`]. Every setting shares one read and one write, which find the field by the
///   address (code per row and field took 0.6 KiB of flash).
/// - `Handler: read_only(address, name, read)`: a read-only register of one address;
/// - `Handler: block(address, Sensors | Slots, name, read)`: a read-only register of one address
///   per sensor or per slot;
/// - `Handler: writable(address, span, name, min..=max, read, write)`: a register with its own
///   write.
///
/// `read` is a closure of the view, the row's (first) address and the index in the block;
/// `write` of the target, the address, the index and the value, false when it refuses the
/// value. The macro makes [`REGISTERS`], the rows as plain data (6 B each in the firmware
/// image), a `Handler` variant for each row with code of its own, and `read_row` and
/// `write_row`, whose match arms run the rows' closures: where every row held pointers to a
/// function of its own (16 B a row), the image is 0.4 KiB smaller.
macro_rules! registers {
    // Row by row: its entry in the table and, for a row with code of its own, its variant and
    // its code (a writable row's also in the list the write matches).
    (@rows [$($table:expr,)*] $writable:tt $own:tt setting($($row:tt)*), $($rest:tt)*) => {
        registers!(@rows [$($table,)* registers!(@row Setting setting($($row)*)),] $writable $own $($rest)*);
    };
    (@rows [$($table:expr,)*] [$($writable:tt)*] [$($own:tt)*] $handler:ident: writable($($row:tt)*), $($rest:tt)*) => {
        registers!(
            @rows [$($table,)* registers!(@row $handler writable($($row)*)),]
            [$($writable)* $handler: writable($($row)*),] [$($own)* $handler: writable($($row)*),] $($rest)*
        );
    };
    (@rows [$($table:expr,)*] $writable:tt [$($own:tt)*] $handler:ident: $kind:ident($($row:tt)*), $($rest:tt)*) => {
        registers!(
            @rows [$($table,)* registers!(@row $handler $kind($($row)*)),]
            $writable [$($own)* $handler: $kind($($row)*),] $($rest)*
        );
    };
    (
        @rows [$($table:expr,)*]
        [$($writable:ident: writable($($written:tt)*),)*]
        [$($own:ident: $kind:ident($($read:tt)*),)*]
    ) => {
        /// The row whose code `read_row` and `write_row` run: a plain setting, or a row of its
        /// own.
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        enum Handler {
            $($own,)*
            Setting,
        }

        impl Handler {
            /// How many addresses its row covers (a row of its own says; a setting has one).
            const fn span(self) -> Span {
                match self {
                    $(Handler::$own => registers!(@span $kind($($read)*)),)*
                    Handler::Setting => Span::One,
                }
            }
        }

        /// The register map, MMU3 registers first. A `static`, not a `const`: each use of a
        /// `const` slice may get its own copy in the image.
        pub static REGISTERS: &[Row] = ROWS;

        /// The rows; used once, by [`REGISTERS`].
        const ROWS: &[Row] = &[$($table,)*];

        /// The value the row of `handler` reads: the view, the row's (first) address, the index
        /// in the block.
        fn read_row(handler: Handler, view: &View, address: u8, index: usize) -> Option<u16> {
            // The settings apart, by a comparison (`Setting` is the last variant): the match of
            // the others then compiles to a table of 2-byte offsets (88 B less than one match).
            if handler as u8 >= Handler::Setting as u8 {
                return read_setting(view, address, index);
            }
            match handler {
                $(Handler::$own => registers!(@read $kind($($read)*))(view, address, index),)*
                Handler::Setting => read_setting(view, address, index),
            }
        }

        /// Whether the row of `handler` took `value` (a read-only row takes none).
        fn write_row(handler: Handler, target: &mut Target, address: u8, index: usize, value: u16) -> bool {
            match handler {
                Handler::Setting => write_setting(target, address, index, value),
                $(Handler::$writable => registers!(@write writable($($written)*))(target, address, index, value),)*
                _ => false,
            }
        }
    };
    (@row $handler:ident read_only($address:expr, $name:literal, $read:expr)) => {
        registers!(@row $handler block($address, One, $name, $read))
    };
    (@row $handler:ident setting($address:expr, $name:literal, $min:literal..=$max:literal)) => {
        registers!(@row $handler writable($address, One, $name, $min..=$max, (), ()))
    };
    (@row $handler:ident block($address:expr, $span:ident, $name:literal, $read:expr)) => {
        Row {
            address: $address,
            name: name!($name),
            accepts: READ_ONLY,
            handler: Handler::$handler,
        }
    };
    (@row $handler:ident writable(
        $address:expr, $span:ident, $name:literal, $min:literal..=$max:literal, $read:expr, $write:expr
    )) => {
        Row {
            address: $address,
            name: name!($name),
            accepts: ($min, $max),
            handler: Handler::$handler,
        }
    };
    (@span read_only($($row:tt)*)) => {
        Span::One
    };
    (@span block($address:expr, $span:ident, $($row:tt)*)) => {
        Span::$span
    };
    (@span writable($address:expr, $span:ident, $($row:tt)*)) => {
        Span::$span
    };
    (@read read_only($address:expr, $name:literal, $read:expr)) => {
        reading($read)
    };
    (@read block($address:expr, $span:ident, $name:literal, $read:expr)) => {
        reading($read)
    };
    (@read writable(
        $address:expr, $span:ident, $name:literal, $min:literal..=$max:literal, $read:expr, $write:expr
    )) => {
        reading($read)
    };
    (@write writable(
        $address:expr, $span:ident, $name:literal, $min:literal..=$max:literal, $read:expr, $write:expr
    )) => {
        writing($write)
    };
    ($($rows:tt)*) => {
        registers!(@rows [] [] [] $($rows)*);
    };
}

/// A row's read closure, typed.
const fn reading<F: Fn(&View, u8, usize) -> Option<u16>>(read: F) -> F {
    read
}

/// A row's write closure, typed.
const fn writing<F: Fn(&mut Target, u8, usize, u16) -> bool>(write: F) -> F {
    write
}

/// The printer's filament sensor as it reports it (the Core One writes it instead of sending
/// `f`): writable, but state, not a setting.
pub const FSENSOR: u8 = 0x09;
/// Extension: number of slots (read only).
pub const SLOT_COUNT: u8 = 0x40;
/// Extension: bitmask of sensors stuck at a rail, bit = diagnostic sensor index (read only).
pub const SENSOR_FAULTS: u8 = 0x50;
/// Extension: responses dropped because a step's transmit buffer was full (read only).
pub const DROPPED_RESPONSES: u8 = 0x51;
/// Extension: the revision `S2` reports.
pub const REPORTED_REVISION: u8 = 0x52;
/// Extension: the Bowden length (0x22) the last Retry of FSENSOR TOO EARLY learned since start,
/// mm; 0 when none (read only).
pub const BOWDEN_LEARNED: u8 = 0x53;
/// Extension: what senses each lane, [`Profile::code`] (read only).
pub const HARDWARE: u8 = 0x8d;
/// Extension: counts of a turn of each lane's motion sensor (read only): register 0x42 is the
/// filament's motion per such turn.
pub const COUNTS_PER_REV: u8 = 0x8e;
/// Extension: length of the filament on slot `k`'s spool when inserted, m, at `SPOOL + k`.
pub const SPOOL: u8 = 0x54;
/// Extension: filament left on slot `k`'s spool, m, at `LEFT + k` (state: a write sets it).
pub const LEFT: u8 = 0x59;
/// Extension: warning bits: bit k, slot k's load distance drifted; bit 8 + k, slot k is low.
pub const LANE_WARNINGS: u8 = 0x5e;
/// Extension: the code of the guards' rule ([`Rule::code`]) the last refusal broke, of a write or
/// of the stored settings at start; 0 when it broke none (an unknown or read-only register, a
/// value out of range) or nothing was refused (read only).
pub const REFUSED_RULE: u8 = 0x8f;
/// Extension: rolling drag of slot `k`, % of a free lane's duty, at `DRAG + k` (read only).
pub const DRAG: u8 = 0x83;
/// Extension: rolling slip of slot `k`'s moves, per mille, two's complement, at `SLIP + k`.
pub const SLIP: u8 = 0x88;
/// Extension: rolling time of a tool change to slot `k` that needed no help, 1/10 s.
pub const LOAD_TIME: u8 = 0xd8;
/// Extension: rolling distance from the hub sensor to the printer's sensor on slot `k`'s loads, mm.
pub const LOAD_DISTANCE: u8 = 0xe8;
/// Extension: stalls of slot `k`'s motor at `STALLS + k` (read only).
pub const STALLS: u8 = 0xed;
/// Extension: tool changes to slot `k` that needed no help, % of the last `SUCCESS_OF + k`.
pub const SUCCESS: u8 = 0xf2;
/// Extension: how many tool changes [`SUCCESS`] counts (up to 32).
pub const SUCCESS_OF: u8 = 0xf7;
/// Extension: why an unload stopped on FSENSOR DIDNT CLEAR (`8004`), while that error waits:
/// [`UnloadStuck`] (1: held in the extruder, 2: the filament free but the printer's sensor still
/// on); 0 otherwise, or when the unit cannot tell (read only).
pub const UNLOAD_STUCK: u8 = 0xfc;
/// Extension: raw sample of sensor `i` at `RAW + i` (read only).
pub const RAW: u8 = 0x60;
/// Extension: filtered value of sensor `i` at `FILTERED + i` (read only).
pub const FILTERED: u8 = 0x70;
/// Extension: "on" threshold of presence/motor sensor `i` at `THRESHOLD_ON + i`.
pub const THRESHOLD_ON: u8 = 0x90;
/// Extension: "off" threshold of presence/motor sensor `i` at `THRESHOLD_OFF + i`.
pub const THRESHOLD_OFF: u8 = 0xa0;
/// Extension: odometry of slot `k` in mm (two's complement) at `ODOMETRY + k` (read only).
pub const ODOMETRY: u8 = 0xb0;
/// Extension: lane state of slot `k` (MMU3 filament-state values) at `LANE + k` (read only).
pub const LANE: u8 = 0xb8;
/// Extension: completed tool changes to slot `k` at `TOOL_CHANGES + k` (read only).
pub const TOOL_CHANGES: u8 = 0xc0;
/// Extension: errors raised while driving slot `k` at `FAILURES + k` (read only).
pub const FAILURES: u8 = 0xc8;
/// Extension: filament speed of slot `k` from its motor Hall sensor, mm/s, at `SPEED + k` (read only).
pub const SPEED: u8 = 0xd0;
/// Extension: filament fed or pulled by slot `k`'s moves, whole metres, at `FED_METRES + k` (read only).
pub const FED_METRES: u8 = 0xe0;

registers! {
    VersionMajor: read_only(0x00, "version.major", |v, _, _| Some(
        v.config.version.major.into()
    )),
    VersionMinor: read_only(0x01, "version.minor", |v, _, _| Some(
        v.config.version.minor.into()
    )),
    VersionRevision: read_only(0x02, "version.revision", |v, _, _| Some(
        v.config.version.revision.into()
    )),
    VersionBuild: read_only(0x03, "version.build", |v, _, _| Some(v.build)),
    Errors: read_only(0x04, "errors", |v, _, _| Some(v.drive_errors)),
    Progress: read_only(0x05, "progress", |v, _, _| Some(match v.status {
        Status::Running(progress) => progress.0.into(),
        Status::Failed(_) => ProgressCode::ERR_WAITING_FOR_USER.0.into(),
        Status::Finished => 0,
    })),
    Error: read_only(0x06, "error", |v, _, _| Some(match v.status {
        Status::Failed(error) => error.0,
        Status::Running(_) => ErrorCode::RUNNING.0,
        Status::Finished => ErrorCode::OK.0,
    })),
    FilamentState: read_only(0x07, "filament_state", |v, _, _| Some(
        v.path_slot
            .and_then(|slot| v.lanes.get(slot))
            .map_or(0, |lane| lane.mmu3_state())
    )),
    HubPresent: read_only(0x08, "hub.present", |v, _, _| Some(v.finda.into())),
    // The Core One reports its filament sensor this way instead of `f`.
    Fsensor: writable(
        FSENSOR,
        One,
        "fsensor",
        0..=255,
        |v, _, _| Some(u16::from(v.fsensor != 0)),
        |t, _, _, value| match u8::try_from(value) {
            Ok(state) => {
                *t.fsensor = state;
                true
            }
            Err(_) => false,
        }
    ),
    MotorMode: read_only(0x0a, "motor_mode", |_, _, _| Some(0)),
    setting(0x0b, "extra_load_mm", 0..=255),
    setting(0x0c, "unload_check_mm", 0..=255),
    setting(0x0d, "unload_speed", 1..=1000),
    setting(0x11, "load_speed", 1..=1000),
    setting(0x14, "slow_speed", 1..=1000),
    Odometry: read_only(0x1a, "odometry", |v, _, _| Some(
        v.path_slot
            .and_then(|slot| v.feeders.get(slot))
            // Two's complement, wrapping as the odometry does (it stuck at 0 and 65 535 mm).
            .map_or(0, |f| f.odometry_mm() as u16)
    )),
    SelectorSlot: read_only(0x1b, "selector_slot", |v, _, _| Some(
        v.path_slot.map_or(5, |slot| slot as u16)
    )),
    IdlerSlot: read_only(0x1c, "idler_slot", |v, _, _| Some(
        v.driving_slot.map_or(5, |slot| slot as u16)
    )),
    setting(0x22, "bowden_mm", 50..=5000),
    Slots: read_only(0x40, "slots", |v, _, _| Some(v.feeders.len() as u16)),
    setting(0x41, "park_mm", 1..=200),
    setting(0x42, "mm_per_rev_centi", 10..=5000),
    setting(0x43, "max_duty", 100..=1000),
    setting(0x44, "stall_min_duty", 0..=1000),
    setting(0x45, "stall_timeout_ms", 50..=10000),
    setting(0x46, "preload_max_mm", 10..=2000),
    setting(0x47, "hub_search_mm", 5..=500),
    setting(0x48, "fsensor_search_mm", 10..=2000),
    setting(0x49, "eject_max_mm", 10..=2000),
    setting(0x4a, "bowden_slowdown_mm", 0..=500),
    setting(0x4b, "full_duty_speed", 10..=2000),
    setting(0x4c, "tension_neutral", 0..=4095),
    setting(0x4d, "tension_deadband", 0..=2000),
    setting(0x4e, "tension_gain", 0..=100),
    setting(0x4f, "tension_max_duty", 0..=1000),
    SensorFaults: read_only(0x50, "sensor_faults", |v, _, _| Some(
        (0..SensorId::count(v.slots))
            .filter(|&i| v.sensor(i).is_some_and(|s| s.fault().is_some()))
            .fold(0u16, |mask, i| mask | (1 << i))
    )),
    DroppedResponses: read_only(0x51, "dropped_responses", |v, _, _| Some(v.dropped_responses)),
    // The revision the first `S2` of a handshake reports: the one a printer accepted last (the
    // unit keeps it on `S3`, app.rs). Asked again, the unit offers the other revisions of
    // `config::REVISIONS`, so every printer finds its own.
    ReportedRevision: writable(
        REPORTED_REVISION,
        One,
        "reported_revision",
        0..=4,
        |v, _, _| Some(v.config.version.revision.into()),
        |t, _, _, value| {
            t.config.version.revision = value as u8;
            true
        }
    ),
    LearnedBowdenMm: read_only(0x53, "learned_bowden_mm", |v, _, _| Some(v.bowden_learned_mm)),
    Hardware: read_only(HARDWARE, "hardware", |v, _, _| Some(v.profile.code())),
    CountsPerRev: read_only(COUNTS_PER_REV, "counts_per_rev", |v, _, _| Some(
        v.profile.motion.counts_per_rev()
    )),
    setting(0x5f, "lane_to_hub_mm", 0..=1000),
    Raw: block(RAW, Sensors, "raw", |v, _, i| Some(
        v.sensor(i)?.raw()
    )),
    Filtered: block(FILTERED, Sensors, "filtered", |v, _, i| Some(
        v.sensor(i)?.filtered()
    )),
    ThresholdOn: writable(
        THRESHOLD_ON,
        Sensors,
        "threshold_on",
        0..=4095,
        |v, _, i| Some(thresholds(v.profile, v.config, SensorId::from_index(i, v.slots))?.on),
        |t, _, i, value| set_threshold(t, SensorId::from_index(i, t.slots), |th| th.on = value)
    ),
    ThresholdOff: writable(
        THRESHOLD_OFF,
        Sensors,
        "threshold_off",
        0..=4095,
        |v, _, i| Some(thresholds(v.profile, v.config, SensorId::from_index(i, v.slots))?.off),
        |t, _, i, value| set_threshold(t, SensorId::from_index(i, t.slots), |th| th.off = value)
    ),
    SlotOdometry: block(ODOMETRY, Slots, "odometry", |v, _, k| Some(
        v.feeders.get(k)?.odometry_mm() as i16 as u16
    )),
    Lane: block(LANE, Slots, "lane", |v, _, k| Some(v.lanes.get(k)?.mmu3_state())),
    ToolChanges: block(TOOL_CHANGES, Slots, "tool_changes", |v, _, k| v
        .tool_changes
        .get(k)
        .copied()),
    Failures: block(FAILURES, Slots, "failures", |v, _, k| v.failures.get(k).copied()),
    Speed: block(SPEED, Slots, "speed", |v, _, k| Some(
        v.feeders.get(k)?.speed_mm_s(v.now)
    )),
    FedMetres: block(FED_METRES, Slots, "fed_metres", |v, _, k| Some(
        u16::try_from(*v.fed_mm.get(k)? / 1000).unwrap_or(u16::MAX)
    )),
    // The lane rows last, out of address order: a read walks the table from the top, and the
    // registers read most (the printer's polls, the sensors') stay where they were.
    SpoolM: writable(
        SPOOL,
        Lanes,
        "spool_m",
        1..=10000,
        |v, _, k| v.config.spool_m.get(k).copied(),
        |t, _, k, value| match t.config.spool_m.get_mut(k) {
            Some(spool) => {
                *spool = value;
                true
            }
            None => false,
        }
    ),
    LeftM: writable(
        LEFT,
        Lanes,
        "left_m",
        0..=10000,
        |v, _, k| Some(
            // To the nearest metre.
            (left_mm(*v.config.spool_m.get(k)?, *v.used_centi.get(k)?).saturating_add(500) / 1000)
                .min(u32::from(u16::MAX)) as u16
        ),
        |t, _, k, value| {
            let (Some(&spool), Some(used)) = (t.config.spool_m.get(k), t.used_centi.get_mut(k)) else {
                return false;
            };
            // No more than the spool holds: what is kept is the metres used, never below 0.
            *used = (i32::from(spool) - i32::from(value.min(spool))) * 100_000;
            true
        }
    ),
    LaneWarnings: read_only(LANE_WARNINGS, "lane_warnings", |v, _, _| Some(crate::lanes::warnings(
        v.lanes_drifted,
        v.used_centi,
        &v.config.spool_m
    ))),
    UnloadStuck: read_only(UNLOAD_STUCK, "unload_stuck", |v, _, _| Some(
        v.unload_stuck.map_or(0, |why| why as u16)
    )),
    RefusedRule: read_only(REFUSED_RULE, "refused_rule", |v, _, _| Some(
        v.refused_rule.map_or(0, |rule| rule.code().into())
    )),
    Drag: block(DRAG, Lanes, "drag_pct", |v, _, k| Some(v.lane_figures.get(k)?.drag_pct)),
    Slip: block(SLIP, Lanes, "slip_permille", |v, _, k| Some(
        v.lane_figures.get(k)?.slip_permille as u16
    )),
    LoadTime: block(LOAD_TIME, Lanes, "load_ds", |v, _, k| Some(v.lane_figures.get(k)?.load_ds)),
    LoadDistance: block(LOAD_DISTANCE, Lanes, "load_distance_mm", |v, _, k| Some(
        v.lane_figures.get(k)?.fsensor_mm
    )),
    Stalls: block(STALLS, Lanes, "stalls", |v, _, k| Some(v.lane_figures.get(k)?.stalls)),
    Success: block(SUCCESS, Lanes, "success_pct", |v, _, k| Some(v.lane_figures.get(k)?.success_pct())),
    SuccessOf: block(SUCCESS_OF, Lanes, "success_of", |v, _, k| Some(
        u16::from(v.lane_figures.get(k)?.attempts)
    )),
}

/// The thresholds of a sensor, if it has any on this hardware: presence sensors have them, a
/// Hall wave's edges have them, a count or an angle has none.
fn thresholds(profile: &Profile, config: &Config, sensor: SensorId) -> Option<Thresholds> {
    match sensor {
        SensorId::HubFilament => profile.hub_sensor.then_some(config.hub_thresholds),
        SensorId::SlotFilament(slot) => config.slot_thresholds.get(slot).copied(),
        SensorId::Motion(slot) if profile.motion == MotionSensor::HallWave => {
            config.motor_thresholds.get(slot).copied()
        }
        SensorId::Motion(_) | SensorId::HubTension | SensorId::HubCutter | SensorId::LaneTension(_) => None,
    }
}

/// Change one threshold of a sensor; false for a sensor without thresholds. Whether the pair is
/// one the sensor can use (ordered, within the rails, wider than the noise, not above the
/// filament it sees now) is the guards' to check ([`crate::guards`]).
fn set_threshold(target: &mut Target, sensor: SensorId, change: impl FnOnce(&mut Thresholds)) -> bool {
    if thresholds(target.profile, target.config, sensor).is_none() {
        return false;
    }
    let config = &mut *target.config;
    let thresholds = match sensor {
        SensorId::HubFilament => Some(&mut config.hub_thresholds),
        SensorId::SlotFilament(slot) => config.slot_thresholds.get_mut(slot),
        SensorId::Motion(slot) => config.motor_thresholds.get_mut(slot),
        SensorId::HubTension | SensorId::HubCutter | SensorId::LaneTension(_) => None,
    };
    let Some(thresholds) = thresholds else {
        return false;
    };
    change(thresholds);
    true
}

/// A register of a unit with `slots` slots: its row and, for a block register, the index.
fn find(address: u8, slots: usize) -> Option<(&'static Row, usize)> {
    let (row, index) = REGISTERS
        .iter()
        .find_map(|row| row.index_of(address).map(|index| (row, index)))?;
    let exists = match row.span() {
        Span::One => true,
        Span::Sensors => index < SensorId::count(slots),
        Span::Slots | Span::Lanes => index < slots,
    };
    exists.then_some((row, index))
}

/// The value of register `address`, or `None` when the unit has no such register.
pub fn read(view: &View, address: u8) -> Option<u16> {
    let (row, index) = find(address, view.feeders.len())?;
    row.read(view, index)
}

/// Write `value` to register `address` of a unit with `slots` slots; `Err` (answered `R`, nothing
/// changed) when the register is unknown or read-only, the value out of its range, or the
/// settings with it would break a rule of the guards ([`guards::check`], the whole configuration,
/// with what the presence sensors see now). The value goes into a copy of the settings, which
/// replaces them only once the guards take it.
pub fn write(target: &mut Target, slots: usize, address: u8, value: u16) -> Result<(), Refused> {
    let (row, index) = find(address, slots).ok_or(Refused::Unknown)?;
    let (min, max) = row.range().ok_or(Refused::ReadOnly)?;
    if !(min..=max).contains(&value) {
        return Err(Refused::OutOfRange);
    }
    let mut candidate = target.config.clone();
    let mut staged = Target {
        profile: target.profile,
        slots: target.slots,
        config: &mut candidate,
        fsensor: &mut *target.fsensor,
        filament_readings: target.filament_readings,
        used_centi: &mut *target.used_centi,
    };
    if !write_row(row.handler, &mut staged, row.address, index, value) {
        return Err(Refused::OutOfRange);
    }
    // State registers (the printer's sensor, filament left) change no setting: nothing to check.
    if candidate != *target.config {
        guards::check(&candidate, &target.filament_readings).map_err(Refused::Broke)?;
        *target.config = candidate;
    }
    Ok(())
}

/// Apply a stored setting (`address`, `value`) to `config` of a unit with `slots` slots, with the
/// register's own checks (a setting register of this unit, within its range) but not the guards:
/// they judge the stored settings once all are in ([`crate::App::restore`]), since a pair of
/// settings may only agree once both are. False when the register is no setting or the value is
/// out of its range (the setting is dropped).
pub fn apply_setting(profile: &Profile, config: &mut Config, slots: usize, address: u8, value: u16) -> bool {
    let Some((row, index)) = find(address, slots) else {
        return false;
    };
    let is_setting = !matches!(row.address, FSENSOR | LEFT);
    let in_range = row.range().is_some_and(|(min, max)| (min..=max).contains(&value));
    if !(is_setting && in_range) {
        return false;
    }
    let mut fsensor = 0;
    write_row(
        row.handler,
        &mut Target::of_settings(profile, slots, config, &mut fsensor),
        row.address,
        index,
        value,
    )
}

/// What a register read sees of a configuration alone: setting registers read only the
/// configuration (`hub` only completes the view: the unit's own, so that no default hub is built).
pub fn settings_view<'a>(profile: &'a Profile, config: &'a Config, hub: &'a Hub, slots: usize) -> View<'a> {
    View {
        profile,
        config,
        hub,
        finda: false,
        feeders: &[],
        slots,
        lanes: &[],
        fsensor: 0,
        path_slot: None,
        driving_slot: None,
        status: Status::Finished,
        drive_errors: 0,
        tool_changes: &[],
        failures: &[],
        fed_mm: &[],
        dropped_responses: 0,
        bowden_learned_mm: 0,
        lane_figures: &[],
        used_centi: &[],
        lanes_drifted: 0,
        refused_rule: None,
        unload_stuck: None,
        build: config.version.build(),
        now: Instant::ZERO,
    }
}

/// One address of a setting register.
#[derive(Clone, Copy)]
pub struct Setting {
    row: &'static Row,
    index: usize,
}

impl Setting {
    /// Its address.
    pub fn address(&self) -> u8 {
        self.row.address.wrapping_add(self.index as u8)
    }

    /// Its value as `view` reads it.
    pub fn read(&self, view: &View) -> Option<u16> {
        self.row.read(view, self.index)
    }
}

/// Every setting register of a unit with `slots` slots (writable, held in [`Config`]; not the
/// printer's sensor state), in table order: what the persistence keeps.
pub fn settings(slots: usize) -> impl Iterator<Item = Setting> {
    REGISTERS
        .iter()
        .filter(|row| row.access() == Access::ReadWrite && !matches!(row.address, FSENSOR | LEFT))
        .flat_map(move |row| {
            let count = match row.span() {
                Span::One => 1,
                Span::Sensors => SensorId::count(slots),
                Span::Slots | Span::Lanes => slots,
            };
            (0..count).map(move |index| Setting { row, index })
        })
}

/// Every setting register ([`settings`]) whose value in `config` differs from `defaults`, in
/// table order, as many as fit `settings`.
pub fn changed_settings<const CAP: usize>(
    profile: &Profile,
    config: &Config,
    defaults: &Config,
    hub: &Hub,
    slots: usize,
    changed: &mut heapless::Vec<(u8, u16), CAP>,
) {
    // One view, its settings switched: setting registers read nothing else.
    let mut view = settings_view(profile, defaults, hub, slots);
    for setting in settings(slots) {
        view.config = defaults;
        let default = setting.read(&view);
        view.config = config;
        if let Some(value) = setting.read(&view).filter(|&v| Some(v) != default) {
            let _ = changed.push((setting.address(), value));
        }
    }
}

/// A register as tools show it: its row and what it is about.
#[derive(Clone, Copy)]
pub struct Register {
    /// The address.
    pub address: u8,
    /// The table row.
    pub row: &'static Row,
    /// The sensor or slot of a block register.
    pub subject: Option<Subject>,
}

impl fmt::Display for Register {
    /// The full name: `bowden_mm`, `raw.hub.filament`, `lane.slot1`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.row.name.as_str())?;
        match self.subject {
            Some(Subject::Sensor(sensor)) => write!(f, ".{sensor}"),
            Some(Subject::Slot(slot)) => write!(f, ".slot{slot}"),
            None => Ok(()),
        }
    }
}

/// The register at `address` on a unit with `slots` slots.
pub fn describe(address: u8, slots: usize) -> Option<Register> {
    let (row, index) = find(address, slots)?;
    let subject = match row.span() {
        Span::One => None,
        Span::Sensors => Some(Subject::Sensor(SensorId::from_index(index, slots))),
        Span::Slots | Span::Lanes => Some(Subject::Slot(index)),
    };
    Some(Register {
        address,
        row,
        subject,
    })
}

/// Every register of a unit with `slots` slots, by address.
pub fn all(slots: usize) -> impl Iterator<Item = Register> {
    (0..=u8::MAX).filter_map(move |address| describe(address, slots))
}

/// The address of the register named `name` (as [`Register`] displays it) on a unit with
/// `slots` slots.
pub fn lookup(name: &str, slots: usize) -> Option<u8> {
    all(slots)
        .find(|register| NameMatch(name).matches(register))
        .map(|r| r.address)
}

/// Compares a name with a register's display form without formatting into a buffer.
struct NameMatch<'a>(&'a str);

impl NameMatch<'_> {
    fn matches(mut self, register: &Register) -> bool {
        fmt::write(&mut self, format_args!("{register}")).is_ok() && self.0.is_empty()
    }
}

impl fmt::Write for NameMatch<'_> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        self.0 = self.0.strip_prefix(s).ok_or(fmt::Error)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::string::ToString;

    use super::*;

    /// A read walks the table from the top: a row over another's addresses would hide them.
    #[test]
    fn no_two_rows_share_an_address() {
        for address in 0..=u8::MAX {
            let rows: std::vec::Vec<_> = REGISTERS
                .iter()
                .filter(|row| row.index_of(address).is_some())
                .map(|row| row.address)
                .collect();
            assert!(rows.len() <= 1, "0x{address:02x} is in the rows at {rows:02x?}");
        }
    }

    #[test]
    fn block_registers_are_named_by_their_sensor_or_slot() {
        let name = |address| describe(address, 3).map(|r| r.to_string());
        assert_eq!(name(0x22).as_deref(), Some("bowden_mm"));
        assert_eq!(name(RAW).as_deref(), Some("raw.hub.filament"));
        assert_eq!(name(FILTERED + 1).as_deref(), Some("filtered.hub.tension"));
        assert_eq!(
            name(THRESHOLD_ON + 5).as_deref(),
            Some("threshold_on.slot1.filament")
        );
        assert_eq!(name(FILTERED + 8).as_deref(), Some("filtered.slot2.motion"));
        assert_eq!(name(LANE + 2).as_deref(), Some("lane.slot2"));
        // A 3-slot unit has twelve sensor places (nine on the thesis build, whose lanes have no
        // tension sensor of their own) and three slots.
        assert_eq!(name(FILTERED + 9).as_deref(), Some("filtered.slot0.tension"));
        assert_eq!(name(FILTERED + 11).as_deref(), Some("filtered.slot2.tension"));
        assert_eq!(name(FILTERED + 12), None);
        assert_eq!(name(LANE + 3), None);
        assert_eq!(name(0x80), None);
    }

    #[test]
    fn every_name_looks_up_its_own_address() {
        for slots in 1..=crate::MAX_SLOTS {
            for register in all(slots) {
                assert_eq!(
                    lookup(&register.to_string(), slots),
                    Some(register.address),
                    "{register}"
                );
            }
        }
        assert_eq!(lookup("bowden", 3), None);
        assert_eq!(lookup("bowden_mm.x", 3), None);
    }

    #[test]
    fn every_plain_setting_reads_and_writes_the_config_field_of_its_name() {
        let mut plain = 0;
        for address in 0..=u8::MAX {
            let Some(field) = setting_field_name(address) else {
                continue;
            };
            plain += 1;
            let row = describe(address, 3).map(|r| r.row);
            assert_eq!(row.map(|r| r.name.as_str()), Some(field), "{address:#x}");
            assert!(row.is_some_and(|r| r.access() == Access::ReadWrite));
        }
        // Every other writable register is state or has its own read and write.
        let own = [
            FSENSOR,
            REPORTED_REVISION,
            THRESHOLD_ON,
            THRESHOLD_OFF,
            SPOOL,
            LEFT,
        ];
        let writable = REGISTERS
            .iter()
            .filter(|row| row.access() == Access::ReadWrite && !own.contains(&row.address))
            .count();
        assert_eq!(writable, plain);
        // Through the registers, each changes its field and no other.
        let mut config = Config::default();
        let mut fsensor = 0;
        let mut target = Target::of_settings(&crate::profile::THESIS, 3, &mut config, &mut fsensor);
        assert_eq!(write(&mut target, 3, 0x4c, 1234), Ok(()));
        assert_eq!(write(&mut target, 3, 0x0d, 77), Ok(()));
        let expected = Config {
            tension_neutral: 1234,
            unload_speed: 77,
            ..Config::default()
        };
        assert!(config == expected);
    }

    #[test]
    fn a_read_only_register_takes_no_value() {
        let mut config = Config::default();
        let mut fsensor = 0;
        let mut target = Target::of_settings(&crate::profile::THESIS, 3, &mut config, &mut fsensor);
        let mut read_only = 0;
        for register in all(3).filter(|r| r.row.access() == Access::Read) {
            read_only += 1;
            assert_eq!(register.row.range(), None, "{register}");
            for value in [0, 1, 2, 255, 4095, u16::MAX] {
                assert!(
                    write(&mut target, 3, register.address, value).is_err(),
                    "{register} = {value}"
                );
            }
        }
        assert!(read_only > 20, "{read_only} read-only registers");
        assert!(config == Config::default());
        assert_eq!(fsensor, 0);
    }

    #[test]
    fn only_settings_are_writable_and_only_within_their_range() {
        let mut config = Config::default();
        let mut fsensor = 0;
        let mut target = Target::of_settings(&crate::profile::THESIS, 3, &mut config, &mut fsensor);
        assert_eq!(write(&mut target, 3, 0x22, 410), Ok(()));
        assert_eq!(write(&mut target, 3, 0x22, 49), Err(Refused::OutOfRange));
        assert_eq!(write(&mut target, 3, 0x40, 3), Err(Refused::ReadOnly));
        assert_eq!(write(&mut target, 3, 0x80, 3), Err(Refused::Unknown));
        assert_eq!(
            write(&mut target, 3, THRESHOLD_ON + 12, 3000),
            Err(Refused::Unknown)
        );
        // The hub tension sensor has no thresholds, nor does a lane's (index 9 of three slots).
        assert_eq!(
            write(&mut target, 3, THRESHOLD_ON + 9, 3000),
            Err(Refused::OutOfRange)
        );
        assert_eq!(
            write(&mut target, 3, THRESHOLD_ON + 1, 3000),
            Err(Refused::OutOfRange)
        );
        assert_eq!(write(&mut target, 3, 0x09, 1), Ok(()));
        assert_eq!(config.bowden_mm, 410);
        assert_eq!(fsensor, 1);
    }

    /// A write the guards refuse answers with the rule it would break; a pair whose two halves
    /// must move together is written in the order that keeps every rule on the way.
    #[test]
    fn a_write_that_would_break_a_rule_is_refused_and_changes_nothing() {
        let mut config = Config::default();
        let mut fsensor = 0;
        let mut target = Target::of_settings(&crate::profile::THESIS, 3, &mut config, &mut fsensor);
        let broke = |rule| Err(Refused::Broke(rule));
        // The "on" threshold must stay above the "off" one.
        assert_eq!(
            write(&mut target, 3, THRESHOLD_ON, 2000),
            broke(Rule::ThresholdsOrdered)
        );
        assert_eq!(
            write(&mut target, 3, THRESHOLD_ON, 4095),
            broke(Rule::ThresholdsWithinRails)
        );
        assert_eq!(write(&mut target, 3, 0x41, 1), broke(Rule::ParkClearsMerge));
        assert_eq!(
            write(&mut target, 3, 0x42, 5000),
            broke(Rule::RevolutionFitsDrive)
        );
        assert_eq!(write(&mut target, 3, 0x4d, 0), broke(Rule::DeadBandAboveNoise));
        // `stall_min_duty` must stay at or below `max_duty` (the stall rule stays on).
        assert_eq!(write(&mut target, 3, 0x44, 700), Ok(()));
        assert_eq!(write(&mut target, 3, 0x43, 699), broke(Rule::StallDutyWithinMax));
        assert_eq!(write(&mut target, 3, 0x43, 700), Ok(()));
        assert_eq!(write(&mut target, 3, 0x44, 701), broke(Rule::StallDutyWithinMax));
        // A longer park needs the hub search first.
        assert_eq!(write(&mut target, 3, 0x41, 60), broke(Rule::HubSearchReachesHub));
        assert_eq!(write(&mut target, 3, 0x47, 64), Ok(()));
        assert_eq!(write(&mut target, 3, 0x41, 60), Ok(()));
        let expected = Config {
            max_duty: 700,
            stall_min_duty: 700,
            hub_search_mm: 64,
            park_mm: 60,
            ..Config::default()
        };
        assert!(config == expected, "{config:?}");
    }

    /// Every setting register, written with values across its range: whatever is taken leaves a
    /// configuration that keeps every rule, and whatever is refused changes nothing.
    #[test]
    fn no_write_leaves_settings_the_guards_refuse() {
        let mut config = Config::default();
        let mut fsensor = 0;
        let mut used = [0i32; 3];
        let mut taken = 0;
        let mut refused = 0;
        for register in all(3).filter(|r| r.row.access() == Access::ReadWrite) {
            let Some((min, max)) = register.row.range() else {
                continue;
            };
            let span = u32::from(max - min);
            for step in 0..=16u32 {
                let value = min + (span * step / 16) as u16;
                let before = config.clone();
                let mut target = Target {
                    used_centi: &mut used,
                    ..Target::of_settings(&crate::profile::THESIS, 3, &mut config, &mut fsensor)
                };
                match write(&mut target, 3, register.address, value) {
                    Ok(()) => taken += 1,
                    Err(why) => {
                        refused += 1;
                        assert!(
                            config == before,
                            "{register} = {value} refused ({why:?}) but changed"
                        );
                    }
                }
                assert_eq!(
                    guards::check(&config, &NO_FILAMENT_READINGS),
                    Ok(()),
                    "after {register} = {value}"
                );
            }
        }
        assert!(taken > 100 && refused > 100, "{taken} taken, {refused} refused");
    }

    /// A stored setting goes in with its register's own checks only: the guards judge the whole.
    #[test]
    fn a_stored_setting_is_applied_within_its_range_and_state_is_no_setting() {
        let mut config = Config::default();
        assert!(apply_setting(&crate::profile::THESIS, &mut config, 3, 0x41, 1));
        assert_eq!(config.park_mm, 1);
        assert!(!apply_setting(&crate::profile::THESIS, &mut config, 3, 0x41, 201));
        assert!(!apply_setting(
            &crate::profile::THESIS,
            &mut config,
            3,
            FSENSOR,
            1
        ));
        assert!(!apply_setting(&crate::profile::THESIS, &mut config, 3, LEFT, 1));
        assert!(!apply_setting(&crate::profile::THESIS, &mut config, 3, 0x40, 1));
        assert!(!apply_setting(
            &crate::profile::THESIS,
            &mut config,
            3,
            SPOOL + 3,
            100
        ));
        assert!(apply_setting(
            &crate::profile::THESIS,
            &mut config,
            3,
            SPOOL + 2,
            100
        ));
        assert_eq!(config.spool_m[2], 100);
    }

    #[test]
    fn a_threshold_that_would_not_see_the_filament_seen_now_is_refused() {
        let mut config = Config::default();
        let mut fsensor = 0;
        let mut filament_readings = NO_FILAMENT_READINGS;
        // The hub sensor reads 3,000 with filament; slot 1's (index 2) 2,800.
        filament_readings[0] = Some(3000);
        filament_readings[2] = Some(2800);
        let mut target = Target {
            filament_readings,
            ..Target::of_settings(&crate::profile::THESIS, 3, &mut config, &mut fsensor)
        };
        let seen = Err(Refused::Broke(Rule::OnAtFilamentSeen));
        for on in [3001, 3072, 3902] {
            assert_eq!(write(&mut target, 3, THRESHOLD_ON, on), seen, "{on}");
        }
        assert_eq!(write(&mut target, 3, THRESHOLD_ON + 5, 2801), seen);
        // At the reading, or what a calibration writes: taken.
        assert_eq!(write(&mut target, 3, THRESHOLD_ON, 3000), Ok(()));
        assert_eq!(write(&mut target, 3, THRESHOLD_ON, 2619), Ok(()));
        assert_eq!(write(&mut target, 3, THRESHOLD_ON + 5, 2500), Ok(()));
        // Slot 0 (index 1) sees no filament the unit knows of: nothing to hold a write to.
        assert_eq!(write(&mut target, 3, THRESHOLD_ON + 3, 3500), Ok(()));
        // "off" only ever lowers what is seen as filament: the pair stays valid, so taken.
        assert_eq!(write(&mut target, 3, THRESHOLD_OFF, 100), Ok(()));
        assert_eq!((config.hub_thresholds.on, config.hub_thresholds.off), (2619, 100));
    }
}
