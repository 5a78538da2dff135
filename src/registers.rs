//! The register map read by `R`/`S` and written by `W`.
//!
//! `0x00`-`0x22` follow the MMU3 map where a register means something on this hardware (the
//! others answer `R`). The unit's own settings and diagnostics live from `0x40`; `0x80`-`0x82`
//! stay free because the MK4 intercepts them printer-side. Writes are validated: an unknown or
//! read-only register, or a value out of range, answers `R` and changes nothing.

use mmu_protocol::ErrorCode;

use crate::app::App;
use crate::config::Config;
use crate::ops::Status;
use crate::persist::MAX_SETTINGS;
use crate::sensor::Thresholds;
use crate::unit::{SensorId, Unit};

/// Extension: number of slots (read only).
pub const SLOT_COUNT: u8 = 0x40;
/// Extension: bitmask of sensors stuck at a rail, bit = diagnostic sensor index (read only).
pub const SENSOR_FAULTS: u8 = 0x50;
/// Extension: responses dropped because a step's transmit buffer was full (read only).
pub const DROPPED_RESPONSES: u8 = 0x51;
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

/// Sensor diagnostic blocks hold up to 16 sensors (3 hub + 2 per slot, at most 13).
const SENSOR_BLOCK: u8 = 16;
/// Per-slot blocks hold up to 8 slots.
const SLOT_BLOCK: u8 = 8;

/// A plain setting: where it lives in [`Config`] and the values it accepts.
struct Setting {
    address: u8,
    min: u16,
    max: u16,
    get: fn(&Config) -> u16,
    set: fn(&mut Config, u16),
}

macro_rules! setting {
    ($address:literal, $min:literal..=$max:literal, $field:ident) => {
        Setting {
            address: $address,
            min: $min,
            max: $max,
            get: |c| c.$field,
            set: |c, v| c.$field = v,
        }
    };
}

/// Every writable plain setting, MMU3 registers first.
const SETTINGS: &[Setting] = &[
    setting!(0x0b, 0..=255, extra_load_mm),
    setting!(0x0c, 0..=255, unload_check_mm),
    setting!(0x0d, 1..=1000, unload_speed),
    setting!(0x11, 1..=1000, load_speed),
    setting!(0x14, 1..=1000, slow_speed),
    setting!(0x22, 50..=2000, bowden_mm),
    setting!(0x41, 1..=200, park_mm),
    setting!(0x42, 10..=5000, mm_per_rev_centi),
    setting!(0x43, 100..=1000, max_duty),
    setting!(0x44, 0..=1000, stall_min_duty),
    setting!(0x45, 50..=10000, stall_timeout_ms),
    setting!(0x46, 10..=2000, preload_max_mm),
    setting!(0x47, 5..=500, hub_search_mm),
    setting!(0x48, 10..=2000, fsensor_search_mm),
    setting!(0x49, 10..=2000, eject_max_mm),
    setting!(0x4a, 0..=500, bowden_slowdown_mm),
    setting!(0x4b, 10..=2000, full_duty_speed),
    setting!(0x4c, 0..=4095, tension_neutral),
    setting!(0x4d, 0..=2000, tension_deadband),
    setting!(0x4e, 0..=100, tension_gain),
    setting!(0x4f, 0..=1000, tension_max_duty),
    // The revision `S2` reports: 3 for Buddy firmware (MK4, MK3.5, Core One), 2 for MK3S firmware.
    Setting {
        address: 0x52,
        min: 0,
        max: 255,
        get: |c| c.version.revision.into(),
        set: |c, v| c.version.revision = v as u8,
    },
];

fn setting(address: u8) -> Option<&'static Setting> {
    SETTINGS.iter().find(|s| s.address == address)
}

/// The thresholds of a sensor, if it has any.
fn thresholds(config: &Config, sensor: SensorId) -> Option<Thresholds> {
    match sensor {
        SensorId::HubFilament => Some(config.hub_thresholds),
        SensorId::SlotFilament(slot) => config.slot_thresholds.get(slot).copied(),
        SensorId::MotorHall(slot) => config.motor_thresholds.get(slot).copied(),
        SensorId::HubTension | SensorId::HubCutter => None,
    }
}

