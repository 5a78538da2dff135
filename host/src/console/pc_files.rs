//! What the console keeps on this PC rather than in the unit: the slot map (the material and
//! colour of each slot's filament) and the statistics' starting point with the tool changes timed
//! at the bench. Plain text files, one fact a line, in `$MMU_CONFIG_DIR`, else
//! `$XDG_CONFIG_HOME/mmu`, else `~/.config/mmu`: `slots.txt` and `stats.txt`.
//!
//! The unit has no register for either yet: a map kept in the unit would follow it to another PC
//! (a firmware follow-up, said in the book's known limits).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;

/// The folder the console's files live in; `None` when no home is known.
pub fn config_dir() -> Option<PathBuf> {
    let from = |name: &str| {
        std::env::var_os(name)
            .filter(|value| !value.is_empty())
            .map(PathBuf::from)
    };
    from("MMU_CONFIG_DIR")
        .or_else(|| from("XDG_CONFIG_HOME").map(|dir| dir.join("mmu")))
        .or_else(|| from("HOME").map(|home| home.join(".config").join("mmu")))
}

/// The path of the console's file `name`.
fn file(name: &str) -> Result<PathBuf, String> {
    config_dir()
        .map(|dir| dir.join(name))
        .ok_or_else(|| "no folder for the console's files: set HOME or MMU_CONFIG_DIR".to_string())
}

/// The lines of `path` that are not blank or `#` comments, numbered; none when it does not exist.
fn read_lines(path: &PathBuf) -> Result<Vec<(usize, Vec<String>)>, String> {
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(error) => return Err(format!("cannot read {}: {error}", path.display())),
    };
    Ok(text
        .lines()
        .enumerate()
        .map(|(index, line)| (index + 1, line.split('#').next().unwrap_or("")))
        .filter(|(_, line)| !line.trim().is_empty())
        .map(|(number, line)| (number, line.split_whitespace().map(str::to_string).collect()))
        .collect())
}

/// Write `text` to `path`, making its folder.
fn write_file(path: &PathBuf, text: &str) -> Result<(), String> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|error| format!("cannot make {}: {error}", dir.display()))?;
    }
    std::fs::write(path, text).map_err(|error| format!("cannot write {}: {error}", path.display()))
}

/// A slot's filament as the maker noted it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SlotNote {
    /// `PLA`, `PETG`, ...
    pub material: String,
    /// `red`, `#ff0000`, ...
    pub colour: String,
}

/// The slot map. See the [module documentation](self).
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct SlotMap {
    notes: BTreeMap<u8, SlotNote>,
}

impl SlotMap {
    /// Where the map is kept.
    pub fn path() -> Result<PathBuf, String> {
        file("slots.txt")
    }

    /// The map from its file; empty when there is none.
    pub fn load() -> Result<SlotMap, String> {
        let path = Self::path()?;
        let mut map = SlotMap::default();
        for (number, words) in read_lines(&path)? {
            let slot = words.first().and_then(|word| word.parse::<u8>().ok());
            match (slot, words.as_slice()) {
                (Some(slot), [_, material, colour]) => {
                    map.notes.insert(
                        slot,
                        SlotNote {
                            material: material.clone(),
                            colour: colour.clone(),
                        },
                    );
                }
                _ => {
                    return Err(format!(
                        "{}:{number}: expected `SLOT MATERIAL COLOUR`, e.g. `1 PETG red`",
                        path.display()
                    ));
                }
            }
        }
        Ok(map)
    }

    /// Write the map to its file; where it went.
    pub fn save(&self) -> Result<PathBuf, String> {
        let path = Self::path()?;
        let mut text = String::from("# mmu slot map: SLOT MATERIAL COLOUR, one slot a line\n");
        for (slot, note) in &self.notes {
            let _ = writeln!(text, "{slot} {} {}", note.material, note.colour);
        }
        write_file(&path, &text)?;
        Ok(path)
    }

    /// What slot `slot` holds, if noted.
    pub fn get(&self, slot: u8) -> Option<&SlotNote> {
        self.notes.get(&slot)
    }

    /// Note what `slot` holds, or forget it (`None`).
    pub fn set(&mut self, slot: u8, note: Option<SlotNote>) {
        match note {
            Some(note) => self.notes.insert(slot, note),
            None => self.notes.remove(&slot),
        };
    }
}

/// The unit's counters of one slot: tool changes, errors, metres fed.
pub type Counters = [u16; 3];

