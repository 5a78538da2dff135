//! What the unit keeps across restarts, and how it is kept in flash.
//!
//! Three records, each written only when it changed: the lane state (where each slot's filament
//! is) and the settings at once, so a power cut leaves the last known position and setting; the
//! counters at most every [`SLOW_RECORD_PERIOD_MS`] (and before a reset). They live in a
//! [`sequential_storage`] map over any `embedded-storage-async` NOR flash: the map writes each
//! record as a new CRC-protected item and wears the pages evenly, so a power cut during a write
//! leaves the previous record readable. A record that does not decode (another format, an
//! older layout) is ignored and the unit starts from its defaults. [`Keeper`] is the policy the
//! firmware and the simulator share: restore at boot, save as the App changes.

use embedded_storage_async::nor_flash::NorFlash;
use heapless::Vec;
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

use crate::app::App;
use crate::app::BoardAction;
use crate::time::Instant;
use crate::unit::Lane;

/// Settings registers a unit has at most (plain settings and two thresholds per sensor).
pub const MAX_SETTINGS: usize = 64;
/// Counters are written at most this often, ms (they change while the unit works).
pub const SLOW_RECORD_PERIOD_MS: u64 = 10_000;
/// [`Keeper::update`] compares counters and settings this often; lanes every step, ms.
pub const FULL_CHECK_MS: u64 = 1000;
/// The layout version of every record: a record with another is ignored.
const FORMAT: u8 = 1;
/// Room for the largest record (the settings: a 2-byte header and 3 bytes each) with its key and
/// the map's word alignment.
const BUFFER: usize = 8 + 3 * MAX_SETTINGS;

/// The record keys of the map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
enum Record {
    Lanes = 1,
    Counters = 2,
    Settings = 3,
}

/// Counters of the unit's life.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Counters<const N: usize> {
    /// Errors raised (register 0x04).
    pub drive_errors: u16,
    /// Completed tool changes per slot.
    pub tool_changes: [u16; N],
    /// Errors raised while driving each slot.
    pub failures: [u16; N],
    /// Filament fed or pulled by each slot's completed moves, mm.
    pub fed_mm: [u32; N],
}

impl<const N: usize> Default for Counters<N> {
    fn default() -> Self {
        Counters {
            drive_errors: 0,
            tool_changes: [0; N],
            failures: [0; N],
            fed_mm: [0; N],
        }
    }
}

/// Everything the unit keeps across a restart.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Snapshot<const N: usize> {
    /// Where each slot's filament is.
    pub lanes: [Lane; N],
    /// The counters.
    pub counters: Counters<N>,
    /// Every writable setting register and its value.
    pub settings: Vec<(u8, u16), MAX_SETTINGS>,
}

impl<const N: usize> Default for Snapshot<N> {
    fn default() -> Self {
        Snapshot {
            lanes: [Lane::Unknown; N],
            counters: Counters::default(),
            settings: Vec::new(),
        }
    }
}

/// One record's bytes.
type Bytes = Vec<u8, BUFFER>;

fn lane_code(lane: Lane) -> u8 {
    match lane {
        Lane::Unknown => 0,
        Lane::Empty => 1,
        Lane::Parked => 2,
        Lane::InHub => 3,
        Lane::AtFsensor => 4,
        Lane::Loaded => 5,
    }
}

fn lane_from(code: u8) -> Option<Lane> {
    Some(match code {
        0 => Lane::Unknown,
        1 => Lane::Empty,
        2 => Lane::Parked,
        3 => Lane::InHub,
        4 => Lane::AtFsensor,
        5 => Lane::Loaded,
        _ => return None,
    })
}

/// Reads a record's fields in order; every read past the end gives `None`.
struct Reader<'a>(&'a [u8]);

impl Reader<'_> {
    fn u8(&mut self) -> Option<u8> {
        let (&first, rest) = self.0.split_first()?;
        self.0 = rest;
        Some(first)
    }

    fn u16(&mut self) -> Option<u16> {
        Some(u16::from_le_bytes([self.u8()?, self.u8()?]))
    }

    fn u32(&mut self) -> Option<u32> {
        Some(u32::from(self.u16()?) | (u32::from(self.u16()?) << 16))
    }
}

