//! The maker's bench actions of `mmu printer`: `stats` (what the unit counts per slot) and
//! `settings save|load` (every writable setting to a text file and back). They run on the
//! read-only connection (no handshake writes), so a dump changes nothing in the unit and a load
//! changes only what the file says.
//!
//! The settings file is plain text, one setting a line, `#` starting a comment:
//!
//! ```text
//! # mmu settings: unit firmware 3.0.3 build 1, 3 slots
//! 0x22 360  # bowden_mm (MMU3 Bowden_Length)
//! 0x90 2600  # threshold_on.hub.filament
//! ```

use std::fmt::Write as _;
use std::path::Path;

use mmu_protocol::{ParamCode, Request, RequestCode};
use serde_json::json;

use super::console::Target;
use super::{Details, Failure, Session};
use crate::codec_cli::{parse_u8, parse_u16};
use crate::console::refused::why_refused;
use crate::explain::{lane_state, register_name};

use mmu_firmware::registers::{Access, FAILURES as ERRORS, FED_METRES, LANE, LEFT, SLOT_COUNT, TOOL_CHANGES};

impl<L: Target> Session<L> {
    /// Register `address`, read quietly; `None` when the unit refuses it (no such register).
    pub(crate) fn read_quietly(&mut self, address: u8) -> Result<Option<u16>, Failure> {
        let request = Request::new(RequestCode::Read, address);
        let answer = self
            .printer
            .request(&mut self.console, request)
            .map_err(|error| self.failure(error))?;
        Ok((answer.param == ParamCode::Accepted)
            .then_some(answer.param_value)
            .flatten())
    }

    /// The unit's slot count (register 0x40).
    pub(crate) fn slots(&mut self) -> Result<u8, Failure> {
        let slots = self
            .read_quietly(SLOT_COUNT)?
            .ok_or_else(|| Failure::new("the unit does not tell its number of slots (register 0x40)"))?;
        u8::try_from(slots)
            .ok()
            .filter(|&slots| slots <= 8)
            .ok_or_else(|| Failure::new(format!("the unit claims {slots} slots (register 0x40)")))
    }

    /// Why the unit refused `value` for register `address`, as the console says it.
    pub(crate) fn why_refused(&mut self, address: u8, value: u16) -> Result<String, Failure> {
        // A unit that does not tell its slot count: name the registers of the most a unit has.
        let slots = self.slots().unwrap_or(mmu_firmware::MAX_SLOTS as u8);
        let mut link_failure = None;
        let why = why_refused(address, value, slots, &mut |address| {
            self.read_quietly(address)
                .map_err(|failure| link_failure.get_or_insert(failure))
                .ok()
                .flatten()
        });
        match link_failure {
            Some(failure) => Err(failure),
            None => Ok(why),
        }
    }

    /// `stats`: per slot, the tool changes, errors and metres fed the unit keeps across restarts,
    /// and where the slot's filament is.
    pub fn stats(&mut self) -> Result<Details, Failure> {
        let slots = self.slots()?;
        let mut rows = Vec::new();
        for slot in 0..slots {
            let mut read = |base: u8| -> Result<u16, Failure> {
                self.read_quietly(base + slot)?
                    .ok_or_else(|| Failure::new(format!("the unit refused register 0x{:02x}", base + slot)))
            };
            let changes = read(TOOL_CHANGES)?;
            let errors = read(ERRORS)?;
            let metres = read(FED_METRES)?;
            let lane = read(LANE)?;
            let plural = |n: u16, word: &str| format!("{n} {word}{}", if n == 1 { "" } else { "s" });
            self.console.say(&format!(
                "slot {slot}: {}, {}, {metres} m fed, filament: {}",
                plural(changes, "tool change"),
                plural(errors, "error"),
                lane_state(lane)
            ));
            rows.push(json!({
                "slot": slot,
                "tool_changes": changes,
                "errors": errors,
                "metres_fed": metres,
                "lane": lane,
                "lane_meaning": lane_state(lane),
            }));
        }
        let mut details = Details::new();
        details.insert("slots".into(), rows.into());
        Ok(details)
    }

    /// Every writable setting this unit has, with its value, in the register table's order
    /// (the plain settings, then the thresholds of the sensors that have them).
    fn settings(&mut self) -> Result<Vec<(u8, u16)>, Failure> {
        let slots = self.slots()?;
        let mut settings = Vec::new();
        // The writable registers but the printer's sensor state (0x09): the unit's settings.
        let writable = mmu_firmware::registers::all(usize::from(slots))
            // Nor what is left on each spool (0x59 + k): state, not a setting.
            .filter(|register| {
                register.row.access() == Access::ReadWrite
                    && register.address != 0x09
                    && register.row.address != LEFT
            })
            .map(|register| register.address);
        for address in writable {
            if let Some(value) = self.read_quietly(address)? {
                settings.push((address, value));
            }
        }
        Ok(settings)
    }