/// The thresholds of a sensor, to change them.
fn thresholds_mut(config: &mut Config, sensor: SensorId) -> Option<&mut Thresholds> {
    match sensor {
        SensorId::HubFilament => Some(&mut config.hub_thresholds),
        SensorId::SlotFilament(slot) => config.slot_thresholds.get_mut(slot),
        SensorId::MotorHall(slot) => config.motor_thresholds.get_mut(slot),
        SensorId::HubTension | SensorId::HubCutter => None,
    }
}

/// The sensor whose threshold register `address` is, and whether it is the "on" threshold.
fn threshold_at<const N: usize>(address: u8) -> Option<(SensorId, bool)> {
    match (
        sensor_at::<N>(address, THRESHOLD_ON),
        sensor_at::<N>(address, THRESHOLD_OFF),
    ) {
        (Some(sensor), _) => Some((sensor, true)),
        (None, Some(sensor)) => Some((sensor, false)),
        (None, None) => None,
    }
}

/// The value of writable setting `address` in `config`: a plain setting or a threshold.
fn setting_value<const N: usize>(config: &Config, address: u8) -> Option<u16> {
    if let Some(setting) = setting(address) {
        return Some((setting.get)(config));
    }
    let (sensor, on) = threshold_at::<N>(address)?;
    let thresholds = thresholds(config, sensor)?;
    Some(if on { thresholds.on } else { thresholds.off })
}

/// A diagnostic block offset: `address - base` when it names one of the unit's sensors.
fn sensor_at<const N: usize>(address: u8, base: u8) -> Option<SensorId> {
    let index = address.checked_sub(base).filter(|&i| i < SENSOR_BLOCK)?;
    let index = usize::from(index);
    (index < Unit::<N>::SENSOR_COUNT).then(|| SensorId::from_index(index))
}

/// A per-slot block offset: `address - base` when it names one of the unit's slots.
fn slot_at<const N: usize>(address: u8, base: u8) -> Option<usize> {
    let slot = usize::from(address.checked_sub(base).filter(|&i| i < SLOT_BLOCK)?);
    (slot < N).then_some(slot)
}

