//! The bookkeeping of one phase attempt: when and where it began, what it has seen on the way,
//! and how much of its budget the drive's leases have used. Kept apart from the phases so their
//! goals read as decisions, and the budget arithmetic sits in one place.

use super::UnloadStuck;
use crate::drive::{Budget, millis_u32};
use crate::feeder::distance_centi;
use crate::time::Instant;

/// Bookkeeping of the running phase.
#[derive(Debug, Clone, Copy)]
pub struct PhaseRun {
    pub(super) started: Instant,
    /// Odometry when the phase first started, kept across Retry: distance goals count from here.
    pub(super) goal_from_centi: i32,
    /// Odometry at a milestone inside the phase (the hub cleared, the printer's sensor cleared).
    pub(super) mark_centi: Option<i32>,
    /// Since when the Bowden tube reads compressed.
    pub(super) compressed_since: Option<Instant>,
    /// Since when the Bowden tube reads taut.
    pub(super) taut_since: Option<Instant>,
    /// When the push (into the extruder, or of a proof) ended, the tip having met something or
    /// gone its distance; when an unload's feel found the filament free and braked to make sure;
    /// when an unload's pull went its check distance.
    pub(super) distance_done_at: Option<Instant>,
    /// Where an unload's feel began, or last found the filament held.
    pub(super) felt_from_centi: Option<i32>,
    /// When a feel last found the tube taut.
    pub(super) last_taut: Option<Instant>,
    /// The budget of the motion in progress: when and where the drive's lease began, and what
    /// earlier leases of this attempt used (a hold ends a lease; the silence is not counted).
    pub(super) budget_use: PhaseBudgetUse,
    /// The motor is held while the printer is silent.
    pub(super) held: bool,
    /// When the printer's `Q0` first saw this phase (it acts on the progress it sees).
    pub(super) printer_saw: Option<Instant>,
    /// An attempt after a Retry: its distance goal counts from the first attempt.
    pub(super) retried: bool,
    /// Whether the slot was proven to hold the hub path when the attempt first looked.
    pub(super) proven_at_start: Option<bool>,
    /// Why the unload stopped on `8004`, when it can tell.
    pub(super) stuck: Option<UnloadStuck>,
}

/// What the drive's leases of one phase attempt used of the phase's budget: a hold or a yield
/// ends a lease, and the next one gets only what is left.
#[derive(Debug, Clone, Copy)]
pub(super) struct PhaseBudgetUse {
    started: Instant,
    from_centi: i32,
    used_mm: u16,
    used_ms: u32,
}

impl PhaseBudgetUse {
    fn new(now: Instant, odometry_centi: i32) -> Self {
        PhaseBudgetUse {
            started: now,
            from_centi: odometry_centi,
            used_mm: 0,
            used_ms: 0,
        }
    }

    /// End the lease in progress at `now`, counting what it used.
    pub(super) fn end(&mut self, now: Instant, odometry_centi: i32) {
        let mm = distance_centi(self.from_centi, odometry_centi).unsigned_abs() / 100;
        self.used_mm = self.used_mm.saturating_add(u16::try_from(mm).unwrap_or(u16::MAX));
        self.used_ms = self
            .used_ms
            .saturating_add(millis_u32(now.millis_since(self.started)));
    }

    /// Begin a new lease at `now`: what is left of `full`.
    pub(super) fn resume(&mut self, full: Budget, now: Instant, odometry_centi: i32) -> Budget {
        self.started = now;
        self.from_centi = odometry_centi;
        let max_ms = full.max_ms.saturating_sub(self.used_ms);
        Budget {
            max_mm: full.max_mm.saturating_sub(self.used_mm),
            max_ms,
            max_still_ms: full.max_still_ms.min(max_ms),
            error: full.error,
        }
    }
}

impl PhaseRun {
    /// When the phase began (or began again after a Retry).
    pub fn started(&self) -> Instant {
        self.started
    }

    /// A phase attempt starting at `now`, its distance goal counting from `goal_from_centi`, with
    /// the filament at `odometry_centi`, written into `slot` (whatever it held is replaced).
    pub(super) fn start(
        slot: &mut Option<PhaseRun>,
        now: Instant,
        goal_from_centi: i32,
        odometry_centi: i32,
    ) -> &mut PhaseRun {
        slot.insert(PhaseRun {
            started: now,
            goal_from_centi,
            mark_centi: None,
            compressed_since: None,
            taut_since: None,
            distance_done_at: None,
            felt_from_centi: None,
            last_taut: None,
            budget_use: PhaseBudgetUse::new(now, odometry_centi),
            held: false,
            printer_saw: None,
            retried: false,
            proven_at_start: None,
            stuck: None,
        })
    }

    /// Where the distance goal of this phase counts from (kept for the attempt after Retry).
    pub fn goal_from_centi(&self) -> i32 {
        self.goal_from_centi
    }

    /// Why the attempt stopped on `8004`, when it can tell.
    pub fn stuck(&self) -> Option<UnloadStuck> {
        self.stuck
    }

    /// How far the filament moved from the goal start to `odometry_centi`, forward positive
    /// (1/100 mm).
    pub fn fed_centi(&self, odometry_centi: i32) -> i32 {
        distance_centi(self.goal_from_centi, odometry_centi)
    }

    /// End the drive's lease, once, as the motor stops for a wait: the wait counts against no
    /// bound; what the phase used so far stays counted.
    pub(super) fn pause(&mut self, now: Instant, odometry_centi: i32) {
        if !self.held {
            self.budget_use.end(now, odometry_centi);
            self.held = true;
        }
    }
}