/// Append `bytes`; every record built here fits [`BUFFER`].
fn put(out: &mut Bytes, bytes: &[u8]) {
    let _ = out.extend_from_slice(bytes);
}

fn header(slots: usize) -> Bytes {
    let mut out = Bytes::new();
    put(&mut out, &[FORMAT, slots as u8]);
    out
}

fn encode_lanes<const N: usize>(lanes: &[Lane; N]) -> Bytes {
    let mut out = header(N);
    for &lane in lanes {
        put(&mut out, &[lane_code(lane)]);
    }
    out
}

fn encode_counters<const N: usize>(counters: &Counters<N>) -> Bytes {
    let mut out = header(N);
    put(&mut out, &counters.drive_errors.to_le_bytes());
    for slot in 0..N {
        put(&mut out, &counters.tool_changes[slot].to_le_bytes());
        put(&mut out, &counters.failures[slot].to_le_bytes());
        put(&mut out, &counters.fed_mm[slot].to_le_bytes());
    }
    out
}

fn encode_settings(settings: &[(u8, u16)]) -> Bytes {
    let mut out = header(settings.len());
    for &(address, value) in settings {
        put(&mut out, &[address]);
        put(&mut out, &value.to_le_bytes());
    }
    out
}

/// A reader past the header, when the record is of this format and for `count` entries.
fn body(bytes: &[u8], count: Option<usize>) -> Option<(Reader<'_>, usize)> {
    let mut reader = Reader(bytes);
    let (format, entries) = (reader.u8()?, usize::from(reader.u8()?));
    (format == FORMAT && count.is_none_or(|n| n == entries)).then_some((reader, entries))
}

fn decode_lanes<const N: usize>(bytes: &[u8]) -> Option<[Lane; N]> {
    let (mut reader, _) = body(bytes, Some(N))?;
    let mut lanes = [Lane::Unknown; N];
    for lane in &mut lanes {
        *lane = lane_from(reader.u8()?)?;
    }
    reader.0.is_empty().then_some(lanes)
}

fn decode_counters<const N: usize>(bytes: &[u8]) -> Option<Counters<N>> {
    let (mut reader, _) = body(bytes, Some(N))?;
    let mut counters = Counters::<N> {
        drive_errors: reader.u16()?,
        ..Counters::default()
    };
    for slot in 0..N {
        counters.tool_changes[slot] = reader.u16()?;
        counters.failures[slot] = reader.u16()?;
        counters.fed_mm[slot] = reader.u32()?;
    }
    reader.0.is_empty().then_some(counters)
}

fn decode_settings(bytes: &[u8]) -> Option<Vec<(u8, u16), MAX_SETTINGS>> {
    let (mut reader, entries) = body(bytes, None)?;
    let mut settings = Vec::new();
    for _ in 0..entries {
        settings.push((reader.u8()?, reader.u16()?)).ok()?;
    }
    reader.0.is_empty().then_some(settings)
}

/// A flash operation failed (the flash driver's error, or a map the library found corrupt and
/// could not repair). The unit carries on with what it has in RAM.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StoreError;

impl<E> From<sequential_storage::Error<E>> for StoreError {
    fn from(_: sequential_storage::Error<E>) -> Self {
        StoreError
    }
}

/// The persisted state in a region of NOR flash.
pub struct Store<F: NorFlash, const N: usize> {
    map: MapStorage<u8, F, Cache<Uncached, Uncached, Uncached, u8>>,
    /// What the flash holds, as far as this store knows.
    saved: Snapshot<N>,
    /// When counters or settings were last written.
    slow_saved_at: Option<Instant>,
    buffer: [u8; BUFFER],
}

impl<F: NorFlash, const N: usize> Store<F, N> {
    /// A store over `range` of `flash` (page aligned, at least two pages).
    pub fn new(flash: F, range: core::ops::Range<u32>) -> Result<Self, StoreError> {
        let config = MapConfig::try_new(range).map_err(|_| StoreError)?;
        Ok(Store {
            map: MapStorage::new(flash, config, Cache::new_uncached()),
            saved: Snapshot::default(),
            slow_saved_at: None,
            buffer: [0; BUFFER],
        })
    }

