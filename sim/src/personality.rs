//! Which printer the simulator plays: each Prusa firmware line that drives an MMU today, with the
//! protocol timing and the extruder behaviour it was released with.
//!
//! A [`Personality`] is read by both halves of the simulated printer: its protocol logic
//! ([`crate::printer::Printer`]: version, heartbeat, link timeout, register poll, premature
//! finish) and its mechanics in [`crate::Sim`] (what its extruder does before and during a
//! tool change). Sources, read at these tags (short names: BFW = Prusa-Firmware-Buddy, read in
//! the fork nomadsgalaxy/Prusa-Firmware-Buddy, which carries Prusa's tags; `M2/` =
//! `lib/Marlin/Marlin/src/feature/prusa/MMU2/`; PFW = prusa3d/Prusa-Firmware):
//!
//! | | [`Buddy65`](Personality::Buddy65) | [`Buddy64`](Personality::Buddy64) | [`Mk3s`](Personality::Mk3s) |
//! |---|---|---|---|
//! | firmware | BFW v6.5.3 (MK4, MK3.5, MK3.9, Core One) | BFW v6.4.1 | PFW v3.13.3 (3.14.0 alike) |
//! | unit version wanted | 3.0.4 (`M2/mmu2_supported_version.h`) | 3.0.3 | 3.0.2 (`Firmware/mmu2_supported_version.h`) |
//! | `Q0` period / answer timeout | 100 ms / 200 ms (`M2/protocol_logic.h`, `heartBeatPeriod_ms`, `linkLayerTimeout_ms`) | 1 s / 2 s | 1 s / 2 s (`Firmware/mmu2_protocol_logic.h`) |
//! | register poll after `Q0` | 08 1b 1c 04 1a 22 (`M2/protocol_logic.cpp`, `regs8Addrs`, `regs16Addrs`) | the same | 08 1b 1c 04 1a (no Bowden length) |
//! | `T` goes out | before its finishing retract of 80 mm at its 0x14 copy, while its gears still grip (`M2/mmu2_mk4.cpp`, `ToolChangeCommonOnce`) | after a 40 mm retract at 20 mm/s (`MMU2_RETRY_UNLOAD_FINISH_LENGTH`/`_FEED_RATE`) | after the slicer's ramming (`Firmware/mmu2.cpp`, `ToolChangeCommonOnce`) |
//! | co-feed during `P1c` | 189.9 mm at 0x14, started on the change to `P1c` (`OnMMUProgressMsgChanged`) | 189.9 mm, planned at the next poll that still shows `P1c` (`OnMMUProgressMsgSame`; the simulator starts it at once) | 350 mm (`Firmware/mmu2.cpp`, `OnMMUProgressMsgSame`) |
//! | premature finish | on its own sensor during `P1c` (after pushing 0x0b + 2 mm) or on `P2` after `P1c` (`OnMMUProgressMsgSame`/`Changed` return true, `manage_response` returns on `PrematureFinish`) | no | no |
//!
//! In every personality the printer takes a `Q0` answer's progress or error as its command's
//! whatever command the answer echoes; only `F` must echo it (`M2/protocol_logic.cpp`,
//! `ProcessCommandQueryResponse`, the same in PFW `Firmware/mmu2_protocol_logic.cpp`).

use std::fmt;
use std::str::FromStr;

use crate::geometry::ExtruderGeometry;

/// A Prusa printer firmware line, as the simulator plays it. See the [module
/// documentation](self) for what differs and where each value comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Personality {
    /// Prusa-Firmware-Buddy 6.5.3 and later (MK4, MK3.5, MK3.9, Core One): wants MMU 3.0.4.
    Buddy65,
    /// Prusa-Firmware-Buddy 6.4.x (and 6.5.2 and earlier): wants MMU 3.0.3.
    #[default]
    Buddy64,
    /// Prusa-Firmware 3.13.3 / 3.14.0 for the MK3S: wants MMU 3.0.2.
    Mk3s,
}

/// The poll of Buddy firmware (6.3.3 and later): FINDA, selector slot, idler slot (8-bit
/// registers), error count, pulley position, Bowden length (16-bit registers), in this order
/// (BFW `M2/protocol_logic.cpp` v6.4.1 and v6.5.3, `regs8Addrs`, `regs16Addrs`).
const BUDDY_POLL: [u8; 6] = [0x08, 0x1b, 0x1c, 0x04, 0x1a, 0x22];
/// The MK3S's poll: the same without the Bowden length (PFW v3.13.3
/// `Firmware/mmu2_protocol_logic.cpp`, `regs16Addrs`).
const MK3S_POLL: [u8; 5] = [0x08, 0x1b, 0x1c, 0x04, 0x1a];

impl Personality {
    /// Every personality, newest first.
    pub const ALL: [Personality; 3] = [Personality::Buddy65, Personality::Buddy64, Personality::Mk3s];

