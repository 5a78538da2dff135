//! `mmu printer status`'s filament left and lane health: every slot's figures, read with the
//! printer's own `R` requests (what `M707` sends), in words and in the result line's JSON.

use super::console::Target;
use super::{Details, Failure, Session};
use crate::lanes_text::{read_lanes, warning_lines};

impl<L: Target> Session<L> {
    /// Each slot's filament left (with its uncertainty) and health, and the warnings; a unit
    /// without these registers (an earlier firmware) is said to report none.
    pub fn lanes_status(&mut self) -> Details {
        let mut details = Details::new();
        let figures = self.slots().and_then(|slots| {
            let read = |address: u8| -> Result<u16, Failure> {
                self.read_quietly(address)?
                    .ok_or_else(|| Failure::new(format!("the unit refused register 0x{address:02x}")))
            };
            read_lanes(slots, read).map(|figures| (slots, figures))
        });
        let Ok((slots, (lanes, warnings))) = figures else {
            self.console
                .say("filament left and lane health: not reported by this unit (an earlier firmware)");
            return details;
        };
        self.console
            .say("filament left (registers 0x54+k spool, 0x59+k left):");
        for lane in &lanes {
            self.console.say(&format!("  {}", lane.left_text()));
        }
        self.console.say("lane health:");
        for lane in &lanes {
            self.console.say(&format!("  {}", lane.health_text()));
        }
        for line in warning_lines(warnings, slots) {
            self.console.say(&line);
        }
        details.insert(
            "lanes".into(),
            lanes.iter().map(|lane| lane.json()).collect::<Vec<_>>().into(),
        );
        details.insert("lane_warnings".into(), warnings.into());
        details
    }
}
