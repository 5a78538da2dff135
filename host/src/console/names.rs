//! Register names the console accepts, until the firmware's register table
//! (`mmu_firmware::registers::lookup`) lands: a handful of names for the bench's own settings and
//! sensors. Addresses and numbers are always accepted too.

/// Names of the bench's registers (a slot's or sensor's number is part of the name).
const NAMES: &[(&str, u8)] = &[
    ("hub.filament", 0x08),
    ("fsensor", 0x09),
    ("extra_load_mm", 0x0b),
    ("bowden", 0x22),
    ("bowden_mm", 0x22),
    ("slots", 0x40),
    ("park", 0x41),
    ("park_mm", 0x41),
    ("mm_per_rev", 0x42),
    ("mm_per_rev_centi", 0x42),
    ("raw.hub.filament", 0x60),
    ("filtered.hub.filament", 0x70),
    ("on.hub.filament", 0x90),
    ("off.hub.filament", 0xa0),
];

/// Per-slot names, `NAME.slotK` → `BASE + K`.
const SLOT_NAMES: &[(&str, u8)] = &[("odometry", 0xb0), ("lane", 0xb8)];

/// Per-sensor names of a slot's filament sensor, `NAME.slotK.filament` → `BASE + 3 + 2K`.
const SLOT_SENSOR_NAMES: &[(&str, u8)] = &[("raw", 0x60), ("filtered", 0x70), ("on", 0x90), ("off", 0xa0)];

/// The address a register name or number (decimal or `0x` hex) stands for.
pub fn resolve(text: &str) -> Option<u8> {
    if let Ok(address) = crate::codec_cli::parse_u8(text) {
        return Some(address);
    }
    let text = text.to_ascii_lowercase();
    if let Some(&(_, address)) = NAMES.iter().find(|(name, _)| *name == text) {
        return Some(address);
    }
    let (prefix, rest) = text.split_once('.')?;
    let (slot_part, sensor) = match rest.split_once('.') {
        Some((slot_part, sensor)) => (slot_part, Some(sensor)),
        None => (rest, None),
    };
    let slot: u8 = slot_part.strip_prefix("slot")?.parse().ok().filter(|&k| k < 8)?;
    let table = match sensor {
        None => SLOT_NAMES,
        Some("filament") => SLOT_SENSOR_NAMES,
        Some(_) => return None,
    };
    let &(_, base) = table.iter().find(|(name, _)| *name == prefix)?;
    Some(match sensor {
        None => base + slot,
        Some(_) => base + 3 + 2 * slot,
    })
}

/// A name of register `address`, if it has one here.
pub fn name(address: u8) -> Option<String> {
    if let Some(&(name, _)) = NAMES.iter().find(|&&(_, a)| a == address) {
        return Some(name.to_string());
    }
    (0..8u8).find_map(|slot| {
        let slot_name = SLOT_NAMES
            .iter()
            .find(|&&(_, base)| base + slot == address)
            .map(|(name, _)| format!("{name}.slot{slot}"));
        slot_name.or_else(|| {
            SLOT_SENSOR_NAMES
                .iter()
                .find(|&&(_, base)| base + 3 + 2 * slot == address)
                .map(|(name, _)| format!("{name}.slot{slot}.filament"))
        })
    })
}

/// Every name, for tab completion (slot names for slots 0..`slots`).
pub fn all(slots: u8) -> Vec<String> {
    let mut names: Vec<String> = NAMES.iter().map(|(name, _)| name.to_string()).collect();
    for slot in 0..slots {
        names.extend(SLOT_NAMES.iter().map(|(name, _)| format!("{name}.slot{slot}")));
        names.extend(
            SLOT_SENSOR_NAMES
                .iter()
                .map(|(name, _)| format!("{name}.slot{slot}.filament")),
        );
    }
    names
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_numbers() {
        assert_eq!(resolve("0x22"), Some(0x22));
        assert_eq!(resolve("34"), Some(0x22));
        assert_eq!(resolve("bowden"), Some(0x22));
        assert_eq!(resolve("hub.filament"), Some(0x08));
        assert_eq!(resolve("lane.slot2"), Some(0xba));
        assert_eq!(resolve("filtered.slot1.filament"), Some(0x75));
        assert_eq!(resolve("on.slot0.filament"), Some(0x93));
        assert_eq!(resolve("lane.slot9"), None);
        assert_eq!(resolve("nonsense"), None);
        assert!(all(3).iter().all(|name| resolve(name).is_some()));
    }
}
