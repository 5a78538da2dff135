//! Filament left on each spool and each lane's health, counted from what the unit senses.
//!
//! - **Filament left.** Every revolution of a slot's motor moves its filament by
//!   `mm_per_rev_centi`, in whichever direction the motor was last driven, forward while it
//!   coasts: so the filament the printer's extruder pulls off the spool while printing (the
//!   motor back-driven or following) counts as well as the unit's own moves. What has left the
//!   spool, net, is taken from the spool length of the slot (register `0x54 + k`, a 1 kg spool
//!   of 1.75 mm PLA by default) and counted again from zero when a filament is inserted into
//!   an empty slot. See [`Ledger`].
//! - **Lane health.** Rolling figures per lane ([`LaneFigures`]): drag, slip, load time, the
//!   distance from the hub sensor to the printer's sensor (warned when it drifts), stalls and
//!   the success rate of tool changes with its denominator.
//!
//! The kept part ([`LaneFigures`]) lives in the counters record: it changes at most once a
//! metre or once a command. The book's "Filament left and lane health" gives the accuracy.

mod figures;
mod motion;

pub use figures::{LaneFigures, WINDOW, roll, roll_signed};

use mmu_protocol::{ErrorCode, RequestCode};

use crate::config::Config;
use crate::drive::millis_u32;
use crate::feeder::distance_centi;
use crate::runner::Status;
use crate::time::Instant;
use crate::unit::{Lane, Unit};
use motion::MotionTally;

/// A 1 kg spool of 1.75 mm PLA (1.24 g/cm³: 2.405 mm² × 1.24 mg/mm³ = 2.98 g/m), m.
pub const DEFAULT_SPOOL_M: u16 = 330;
/// Under this many metres left, a slot's "low" warning bit is set (register 0x5e).
pub const LOW_LEFT_M: u16 = 10;
/// A load distance more than this far from its rolling figure is a drift, mm (or
/// [`DRIFT_PERMILLE`] of it, whichever is more).
pub const DRIFT_MM: u16 = 15;
/// A load distance more than this far from its rolling figure is a drift, per mille.
pub const DRIFT_PERMILLE: u16 = 40;
/// 1/100 mm in a metre.
const CENTI_PER_M: i32 = 100_000;

/// A tool change in progress, as the ledger follows it.
#[derive(Debug, Clone, Copy)]
struct ToolChange {
    slot: usize,
    started: Instant,
    /// No error was raised since it began.
    clean: bool,
    /// It drove its slot's motor: a change to the slot already loaded, which finishes at once,
    /// is no measurement of the lane.
    drove: bool,
    /// The odometry when the hub sensor began to see this slot's filament during it.
    at_hub_centi: Option<i32>,
    /// The hub sensor and the printer's sensor at the last step: taken as seeing filament when
    /// the change starts, so that only a filament arriving during it is measured.
    hub_seen: bool,
    fsensor_seen: bool,
}

/// What the ledger follows between steps (not kept across restarts).
#[derive(Debug, Clone)]
pub struct Ledger<const N: usize> {
    /// Filament taken off each spool since it was inserted, net, 1/100 mm.
    used_centi: [i32; N],
    /// Per slot: its lane was found empty, and no filament was parked in it since.
    emptied: [bool; N],
    /// The lanes as last looked at.
    lanes: [Lane; N],
    motions: [MotionTally; N],
    /// Per slot: a move is tallied, to fold once the command stops driving it (bit k).
    open: u8,
    /// Per slot: its move ended in the last step, to fold in this one (bit k).
    ended: u8,
    tool_change: Option<ToolChange>,
    /// Per slot: its last load distance drifted from its rolling figure (bit k).
    drifted: u8,
    last_step: Instant,
}

impl<const N: usize> Default for Ledger<N> {
    fn default() -> Self {
        Ledger {
            used_centi: [0; N],
            emptied: [false; N],
            lanes: [Lane::Unknown; N],
            motions: [MotionTally::default(); N],
            open: 0,
            ended: 0,
            tool_change: None,
            drifted: 0,
            last_step: Instant::ZERO,
        }
    }
}

/// The whole metres of `used_centi` (none below 0).
fn used_m(used_centi: i32) -> u16 {
    (used_centi.max(0).unsigned_abs() / 100_000).min(u32::from(u16::MAX)) as u16
}

/// The warning bits of register 0x5e: bit k, slot k's last load distance drifted (`drifted`);
/// bit 8 + k, slot k has less than [`LOW_LEFT_M`] left. Worked out only when the register is
/// read.
pub fn warnings(drifted: u8, used_centi: &[i32], spool_m: &[u16]) -> u16 {
    let mut bits = u16::from(drifted);
    for (slot, (&used, &spool)) in used_centi.iter().zip(spool_m).enumerate() {
        if left_mm(spool, used) < u32::from(LOW_LEFT_M) * 1000 {
            bits |= 1 << (8 + slot);
        }
    }
    bits
}

