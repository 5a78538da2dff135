//! Filament left and lane health (`src/lanes`, registers 0x54-0x5e, 0x83, 0x88, 0xd8, 0xe8-0xfb)
//! in words and JSON, for `mmu printer status` and the console's `status`.

use mmu_firmware::registers::{
    DRAG, LANE_WARNINGS, LEFT, LOAD_DISTANCE, LOAD_TIME, SLIP, SPOOL, STALLS, SUCCESS, SUCCESS_OF,
};
use serde_json::{Value, json};

/// Uncertainty of the metres used, per mille of them: the mm per revolution is calibrated to
/// within one revolution over the 95 mm slot-to-hub path (2.1 %), and the drive gear's slip and
/// the printer's retractions while the motor coasts add up to about 1 % (book: "Filament left
/// and lane health").
pub const USED_ERROR_PERMILLE: u32 = 30;
/// Uncertainty on top, m: the register's rounding to the metre, and half a metre a power cut.
pub const FIXED_ERROR_M: u32 = 1;

/// One slot's figures as the unit reports them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LaneReport {
    pub slot: u8,
    pub spool_m: u16,
    pub left_m: u16,
    pub drag_pct: u16,
    pub slip_permille: i16,
    pub load_ds: u16,
    pub load_distance_mm: u16,
    pub stalls: u16,
    pub success_pct: u16,
    pub success_of: u16,
}

/// Every slot's figures and the warning bits (register 0x5e), read with `read`.
pub fn read_lanes<E>(
    slots: u8,
    mut read: impl FnMut(u8) -> Result<u16, E>,
) -> Result<(Vec<LaneReport>, u16), E> {
    let mut lanes = Vec::new();
    for slot in 0..slots {
        lanes.push(LaneReport {
            slot,
            spool_m: read(SPOOL + slot)?,
            left_m: read(LEFT + slot)?,
            drag_pct: read(DRAG + slot)?,
            slip_permille: read(SLIP + slot)? as i16,
            load_ds: read(LOAD_TIME + slot)?,
            load_distance_mm: read(LOAD_DISTANCE + slot)?,
            stalls: read(STALLS + slot)?,
            success_pct: read(SUCCESS + slot)?,
            success_of: read(SUCCESS_OF + slot)?,
        });
    }
    Ok((lanes, read(LANE_WARNINGS)?))
}

impl LaneReport {
    /// The uncertainty of the metres left, m.
    pub fn error_m(&self) -> u32 {
        let used = u32::from(self.spool_m.saturating_sub(self.left_m));
        (used * USED_ERROR_PERMILLE).div_ceil(1000) + FIXED_ERROR_M
    }

    /// `slot 0: 318 m left of a 330 m spool (± 2 m)`.
    pub fn left_text(&self) -> String {
        format!(
            "slot {}: {} m left of a {} m spool (± {} m)",
            self.slot,
            self.left_m,
            self.spool_m,
            self.error_m()
        )
    }

    /// The health figures in words.
    pub fn health_text(&self) -> String {
        let stalls = match self.stalls {
            1 => "1 stall".to_string(),
            n => format!("{n} stalls"),
        };
        if self.success_of == 0 {
            return format!("slot {} health: no tool change yet, {stalls}", self.slot);
        }
        let slip = f32::from(self.slip_permille) / 10.0;
        format!(
            "slot {} health: drag {} %, slip {slip:.1} %, load {:.1} s, load distance {} mm, {stalls}, \
             {} % of the last {} without help",
            self.slot,
            self.drag_pct,
            f32::from(self.load_ds) / 10.0,
            self.load_distance_mm,
            self.success_pct,
            match self.success_of {
                1 => "tool change".to_string(),
                n => format!("{n} tool changes"),
            }
        )
    }

    pub fn json(&self) -> Value {
        json!({
            "slot": self.slot,
            "spool_m": self.spool_m,
            "left_m": self.left_m,
            "left_error_m": self.error_m(),
            "drag_pct": self.drag_pct,
            "slip_permille": self.slip_permille,
            "load_s": f32::from(self.load_ds) / 10.0,
            "load_distance_mm": self.load_distance_mm,
            "stalls": self.stalls,
            "success_pct": self.success_pct,
            "success_of": self.success_of,
        })
    }
}

/// The warnings register 0x5e in words, one line per warning.
pub fn warning_lines(warnings: u16, slots: u8) -> Vec<String> {
    let mut lines = Vec::new();
    for slot in 0..slots.min(8) {
        if warnings & (1 << slot) != 0 {
            lines.push(format!(
                "warning: slot {slot}'s load distance drifted (the Bowden tube, its fittings or the drive gear's grip changed)"
            ));
        }
        if warnings & (1 << (8 + slot)) != 0 {
            lines.push(format!(
                "warning: slot {slot} has less than 10 m of filament left"
            ));
        }
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_uncertainty_grows_with_the_metres_used() {
        let mut lane = LaneReport {
            slot: 0,
            spool_m: 330,
            left_m: 330,
            drag_pct: 0,
            slip_permille: 0,
            load_ds: 0,
            load_distance_mm: 0,
            stalls: 0,
            success_pct: 0,
            success_of: 0,
        };
        assert_eq!(lane.error_m(), 1);
        lane.left_m = 30;
        assert_eq!(lane.error_m(), 10);
        assert_eq!(lane.left_text(), "slot 0: 30 m left of a 330 m spool (± 10 m)");
        assert!(lane.health_text().contains("no tool change yet"));
        assert_eq!(warning_lines(1 << 9 | 1, 3).len(), 2);
    }
}
