//! The persistence policy of a running unit, shared by the firmware and the simulator: restore at
//! boot; then lanes saved in the step they change (within the steps of a page move when the head
//! page is full), settings within a second, counters as the store allows,
//! everything before a reset. A flash that fails is retried with a growing pause, and the page
//! erases of any hour stay under [`ERASE_BURST`] + [`ERASES_PER_HOUR`] whatever happens (each
//! erase stalls the CPU up to 40 ms on the STM32G0). Each call of [`Keeper::update`] does one
//! bounded piece of a save (at most 8 double words programmed or one page erased).

use embedded_storage::nor_flash::NorFlash;

use super::{Damage, Store, StoreError};
use crate::app::{App, BoardAction};
use crate::time::Instant;
use crate::unit::Lane;

/// [`Keeper::update`] compares counters and settings this often; lanes every step, ms.
pub const FULL_CHECK_MS: u64 = 1000;
/// Page erases a running unit may do per hour, on top of [`ERASE_BURST`].
pub const ERASES_PER_HOUR: u32 = 60;
/// Page erases a unit may do at once (its budget when it starts, and the most it saves up).
pub const ERASE_BURST: u32 = 24;
/// The first pause after a failed save, ms; it doubles up to [`RETRY_MAX_MS`].
const RETRY_MIN_MS: u64 = 1000;
/// The longest pause between two tries of a failing store, ms.
pub const RETRY_MAX_MS: u64 = 600_000;
/// A reset (`X0`, `X42`) may always erase this many pages (one save's page moves).
const ERASES_BEFORE_RESET: u32 = 2;

/// What [`Keeper::boot`] found in the flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Boot {
    /// The stored state is restored into the App.
    Restored,
    /// What could be read is restored; the store held damage (a program or an erase cut short),
    /// which the saves that follow leave behind.
    Damaged(Damage),
}

/// How the store is doing, for a register and the log.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Health {
    /// Times the store was found damaged at boot or recovered from failing saves.
    pub repairs: u16,
    /// Saves that failed (the flash refused, or the erase budget was spent).
    pub failed_saves: u32,
    /// Page erases since boot.
    pub erases: u32,
    /// Whether the last save failed: the flash holds older state than the unit.
    pub failing: bool,
}

/// The save policy over a [`Store`].
#[derive(Clone)]
pub struct Keeper<F: NorFlash, const N: usize> {
    store: Store<F, N>,
    /// The lanes as of the last comparison with the flash.
    lanes: [Lane; N],
    /// The [`App::settings_revision`] whose settings were last compared with the flash (`None`:
    /// compare them at the next full check).
    settings_seen: Option<u32>,
    /// When counters and settings were last compared.
    checked_at: Option<Instant>,
    /// Erases allowed now, and when the budget was last topped up.
    erase_credit: u32,
    refilled_at: Option<Instant>,
    /// After a failed save: no new try before this, and the pause after the next failure.
    retry_at: Option<Instant>,
    retry_pause_ms: u64,
    health: Health,
    /// Something [`Keeper::take_news`] has not reported yet.
    news: bool,
}

impl<F: NorFlash, const N: usize> Keeper<F, N> {
    /// Restore into `app` (before its first step) what `store` holds. A store that cannot be read
    /// in places still gives every record it can (the newest complete copy of each).
    pub fn boot(mut store: Store<F, N>, app: &mut App<N>) -> (Self, Boot) {
        let snapshot = store.load();
        app.restore(&snapshot);
        let damage = store.damage();
        let boot = if damage.is_none() {
            Boot::Restored
        } else {
            Boot::Damaged(damage)
        };
        let keeper = Keeper {
            store,
            lanes: app.lanes(),
            settings_seen: None,
            checked_at: None,
            erase_credit: ERASE_BURST,
            refilled_at: None,
            retry_at: None,
            retry_pause_ms: RETRY_MIN_MS,
            health: Health {
                repairs: u16::from(!damage.is_none()),
                ..Health::default()
            },
            news: !damage.is_none(),
        };
        (keeper, boot)
    }

