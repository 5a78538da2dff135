//! The records in flash: a log of entries over a ring of pages, built for what the STM32G0's flash
//! does when the power goes (RM0444 §3.3): a double word is programmed once between erases, a
//! program cut short leaves a double word that reads with an ECC error, and an erase cut short
//! leaves any mix of erased, old and unreadable double words.
//!
//! Each entry is a header double word (record key, payload length, sequence number, header CRC),
//! the payload, and a trailer double word (CRC-32 of both, written last). Sequence numbers grow by
//! one per entry across the whole region, so the newest complete copy of each record wins,
//! whatever a torn erase left elsewhere. A page is opened by erasing it (unless it reads erased),
//! writing a full copy of every record and then a commit entry; a page counts only once its commit
//! is complete, so every record's newest copy is always in one page, the head. Entries are
//! appended to the head only where it reads erased; when it is full or damaged, the next page is
//! opened. So a page is only ever erased once every record in it has a newer copy, and an
//! interrupted erase or program leaves entries that are older than, or lose against, a complete
//! one. A double word that does not read (ECC) costs the entry it belongs to, never the store.
//!
//! A load is one call; a save runs a bounded piece per [`Store::step`] (module `save`), so that
//! it fits a control step, and a power loss between two pieces is no different from one during a
//! program. The store is synchronous over blocking NOR flash: the G0's flash stalls the CPU while
//! it programs or erases anyway.
//!
//! An erase stalls the CPU for tens to hundreds of milliseconds while the motors keep their last
//! duty, so no page is erased while a motor is driven ([`Store::hold_erases`]): a save that needs
//! a fresh page then waits at its erase until the motors stop. So that a save during a tool
//! change rarely waits, the next fresh page is found erased, or erased, while the unit rests
//! ([`Store::prepare_fresh_page`]).

mod save;

use embedded_storage::nor_flash::NorFlash;

use super::crc::{EntryCrc, SoftwareCrc};
use super::entry::{COMMIT, DOUBLE_WORD, EntryWriter, MAX_ENTRY, entry_size, is_complete, parse_header};
use super::records::{Record, Records};
use super::{Counters, Snapshot, StoreError};
use crate::time::Instant;

use save::Job;
pub use save::Progress;

/// Counters are written at most this often, ms (they change while the unit works).
pub const SLOW_RECORD_PERIOD_MS: u64 = 10_000;

/// Where a record's newest complete copy lies (in 16 bits: [`Store::with_crc`] takes no more
/// pages, nor larger ones).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Newest {
    sequence: u32,
    page: u16,
    /// Its offset in the page.
    offset: u16,
}

/// What a load found that a healthy store does not hold.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Damage {
    /// Double words that did not read (ECC errors) where entries were expected.
    pub unreadable: u16,
    /// Entries whose checks failed (a write or an erase cut short).
    pub torn: u16,
}

impl Damage {
    /// One more entry whose checks failed.
    fn note_torn(&mut self) {
        self.torn = self.torn.saturating_add(1);
    }

    /// Whether nothing was found.
    pub fn is_none(&self) -> bool {
        *self == Damage::default()
    }
}

/// The persisted state in a region of NOR flash, its entries checked with the CRC `C`.
#[derive(Clone)]
pub struct Store<F: NorFlash, const N: usize, C: EntryCrc = SoftwareCrc> {
    flash: F,
    crc: C,
    /// The region: its first address and its pages.
    base: u32,
    pages: u32,
    /// What the flash holds, as far as this store knows.
    saved: Records<N>,
    /// Per record ([`Record::index`]): its newest copy.
    newest: [Option<Newest>; 4],
    /// The committed page holding every record's newest copy, and where its next entry goes
    /// (`None`: full or damaged, the next write opens a fresh page). While a fresh page is being
    /// opened, that page.
    head: Option<(u32, Option<u32>)>,
    next_sequence: u32,
    /// When counters were last written.
    slow_saved_at: Option<Instant>,
    /// Page erases this store may still do (its owner's budget).
    erase_allowance: u32,
    /// Page erases done since it was made.
    erases: u32,
    damage: Damage,
    /// The entry being programmed ([`Store::step`]), or scratch space for a load.
    buffer: [u8; MAX_ENTRY],
    /// What the save in progress makes the stored records; between saves, the stored ones.
    target: Records<N>,
    /// The save in progress, advanced one bounded piece per [`Store::step`].
    job: Option<Job>,
    /// The entry of the save in progress being programmed, chunk by chunk.
    writing: Option<Writing>,
    /// Where the fresh page being opened holds each record so far.
    placed: [Option<Newest>; 4],
    /// When the save in progress writes counters: the time to note once it completes.
    slow_due: Option<Option<Instant>>,
    /// Whether the current step programmed or erased (and so stalled the CPU).
    flash_work: bool,
    /// A motor is driven: no page is erased now ([`Store::hold_erases`]).
    erases_held: bool,
    /// A page found to read erased, for the next page move ([`Store::prepare_fresh_page`]),
    /// and the page being checked, with how far.
    ready: Option<u32>,
    checking: Option<(u32, u32)>,
}

