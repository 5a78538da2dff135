//! The persistence policy of a running unit, shared by the firmware and the simulator: restore at
//! boot; then lanes saved in the calls right after they change (an entry is laid out in one piece
//! and programmed in the next; more steps when the head page is full), settings about a second
//! after they change (compared a register per call), counters as the store allows, everything
//! before a reset. A flash that fails is retried with a growing pause, and the page erases of
//! any hour stay under [`ERASE_BURST`] + [`ERASES_PER_HOUR`] whatever happens (each erase stalls
//! the CPU up to 40 ms on the STM32G0); a unit starts with only [`ERASES_AT_BOOT`] of them, so
//! that a reset loop cannot renew the budget at every boot. Each call of [`Keeper::update`] does
//! one bounded piece of a save (at most 2 double words programmed or one page erased); the
//! control step says after which steps a piece runs ([`crate::control::Deferral`]).

use embedded_storage::nor_flash::NorFlash;

use super::crc::{EntryCrc, SoftwareCrc};
use super::settings::{Defaults, Scan};
use super::{Damage, Snapshot, Store, StoreError};
use crate::app::{App, BoardAction};
use crate::time::{Instant, div_rem_u64};
use crate::unit::Lane;

/// [`Keeper::update`] compares counters and settings this often; lanes every step, ms.
pub const FULL_CHECK_MS: u64 = 1000;
/// Page erases a running unit may do per hour, on top of [`ERASE_BURST`].
pub const ERASES_PER_HOUR: u32 = 60;
/// Page erases a unit may do at once: the most it saves up (it starts with [`ERASES_AT_BOOT`]).
pub const ERASE_BURST: u32 = 24;
/// The first pause after a failed save, ms; it doubles up to [`RETRY_MAX_MS`].
const RETRY_MIN_MS: u32 = 1000;
/// The longest pause between two tries of a failing store, ms.
pub const RETRY_MAX_MS: u64 = 600_000;
/// A reset (`X0`, `X42`) may always erase this many pages (one save's page moves).
const ERASES_BEFORE_RESET: u32 = 2;
/// Page erases a unit may do right after it starts (one save's page moves); it earns the rest
/// at [`ERASES_PER_HOUR`], up to [`ERASE_BURST`]. Not a full burst: nothing in the flash tells
/// how long ago the last boot spent its erases, and a reset loop on a store found damaged at
/// every boot would have a full budget to spend at every boot (24 erases a boot). So each boot
/// erases at most this many pages plus one per minute it runs, whatever the loop (and two more
/// when it ends on the printer's `X0` or `X42`: a reset's save may always move its pages).
pub const ERASES_AT_BOOT: u32 = 2;
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
pub struct Keeper<F: NorFlash, const N: usize, C: EntryCrc = SoftwareCrc> {
    store: Store<F, N, C>,
    /// The lanes as of the last comparison with the flash.
    lanes: [Lane; N],
    /// The [`App::settings_revision`] whose settings were last compared with the flash (`None`:
    /// compare them at the next full check).
    settings_seen: Option<u32>,
    /// Every setting register and its default value.
    defaults: Defaults,
    /// The comparison of the settings in progress, a register per call.
    scan: Option<Scan>,
    /// When counters and settings were last compared.
    checked_at: Option<Instant>,
    /// Erases allowed now, and when the budget was last topped up.
    erase_credit: u32,
    refilled_at: Option<Instant>,
    /// After a failed save: no new try before this, and the pause after the next failure.
    retry_at: Option<Instant>,
    retry_pause_ms: u32,
    health: Health,
    /// Something [`Keeper::take_news`] has not reported yet.
    news: bool,
}