    /// The name on the command line: `buddy-6.5`, `buddy-6.4`, `mk3s`.
    pub const fn name(self) -> &'static str {
        match self {
            Personality::Buddy65 => "buddy-6.5",
            Personality::Buddy64 => "buddy-6.4",
            Personality::Mk3s => "mk3s",
        }
    }

    /// The unit version the printer accepts, exactly (`mmuVersionMajor/Minor/Patch`).
    pub const fn version(self) -> (u8, u8, u8) {
        match self {
            Personality::Buddy65 => (3, 0, 4),
            Personality::Buddy64 => (3, 0, 3),
            Personality::Mk3s => (3, 0, 2),
        }
    }

    /// `Q0` goes out this long after the last exchange, ms (`heartBeatPeriod`).
    pub const fn heartbeat_ms(self) -> u64 {
        match self {
            Personality::Buddy65 => 100,
            Personality::Buddy64 | Personality::Mk3s => 1000,
        }
    }

    /// The longest wait for an answer before the printer restarts the handshake, ms
    /// (`linkLayerTimeout`).
    pub const fn link_timeout_ms(self) -> u64 {
        match self {
            Personality::Buddy65 => 200,
            Personality::Buddy64 | Personality::Mk3s => 2000,
        }
    }

    /// The registers read after every `Q0`, in order.
    pub fn polled_registers(self) -> &'static [u8] {
        match self {
            Personality::Buddy65 | Personality::Buddy64 => &BUDDY_POLL,
            Personality::Mk3s => &MK3S_POLL,
        }
    }

    /// The co-feed move the printer plans while the unit reports `P1c` and its sensor is clear,
    /// mm (BFW: `maximumAllowedExtruderMove`, 189.9; PFW: 350).
    pub const fn cofeed_mm(self) -> f32 {
        match self {
            Personality::Buddy65 | Personality::Buddy64 => 189.9,
            Personality::Mk3s => 350.0,
        }
    }

    /// The printer sends `T` before its own finishing retract, while its gears still grip the
    /// filament, and counts on the unit to wait for its sensor (BFW 6.5.3, `ccb208bf5af1`).
    /// Otherwise `T` goes out once the filament is out of its gears.
    pub const fn sends_tool_before_retract(self) -> bool {
        matches!(self, Personality::Buddy65)
    }

    /// The printer leaves a tool change before the unit's `F`: on its own sensor during `P1c`
    /// (after the extra push) or on `P2` after `P1c`, and loads on to the nozzle while it keeps
    /// polling the unit (BFW 6.5.3, `PrematureFinish`).
    pub const fn premature_finish(self) -> bool {
        matches!(self, Personality::Buddy65)
    }

    /// The extruder geometry played by default ([`ExtruderGeometry`] says what the sources
    /// show): Buddy's MK4, MK3.9 and Core One carry the Nextruder, whose sensor reads the
    /// filament until it leaves the drive gear ([`ExtruderGeometry::GEARS_FIRST`], Buddy 6.5's
    /// default); the MK3S and the MK3.5 (on Buddy firmware) have the sensor above the gears
    /// ([`ExtruderGeometry::SENSOR_FIRST`]). Buddy 6.4 runs on both; it plays the MK3.5's order
    /// by default, which the session tests and the tool-change figures were written against;
    /// `--extruder gears-first` plays an MK4 on it.
    pub const fn extruder(self) -> ExtruderGeometry {
        match self {
            Personality::Buddy65 => ExtruderGeometry::GEARS_FIRST,
            Personality::Buddy64 | Personality::Mk3s => ExtruderGeometry::SENSOR_FIRST,
        }
    }

    /// Where the printer's extruder gears sit before its filament sensor by default, mm, if they
    /// do ([`Personality::extruder`]).
    pub fn gears_before_sensor_mm(self) -> Option<f32> {
        self.extruder().gears_before_sensor_mm()
    }

    /// The longest the simulator may hold the printer's bytes back while it plays a printer move
    /// that comes before them on the real printer, ms: well inside the printer's link timeout.
    pub const fn max_hold_ms(self) -> u64 {
        self.link_timeout_ms() / 2
    }
}

impl fmt::Display for Personality {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A name that is no personality.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UnknownPersonality(pub String);

impl fmt::Display for UnknownPersonality {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names: Vec<&str> = Personality::ALL.iter().map(|p| p.name()).collect();
        write!(f, "{:?} is no printer: {}", self.0, names.join(", "))
    }
}

impl std::error::Error for UnknownPersonality {}

impl FromStr for Personality {
    type Err = UnknownPersonality;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        Personality::ALL
            .into_iter()
            .find(|p| p.name() == text)
            .ok_or_else(|| UnknownPersonality(text.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_unknown_names_list_the_choices() {
        for personality in Personality::ALL {
            assert_eq!(personality.name().parse(), Ok(personality));
        }
        let error = "mk4".parse::<Personality>().unwrap_err().to_string();
        assert!(error.contains("buddy-6.5, buddy-6.4, mk3s"), "{error}");
    }

    #[test]
    fn no_personality_holds_bytes_past_its_own_timeout() {
        for personality in Personality::ALL {
            assert!(personality.max_hold_ms() < personality.link_timeout_ms());
            assert!(personality.heartbeat_ms() < personality.link_timeout_ms());
        }
    }
}