/// An entry of the save in progress, programmed a chunk per step.
#[derive(Clone)]
struct Writing {
    entry: EntryWriter,
    key: u8,
    /// Where it goes.
    place: Newest,
}

fn page_size<F: NorFlash>() -> u32 {
    F::ERASE_SIZE as u32
}

impl<F: NorFlash, const N: usize> Store<F, N> {
    /// A store over `range` of `flash` (see [`Store::with_crc`]), its CRC computed in software.
    pub fn new(flash: F, range: core::ops::Range<u32>) -> Result<Self, StoreError> {
        Store::with_crc(flash, SoftwareCrc::default(), range)
    }
}

impl<F: NorFlash, const N: usize, C: EntryCrc> Store<F, N, C> {
    /// A store over `range` of `flash`: page aligned, at least three pages and at most 65,536 of
    /// at most 64 KiB, on a flash that programs whole double words (or less) and reads bytes;
    /// `crc` computes its entries' CRC.
    pub fn with_crc(flash: F, crc: C, range: core::ops::Range<u32>) -> Result<Self, StoreError> {
        let page = page_size::<F>();
        let fits = page > 0
            && range.start.is_multiple_of(page)
            && range.end.is_multiple_of(page)
            && range.end >= range.start.saturating_add(3 * page)
            && DOUBLE_WORD.is_multiple_of(F::WRITE_SIZE)
            && DOUBLE_WORD.is_multiple_of(F::READ_SIZE)
            && F::ERASE_SIZE.is_multiple_of(DOUBLE_WORD)
            && F::ERASE_SIZE >= 4 * MAX_ENTRY
            // Where an entry lies is kept in 16 bits (`Newest`).
            && F::ERASE_SIZE <= 1 << 16
            && (range.end - range.start) / page <= 1 << 16;
        if !fits {
            return Err(StoreError::Layout);
        }
        Ok(Store {
            flash,
            crc,
            base: range.start,
            pages: (range.end - range.start) / page,
            saved: Records::blank(),
            newest: [None; 4],
            head: None,
            next_sequence: 0,
            slow_saved_at: None,
            erase_allowance: u32::MAX,
            erases: 0,
            damage: Damage::default(),
            buffer: [0; MAX_ENTRY],
            target: Records::blank(),
            job: None,
            writing: None,
            placed: [None; 4],
            slow_due: None,
            flash_work: false,
            erases_held: false,
            ready: None,
            checking: None,
        })
    }

    /// The flash, e.g. to look at it in tests.
    pub fn flash(&mut self) -> &mut F {
        &mut self.flash
    }

    /// Give the flash back.
    pub fn into_flash(self) -> F {
        self.flash
    }

    /// Page erases done since this store was made.
    pub fn erases(&self) -> u32 {
        self.erases
    }

    /// Allow at most `erases` more page erases: an operation that needs more fails
    /// ([`StoreError::EraseBudget`]) without erasing.
    pub fn set_erase_allowance(&mut self, erases: u32) {
        self.erase_allowance = erases;
    }

    /// What the last [`Store::load`] found damaged.
    pub fn damage(&self) -> Damage {
        self.damage
    }

    fn page_address(&self, page: u32) -> u32 {
        self.base + page * page_size::<F>()
    }

    /// What the flash holds: each record's newest complete copy in a committed page, or its
    /// default (lanes unknown, counters zero, no settings) when there is none or it does not
    /// decode. Never fails: a double word that does not read costs only the entry it belongs to.
    pub fn load(&mut self) -> Snapshot<N> {
        self.saved = Records::blank();
        self.newest = [None; 4];
        self.head = None;
        self.damage = Damage::default();
        self.job = None;
        self.writing = None;
        self.ready = None;
        self.checking = None;
        let (mut newest_header, mut newest_commit) = (None::<u32>, None::<u32>);
        for page in 0..self.pages {
            let scan = self.scan_page(page);
            newest_header = newest_header.max(scan.newest_header);
            if scan.committed && scan.newest_header > newest_commit {
                newest_commit = scan.newest_header;
                self.head = Some((page, scan.tail));
            }
        }
        self.next_sequence = newest_header.map_or(0, |s| s.wrapping_add(1));
        for record in Record::ALL {
            let Some(newest) = self.newest[record.index()] else {
                continue;
            };
            if let Some(len) = self.find(newest, record)
                && let Some(payload) = self.buffer.get(DOUBLE_WORD..DOUBLE_WORD + len)
            {
                self.saved.decode(record, payload);
            }
        }
        self.target.copy_from(&self.saved);
        self.saved.snapshot()
    }

