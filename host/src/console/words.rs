//! What the unit says, in words a person at the bench understands: finished commands, lane
//! states, the printer's sensor, register values.

use mmu_protocol::{Request, RequestCode};

use crate::explain::request_label;

/// What a finished command did, in words.
pub fn done_text(request: &Request) -> String {
    let slot = request.value;
    match request.code {
        RequestCode::Tool => format!("slot {slot} is loaded: its filament is in the printer's extruder"),
        RequestCode::Load => {
            format!("slot {slot} is preloaded: its filament waits at the park position before the hub")
        }
        RequestCode::Unload => {
            "unloaded: the filament is back at its park position, the printer's path is free".into()
        }
        RequestCode::Eject => format!("slot {slot} is ejected: its filament is out of the unit's drive"),
        RequestCode::Cut => format!("slot {slot}: fed to the hub and parked again (this unit has no cutter)"),
        RequestCode::Home => {
            "the sensors are healthy and agree with where the unit knows the filament".into()
        }
        _ => format!("{} finished", request_label(request)),
    }
}

/// A lane register's value (MMU3 filament state) in words.
pub fn lane_text(lane: u16) -> &'static str {
    match lane {
        0 => "empty, or not known yet",
        1 => "parked before the hub",
        2 => "in the hub or the Bowden tube",
        4 => "at the printer's filament sensor",
        8 => "loaded in the printer's extruder",
        _ => "in an unknown state",
    }
}

/// The printer's filament sensor state in words.
pub fn fsensor_text(state: u8) -> &'static str {
    match state {
        0 => "no filament",
        1 => "filament at the sensor",
        2 => "filament in the nozzle",
        _ => "unavailable",
    }
}

/// Why `name` names no register.
pub fn unknown_register(name: &str) -> String {
    format!("no register named {name:?}: tab completes the names, or give an address such as 0x22")
}

/// A note on a register value where the number alone says little.
pub fn value_note(address: u8, value: u16) -> String {
    match address {
        0x08 => format!(
            " ({})",
            if value != 0 {
                "filament present"
            } else {
                "no filament"
            }
        ),
        0x09 => format!(" ({})", fsensor_text(u8::try_from(value).unwrap_or(u8::MAX))),
        0xb8..=0xbf => format!(" ({})", lane_text(value)),
        0xb0..=0xb7 => format!(" ({} mm)", value as i16),
        _ => String::new(),
    }
}
