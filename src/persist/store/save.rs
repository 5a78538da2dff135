//! Saving, a bounded piece at a time: a save is a small state machine ([`Job`]) that
//! [`Store::step`] advances by one piece per call (an entry laid out in the buffer, one chunk of
//! it programmed, a slice of a page's erased check, one page erase), so that a save fits the control step it runs in. Every piece
//! keeps the guarantees of the store (module `store`): entries are programmed in order, their
//! trailer last, only where the flash reads erased, and a fresh page counts only once its commit
//! entry is complete. So a cut between two pieces is no different from a cut during one.

use embedded_storage::nor_flash::NorFlash;

use super::{COMMIT, EntryWriter, Newest, Record, Records, SLOW_RECORD_PERIOD_MS, Store, Writing};
use super::{Counters, EntryCrc, Snapshot, StoreError, entry_size, page_size};
use crate::time::Instant;
use crate::unit::Lane;

/// Page moves one save may try (each erases at most one page) before it gives up.
const MOVES_PER_SAVE: u8 = 2;
/// Bytes of an entry programmed per step: 2 double words, at most 0.25 ms of CPU stall on the
/// STM32G071 (125 µs each at most), so a piece under a running motor moves a fraction of a
/// millimetre uncommanded.
const PROGRAM_CHUNK: usize = 16;
/// Bytes of a fresh page checked for erased per step.
const CHECK_CHUNK: usize = 128;
/// Steps of the largest entry: its layout, then its chunks.
const ENTRY_STEPS: usize = 1 + super::MAX_ENTRY.div_ceil(PROGRAM_CHUNK);

/// A save in progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Job {
    /// Append the records whose bits ([`Record::index`]) are set to the head page, one entry
    /// each; any failure moves to a fresh page.
    Append { pending: u8 },
    /// Pick the next page that holds no record's newest copy, for the `tries`th page move.
    Move { tries: u8 },
    /// Open `page` (the `tries`th move of this save): check that it reads erased, erase it if
    /// not, copy every record, commit.
    Open { page: u32, tries: u8, stage: Stage },
}

/// Where the opening of a fresh page stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Stage {
    /// Reading the page from `offset` for anything not erased.
    Check {
        offset: u32,
    },
    Erase,
    /// Writing the full copy: the next record of [`Record::ALL`] (past the last: the commit).
    Copy {
        next: u8,
    },
}

/// What a slice of a page's erased check found.
enum Slice {
    /// Something in it is not erased.
    Written,
    /// It reads erased, and it was the page's last.
    Erased,
    /// It reads erased; the next slice starts here.
    More(u32),
}

/// What one [`Store::step`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    /// The save is complete (or there was none).
    pub done: bool,
    /// It programmed or erased the flash (which stalls the CPU on the STM32G0).
    pub wrote: bool,
}

/// Whether the `len` bytes (at most `MAX`, the caller's chunk) at `address` of `flash` read
/// erased.
fn reads_erased<F: NorFlash, const MAX: usize>(flash: &mut F, address: u32, len: usize) -> bool {
    let mut bytes = [0u8; MAX];
    let Some(bytes) = bytes.get_mut(..len) else {
        return false;
    };
    flash.read(address, bytes).is_ok() && bytes.iter().all(|&b| b == 0xff)
}

fn bit(record: Record) -> u8 {
    1 << record.index()
}

impl<F: NorFlash, const N: usize, C: EntryCrc> Store<F, N, C> {
    /// Whether a save is in progress ([`Store::step`] advances it).
    pub fn is_saving(&self) -> bool {
        self.job.is_some()
    }

    /// Start saving what changed in `snapshot`: lanes and settings at once, counters at most
    /// every [`SLOW_RECORD_PERIOD_MS`] (`now` `None`: whatever the period, e.g. before a reset).
    /// Returns how many records it will write (0: nothing to save, no save started). A save in
    /// progress is abandoned (what it completed stays saved).
    pub fn begin_save(&mut self, snapshot: &Snapshot<N>, now: Option<Instant>) -> u8 {
        self.begin_save_of(&snapshot.lanes, &snapshot.counters, &snapshot.settings, now)
    }