/// The statistics kept on this PC. See the [module documentation](self).
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct Stats {
    /// The unit's counters per slot at the last reset.
    pub baseline: BTreeMap<u8, Counters>,
    /// Each tool change run at the bench since the last reset: slot and duration, ms.
    pub changes: Vec<(u8, u64)>,
}

impl Stats {
    /// Where the statistics are kept.
    pub fn path() -> Result<PathBuf, String> {
        file("stats.txt")
    }

    /// The statistics from their file; empty when there is none.
    pub fn load() -> Result<Stats, String> {
        let path = Self::path()?;
        let mut stats = Stats::default();
        for (number, words) in read_lines(&path)? {
            let numbers: Option<Vec<u64>> = words.iter().skip(1).map(|w| w.parse().ok()).collect();
            let fits = |n: u64| u16::try_from(n).ok();
            match (words.first().map(String::as_str), numbers.as_deref()) {
                (Some("baseline"), Some(&[slot, changes, errors, metres])) => {
                    let slot = u8::try_from(slot).ok();
                    if let (Some(slot), Some(c), Some(e), Some(m)) =
                        (slot, fits(changes), fits(errors), fits(metres))
                    {
                        stats.baseline.insert(slot, [c, e, m]);
                        continue;
                    }
                }
                (Some("change"), Some(&[slot, ms])) => {
                    if let Ok(slot) = u8::try_from(slot) {
                        stats.changes.push((slot, ms));
                        continue;
                    }
                }
                _ => {}
            }
            return Err(format!(
                "{}:{number}: expected `baseline SLOT CHANGES ERRORS METRES` or `change SLOT MS`",
                path.display()
            ));
        }
        Ok(stats)
    }

    /// Write the statistics to their file.
    pub fn save(&self) -> Result<PathBuf, String> {
        let path = Self::path()?;
        let mut text = String::from(
            "# mmu console statistics: the unit's counters at the last `stats reset` (baseline SLOT \
             CHANGES ERRORS METRES) and each tool change timed at the bench since (change SLOT MS)\n",
        );
        for (slot, [changes, errors, metres]) in &self.baseline {
            let _ = writeln!(text, "baseline {slot} {changes} {errors} {metres}");
        }
        for (slot, ms) in &self.changes {
            let _ = writeln!(text, "change {slot} {ms}");
        }
        write_file(&path, &text)?;
        Ok(path)
    }

    /// One slot's line: its counters since the reset (the unit's `now`) and its timed changes.
    pub fn slot_line(&self, slot: u8, now: Counters) -> String {
        let base = self.baseline.get(&slot).copied().unwrap_or([0; 3]);
        // A unit whose counters went down was erased (`X42`): count from zero again.
        let erased = now.iter().zip(base).any(|(now, base)| *now < base);
        let since = |i: usize| if erased { now[i] } else { now[i] - base[i] };
        let mut line = format!(
            "slot {slot}: {} tool change(s), {} error(s), {} m fed",
            since(0),
            since(1),
            since(2)
        );
        if erased {
            line.push_str(" (the unit's counters were reset since: counted from zero)");
        }
        let times: Vec<u64> = self
            .changes
            .iter()
            .filter(|(s, _)| *s == slot)
            .map(|(_, ms)| *ms)
            .collect();
        if let (Some(fastest), Some(slowest)) = (times.iter().min(), times.iter().max()) {
            let mean = times.iter().sum::<u64>() as f64 / times.len() as f64;
            let _ = write!(
                line,
                "; {} tool change(s) to it timed here: mean {:.1} s, fastest {:.1} s, slowest {:.1} s",
                times.len(),
                mean / 1000.0,
                *fastest as f64 / 1000.0,
                *slowest as f64 / 1000.0
            );
        }
        line
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_slot_line_counts_since_the_reset_and_times_the_changes() {
        let mut stats = Stats::default();
        stats.baseline.insert(1, [10, 2, 5]);
        stats.changes = vec![(1, 9000), (1, 11000), (2, 8000)];
        assert_eq!(
            stats.slot_line(1, [13, 2, 6]),
            "slot 1: 3 tool change(s), 0 error(s), 1 m fed; 2 tool change(s) to it timed here: \
             mean 10.0 s, fastest 9.0 s, slowest 11.0 s"
        );
        assert!(stats.slot_line(1, [1, 0, 0]).contains("counted from zero"));
        assert_eq!(
            stats.slot_line(0, [4, 1, 0]),
            "slot 0: 4 tool change(s), 1 error(s), 0 m fed"
        );
    }
}