/// Filament left of a spool of `spool_m` metres once `used_centi` left it, mm (never below 0).
pub fn left_mm(spool_m: u16, used_centi: i32) -> u32 {
    // At most 65.5 km less 21.5 km or more: no overflow in 32 bits.
    let left = i32::from(spool_m) * 1000 - used_centi / 100;
    left.max(0) as u32
}

impl<const N: usize> Ledger<N> {
    /// Filament taken off each spool, net, 1/100 mm.
    pub fn used_centi(&self) -> &[i32; N] {
        &self.used_centi
    }

    /// Filament taken off each spool, to write (register `0x59 + k` sets what is left).
    pub fn used_centi_mut(&mut self) -> &mut [i32; N] {
        &mut self.used_centi
    }

    /// Take back what a previous run kept: the metres used (the middle of the metre last kept:
    /// a power cut loses at most half a metre either way) and the lanes as restored.
    pub fn restore(&mut self, figures: &[LaneFigures; N], lanes: &[Lane; N]) {
        for (used, lane) in self.used_centi.iter_mut().zip(figures) {
            *used = match lane.used_m {
                0 => 0,
                m => i32::from(m) * CENTI_PER_M + CENTI_PER_M / 2,
            };
        }
        self.emptied = lanes.map(|lane| lane == Lane::Empty);
        self.lanes = *lanes;
    }

    /// Per slot: its last load distance drifted from its rolling figure (bit k of register 0x5e).
    pub fn drifted(&self) -> u8 {
        self.drifted
    }

    /// Slot `slot`'s motor moved its filament by `moved` 1/100 mm (forward positive) since the
    /// last step: driven, or turned by the filament the printer pulls (the App calls it only when
    /// the odometry moved).
    pub fn moved(&mut self, slot: usize, moved: i32, figures: &mut [LaneFigures; N]) {
        if let (Some(used), Some(lane)) = (self.used_centi.get_mut(slot), figures.get_mut(slot)) {
            *used = used.saturating_add(moved);
            lane.used_m = used_m(*used);
        }
    }

    /// Where each slot's filament is now: a slot found empty, then holding a parked (or
    /// further) filament, has a new spool. Called while a command runs and when its status
    /// changes: only commands change the lanes.
    pub fn lanes_seen(&mut self, lanes: &[Lane; N], figures: &mut [LaneFigures; N]) {
        if *lanes == self.lanes {
            return;
        }
        self.lanes = *lanes;
        for (((&lane, emptied), used), figures) in lanes
            .iter()
            .zip(self.emptied.iter_mut())
            .zip(self.used_centi.iter_mut())
            .zip(figures.iter_mut())
        {
            match lane {
                Lane::Empty => *emptied = true,
                // Not known yet (a start-up check sees a filament in an empty slot): wait.
                Lane::Unknown => {}
                _ if *emptied => {
                    *emptied = false;
                    *used = 0;
                    figures.used_m = 0;
                }
                _ => {}
            }
        }
    }

    /// One step of the unit's own moves (drag, slip) and of a tool change (the hub and the
    /// printer's sensor on a load); the lanes while a command runs (`running`). Called after
    /// the sensors were read, before the command steps: a few comparisons in an idle step (it
    /// runs every millisecond on the MCU).
    pub fn observe(
        &mut self,
        unit: &Unit<N>,
        driving: Option<usize>,
        running: bool,
        figures: &mut [LaneFigures; N],
        config: &Config,
        now: Instant,
    ) {
        let last_step = core::mem::replace(&mut self.last_step, now);
        if running {
            self.lanes_seen(&unit.lanes, figures);
        }
        let driving = driving.filter(|&slot| slot < N);
        // A move that ended in the last step is folded first.
        if self.ended != 0 {
            for (slot, (tally, lane)) in self.motions.iter_mut().zip(figures.iter_mut()).enumerate() {
                if self.ended & (1 << slot) != 0 {
                    tally.fold(lane, config);
                }
            }
            self.ended = 0;
        }
        if let (Some(slot), Some(tally), Some(drive), Some(feeder)) = (
            driving,
            driving.and_then(|slot| self.motions.get_mut(slot)),
            driving.and_then(|slot| unit.drives.get(slot)),
            driving.and_then(|slot| unit.feeders.get(slot)),
        ) {
            let dt_ms = now.millis_since(last_step).min(1000) as u32;
            tally.add(drive, feeder, dt_ms, now);
            self.open |= 1 << slot;
        }
        let driving_bit = driving.map_or(0, |slot| 1u8 << slot);
        self.ended = self.open & !driving_bit;
        self.open &= driving_bit;
        if self.tool_change.is_some() {
            self.watch_load(unit, driving, figures);
        }
    }