    /// [`Store::begin_save`] of the snapshot of `lanes`, `counters` and `settings` (no snapshot
    /// built on the way).
    pub(in crate::persist) fn begin_save_of(
        &mut self,
        lanes: &[Lane; N],
        counters: &Counters<N>,
        settings: &[(u8, u16)],
        now: Option<Instant>,
    ) -> u8 {
        self.target.set(lanes, counters, settings);
        self.begin_changed(now, true).count_ones() as u8
    }

    /// Start saving the target's records that differ from the stored ones (settings and
    /// identity only when `settings`), counters only when due: their bits.
    fn begin_changed(&mut self, now: Option<Instant>, settings: bool) -> u8 {
        let changed = self.changed(&self.target, now, settings);
        if changed & bit(Record::Counters) == 0 {
            // Not due (or unchanged): the target stays the stored records but for the changes.
            self.target.counters = self.saved.counters;
            self.slow_due = None;
        } else {
            self.slow_due = Some(now);
        }
        if changed != 0 {
            self.begin(changed);
        }
        changed
    }

    /// Start saving `lanes`, and `counters` when given and due (as in [`Store::begin_save`]),
    /// the settings as stored: whether any differ from the stored ones (`false`: nothing to
    /// save, no save started). Cheaper than a snapshot when the settings are known unchanged.
    pub fn begin_changes(&mut self, lanes: [Lane; N], counters: Option<&Counters<N>>, now: Instant) -> bool {
        // Between saves the target is the stored records: only these two can differ.
        self.target.lanes = lanes;
        if let Some(counters) = counters {
            self.target.counters = *counters;
        }
        self.begin_changed(Some(now), false) != 0
    }

    /// Start forgetting everything but the identity (`X42`): blank records (lanes unknown,
    /// counters zero, no settings) written as ordinary entries, so a power cut leaves each record
    /// either as it was or blank. (Erasing pages instead could bring old records back: a cut
    /// erase leaves old entries behind.)
    ///
    /// `settings` are the unit's settings as they are now: their identity registers are kept,
    /// whether or not a save has stored them yet (`W52 2` at once followed by `X42` keeps the 2).
    pub fn begin_forget(&mut self, settings: &[(u8, u16)]) {
        self.target.blank_but_identity_of(settings);
        let identity = if self.target.identity == self.saved.identity {
            0
        } else {
            bit(Record::Identity)
        };
        self.slow_due = None;
        self.begin(bit(Record::Settings) | bit(Record::Counters) | bit(Record::Lanes) | identity);
    }

    /// Append `records` to the head, or open a fresh page when there is no head to append to.
    fn begin(&mut self, records: u8) {
        self.writing = None;
        self.job = Some(match self.head {
            Some((_, Some(_))) => Job::Append { pending: records },
            _ => Job::Move { tries: 0 },
        });
    }

    /// Do one bounded piece of the save in progress. A save that fails leaves every record as it
    /// was or as it was being written; the next one tries again on a fresh page.
    pub fn step(&mut self) -> Result<Progress, StoreError> {
        let Some(job) = self.job else {
            return Ok(Progress {
                done: true,
                wrote: false,
            });
        };
        self.flash_work = false;
        let next = match self.advance(job) {
            Ok(next) => Ok(next),
            Err(error) => self.recover(job, error),
        };
        self.job = next.as_ref().ok().copied().flatten();
        match next {
            Ok(next) => {
                if next.is_none()
                    && let Some(at) = self.slow_due.take()
                {
                    self.slow_saved_at = at;
                }
                Ok(Progress {
                    done: next.is_none(),
                    wrote: self.flash_work,
                })
            }
            Err(error) => {
                self.writing = None;
                self.slow_due = None;
                // What the flash holds: the records the failed save did not complete.
                self.target.copy_from(&self.saved);
                Err(error)
            }
        }
    }

