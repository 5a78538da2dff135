//! A spool that ends while the printer prints, handed to the printer the way its own runout
//! handling expects (book: "Spool end").
//!
//! Prusa's printer starts its filament change (`M600`, or `M600 A` / `M600 AUTO` with SpoolJoin)
//! when FINDA reads empty after an idle poll while it believes the filament in its nozzle
//! (`MMU2::CheckFINDARunout`). FINDA is register 0x08 (and `P0`): the hub sensor. Read honestly,
//! it empties only once the tail has passed the hub: by then the tail is far past the slot's
//! drive gear, and neither the printer's retract nor the unit can pull it back out (`8002`).
//!
//! So FINDA reads empty as soon as the spool end is certain: the loaded slot's own sensor reads
//! empty for [`CONFIRM_MS`] while the unit runs no command and the printer reports filament at
//! its sensor. The tail is then just past the slot sensor, a few millimetres past the drive gear;
//! the printer's ramming before its `U0` pulls it back behind the gear, and the unit's unload
//! takes it from there. Nothing else empties the slot sensor of a filament that runs through the
//! whole path: a tangle or a clog stops the filament with the sensor still covered and stays an
//! error ([`crate::follower`]). A sensor that cannot be read reports nothing.
//!
//! A spool end **fastened** to the core leaves the slot sensor covered: the filament stops while
//! the extruder pulls, as under a tangle, and the follower finds its motor still
//! ([`crate::follower`]). Told apart by the filament left ([`fastened_end`]): when the lane's
//! filament left is within its uncertainty of zero, the stop is reported as a spool end the same
//! way (FINDA empty, [`SpoolEnd::report_fastened`]) instead of the jam error. The filament is
//! still whole from the core to the nozzle, so the printer's `U0` pulls it back as from any
//! loaded slot. With more left, the stop stays the jam error: a tangle is never a spool end.
//!
//! A hub sensor that fails reads as what the unit believes (a slot holds the path or none does),
//! never as a runout of its own.
//!
//! Reported, the slot is no longer followed (its drive grips nothing), and the report lasts until
//! the printer's next command (its `U0`) or a restart.

use crate::lanes::left_mm;
use crate::time::Instant;
use crate::unit::{Lane, Unit};

/// How long the loaded slot's sensor must read empty before the unit reports a spool end, ms.
pub const CONFIRM_MS: u64 = 300;

/// The spool-end watch of the loaded slot.
#[derive(Debug, Clone, Copy, Default)]
pub struct SpoolEnd {
    /// The loaded slot whose sensor reads empty, and since when.
    candidate: Option<(usize, Instant)>,
    /// The slot whose spool end FINDA reports.
    reported: Option<usize>,
}

impl SpoolEnd {
    /// Nothing seen.
    pub const NEW: SpoolEnd = SpoolEnd {
        candidate: None,
        reported: None,
    };

    /// Look at the loaded slot at `now`; `idle` is true while no command runs and no error is
    /// held.
    pub fn watch<const N: usize>(&mut self, unit: &Unit<N>, idle: bool, now: Instant) {
        if self.reported.is_some() {
            return;
        }
        let loose_end = idle
            .then(|| unit.lanes.iter().position(|&lane| lane == Lane::Loaded))
            .flatten()
            .filter(|&slot| unit.owner_proven(slot) && unit.fsensor_triggered())
            .filter(|&slot| unit.feeders.get(slot).and_then(|f| f.filament.present()) == Some(false));
        self.candidate = match (loose_end, self.candidate) {
            (Some(slot), Some((seen, since))) if seen == slot => {
                if now.millis_since(since) >= CONFIRM_MS {
                    self.reported = Some(slot);
                }
                Some((seen, since))
            }
            (Some(slot), _) => Some((slot, now)),
            (None, _) => None,
        };
    }

    /// The follower found the loaded `slot`'s filament stopped while the printer pulls (its jam
    /// evidence): with `idle` (no command runs, no error held), the slot loaded, proven and the
    /// printer's sensor holding filament, and the spool's filament left within its uncertainty of
    /// zero ([`fastened_end`] of `spool_m` and `used_centi`), report the slot's spool end and
    /// return true; otherwise false (the stop is the jam error).
    pub fn report_fastened<const N: usize>(
        &mut self,
        unit: &Unit<N>,
        slot: usize,
        idle: bool,
        spool_m: u16,
        used_centi: i32,
    ) -> bool {
        let end = idle
            && unit.lanes.get(slot) == Some(&Lane::Loaded)
            && unit.owner_proven(slot)
            && unit.fsensor_triggered()
            && fastened_end(spool_m, used_centi);
        if end {
            self.candidate = None;
            self.reported = Some(slot);
        }
        end
    }

    /// The slot whose spool end is reported: FINDA reads empty.
    pub fn reported(&self) -> Option<usize> {
        self.reported
    }

    /// The printer took it up (a command started): FINDA tells the hub sensor again.
    pub fn clear(&mut self) {
        *self = SpoolEnd::NEW;
    }

    /// What FINDA (register 0x08, `P0`) reads with the hub sensor reading `hub` (`None`: faulty)
    /// and `owned` telling whether a slot holds the hub path as far as the unit knows. A faulty
    /// hub sensor reads as that belief: an empty FINDA would start the printer's filament change
    /// for a runout that did not happen (the sensor fault itself is reported by the next command).
    pub fn finda(&self, hub: Option<bool>, owned: bool) -> bool {
        self.reported.is_none() && hub.unwrap_or(owned)
    }
}

/// The rule that tells a spool end fastened to the core from a tangle: the filament left on a
/// spool of `spool_m` metres once `used_centi` (1/100 mm) left it is at most the count's stated
/// uncertainty, 3 % of the metres used plus 1 m (book: "Filament left and lane health"). Worked
/// out only when the follower finds a motor stopped.
pub fn fastened_end(spool_m: u16, used_centi: i32) -> bool {
    let used_mm = used_centi.max(0).unsigned_abs() / 100;
    let uncertainty_mm = (used_mm / 100).saturating_mul(3).saturating_add(1000);
    left_mm(spool_m, used_centi) <= uncertainty_mm
}

#[cfg(test)]
mod tests {
    use super::fastened_end;

    #[test]
    fn a_spool_end_is_within_the_uncertainty_of_empty() {
        // 1/100 mm in a metre.
        const M: i32 = 100_000;
        // A fresh 330 m spool: 330 m left, ± 1 m.
        assert!(!fastened_end(330, 0));
        // 320 m used: 10 m left, ± 10.6 m; 319 m used: 11 m left, ± 10.57 m.
        assert!(fastened_end(330, 320 * M));
        assert!(!fastened_end(330, 319 * M));
        // A 10 m spool: 9 m used, 1 m left, ± 1.27 m; 8 m used, 2 m left, ± 1.24 m.
        assert!(fastened_end(10, 9 * M));
        assert!(!fastened_end(10, 8 * M));
        // Counted past the spool's length.
        assert!(fastened_end(330, 340 * M));
    }
}