impl<F: NorFlash, const N: usize, C: EntryCrc> Keeper<F, N, C> {
    /// Restore into `app` (before its first step) what `store` holds. A store that cannot be read
    /// in places still gives every record it can (the newest complete copy of each).
    pub fn boot(mut store: Store<F, N, C>, app: &mut App<N>) -> (Self, Boot) {
        let snapshot = store.load();
        let defaults = Defaults::new(app);
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
            defaults,
            scan: None,
            checked_at: None,
            // Not a full burst: see ERASES_AT_BOOT.
            erase_credit: ERASES_AT_BOOT,
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
    /// (cheap) and a lane change starts its save at once (a lane entry is two pieces, laid out
    /// and programmed: it is saved by the step after the change, unless the head page is full);
    /// counters and [`App::settings_revision`] are compared every [`FULL_CHECK_MS`]; when the
    /// revision moved, the settings are compared with their defaults a register per call, and the
    /// save it starts runs in the calls that follow. While a save is in progress each call does
    /// one piece of it ([`Store::step`]: an entry laid out, one chunk of it, a slice of a fresh
    /// page's erased check, or one page erase). `Ok(true)` when the call programmed or erased
    /// (the flash stalled the CPU); a failed save leaves the previous records and is tried again
    /// after a pause (1 s, doubling up to [`RETRY_MAX_MS`]).
    pub fn update(&mut self, app: &App<N>, now: Instant) -> Result<bool, StoreError> {
        self.top_up(now);
        // A motor the step drives keeps its duty through an erase's stall: none now.
        let resting = !app.motors_driven();
        self.store.hold_erases(!resting);
        if self.store.is_saving() {
            return self.advance(now);
        }
        if self.retry_at.is_some_and(|at| now.as_millis() < at.as_millis()) {
            return Ok(false);
        }
        let lanes = app.lanes();
        // No full check while the settings are being compared: the one that started it is.
        let full_check = self.scan.is_none()
            && (self.health.failing
                || self
                    .checked_at
                    .is_none_or(|at| now.millis_since(at) >= FULL_CHECK_MS));
        if lanes == self.lanes && !full_check && self.scan.is_none() {
            return if resting {
                self.prepare_fresh_page(now)
            } else {
                Ok(false)
            };
        }
        self.lanes = lanes;
        self.store.set_erase_allowance(self.erase_credit);
        let mut counters = None;
        if full_check {
            self.checked_at = Some(now);
            if self.settings_seen == Some(app.settings_revision()) {
                counters = Some(&app.tally.counters);
            } else {
                // Changed settings: compared in this call and the following ones (after a lane
                // change's save), then saved with the counters.
                self.settings_seen = Some(app.settings_revision());
                self.scan = Some(Scan::default());
            }
        }
        if self.store.begin_changes(lanes, counters, now) {
            return self.advance(now);
        }
        Ok(self.scan_settings(app, now))
    }

    /// Between saves, at rest: a piece of readying the page the next page move opens, so that a
    /// save during motion finds it erased. `Ok(true)` when it erased.
    fn prepare_fresh_page(&mut self, now: Instant) -> Result<bool, StoreError> {
        self.store.set_erase_allowance(self.erase_credit);
        match self.store.prepare_fresh_page() {
            Ok(progress) => {
                self.count_erases();
                Ok(progress.wrote)
            }
            // Ready once the budget allows.
            Err(StoreError::EraseBudget) => Ok(false),
            Err(error) => self.settle(Err(error), now).map(|()| true),
        }
    }

    /// Compare the next few settings; once all are, start saving them with the lanes and the
    /// counters (settings that changed meanwhile are compared again from the start).
    /// Never writes.
    fn scan_settings(&mut self, app: &App<N>, now: Instant) -> bool {
        let Some(scan) = self.scan.as_mut() else {
            return false;
        };
        if !scan.compare_next(app, &self.defaults) {
            return false;
        }
        if self.settings_seen != Some(app.settings_revision()) {
            self.settings_seen = Some(app.settings_revision());
            self.scan = Some(Scan::default());
            return false;
        }
        self.store.set_erase_allowance(self.erase_credit);
        self.store
            .begin_save_of(&self.lanes, &app.tally.counters, scan.settings(), Some(now));
        self.scan = None;
        false
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
        // The whole snapshot is saved below, the motors stopped first (`control::reset`).
        self.scan = None;
        self.store.hold_erases(false);
        if self.store.is_saving() {
            let finished = self.store.finish();
            let _ = self.settle(finished, now);
        }
        self.store
            .set_erase_allowance(self.erase_credit.max(ERASES_BEFORE_RESET));
        let result = match action {
            BoardAction::Reset => self.store.save(&self.snapshot(app), None).map(drop),
            BoardAction::EraseAndReset => self.store.forget(&Scan::all(app, &self.defaults)),
        };
        self.settle(result, now)
    }

    /// What `app` keeps across a restart, as [`App::snapshot`] gives it, its settings compared
    /// with the defaults read at boot (no default configuration built).
    pub fn snapshot(&self, app: &App<N>) -> Snapshot<N> {
        Snapshot {
            lanes: app.lanes(),
            counters: app.tally.counters,
            settings: Scan::all(app, &self.defaults),
        }
    }

    /// Whether a save is in progress (or the settings it saves are being compared): the next
    /// calls of [`Keeper::update`] carry it on.
    pub fn is_saving(&self) -> bool {
        self.scan.is_some() || self.store.is_saving()
    }

    /// Take the store's erases since the last count off the budget.
    fn count_erases(&mut self) {
        let erases = self.store.erases();
        let used = erases.saturating_sub(self.health.erases);
        self.health.erases = erases;
        self.erase_credit = self.erase_credit.saturating_sub(used);
    }

    /// Account for a save's erases and outcome.
    fn settle(&mut self, result: Result<(), StoreError>, now: Instant) -> Result<(), StoreError> {
        self.count_erases();
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
                self.retry_at = Some(Instant::from_millis(
                    now.as_millis() + u64::from(self.retry_pause_ms),
                ));
                // 32 bits: RETRY_MAX_MS is 10 minutes.
                self.retry_pause_ms = (self.retry_pause_ms * 2).min(RETRY_MAX_MS as u32);
            }
        }
        result
    }

    /// One erase more every hour / [`ERASES_PER_HOUR`], up to [`ERASE_BURST`].
    fn top_up(&mut self, now: Instant) {
        const PERIOD_MS: u16 = (3_600_000 / ERASES_PER_HOUR) as u16;
        const { assert!(3_600_000 / ERASES_PER_HOUR <= u16::MAX as u32) };
        let since = *self.refilled_at.get_or_insert(now);
        if self.erase_credit >= ERASE_BURST {
            self.refilled_at = Some(now);
            return;
        }
        // Divides only once a period has passed.
        let elapsed = now.millis_since(since);
        if elapsed >= u64::from(PERIOD_MS) {
            let (earned, _) = div_rem_u64(elapsed, PERIOD_MS);
            self.erase_credit = (self.erase_credit + earned as u32).min(ERASE_BURST);
            self.refilled_at = Some(Instant::from_millis(
                since.as_millis() + earned * u64::from(PERIOD_MS),
            ));
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
    pub fn store(&mut self) -> &mut Store<F, N, C> {
        &mut self.store
    }

    /// Give the store back (e.g. its flash, for the next boot in a simulation).
    pub fn into_store(self) -> Store<F, N, C> {
        self.store
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use crate::config::Config;
    use crate::control::{Deferral, MAX_DEFERRED_STEPS};
    use std::vec::Vec;

    use embedded_storage::nor_flash::{ErrorType, NorFlashErrorKind, ReadNorFlash};

    use super::*;
    use crate::persist::ram_flash::{PAGE, RamFlash};

    struct Unit {
        app: App<3>,
        keeper: Keeper<RamFlash, 3>,
        now: Instant,
        deferral: Deferral,
    }

    impl Unit {
        fn boot() -> Self {
            let flash = RamFlash::erased(3);
            let mut app = App::new(Config::default());
            let store = Store::new(flash, 0..3 * PAGE as u32).unwrap();
            let (keeper, _) = Keeper::boot(store, &mut app);
            let mut unit = Unit {
                app,
                keeper,
                now: Instant::ZERO,
                deferral: Deferral::default(),
            };
            // The first save (it opens a page: the flash is blank), then quiet.
            let lanes = [Lane::Empty; 3];
            unit.change_lanes(lanes);
            unit.steps_until_stored(false, |s| s.lanes == lanes);
            unit
        }

        /// What a restart would restore.
        fn stored(&mut self) -> Snapshot<3> {
            let flash = self.keeper.store().flash().clone();
            Store::<_, 3>::new(flash, 0..3 * PAGE as u32).unwrap().load()
        }

        /// Steps (each `busy` or not) until the flash holds what `done` wants and no save is in
        /// progress: how many.
        fn steps_until_stored(&mut self, busy: bool, done: impl Fn(&Snapshot<3>) -> bool) -> usize {
            for steps in 1..=5000 {
                if self.deferral.piece_due(busy) {
                    self.keeper.update(&self.app, self.now).unwrap();
                }
                self.now = self.now + 1;
                if !self.keeper.is_saving() && done(&self.stored()) {
                    return steps;
                }
            }
            panic!("never saved");
        }

        fn change_lanes(&mut self, lanes: [Lane; 3]) {
            let snapshot = Snapshot {
                lanes,
                ..self.app.snapshot()
            };
            self.app.restore(&snapshot);
        }
    }

    /// A printer that talks in every step (a query each millisecond) defers each piece of a save
    /// by at most [`MAX_DEFERRED_STEPS`] steps: the save still completes, a lane change as
    /// (K + 1) times the steps it takes alone, a changed setting (its registers compared one
    /// per call) likewise.
    #[test]
    fn a_save_completes_under_a_printer_that_talks_in_every_step() {
        let bound = usize::from(MAX_DEFERRED_STEPS) + 1;
        let lanes = [Lane::Parked, Lane::Loaded, Lane::Empty];
        let mut quiet = Unit::boot();
        quiet.change_lanes(lanes);
        let alone = quiet.steps_until_stored(false, |s| s.lanes == lanes);
        let mut talking = Unit::boot();
        talking.change_lanes(lanes);
        let busy = talking.steps_until_stored(true, |s| s.lanes == lanes);
        assert_eq!(alone, 3, "laid out, then programmed in two chunks");
        assert_eq!(
            busy,
            alone * bound,
            "lanes: {alone} pieces, each after {bound} busy steps"
        );

        // A setting: saved at the next full check, its registers compared a call each.
        let setting = |s: &Snapshot<3>| s.settings.contains(&(0x22, 777));
        for unit in [&mut quiet, &mut talking] {
            unit.now = unit.now + FULL_CHECK_MS;
            assert!(unit.app.write_register(0x22, 777));
        }
        let alone = quiet.steps_until_stored(false, setting);
        let busy = talking.steps_until_stored(true, setting);
        assert!(alone > 20, "{alone} steps alone");
        assert_eq!(busy, alone * bound, "settings: {alone} pieces");
    }

    /// A step that is not busy runs its piece at once, whatever came before.
    #[test]
    fn a_quiet_step_saves_at_once() {
        let lanes = [Lane::Empty, Lane::Parked, Lane::InHub];
        let mut unit = Unit::boot();
        unit.change_lanes(lanes);
        for _ in 0..3 {
            assert!(!unit.deferral.piece_due(true));
            assert_ne!(unit.stored().lanes, lanes, "deferred after a busy step");
        }
        assert_eq!(unit.steps_until_stored(false, |s| s.lanes == lanes), 3);
    }

    /// The newest copy of a record torn (a cut before its trailer was programmed): a restart
    /// restores the copy before it and reports the torn entry, once; the next save leaves it
    /// behind.
    #[test]
    fn a_torn_newest_entry_restores_the_copy_before_it() {
        let (first, second) = (
            [Lane::Parked, Lane::Loaded, Lane::Empty],
            [Lane::InHub, Lane::Parked, Lane::Empty],
        );
        let mut unit = Unit::boot();
        for lanes in [first, second] {
            unit.change_lanes(lanes);
            unit.steps_until_stored(false, |s| s.lanes == lanes);
        }
        let mut flash = unit.keeper.store().flash().clone();
        let trailer = flash.bytes.iter().rposition(|&b| b != 0xff).unwrap() / 8 * 8;
        flash.bytes[trailer..trailer + 8].fill(0xff);
        let mut store = Store::<_, 3>::new(flash, 0..3 * PAGE as u32).unwrap();
        assert_eq!(store.load().lanes, first);
        assert_eq!(
            store.damage(),
            Damage {
                unreadable: 0,
                torn: 1
            }
        );

        let mut app = App::new(Config::default());
        let (keeper, boot) = Keeper::boot(store, &mut app);
        assert_eq!(
            boot,
            Boot::Damaged(Damage {
                unreadable: 0,
                torn: 1
            })
        );
        assert_eq!(app.lanes(), first);
        let mut unit = Unit {
            app,
            keeper,
            now: Instant::ZERO,
            deferral: Deferral::default(),
        };
        unit.change_lanes(second);
        unit.steps_until_stored(false, |s| s.lanes == second);
        let mut store = Store::<_, 3>::new(unit.keeper.store().flash().clone(), 0..3 * PAGE as u32).unwrap();
        assert_eq!(store.load().lanes, second);
        assert!(store.damage().is_none(), "{:?}", store.damage());
    }

    /// A worn flash: every erase leaves a stuck double word in its page, so every page a save
    /// opens is damaged and every load finds damage.
    #[derive(Clone)]
    struct Worn(RamFlash);

    impl ErrorType for Worn {
        type Error = NorFlashErrorKind;
    }

    impl ReadNorFlash for Worn {
        const READ_SIZE: usize = 1;

        fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
            self.0.read(offset, bytes)
        }

        fn capacity(&self) -> usize {
            self.0.capacity()
        }
    }

    impl NorFlash for Worn {
        const WRITE_SIZE: usize = 8;
        const ERASE_SIZE: usize = PAGE;

        fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
            self.0.erase(from, to)?;
            for page in (from..to).step_by(PAGE) {
                self.0.write(page + 64, &[0; 8])?;
            }
            Ok(())
        }

        fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
            self.0.write(offset, bytes)
        }
    }

    /// Boots in a reset loop (a power cut every 50 s, tearing a program) on a worn store, found
    /// damaged at every boot: the
    /// budget must not start full at every boot. Each boot starts with [`ERASES_AT_BOOT`] (one
    /// save's page moves) and earns one more a minute, so boots shorter than a minute erase at
    /// most `BOOTS × ERASES_AT_BOOT` pages in total: 2 a boot instead of up to [`ERASE_BURST`].
    #[test]
    fn a_reset_loop_on_a_store_damaged_at_every_boot_erases_at_most_two_pages_a_boot() {
        const BOOTS: u32 = 40;
        let mut flash = Worn(RamFlash::erased(3));
        for boot in 0..BOOTS {
            if boot > 0 {
                // The power cut tore a program: a double word after the last one programmed
                // reads neither erased nor as an entry.
                let last = flash.0.bytes.iter().rposition(|&b| b != 0xff).unwrap_or(0) / 8 * 8;
                if let Some(torn) = flash.0.bytes.get_mut(last + 8..last + 16) {
                    torn.copy_from_slice(&[0x5a, 0, 0x5a, 0, 0x5a, 0, 0x5a, 0]);
                }
            }
            let mut app = App::new(Config::default());
            let store = Store::<_, 3>::new(flash, 0..3 * PAGE as u32).unwrap();
            let (mut keeper, found) = Keeper::boot(store, &mut app);
            if boot > 0 {
                assert!(
                    matches!(found, Boot::Damaged(_)),
                    "boot {boot} found the store damaged"
                );
            }
            for ms in (0..50_000).step_by(5) {
                if ms % 1000 == 0 {
                    // A lane changes every second: something to save.
                    let lanes = [
                        Lane::ALL[(ms / 1000 + boot as u64) as usize % 6],
                        Lane::Empty,
                        Lane::Empty,
                    ];
                    let snapshot = Snapshot {
                        lanes,
                        ..app.snapshot()
                    };
                    app.restore(&snapshot);
                }
                let _ = keeper.update(&app, Instant::from_millis(ms));
            }
            flash = keeper.into_store().into_flash();
        }
        let erases = flash.0.erases;
        assert!(erases > 0, "the worn store was tried");
        assert!(
            erases <= BOOTS * ERASES_AT_BOOT,
            "{erases} erases in {BOOTS} boots"
        );
    }

    /// A flash that erases 128 KiB at once (as some NOR flashes do): a store keeps where its
    /// entries lie in 16 bits, so it refuses such pages rather than mislay entries.
    struct LargePages;

    impl ErrorType for LargePages {
        type Error = NorFlashErrorKind;
    }

    impl ReadNorFlash for LargePages {
        const READ_SIZE: usize = 1;

        fn read(&mut self, _: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
            bytes.fill(0xff);
            Ok(())
        }

        fn capacity(&self) -> usize {
            3 << 17
        }
    }

    impl NorFlash for LargePages {
        const WRITE_SIZE: usize = 8;
        const ERASE_SIZE: usize = 1 << 17;

        fn erase(&mut self, _: u32, _: u32) -> Result<(), Self::Error> {
            Ok(())
        }

        fn write(&mut self, _: u32, _: &[u8]) -> Result<(), Self::Error> {
            Ok(())
        }
    }

    #[test]
    fn a_flash_of_pages_over_64_kib_is_refused() {
        let store = Store::<_, 3>::new(LargePages, 0..3 << 17);
        assert!(matches!(store, Err(StoreError::Layout)));
        let store = Store::<_, 3>::new(<RamFlash>::new(Vec::new()), 0..3 * PAGE as u32);
        assert!(store.is_ok(), "pages of 2 KiB");
    }

    /// The keeper's snapshot (the one a reset saves, and the boot logs) is the App's, its
    /// settings found against the defaults read at boot.
    #[test]
    fn the_keepers_snapshot_is_the_apps() {
        let mut unit = Unit::boot();
        assert_eq!(unit.keeper.snapshot(&unit.app), unit.app.snapshot());
        unit.change_lanes([Lane::Parked, Lane::Loaded, Lane::Empty]);
        unit.app.tally.counters.tool_changes[1] = 7;
        for (address, value) in [(0x22, 777), (0x52, 2)] {
            assert!(unit.app.write_register(address, value), "{address:#04x}");
        }
        let snapshot = unit.keeper.snapshot(&unit.app);
        assert_eq!(snapshot.settings.len(), 2);
        assert_eq!(snapshot, unit.app.snapshot());
        unit.keeper.before(BoardAction::Reset, &unit.app).unwrap();
        assert_eq!(unit.stored(), snapshot, "saved before the reset");
    }

    /// A store holding settings the guards refuse (a park inside the merge: from a firmware
    /// without the guards, or flash damaged past its check sums) boots on the defaults, keeping
    /// the identity; the first full check saves the settings in force over the refused ones, so
    /// the next boot restores them without a refusal.
    #[test]
    fn refused_stored_settings_are_replaced_by_the_settings_in_force() {
        use crate::guards::Rule;
        let mut store = Store::<_, 3>::new(RamFlash::erased(3), 0..3 * PAGE as u32).unwrap();
        let mut refused = Snapshot::<3>::default();
        for setting in [(0x41, 1), (0x22, 500), (0x52, 2)] {
            refused.settings.push(setting).unwrap();
        }
        store.save(&refused, None).unwrap();
        let mut app = App::<3>::new(Config::default());
        let (keeper, _) = Keeper::boot(store, &mut app);
        assert_eq!(app.refused_rule(), Some(Rule::ParkClearsMerge));
        assert_eq!((app.config().park_mm, app.config().bowden_mm), (15, 360));
        assert_eq!(app.config().version.revision, 2, "the identity is kept");
        let mut unit = Unit {
            app,
            keeper,
            now: Instant::ZERO,
            deferral: Deferral::default(),
        };
        unit.steps_until_stored(false, |stored| stored.settings.as_slice() == [(0x52, 2)]);
        let mut restarted = App::<3>::new(Config::default());
        let store = Store::<_, 3>::new(unit.keeper.into_store().into_flash(), 0..3 * PAGE as u32).unwrap();
        let _ = Keeper::boot(store, &mut restarted);
        assert_eq!(restarted.refused_rule(), None);
        assert!(restarted.config() == unit.app.config());
    }
}