    /// The flash, e.g. to look at it in tests.
    pub fn flash(&mut self) -> &mut F {
        self.map.flash()
    }

    /// Give the flash back.
    pub fn into_flash(self) -> F {
        self.map.destroy().0
    }

    async fn fetch(&mut self, record: Record) -> Result<Option<Bytes>, StoreError> {
        let item: Option<&[u8]> = self.map.fetch_item(&mut self.buffer, &(record as u8)).await?;
        Ok(item.and_then(|bytes| Bytes::from_slice(bytes).ok()))
    }

    /// What the flash holds; a record that is missing or does not decode gives its defaults
    /// (lanes unknown, counters zero, no settings).
    pub async fn load(&mut self) -> Result<Snapshot<N>, StoreError> {
        let lanes = self.fetch(Record::Lanes).await?;
        let counters = self.fetch(Record::Counters).await?;
        let settings = self.fetch(Record::Settings).await?;
        let snapshot = Snapshot {
            lanes: lanes.and_then(|b| decode_lanes(&b)).unwrap_or([Lane::Unknown; N]),
            counters: counters.and_then(|b| decode_counters(&b)).unwrap_or_default(),
            settings: settings.and_then(|b| decode_settings(&b)).unwrap_or_default(),
        };
        self.saved = snapshot.clone();
        Ok(snapshot)
    }

    /// Whether [`Store::save`] would write something now.
    pub fn save_due(&self, snapshot: &Snapshot<N>, now: Instant) -> bool {
        snapshot.lanes != self.saved.lanes
            || snapshot.settings != self.saved.settings
            || (snapshot.counters != self.saved.counters && self.slow_allowed(now))
    }

    fn slow_allowed(&self, now: Instant) -> bool {
        self.slow_saved_at
            .is_none_or(|at| now.millis_since(at) >= SLOW_RECORD_PERIOD_MS)
    }

    /// Write what changed: lanes and settings at once, counters at most every
    /// [`SLOW_RECORD_PERIOD_MS`] (`None`: now, whatever the period, e.g. before a reset).
    /// Returns how many records were written.
    pub async fn save(&mut self, snapshot: &Snapshot<N>, now: Option<Instant>) -> Result<u8, StoreError> {
        let mut written = 0;
        if snapshot.lanes != self.saved.lanes {
            self.write(Record::Lanes, &encode_lanes(&snapshot.lanes)).await?;
            self.saved.lanes = snapshot.lanes;
            written += 1;
        }
        if snapshot.settings != self.saved.settings {
            self.write(Record::Settings, &encode_settings(&snapshot.settings))
                .await?;
            self.saved.settings = snapshot.settings.clone();
            written += 1;
        }
        if snapshot.counters != self.saved.counters && now.is_none_or(|now| self.slow_allowed(now)) {
            self.write(Record::Counters, &encode_counters(&snapshot.counters))
                .await?;
            self.saved.counters = snapshot.counters;
            self.slow_saved_at = now;
            written += 1;
        }
        Ok(written)
    }

    async fn write(&mut self, record: Record, bytes: &[u8]) -> Result<(), StoreError> {
        self.map
            .store_item(&mut self.buffer, &(record as u8), &bytes)
            .await?;
        Ok(())
    }

    /// Forget everything (`X42`): write blank records (lanes unknown, counters zero, no
    /// settings) as ordinary items, so a power cut leaves either the old state or the blank one.
    /// (Erasing the pages instead could bring old records back: a cut mid-erase leaves some
    /// pages erased and older ones intact.)
    pub async fn forget(&mut self) -> Result<(), StoreError> {
        let blank = Snapshot::<N>::default();
        self.write(Record::Lanes, &encode_lanes(&blank.lanes)).await?;
        self.write(Record::Counters, &encode_counters(&blank.counters))
            .await?;
        self.write(Record::Settings, &encode_settings(&blank.settings))
            .await?;
        self.saved = blank;
        Ok(())
    }

    /// Erase the region when it cannot be read, then write blank records (see [`Store::forget`]).
    pub async fn wipe(&mut self) -> Result<(), StoreError> {
        self.map.erase_all().await?;
        self.forget().await
    }
}