    /// The most steps a save takes: appending all four records, then every page move it may
    /// try (pick a page, check it, erase it, copy every record, commit).
    pub fn max_steps_per_save() -> usize {
        let check = page_size::<F>().div_ceil(CHECK_CHUNK as u32) as usize;
        4 * ENTRY_STEPS + usize::from(MOVES_PER_SAVE) * (1 + check + 1 + 5 * ENTRY_STEPS)
    }

    /// Run the save in progress to its end ([`Store::max_steps_per_save`] steps at most: one
    /// that does not end by then is given up).
    pub fn finish(&mut self) -> Result<(), StoreError> {
        for _ in 0..Self::max_steps_per_save() {
            if self.step()?.done {
                return Ok(());
            }
        }
        self.job = None;
        Err(StoreError::Flash)
    }

    /// Save what changed, whole (see [`Store::begin_save`]); how many records it wrote.
    pub fn save(&mut self, snapshot: &Snapshot<N>, now: Option<Instant>) -> Result<u8, StoreError> {
        let records = self.begin_save(snapshot, now);
        self.finish()?;
        Ok(records)
    }

    /// Forget everything but the identity in `settings`, whole (see [`Store::begin_forget`]).
    pub fn forget(&mut self, settings: &[(u8, u16)]) -> Result<(), StoreError> {
        self.begin_forget(settings);
        self.finish()
    }

    /// Erase the whole region, then write the identity this store knows (nothing before a
    /// [`Store::load`]) and blank records, whole. For a region that is past saving: unlike
    /// [`Store::forget`], a cut during it can lose every record.
    pub fn wipe(&mut self) -> Result<(), StoreError> {
        self.job = None;
        self.ready = None;
        for page in 0..self.pages {
            self.erase(page)?;
        }
        self.newest = [None; 4];
        self.head = None;
        self.target.blank_but_identity(&self.saved);
        self.slow_due = None;
        self.begin(0);
        self.finish()
    }

    /// The records of `next` that differ from the stored ones and are due, as bits; its
    /// settings and identity only when `settings` (they are compared a register at a time).
    fn changed(&self, next: &Records<N>, now: Option<Instant>, settings: bool) -> u8 {
        let saved = &self.saved;
        let bit_if = |differs: bool, record| if differs { bit(record) } else { 0 };
        bit_if(next.lanes != saved.lanes, Record::Lanes)
            | bit_if(settings && next.settings != saved.settings, Record::Settings)
            | bit_if(settings && next.identity != saved.identity, Record::Identity)
            | bit_if(
                next.counters != saved.counters && self.slow_allowed(now),
                Record::Counters,
            )
    }

    /// Whether counters may be written at `now` (`None`: whenever).
    fn slow_allowed(&self, now: Option<Instant>) -> bool {
        now.is_none_or(|now| {
            self.slow_saved_at
                .is_none_or(|at| now.millis_since(at) >= SLOW_RECORD_PERIOD_MS)
        })
    }

