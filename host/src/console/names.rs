//! Register names as a person types them: the firmware's register table
//! ([`mmu_firmware::registers`]) by name or address, plus two shorthands: a name without its unit
//! (`bowden` for `bowden_mm`, `mm_per_rev` for `mm_per_rev_centi`), and a sensor's or slot's own
//! name (`hub.filament`, `slot1.filament`, `slot0`) for every register about it.

use mmu_firmware::registers::{self, Register};

/// Unit suffixes a person may leave out.
const UNITS: &[&str] = &["_mm", "_centi", "_ms"];

/// The address of the one register `text` names (a table name, a name without its unit, or a
/// number in decimal or `0x` hex) on a unit with `slots` slots.
pub fn resolve(text: &str, slots: u8) -> Option<u8> {
    if let Ok(address) = crate::codec_cli::parse_u8(text) {
        return Some(address);
    }
    let text = text.to_ascii_lowercase();
    let slots = usize::from(slots);
    registers::lookup(&text, slots).or_else(|| {
        UNITS
            .iter()
            .find_map(|unit| registers::lookup(&format!("{text}{unit}"), slots))
    })
}

/// The registers `text` names: one register, or every register about the sensor or slot it
/// names (`hub.filament`: raw, filtered, thresholds), in address order.
pub fn resolve_all(text: &str, slots: u8) -> Vec<u8> {
    if let Some(address) = resolve(text, slots) {
        return vec![address];
    }
    let suffix = format!(".{}", text.to_ascii_lowercase());
    registers::all(usize::from(slots))
        .filter(|register| register.subject.is_some() && register.to_string().ends_with(&suffix))
        .map(|register| register.address)
        .collect()
}

/// The table's name of register `address`.
pub fn name(address: u8, slots: u8) -> Option<String> {
    registers::describe(address, usize::from(slots)).map(|register| register.to_string())
}

/// Whether register `address` can be written.
pub fn writable(address: u8, slots: u8) -> Option<bool> {
    registers::describe(address, usize::from(slots))
        .map(|register| register.row.access() == registers::Access::ReadWrite)
}

/// Every name, for tab completion: the table's and the sensors' and slots' own.
pub fn all(slots: u8) -> Vec<String> {
    let mut names: Vec<String> = registers::all(usize::from(slots))
        .map(|register: Register| register.to_string())
        .collect();
    let subjects: Vec<String> = names
        .iter()
        .filter_map(|name| name.split_once('.').map(|(_, subject)| subject.to_string()))
        .filter(|subject| subject.starts_with("slot") || subject.starts_with("hub."))
        .collect();
    for subject in subjects {
        if !names.contains(&subject) {
            names.push(subject);
        }
    }
    names
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_numbers() {
        assert_eq!(resolve("0x22", 3), Some(0x22));
        assert_eq!(resolve("34", 3), Some(0x22));
        assert_eq!(resolve("bowden_mm", 3), Some(0x22));
        assert_eq!(resolve("bowden", 3), Some(0x22));
        assert_eq!(resolve("mm_per_rev", 3), Some(0x42));
        assert_eq!(resolve("lane.slot2", 3), Some(0xba));
        assert_eq!(resolve("lane.slot3", 3), None, "a 3-slot unit has no slot 3");
        assert_eq!(resolve("filtered.slot1.filament", 3), Some(0x75));
        assert_eq!(resolve("nonsense", 3), None);
        assert_eq!(name(0x22, 3).as_deref(), Some("bowden_mm"));
        assert_eq!(writable(0x22, 3), Some(true));
        assert_eq!(writable(0x70, 3), Some(false));
    }

    #[test]
    fn a_sensor_s_name_reads_all_its_registers() {
        assert_eq!(resolve_all("hub.filament", 3), [0x60, 0x70, 0x90, 0xa0]);
        assert_eq!(resolve_all("bowden", 3), [0x22]);
        assert!(resolve_all("slot1", 3).contains(&0xb9));
        assert!(resolve_all("nonsense", 3).is_empty());
        for name in all(3) {
            assert!(!resolve_all(&name, 3).is_empty(), "{name}");
        }
    }
}
