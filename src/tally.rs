//! What the unit counts of its life: errors, tool changes, failures and fed distance per slot
//! (registers 0x04, 0x40.., kept across restarts), and each lane's filament and health
//! ([`Ledger`]). Fed by the App as commands start, change and end and as the odometry moves.

use mmu_protocol::{ErrorCode, RequestCode};

use crate::config::Config;
use crate::feeder::distance_centi;
use crate::lanes::Ledger;
use crate::persist::{Counters, Snapshot};
use crate::phases::Phase;
use crate::runner::{Runner, Status};
use crate::time::Instant;
use crate::unit::{Lane, Unit};

/// The counters and the ledger of a unit with `N` slots.
#[derive(Clone)]
pub struct Tally<const N: usize> {
    /// The counters the store keeps.
    pub counters: Counters<N>,
    /// Odometry of each slot at the last step, 1/100 mm.
    odometry_seen: [i32; N],
    /// The hundredths of a millimetre each slot drove beyond its whole millimetres in
    /// `counters.fed_mm` (below 100).
    fed_centi_beyond_mm: [u8; N],
    /// Filament left and lane health, as they are counted ([`crate::lanes`]).
    pub ledger: Ledger<N>,
}

impl<const N: usize> Tally<N> {
    /// Nothing counted.
    pub fn new() -> Self {
        Tally {
            counters: Counters::default(),
            odometry_seen: [0; N],
            fed_centi_beyond_mm: [0; N],
            ledger: Ledger::default(),
        }
    }

    /// What a restart restores: the counters and the lanes the ledger counts from.
    pub fn restore(&mut self, snapshot: &Snapshot<N>) {
        self.counters = snapshot.counters;
        self.ledger.restore(&snapshot.counters.lanes, &snapshot.lanes);
        self.fed_centi_beyond_mm = [0; N];
    }

    /// A register write set the filament left of a lane: the whole metres kept follow.
    pub fn left_written(&mut self) {
        self.ledger.sync_used(&mut self.counters.lanes);
    }

    /// `slot`'s odometry was set to `centi` (not a motion).
    pub fn odometry_set(&mut self, slot: usize, centi: i32) {
        if let Some(seen) = self.odometry_seen.get_mut(slot) {
            *seen = centi;
        }
    }

    /// The step's sensors, for the ledger: `driving` the slot the running command drives.
    pub fn observe(
        &mut self,
        unit: &Unit<N>,
        driving: Option<usize>,
        running: bool,
        config: &Config,
        now: Instant,
    ) {
        self.ledger
            .observe(unit, driving, running, &mut self.counters.lanes, config, now);
    }

    /// Add the motion of the slot the running command drives to its fed distance (the extruder
    /// pulling a loaded slot while printing does not count), and every slot's motion to what
    /// left its spool ([`Ledger::moved`]).
    pub fn count_fed(&mut self, unit: &Unit<N>, driving: Option<usize>) {
        for (slot, (feeder, seen)) in unit.feeders.iter().zip(self.odometry_seen.iter_mut()).enumerate() {
            let odometry = feeder.odometry_centi();
            let seen = core::mem::replace(seen, odometry);
            if odometry == seen {
                continue;
            }
            // Every motion counts off the spool, the printer's pull too.
            let moved = distance_centi(seen, odometry);
            self.ledger.moved(slot, moved, &mut self.counters.lanes);
            if driving == Some(slot)
                && let (Some(mm), Some(centi)) = (
                    self.counters.fed_mm.get_mut(slot),
                    self.fed_centi_beyond_mm.get_mut(slot),
                )
            {
                (*mm, *centi) = add_centi(*mm, *centi, moved.unsigned_abs());
            }
        }
    }

    /// The command `code` `value` starts at `now` (`superseded`: it took over an error).
    pub fn command_started(&mut self, code: RequestCode, value: u8, superseded: bool, now: Instant) {
        self.ledger
            .command_started(code, value, superseded, &mut self.counters.lanes, now);
    }

    /// The running command's status changed from `before` to what `operation` shows: a failure
    /// is counted on the slot its phase drove, a finished tool change on its slot.
    pub fn command_changed(&mut self, operation: &Runner, before: Status, lanes: &[Lane; N], now: Instant) {
        let after = operation.status();
        if after == before {
            return;
        }
        let slot = operation.phase().and_then(Phase::slot);
        self.ledger.lanes_seen(lanes, &mut self.counters.lanes);
        self.ledger
            .command_changed(operation.request.0, after, slot, &mut self.counters.lanes, now);
        match after {
            Status::Failed(error) if error != ErrorCode::FILAMENT_EJECTED => self.count_failure(slot),
            Status::Finished if operation.request.0 == RequestCode::Tool => {
                if let Some(count) = self
                    .counters
                    .tool_changes
                    .get_mut(usize::from(operation.request.1))
                {
                    *count = count.saturating_add(1);
                }
            }
            _ => {}
        }
    }

    /// `slot`'s motor stopped on `error` while no command drove it (the follower's).
    pub fn stalled(&mut self, slot: usize, error: ErrorCode) {
        self.ledger.stalled(slot, error, &mut self.counters.lanes);
        self.count_failure(Some(slot));
    }

    /// One error more, on `slot` if one is named.
    fn count_failure(&mut self, slot: Option<usize>) {
        self.counters.drive_errors = self.counters.drive_errors.saturating_add(1);
        if let Some(count) = slot.and_then(|slot| self.counters.failures.get_mut(slot)) {
            *count = count.saturating_add(1);
        }
    }
}

impl<const N: usize> Default for Tally<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// `mm` whole millimetres and `centi` hundredths (below 100) after `more` hundredths more, the
/// millimetres saturating at `u32::MAX`.
fn add_centi(mm: u32, centi: u8, more: u32) -> (u32, u8) {
    let more_mm = more / 100;
    let centi = more - more_mm * 100 + u32::from(centi);
    let carry = u32::from(centi >= 100);
    // Below 100 after the carry; `more_mm + carry` is below 2³².
    (mm.saturating_add(more_mm + carry), (centi - carry * 100) as u8)
}

#[cfg(test)]
mod tests {
    use super::add_centi;

    /// The fed distance as a 64-bit sum of hundredths, divided for the register.
    fn dividing_add(total_centi: u64, more: u32) -> (u64, u32) {
        let total = total_centi + u64::from(more);
        (total, u32::try_from(total / 100).unwrap_or(u32::MAX))
    }

    #[test]
    fn the_fed_millimetres_carry_their_hundredths_as_a_64_bit_sum() {
        let steps = [0, 1, 99, 100, 101, 199, 200, 201, 65_535, 4_294_967_199, u32::MAX];
        let starts = [
            0u64,
            1,
            99,
            12_345,
            429_496_729_500,
            429_496_729_599,
            u64::from(u32::MAX) * 100 + 99,
        ];
        for start in starts {
            for more in steps {
                for again in steps {
                    let (mut total, mut mm, mut centi) = (
                        start,
                        u32::try_from(start / 100).unwrap_or(u32::MAX),
                        (start % 100) as u8,
                    );
                    for step in [more, again] {
                        let expected;
                        (total, expected) = dividing_add(total, step);
                        (mm, centi) = add_centi(mm, centi, step);
                        assert_eq!(mm, expected, "{start} + {more} + {again}");
                        assert!(centi < 100);
                    }
                }
            }
        }
    }
}