    /// One piece of `job`; the job left (`None`: the save is complete).
    fn advance(&mut self, job: Job) -> Result<Option<Job>, StoreError> {
        if self.writing.is_some() {
            return self.program_chunk(job);
        }
        match job {
            Job::Append { pending } => {
                let (Some(record), Some((page, _))) = (
                    Record::ALL.into_iter().find(|&r| pending & bit(r) != 0),
                    self.head,
                ) else {
                    return Ok(None);
                };
                // Laid out (encoded) in a step of its own, programmed in the next ones: a lane
                // change takes three steps, each well within what a control step leaves.
                self.prepare(page, record as u8, Some(record))?;
                Ok(Some(Job::Append {
                    pending: pending & !bit(record),
                }))
            }
            Job::Move { tries } => {
                let page = self.fresh_page().ok_or(StoreError::Flash)?;
                // Whatever happens next, the page after this one is tried next.
                self.head = Some((page, None));
                self.placed = [None; 4];
                let stage = if self.ready.take() == Some(page) {
                    self.head = Some((page, Some(0)));
                    Stage::Copy { next: 0 }
                } else {
                    Stage::Check { offset: 0 }
                };
                Ok(Some(Job::Open { page, tries, stage }))
            }
            Job::Open { page, tries, stage } => {
                let stage = match stage {
                    Stage::Check { offset } => self.check_erased(page, offset),
                    Stage::Erase if self.erases_held => Stage::Erase,
                    Stage::Erase => {
                        self.erase(page)?;
                        self.head = Some((page, Some(0)));
                        Stage::Copy { next: 0 }
                    }
                    Stage::Copy { next } => {
                        let record = Record::ALL.get(usize::from(next)).copied();
                        self.prepare(page, record.map_or(COMMIT, |r| r as u8), record)?;
                        Stage::Copy { next: next + 1 }
                    }
                };
                Ok(Some(Job::Open { page, tries, stage }))
            }
        }
    }

    /// The page the next page move opens: the page after the head that holds no record's
    /// newest copy (`None`: there is none).
    fn fresh_page(&self) -> Option<u32> {
        let after = self.head.map_or(self.pages - 1, |(page, _)| page);
        let mut page = after;
        loop {
            page = if page + 1 < self.pages { page + 1 } else { 0 };
            if page == after {
                return None;
            }
            if self
                .newest
                .iter()
                .flatten()
                .all(|newest| u32::from(newest.page) != page)
            {
                return Some(page);
            }
        }
    }

    /// No page is erased while `held` (a motor is driven): a save that needs an erase waits at
    /// it, and so does [`Store::prepare_fresh_page`].
    pub fn hold_erases(&mut self, held: bool) {
        self.erases_held = held;
    }

    /// Whether the page the next page move opens is known to read erased.
    pub fn fresh_page_ready(&self) -> bool {
        self.ready.is_some() && self.ready == self.fresh_page()
    }

    /// One bounded piece of readying the page the next page move opens, between saves: a slice
    /// of its erased check, or its erase (none while erases are held). `wrote` when it erased;
    /// `done` once the page is ready.
    pub fn prepare_fresh_page(&mut self) -> Result<Progress, StoreError> {
        let (done, idle) = (
            Progress {
                done: true,
                wrote: false,
            },
            Progress {
                done: false,
                wrote: false,
            },
        );
        if self.job.is_some() {
            return Ok(done);
        }
        let Some(page) = self.fresh_page() else {
            return Err(StoreError::Flash);
        };
        if self.ready == Some(page) {
            return Ok(done);
        }
        let offset = match self.checking {
            Some((checked, offset)) if checked == page => offset,
            _ => 0,
        };
        self.checking = None;
        match self.check_slice(page, offset) {
            Slice::Erased => {
                self.ready = Some(page);
                Ok(done)
            }
            Slice::More(next) => {
                self.checking = Some((page, next));
                Ok(idle)
            }
            Slice::Written if self.erases_held => Ok(idle),
            Slice::Written => {
                self.erase(page)?;
                self.ready = Some(page);
                Ok(Progress {
                    done: true,
                    wrote: true,
                })
            }
        }
    }

    /// After a failed piece of `job`: move to a fresh page, unless this save has moved as often
    /// as it may.
    fn recover(&mut self, job: Job, error: StoreError) -> Result<Option<Job>, StoreError> {
        self.writing = None;
        let tries = match job {
            Job::Append { .. } => 0,
            Job::Move { tries } | Job::Open { tries, .. } => tries + 1,
        };
        if tries >= MOVES_PER_SAVE || error == StoreError::Layout {
            return Err(error);
        }
        Ok(Some(Job::Move { tries }))
    }