    /// `settings save FILE`.
    pub fn save_settings(&mut self, file: &Path) -> Result<Details, Failure> {
        let settings = self.settings()?;
        let slots = self.slots()?;
        let mut text = String::from("# mmu settings");
        if let Some(((major, minor, revision), build)) = self.console.version() {
            let _ = write!(text, ": unit firmware {major}.{minor}.{revision} build {build}");
        }
        let _ = writeln!(text, ", {slots} slots");
        let _ = writeln!(
            text,
            "# ADDRESS VALUE  # what; `mmu printer ... settings load FILE` writes them back"
        );
        for &(address, value) in &settings {
            let _ = writeln!(text, "0x{address:02x} {value}  # {}", setting_name(address));
        }
        std::fs::write(file, &text)
            .map_err(|error| Failure::new(format!("cannot write {}: {error}", file.display())))?;
        self.console.say(&format!(
            "{} settings saved to {}",
            settings.len(),
            file.display()
        ));
        let mut details = Details::new();
        details.insert("file".into(), file.display().to_string().into());
        details.insert(
            "settings".into(),
            settings
                .iter()
                .map(|&(address, value)| json!({"address": address, "value": value}))
                .collect::<Vec<_>>()
                .into(),
        );
        Ok(details)
    }

    /// `settings load FILE`: each setting written where it differs; a refused one fails the load
    /// after the others were written.
    pub fn load_settings(&mut self, file: &Path) -> Result<Details, Failure> {
        let text = std::fs::read_to_string(file)
            .map_err(|error| Failure::new(format!("cannot read {}: {error}", file.display())))?;
        let settings =
            parse_settings(&text).map_err(|why| Failure::new(format!("{}: {why}", file.display())))?;
        let (mut written, mut refused) = (Vec::new(), Vec::new());
        for (address, value) in settings {
            let name = setting_name(address);
            if self.read_quietly(address)? == Some(value) {
                continue;
            }
            let answer = self
                .printer
                .request(&mut self.console, Request::write(address, value))
                .map_err(|error| self.failure(error))?;
            if answer.param == ParamCode::Accepted {
                self.console
                    .say(&format!("0x{address:02x} {name} = {value}: written"));
                written.push(address);
            } else {
                let why = self.why_refused(address, value)?;
                self.console.say(&format!(
                    "0x{address:02x} {name} = {value}: refused by the unit: {why}"
                ));
                refused.push(format!("0x{address:02x} = {value} ({why})"));
            }
        }
        if written.is_empty() && refused.is_empty() {
            self.console.say("every setting already had its value");
        }
        if !refused.is_empty() {
            return Err(Failure::new(format!("the unit refused {}", refused.join("; "))));
        }
        let mut details = Details::new();
        details.insert("written".into(), written.into());
        Ok(details)
    }
}

/// What setting `address` is, for the file's comments: this unit's name, and the MMU3 one the
/// printer's M707/M708 use where there is one.
fn setting_name(address: u8) -> String {
    let own = mmu_firmware::registers::describe(address, mmu_firmware::MAX_SLOTS).map(|r| r.to_string());
    match (own, register_name(address)) {
        (Some(own), Some(mmu3)) => format!("{own} (MMU3 {mmu3})"),
        (Some(own), None) => own,
        (None, Some(mmu3)) => mmu3.to_string(),
        (None, None) => format!("register 0x{address:02x}"),
    }
}

/// The `ADDRESS VALUE` lines of a settings file; `#` starts a comment.
fn parse_settings(text: &str) -> Result<Vec<(u8, u16)>, String> {
    let mut settings = Vec::new();
    for (number, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let bad = |why: String| {
            format!(
                "line {}: {why} (expected `ADDRESS VALUE`, e.g. `0x22 360`)",
                number + 1
            )
        };
        let mut words = line.split_whitespace();
        let (Some(address), Some(value), None) = (words.next(), words.next(), words.next()) else {
            return Err(bad(format!("{line:?}")));
        };
        settings.push((parse_u8(address).map_err(bad)?, parse_u16(value).map_err(bad)?));
    }
    Ok(settings)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_files_parse_with_comments_and_say_where_they_are_wrong() {
        let text = "# header\n0x22 360  # Bowden_Length\n\n 0x90 2600\n";
        assert_eq!(parse_settings(text), Ok(vec![(0x22, 360), (0x90, 2600)]));
        let error = parse_settings("0x22 360\n0x22\n").unwrap_err();
        assert!(error.starts_with("line 2:"), "{error}");
        let error = parse_settings("0x22 70000\n").unwrap_err();
        assert!(error.contains("too large"), "{error}");
        assert_eq!(setting_name(0x93), "threshold_on.slot0.filament");
        assert_eq!(setting_name(0xa4), "threshold_off.slot0.motion");
        assert_eq!(setting_name(0x22), "bowden_mm (MMU3 Bowden_Length)");
    }
}
