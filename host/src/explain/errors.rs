//! What each error the unit raises means on this hardware, and what to check, in the words of
//! this unit's parts (hub filament sensor, slot motor and its Hall sensor, slot sensor, Bowden
//! tube, the printer's filament sensor) rather than the MMU3's (FINDA, pulley, selector, idler).
//! The code names stay Prusa's: they are what the printer shows. The book's error table says
//! the same.

use mmu_protocol::ErrorCode;

/// An error explained for a person at the bench.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ErrorHelp {
    /// What happened, on this unit.
    pub meaning: &'static str,
    /// What to look at before pressing Retry.
    pub check: &'static str,
}

const fn help(meaning: &'static str, check: &'static str) -> ErrorHelp {
    ErrorHelp { meaning, check }
}

/// The explanation of `error`. Codes this unit never raises (MMU3 parts it does not have) say so.
pub fn error_help(error: ErrorCode) -> ErrorHelp {
    match error {
        ErrorCode::FINDA_DIDNT_SWITCH_ON => help(
            "the hub filament sensor did not see the filament arrive within the hub search distance (register 0x47)",
            "the slot's spool has filament and its tip reaches the slot's drive gear; nothing blocks the path from the slot to the hub; the hub filament sensor with `mmu sensors` (with filament in the hub its filtered value must rise above its \"on\" threshold, register 0x90)",
        ),
        ErrorCode::FINDA_DIDNT_SWITCH_OFF => help(
            "the hub filament sensor still sees filament after the slot motor pulled it back the unload or park distance",
            "a broken-off tip or a blob left in the hub; that the slot motor turns backwards; the hub filament sensor with `mmu sensors` (with the hub empty its filtered value must fall below its \"off\" threshold, register 0xa0)",
        ),
        ErrorCode::FSENSOR_DIDNT_SWITCH_ON => help(
            "the printer's filament sensor did not trigger within the search distance past the Bowden tube (register 0x48), or the filament stopped on its way there (a jam in the Bowden tube, or the tip pressed into the printer's idle extruder)",
            "the Bowden tube is seated at both ends and nothing blocks it; the filament is not caught at its printer end; the Bowden length (register 0x22) matches the real tube; the printer's filament sensor works and the printer reports it (`f`, or register 0x09)",
        ),
        ErrorCode::FSENSOR_DIDNT_SWITCH_OFF => help(
            "the printer's filament sensor still reads filament: the unit felt the filament held still in the extruder for 4 s, or pulled it back freely the check distance (register 0x0c) and the sensor did not clear (register 0xfc says which)",
            "filament stuck in the extruder (a blob on the tip, a cold nozzle); the printer's filament sensor is not stuck on; the check distance is not shorter than the path from the extruder gears to the sensor",
        ),
        ErrorCode::FILAMENT_ALREADY_LOADED => help(
            "a preload was asked for while a slot is loaded",
            "unload first (`U0`, or the printer's Unload), then preload",
        ),
        ErrorCode::INVALID_TOOL => help(
            "the request names a slot this unit does not have (register 0x40 holds how many it has)",
            "the slicer profile: one made for a 5-slot MMU3 sends T3 and T4 to a 3-slot unit; set the printer profile's number of extruders to this unit's slot count and slice again; on the printer, Stop print (the unit is ready for the next print at once)",
        ),
        ErrorCode::FINDA_VS_EEPROM_DISREPANCY => help(
            "what the unit remembers (or knows) about the lanes and what the hub filament sensor sees disagree: filament in the hub that no slot owns, or none where a slot should be",
            "pull the filament out of the hub by hand or push it back to its park position, then press Retry; if the hub is empty, check the hub filament sensor with `mmu sensors`",
        ),
        ErrorCode::FSENSOR_TOO_EARLY => help(
            "the printer's filament sensor triggered during the fast feed through the Bowden tube, before the filament could be there",
            "the Bowden length (register 0x22) is not longer than the real tube; no filament is left in the printer's path; the printer's filament sensor is not stuck on",
        ),
        ErrorCode::FINDA_FLICKERS => help(
            "a hub sensor (filament, tension or cutter) reads a supply rail (40 counts or less, or 4055 or more): it is unplugged, broken or shorted",
            "the hub sensors' cables and connectors; `mmu sensors` shows which raw reading sits at 0 or 4095 (register 0x50 has one bit per stuck sensor)",
        ),
        ErrorCode::FILAMENT_EJECTED => help(
            "the slot's filament was pulled out past its slot sensor (not a fault: the unit waits for the user)",
            "take the filament out of the slot, then press Continue",
        ),
        ErrorCode::STALLED_PULLEY => help(
            "a slot motor is driven but does not turn: its motor Hall sensor saw no revolution for the stall timeout (register 0x45) at the stall duty (register 0x44) or more",
            "the slot's filament for a tangle on the spool or a jam between the spool and the hub; the slot motor's wires and driver; its motor Hall sensor with `mmu sensors` (its reading must swing across its thresholds while the motor turns)",
        ),
        ErrorCode::MOVE_PULLEY_FAILED => help(
            "a slot's motor Hall sensor or slot sensor reads a supply rail, or the slot motor turns without moving the filament as far as it should",
            "the slot sensor's and motor Hall sensor's cables (`mmu sensors`: a raw reading at 0 or 4095 is a broken wire); that the drive gear grips the filament; the filament per motor revolution (register 0x42)",
        ),
        ErrorCode::INTERNAL => help(
            "the firmware reached a state it should never reach",
            "nothing on the hardware: report it with the serial log (`mmu decode` explains it) and the unit's `mmu printer ... status`",
        ),
        ErrorCode::VERSION_MISMATCH => help(
            "the unit reports a firmware version the printer does not support",
            "the revision the unit reports (register 0x52: 3 for MK4, MK3.5 and Core One, 2 for MK3S)",
        ),
        ErrorCode::PROTOCOL_ERROR => help(
            "the printer receives garbled answers",
            "the serial wiring (TX to RX, RX to TX, a common ground, 3.3 V levels), 115200 baud, and noise from motor wires running along the serial cable",
        ),
        ErrorCode::MMU_NOT_RESPONDING => help(
            "the unit does not answer",
            "the unit's power; the serial wiring (the protocol is on USART1, PB6 TX and PB7 RX, on a NUCLEO (UART0, GP0 TX and GP1 RX, on a Pico), not on the ST-LINK's USB port); TX and RX not swapped; a common ground",
        ),
        _ => help(
            "an MMU3 error for a part this unit does not have (selector, idler, stepper drivers) or for the printer's side: this unit never raises it",
            "that the unit on the port runs this firmware",
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every error the firmware raises (kept equal to what `src/` names by a test below).
    const RAISED: [ErrorCode; 13] = [
        ErrorCode::FINDA_DIDNT_SWITCH_ON,
        ErrorCode::FINDA_DIDNT_SWITCH_OFF,
        ErrorCode::FSENSOR_DIDNT_SWITCH_ON,
        ErrorCode::FSENSOR_DIDNT_SWITCH_OFF,
        ErrorCode::FILAMENT_ALREADY_LOADED,
        ErrorCode::INVALID_TOOL,
        ErrorCode::FINDA_VS_EEPROM_DISREPANCY,
        ErrorCode::FSENSOR_TOO_EARLY,
        ErrorCode::FINDA_FLICKERS,
        ErrorCode::FILAMENT_EJECTED,
        ErrorCode::STALLED_PULLEY,
        ErrorCode::MOVE_PULLEY_FAILED,
        ErrorCode::INTERNAL,
    ];

    /// Every error the firmware raises has its own explanation, in this unit's words.
    #[test]
    fn every_raised_error_is_explained_in_this_units_words() {
        let fallback = error_help(ErrorCode::HOMING_SELECTOR_FAILED);
        for error in RAISED {
            let help = error_help(error);
            assert_ne!(help, fallback, "{error} is not explained");
            for words in [help.meaning, help.check] {
                let lower = words.to_lowercase();
                for mmu3 in ["finda", "pulley", "bondtech", "selector", "idler"] {
                    assert!(!lower.contains(mmu3), "{error}: {mmu3} in {words:?}");
                }
            }
        }
    }

    /// The book's error table (`book/src/errors.md`) says what `mmu` says: each raised error's
    /// "what to check".
    #[test]
    fn the_book_s_error_table_says_the_same() {
        let table = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../book/src/errors.md"))
            .expect("the book's error chapter is readable");
        for error in RAISED {
            let row = table
                .lines()
                .find(|line| line.starts_with(&format!("| `{:04x}` {error} |", error.0)))
                .unwrap_or_else(|| panic!("no row for {error} in book/src/errors.md"));
            assert!(row.contains(error_help(error).check), "{error}: {row}");
        }
    }

    /// A new error raised in the firmware must be explained here (and in the book's error table).
    #[test]
    fn every_error_the_firmware_names_is_in_the_list() {
        fn sources(dir: &std::path::Path, into: &mut String) {
            for entry in std::fs::read_dir(dir).expect("src/ is readable").flatten() {
                let path = entry.path();
                if path.is_dir() {
                    sources(&path, into);
                } else if path.extension().is_some_and(|e| e == "rs") {
                    into.push_str(&std::fs::read_to_string(&path).expect("a source file"));
                }
            }
        }
        let mut text = String::new();
        sources(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../src"),
            &mut text,
        );
        let raised: Vec<String> = RAISED.iter().map(ToString::to_string).collect();
        for (at, _) in text.match_indices("ErrorCode::") {
            let name: String = text[at + "ErrorCode::".len()..]
                .chars()
                .take_while(|c| c.is_ascii_uppercase() || *c == '_')
                .collect();
            if name.is_empty() || name == "OK" || name == "RUNNING" {
                continue;
            }
            assert!(
                raised.contains(&name),
                "the firmware raises {name}: explain it in error_help and RAISED"
            );
        }
    }
}