    /// After a step: save what changed, a bounded piece per call. Lanes are compared every step
    /// (cheap) and a lane change starts its save at once (a lane entry is one piece: it is
    /// saved in the step it changed, unless the head page is full); the full snapshot is compared
    /// every [`FULL_CHECK_MS`], and the save it starts runs in the calls that follow. While a
    /// save is in progress each call does one piece of it ([`Store::step`]: one chunk of an
    /// entry, a slice of a fresh page's erased check, or one page erase). `Ok(true)` when the
    /// call programmed or erased (the flash stalled the CPU); a failed save leaves the previous
    /// records and is tried again after a pause (1 s, doubling up to [`RETRY_MAX_MS`]).
    pub fn update(&mut self, app: &App<N>, now: Instant) -> Result<bool, StoreError> {
        self.top_up(now);
        if self.store.is_saving() {
            return self.advance(now);
        }
        if self.retry_at.is_some_and(|at| now.as_millis() < at.as_millis()) {
            return Ok(false);
        }
        let lanes = app.lanes();
        let full_check = self.health.failing
            || self
                .checked_at
                .is_none_or(|at| now.millis_since(at) >= FULL_CHECK_MS);
        if lanes == self.lanes && !full_check {
            return Ok(false);
        }
        self.lanes = lanes;
        self.store.set_erase_allowance(self.erase_credit);
        if full_check {
            self.checked_at = Some(now);
            // The settings come from a snapshot (thousands of instructions): taken only when the
            // configuration changed, in a call of its own; the save runs in the calls after it.
            if self.settings_seen != Some(app.settings_revision()) {
                self.settings_seen = Some(app.settings_revision());
                self.store.begin_save(&app.snapshot(), Some(now));
                return Ok(false);
            }
        }
        let counters = full_check.then_some(&app.counters);
        if !self.store.begin_changes(lanes, counters, now) {
            return Ok(false);
        }
        self.advance(now)
    }

    /// One piece of the save in progress; its outcome once it ends.
    fn advance(&mut self, now: Instant) -> Result<bool, StoreError> {
        match self.store.step() {
            Ok(progress) => {
                if progress.done {
                    self.settle(Ok(()), now)?;
                }
                Ok(progress.wrote)
            }
            Err(error) => self.settle(Err(error), now).map(|()| true),
        }
    }

    /// Before the board carries out `action`: finish the save in progress, then save everything
    /// (`X0`), or forget all but the identity (`X42`), whole: the reset follows.
    pub fn before(&mut self, action: BoardAction, app: &App<N>) -> Result<(), StoreError> {
        let now = self.refilled_at.unwrap_or(Instant::ZERO);
        if self.store.is_saving() {
            let finished = self.store.finish();
            let _ = self.settle(finished, now);
        }
        self.store
            .set_erase_allowance(self.erase_credit.max(ERASES_BEFORE_RESET));
        let result = match action {
            BoardAction::Reset => self.store.save(&app.snapshot(), None).map(drop),
            BoardAction::EraseAndReset => self.store.forget(),
        };
        self.settle(result, now)
    }

    /// Whether a save is in progress: the next calls of [`Keeper::update`] carry it on.
    pub fn is_saving(&self) -> bool {
        self.store.is_saving()
    }

    /// Account for a save's erases and outcome.
    fn settle(&mut self, result: Result<(), StoreError>, now: Instant) -> Result<(), StoreError> {
        let erases = self.store.erases();
        let used = erases.saturating_sub(self.health.erases);
        self.health.erases = erases;
        self.erase_credit = self.erase_credit.saturating_sub(used);
        match result {
            Ok(()) => {
                if self.health.failing {
                    self.health.failing = false;
                    self.health.repairs = self.health.repairs.saturating_add(1);
                    self.news = true;
                }
                self.retry_at = None;
                self.retry_pause_ms = RETRY_MIN_MS;
            }
            Err(_) => {
                // The settings may be what failed: compare them again at the next try.
                self.settings_seen = None;
                self.health.failed_saves = self.health.failed_saves.saturating_add(1);
                if !self.health.failing {
                    self.health.failing = true;
                    self.news = true;
                }
                self.retry_at = Some(Instant::from_millis(now.as_millis() + self.retry_pause_ms));
                self.retry_pause_ms = (self.retry_pause_ms * 2).min(RETRY_MAX_MS);
            }
        }
        result
    }

    /// One erase more every hour / [`ERASES_PER_HOUR`], up to [`ERASE_BURST`].
    fn top_up(&mut self, now: Instant) {
        const PERIOD_MS: u64 = 3_600_000 / ERASES_PER_HOUR as u64;
        let since = *self.refilled_at.get_or_insert(now);
        if self.erase_credit >= ERASE_BURST {
            self.refilled_at = Some(now);
            return;
        }
        // Divides (a 64-bit library call on the M0+) only once a period has passed.
        let elapsed = now.millis_since(since);
        if elapsed >= PERIOD_MS {
            let earned = elapsed / PERIOD_MS;
            self.erase_credit = (self.erase_credit + earned as u32).min(ERASE_BURST);
            self.refilled_at = Some(Instant::from_millis(since.as_millis() + earned * PERIOD_MS));
        }
    }

    /// How the store is doing.
    pub fn health(&self) -> Health {
        self.health
    }

    /// The health, once after each change worth a log line: damage found at boot, the first of
    /// a run of failed saves, the recovery from it.
    pub fn take_news(&mut self) -> Option<Health> {
        core::mem::take(&mut self.news).then_some(self.health)
    }

    /// The store.
    pub fn store(&mut self) -> &mut Store<F, N> {
        &mut self.store
    }

    /// Give the store back (e.g. its flash, for the next boot in a simulation).
    pub fn into_store(self) -> Store<F, N> {
        self.store
    }
}