    /// Check the next slice of `page` from `offset`: the stage that follows.
    fn check_erased(&mut self, page: u32, offset: u32) -> Stage {
        match self.check_slice(page, offset) {
            Slice::Written => Stage::Erase,
            Slice::Erased => {
                self.head = Some((page, Some(0)));
                Stage::Copy { next: 0 }
            }
            Slice::More(offset) => Stage::Check { offset },
        }
    }

    /// Read the slice of `page` from `offset` for anything not erased.
    fn check_slice(&mut self, page: u32, offset: u32) -> Slice {
        let size = page_size::<F>();
        let len = CHECK_CHUNK.min(size.saturating_sub(offset) as usize);
        let start = self.page_address(page) + offset;
        if !reads_erased::<F, CHECK_CHUNK>(&mut self.flash, start, len) {
            Slice::Written
        } else if offset + len as u32 >= size {
            Slice::Erased
        } else {
            Slice::More(offset + len as u32)
        }
    }

    pub(super) fn erase(&mut self, page: u32) -> Result<(), StoreError> {
        if self.erase_allowance == 0 {
            return Err(StoreError::EraseBudget);
        }
        self.erase_allowance -= 1;
        self.erases = self.erases.saturating_add(1);
        self.flash_work = true;
        let start = self.page_address(page);
        self.flash
            .erase(start, start + page_size::<F>())
            .map_err(|_| StoreError::Flash)
    }

    /// Lay out the entry (`key`, `record` of the target, or no payload) for the head `page`'s
    /// tail. The head is closed until the entry is complete, so that a save that fails on the way
    /// leaves the next one to a fresh page.
    fn prepare(&mut self, page: u32, key: u8, record: Option<Record>) -> Result<(), StoreError> {
        let Some((_, Some(offset))) = self.head else {
            return Err(StoreError::Flash);
        };
        self.head = Some((page, None));
        // Encoded in place: no copy of the record on its way to the flash.
        let len = record.map_or(0, |record| {
            self.target.encode(record, EntryWriter::payload(&mut self.buffer))
        });
        if offset as usize + entry_size(len) > F::ERASE_SIZE {
            return Err(StoreError::Full);
        }
        let sequence = self.next_sequence;
        // Spent even if the entry is never completed: a torn entry must not share its number.
        self.next_sequence = sequence.wrapping_add(1);
        self.writing = Some(Writing {
            entry: EntryWriter::new(&mut self.buffer, key, sequence, len),
            key,
            place: Newest {
                sequence,
                page: page as u16,
                offset: offset as u16,
            },
        });
        Ok(())
    }

    /// Program the next chunk of the entry being written (only where the flash reads erased: a
    /// double word is programmed once, PROGERR otherwise); once it is complete, account for it.
    fn program_chunk(&mut self, job: Job) -> Result<Option<Job>, StoreError> {
        let Some(writing) = self.writing.as_mut() else {
            return Ok(Some(job));
        };
        let place = writing.place;
        let Some((offset, bytes)) = writing
            .entry
            .next_chunk(&mut self.buffer, PROGRAM_CHUNK, &mut self.crc)
        else {
            return Err(StoreError::Flash);
        };
        let done = offset + bytes.len() == writing.entry.size();
        let address =
            self.base + u32::from(place.page) * page_size::<F>() + u32::from(place.offset) + offset as u32;
        if !reads_erased::<F, PROGRAM_CHUNK>(&mut self.flash, address, bytes.len()) {
            return Err(StoreError::Flash);
        }
        self.flash_work = true;
        self.flash.write(address, bytes).map_err(|_| StoreError::Flash)?;
        if !done {
            return Ok(Some(job));
        }
        let size = writing.entry.size() as u32;
        let key = writing.key;
        self.writing = None;
        self.head = Some((place.page.into(), Some(u32::from(place.offset) + size)));
        Ok(self.entry_written(job, key, place))
    }