    /// Read the header double word at `address`: `Ok(None)` when erased, `Err` when it does not
    /// read or is not a header; the key is a record's or [`COMMIT`].
    fn header(&mut self, address: u32) -> Result<Option<(u8, usize, u32)>, NotHeader> {
        let mut word = [0u8; DOUBLE_WORD];
        self.flash
            .read(address, &mut word)
            .map_err(|_| NotHeader::Unreadable)?;
        if word == [0xff; DOUBLE_WORD] {
            return Ok(None);
        }
        parse_header(&word).map(Some).ok_or(NotHeader::Torn)
    }

    /// Read the whole entry at `address` whose payload is `len` bytes into the buffer: whether it
    /// is complete (it reads and its trailer matches).
    fn entry_complete(&mut self, address: u32, len: usize) -> bool {
        let Some(bytes) = self.buffer.get_mut(..entry_size(len)) else {
            return false;
        };
        self.flash.read(address, bytes).is_ok() && is_complete(bytes, &mut self.crc)
    }

    /// Walk one page's entries, each checked whole. In a committed page, note each record's
    /// newest complete copy, and as damage a record whose newest entry there is torn (as the
    /// damage the walk met); damage in a page that does not count (a torn erase's leftovers) is
    /// not reported.
    fn scan_page(&mut self, page: u32) -> PageScan {
        // Per record: the newest sequence number of its headers, and its newest complete copy.
        let mut newest_headers: [Option<u32>; 4] = [None; 4];
        let mut complete: [Option<Newest>; 4] = [None; 4];
        let mut scan = PageScan {
            newest_header: None,
            committed: false,
            tail: None,
        };
        let damage_before = self.damage;
        let (start, size) = (self.page_address(page), page_size::<F>());
        let mut offset = 0;
        while offset + DOUBLE_WORD as u32 <= size {
            let (key, len, sequence) = match self.header(start + offset) {
                Ok(Some(header)) => header,
                Ok(None) => {
                    scan.tail = Some(offset);
                    break;
                }
                Err(NotHeader::Unreadable) => {
                    self.damage.unreadable = self.damage.unreadable.saturating_add(1);
                    break;
                }
                Err(NotHeader::Torn) => {
                    self.damage.note_torn();
                    break;
                }
            };
            let entry = entry_size(len) as u32;
            if offset + entry > size {
                self.damage.note_torn();
                break;
            }
            scan.newest_header = scan.newest_header.max(Some(sequence));
            let is_complete = self.entry_complete(start + offset, len);
            if key == COMMIT {
                // The last commit entry of the page decides.
                scan.committed = is_complete;
            } else if let Some(record) = Record::from_key(key) {
                let index = record.index();
                newest_headers[index] = newest_headers[index].max(Some(sequence));
                if is_complete && complete[index].is_none_or(|c| sequence > c.sequence) {
                    complete[index] = Some(Newest {
                        sequence,
                        page: page as u16,
                        offset: offset as u16,
                    });
                }
            }
            offset += entry;
        }
        if scan.committed {
            self.note_newest(&newest_headers, &complete);
        } else {
            self.damage = damage_before;
        }
        scan
    }

    /// A committed page's records: per record the newest sequence number of its headers and its
    /// newest complete copy. A copy newer than the one known is the newest; a header newer than
    /// the page's complete copy is a torn entry.
    fn note_newest(&mut self, newest_headers: &[Option<u32>; 4], complete: &[Option<Newest>; 4]) {
        for ((newest, &header), &complete) in self.newest.iter_mut().zip(newest_headers).zip(complete) {
            let known = newest.map(|known| known.sequence);
            if header <= known {
                continue;
            }
            if complete.map(|c| c.sequence) != header {
                self.damage.note_torn();
            }
            if let Some(complete) = complete
                && Some(complete.sequence) > known
            {
                *newest = Some(complete);
            }
        }
    }

    /// Read `record`'s newest entry into the buffer: its payload's length.
    fn find(&mut self, newest: Newest, record: Record) -> Option<usize> {
        let address = self.page_address(newest.page.into()) + u32::from(newest.offset);
        let (key, len, sequence) = self.header(address).ok()??;
        if key != record as u8 || sequence != newest.sequence || !self.entry_complete(address, len) {
            return None;
        }
        Some(len)
    }
}

/// Why a double word where an entry was expected is not its header.
enum NotHeader {
    /// It does not read (ECC error).
    Unreadable,
    /// It reads, but not as a header (a program or an erase cut short).
    Torn,
}

/// What one page's walk found.
struct PageScan {
    /// The newest sequence number of any entry header (complete entry or not).
    newest_header: Option<u32>,
    /// Whether the page's commit entry is complete.
    committed: bool,
    /// Where an entry may be appended.
    tail: Option<u32>,
}