/// What [`Keeper::boot`] found in the flash.
#[derive(Debug)]
pub enum Boot {
    /// The stored state is restored into the App.
    Restored,
    /// The store could not be read and was wiped (or could not even be wiped): a first start.
    Wiped(Result<(), StoreError>),
}

/// The persistence policy of a running unit, shared by the firmware and the simulator: restore
/// at boot; then lanes and settings saved in the step they change, counters as the store allows,
/// everything before a reset.
pub struct Keeper<F: NorFlash, const N: usize> {
    store: Store<F, N>,
    /// The lanes as of the last comparison with the flash.
    lanes: [Lane; N],
    /// When counters and settings were last compared.
    checked_at: Option<Instant>,
}

impl<F: NorFlash, const N: usize> Keeper<F, N> {
    /// Restore into `app` (before its first step) what `store` holds; a store that cannot be
    /// read is wiped, and the unit starts as new rather than not at all.
    pub async fn boot(mut store: Store<F, N>, app: &mut App<N>) -> (Self, Boot) {
        let boot = match store.load().await {
            Ok(snapshot) => {
                app.restore(&snapshot);
                Boot::Restored
            }
            Err(StoreError) => Boot::Wiped(store.wipe().await),
        };
        let keeper = Keeper {
            store,
            lanes: app.lanes(),
            checked_at: None,
        };
        (keeper, boot)
    }

    /// After a step: save what changed. Lanes are compared every step (cheap); the full snapshot
    /// every [`FULL_CHECK_MS`] or when lanes changed. `Ok(true)` when it wrote (the flash may
    /// have stalled the CPU); a failed write leaves the previous record and is tried again.
    pub async fn update(&mut self, app: &App<N>, now: Instant) -> Result<bool, StoreError> {
        let lanes = app.lanes();
        let full_check = self
            .checked_at
            .is_none_or(|at| now.millis_since(at) >= FULL_CHECK_MS);
        if lanes == self.lanes && !full_check {
            return Ok(false);
        }
        self.checked_at = Some(now);
        let snapshot = app.snapshot();
        if !self.store.save_due(&snapshot, now) {
            self.lanes = lanes;
            return Ok(false);
        }
        self.store.save(&snapshot, Some(now)).await?;
        self.lanes = lanes;
        Ok(true)
    }

    /// Before the board carries out `action`: save everything (`X0`), or forget it (`X42`).
    pub async fn before(&mut self, action: BoardAction, app: &App<N>) -> Result<(), StoreError> {
        match action {
            BoardAction::Reset => self.store.save(&app.snapshot(), None).await.map(drop),
            BoardAction::EraseAndReset => self.store.forget().await,
        }
    }

    /// The store.
    pub fn store(&mut self) -> &mut Store<F, N> {
        &mut self.store
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_decode_to_what_was_encoded() {
        let lanes = [Lane::Parked, Lane::Loaded, Lane::Empty];
        assert_eq!(decode_lanes::<3>(&encode_lanes(&lanes)), Some(lanes));
        let counters = Counters::<3> {
            drive_errors: 7,
            tool_changes: [1, 2, 65535],
            failures: [0, 4, 0],
            fed_mm: [0, 123_456_789, 5],
        };
        assert_eq!(decode_counters::<3>(&encode_counters(&counters)), Some(counters));
        let settings = [(0x0b, 30), (0x22, 360), (0x90, 2600)];
        assert_eq!(
            decode_settings(&encode_settings(&settings)).as_deref(),
            Some(&settings[..])
        );
    }

    #[test]
    fn records_of_another_shape_are_refused() {
        let lanes = encode_lanes(&[Lane::Parked; 3]);
        assert_eq!(decode_lanes::<4>(&lanes), None, "another slot count");
        let mut other_format = lanes.clone();
        other_format[0] = FORMAT + 1;
        assert_eq!(decode_lanes::<3>(&other_format), None);
        let mut bad_lane = lanes.clone();
        bad_lane[2] = 9;
        assert_eq!(decode_lanes::<3>(&bad_lane), None);
        assert_eq!(decode_lanes::<3>(&lanes[..4]), None, "cut short");
        assert_eq!(decode_counters::<3>(&[FORMAT, 3, 1]), None);
        assert_eq!(decode_settings(&[FORMAT, 2, 0x0b, 30, 0]), None);
    }
}