    /// An entry of `job` is complete: the job left.
    fn entry_written(&mut self, job: Job, key: u8, place: Newest) -> Option<Job> {
        let record = Record::from_key(key);
        match job {
            Job::Append { pending } => {
                if let Some(record) = record {
                    self.newest[record.index()] = Some(place);
                    self.saved.copy_record(record, &self.target);
                }
                (pending != 0).then_some(job)
            }
            Job::Open { .. } => match record {
                Some(record) => {
                    self.placed[record.index()] = Some(place);
                    Some(job)
                }
                // The commit: the fresh page holds every record's newest copy.
                None => {
                    self.newest = self.placed;
                    self.saved.copy_from(&self.target);
                    None
                }
            },
            Job::Move { .. } => Some(job),
        }
    }
}

#[cfg(test)]
mod tests {
    //! No page is erased while a motor is driven, and a page readied at rest lets a save under
    //! motion move pages without one.

    use super::*;
    use crate::persist::ram_flash::{PAGE, RamFlash};
    use crate::persist::{Counters, Settings};

    type TestStore = Store<RamFlash, 3>;

    fn snapshot(round: usize) -> Snapshot<3> {
        let lane = [Lane::Parked, Lane::Empty, Lane::Loaded][round % 3];
        Snapshot {
            lanes: [lane; 3],
            counters: Counters::default(),
            settings: Settings::new(),
        }
    }

    /// A store of three pages that has erased one (every page has been written): the next page
    /// move needs an erase, unless a page is readied first.
    fn worn_store() -> (TestStore, usize) {
        let mut store = TestStore::new(RamFlash::erased(3), 0..3 * PAGE as u32).unwrap();
        store.load();
        let mut round = 0;
        while store.erases() == 0 {
            store.save(&snapshot(round), None).unwrap();
            round += 1;
        }
        (store, round)
    }

    /// Saves of `round` on, erases held, until one does not complete within a save's steps:
    /// returns how many completed, and whether one was left waiting.
    fn save_while_held(store: &mut TestStore, round: &mut usize, saves: usize) -> (usize, bool) {
        store.hold_erases(true);
        for completed in 0..saves {
            store.begin_save(&snapshot(*round), None);
            *round += 1;
            let done = (0..TestStore::max_steps_per_save()).any(|_| store.step().unwrap().done);
            if !done {
                return (completed, true);
            }
        }
        (saves, false)
    }

    #[test]
    fn a_save_that_needs_an_erase_waits_while_a_motor_is_driven() {
        let (mut store, mut round) = worn_store();
        let erases = store.erases();
        // A page holds a few dozen lane entries: the head fills well within 500 saves.
        let (_, waiting) = save_while_held(&mut store, &mut round, 500);
        assert!(waiting, "a save reached a page move");
        assert_eq!(store.erases(), erases, "nothing erased while held");
        assert!(store.is_saving());
        store.hold_erases(false);
        store.finish().unwrap();
        assert_eq!(store.erases(), erases + 1);
        assert_eq!(store.load(), snapshot(round - 1));
    }

    #[test]
    fn a_page_readied_at_rest_lets_saves_under_motion_move_pages_without_an_erase() {
        let (mut store, mut round) = worn_store();
        assert!(!store.fresh_page_ready());
        store.hold_erases(true);
        for _ in 0..100 {
            assert!(!store.prepare_fresh_page().unwrap().done, "no erase while held");
        }
        store.hold_erases(false);
        let mut pieces = 0;
        while !store.prepare_fresh_page().unwrap().done {
            pieces += 1;
            assert!(pieces < PAGE, "readied in bounded pieces");
        }
        assert!(store.fresh_page_ready());
        let erases = store.erases();
        // Saves under motion until the readied page is taken: each completes, none erases.
        let mut saves = 0;
        while store.fresh_page_ready() {
            let (completed, waiting) = save_while_held(&mut store, &mut round, 1);
            assert!(!waiting && completed == 1, "save {saves} completed");
            saves += 1;
            assert!(saves < 500);
        }
        assert!(saves > 1, "{saves} saves");
        assert_eq!(store.erases(), erases);
        assert_eq!(store.load(), snapshot(round - 1));
    }
}