impl<const N: usize> App<N> {
    /// The value of register `address`, or `None` when the unit has no such register.
    pub fn read_register(&self, address: u8) -> Option<u16> {
        let config = &self.config;
        let unit = &self.unit;
        if let Some(value) = setting_value::<N>(config, address) {
            return Some(value);
        }
        let value = match address {
            0x00 => config.version.major.into(),
            0x01 => config.version.minor.into(),
            0x02 => config.version.revision.into(),
            0x03 => config.version.build,
            0x04 => self.counters.drive_errors,
            0x05 => match self.operation.status() {
                Status::Running(progress) => progress.0.into(),
                Status::Failed(_) => mmu_protocol::ProgressCode::ERR_WAITING_FOR_USER.0.into(),
                Status::Finished => 0,
            },
            0x06 => match self.operation.status() {
                Status::Failed(error) => error.0,
                Status::Running(_) => ErrorCode::RUNNING.0,
                Status::Finished => ErrorCode::OK.0,
            },
            0x07 => unit
                .active()
                .or(unit.selected)
                .map_or(0, |slot| unit.lane(slot).mmu3_state()),
            0x08 => unit.hub_present().unwrap_or(false).into(),
            0x09 => unit.fsensor_triggered().into(),
            0x0a => 0,
            0x1a => unit
                .active()
                .or(unit.selected)
                .and_then(|slot| unit.feeders.get(slot))
                .map_or(0, |f| f.odometry_mm().clamp(0, i32::from(u16::MAX)) as u16),
            0x1b => unit.active().or(unit.selected).map_or(5, |slot| slot as u16),
            0x1c => self.operation.driving_slot().map_or(5, |slot| slot as u16),
            SLOT_COUNT => N as u16,
            SENSOR_FAULTS => (0..Unit::<N>::SENSOR_COUNT)
                .filter(|&i| {
                    unit.sensor(SensorId::from_index(i))
                        .is_some_and(|s| s.fault().is_some())
                })
                .fold(0u16, |mask, i| mask | (1 << i)),
            DROPPED_RESPONSES => self.dropped_responses,
            a if sensor_at::<N>(a, RAW).is_some() => unit.sensor(sensor_at::<N>(a, RAW)?)?.raw(),
            a if sensor_at::<N>(a, FILTERED).is_some() => {
                unit.sensor(sensor_at::<N>(a, FILTERED)?)?.filtered()
            }
            a if slot_at::<N>(a, ODOMETRY).is_some() => {
                unit.feeders.get(slot_at::<N>(a, ODOMETRY)?)?.odometry_mm() as i16 as u16
            }
            a if slot_at::<N>(a, LANE).is_some() => unit.lane(slot_at::<N>(a, LANE)?).mmu3_state(),
            a if slot_at::<N>(a, TOOL_CHANGES).is_some() => {
                *self.counters.tool_changes.get(slot_at::<N>(a, TOOL_CHANGES)?)?
            }
            a if slot_at::<N>(a, SPEED).is_some() => unit
                .feeders
                .get(slot_at::<N>(a, SPEED)?)?
                .speed_mm_s(self.now, config),
            a if slot_at::<N>(a, FAILURES).is_some() => {
                *self.counters.failures.get(slot_at::<N>(a, FAILURES)?)?
            }
            a if slot_at::<N>(a, FED_METRES).is_some() => {
                let mm = *self.counters.fed_mm.get(slot_at::<N>(a, FED_METRES)?)?;
                u16::try_from(mm / 1000).unwrap_or(u16::MAX)
            }
            _ => return None,
        };
        Some(value)
    }

    /// Every writable setting that differs from its default, and its value: the plain settings,
    /// then the sensors' thresholds.
    pub(crate) fn settings(&self) -> heapless::Vec<(u8, u16), MAX_SETTINGS> {
        let defaults = Config::default();
        let threshold_registers =
            (0..Unit::<N>::SENSOR_COUNT as u8).flat_map(|i| [THRESHOLD_ON + i, THRESHOLD_OFF + i]);
        let mut settings = heapless::Vec::new();
        for address in SETTINGS.iter().map(|s| s.address).chain(threshold_registers) {
            let value = setting_value::<N>(&self.config, address);
            // Only what differs from the defaults: a later firmware's defaults then apply.
            if let Some(value) = value.filter(|&v| Some(v) != setting_value::<N>(&defaults, address)) {
                // MAX_SETTINGS holds every setting of a 5-slot unit.
                let _ = settings.push((address, value));
            }
        }
        settings
    }

    /// Write `value` to register `address`; false (answered `R`) when the register is unknown or
    /// read-only or the value is out of range.
    pub fn write_register(&mut self, address: u8, value: u16) -> bool {
        if let Some(setting) = setting(address) {
            if !(setting.min..=setting.max).contains(&value) {
                return false;
            }
            (setting.set)(&mut self.config, value);
            return true;
        }
        if address == 0x09 {
            // The Core One reports its filament sensor this way instead of `f`.
            return match u8::try_from(value) {
                Ok(state) => {
                    self.unit.fsensor = state;
                    true
                }
                Err(_) => false,
            };
        }
        let Some((sensor, on)) = threshold_at::<N>(address) else {
            return false;
        };
        let Some(thresholds) = thresholds_mut(&mut self.config, sensor) else {
            return false;
        };
        let updated = if on {
            Thresholds {
                on: value,
                ..*thresholds
            }
        } else {
            Thresholds {
                off: value,
                ..*thresholds
            }
        };
        if !updated.is_valid() {
            return false;
        }
        *thresholds = updated;
        true
    }
}