    /// Bring the kept whole metres used up to date after a write of what is left.
    pub fn sync_used(&self, figures: &mut [LaneFigures; N]) {
        for (lane, &used) in figures.iter_mut().zip(&self.used_centi) {
            lane.used_m = used_m(used);
        }
    }

    /// On a tool change: the odometry when the hub sensor begins to see the filament, and the
    /// distance from there when the printer's sensor triggers (the Bowden length as measured).
    fn watch_load(&mut self, unit: &Unit<N>, driving: Option<usize>, figures: &mut [LaneFigures; N]) {
        let Some(change) = self.tool_change.as_mut() else {
            return;
        };
        let hub = unit.hub_present().unwrap_or(false);
        let fsensor = unit.fsensor_triggered();
        let (hub_rose, fsensor_rose) = (hub && !change.hub_seen, fsensor && !change.fsensor_seen);
        change.hub_seen = hub;
        change.fsensor_seen = fsensor;
        change.drove |= driving == Some(change.slot);
        let Some(odometry) = unit.feeders.get(change.slot).map(|f| f.odometry_centi()) else {
            return;
        };
        if hub_rose && driving == Some(change.slot) {
            change.at_hub_centi = Some(odometry);
        }
        if !fsensor_rose {
            return;
        }
        let Some(at_hub) = change.at_hub_centi.take() else {
            return;
        };
        let Ok(mm) = u16::try_from(distance_centi(at_hub, odometry) / 100) else {
            return;
        };
        let Some(lane) = figures.get_mut(change.slot) else {
            return;
        };
        let bit = 1u8 << change.slot;
        let before = lane.fsensor_mm;
        let allowed = DRIFT_MM.max((u32::from(before) * u32::from(DRIFT_PERMILLE) / 1000) as u16);
        if before != 0 && before.abs_diff(mm) > allowed {
            self.drifted |= bit;
        } else {
            self.drifted &= !bit;
        }
        lane.fsensor_mm = roll(before, mm);
    }

    /// A command was accepted: a tool change starts being followed; one that supersedes a
    /// failed command carries its tool change on (already not clean); any other ends the one
    /// followed as one that needed help.
    pub fn command_started(
        &mut self,
        code: RequestCode,
        value: u8,
        superseded: bool,
        figures: &mut [LaneFigures; N],
        now: Instant,
    ) {
        let slot = usize::from(value);
        let same = self
            .tool_change
            .is_some_and(|change| code == RequestCode::Tool && change.slot == slot);
        if superseded && same {
            return;
        }
        if let Some(change) = self.tool_change.take()
            && let Some(lane) = figures.get_mut(change.slot)
            && change.drove
        {
            lane.record_outcome(false);
        }
        if code == RequestCode::Tool && slot < N {
            self.tool_change = Some(ToolChange {
                slot,
                started: now,
                clean: true,
                drove: false,
                at_hub_centi: None,
                hub_seen: true,
                fsensor_seen: true,
            });
        }
    }

    /// The command's status changed to `after` (its request `code`); `slot`, the slot of its
    /// phase.
    pub fn command_changed(
        &mut self,
        code: RequestCode,
        after: Status,
        slot: Option<usize>,
        figures: &mut [LaneFigures; N],
        now: Instant,
    ) {
        match after {
            Status::Failed(error) => {
                if let Some(change) = self.tool_change.as_mut() {
                    change.clean = false;
                }
                if let Some(slot) = slot {
                    self.stalled(slot, error, figures);
                }
            }
            Status::Finished if code == RequestCode::Tool => {
                if let Some(change) = self.tool_change.take()
                    && let Some(lane) = figures.get_mut(change.slot)
                    && change.drove
                {
                    lane.record_outcome(change.clean);
                    if change.clean {
                        let ds = millis_u32(now.millis_since(change.started)) / 100;
                        lane.load_ds = roll(lane.load_ds, ds.min(u32::from(u16::MAX)) as u16);
                    }
                }
            }
            _ => {}
        }
    }

    /// Slot `slot` stopped on `error`: a stall is counted.
    pub fn stalled(&mut self, slot: usize, error: ErrorCode, figures: &mut [LaneFigures; N]) {
        if error == ErrorCode::STALLED_PULLEY
            && let Some(lane) = figures.get_mut(slot)
        {
            lane.stalls = lane.stalls.saturating_add(1);
        }
    }
}
