//! The records and their bytes: a format byte, an entry count, then the fields in little endian.
//! A record that does not decode (another format, another slot count, a length other than its
//! entries take) gives `None`, and the unit starts that record from its defaults. [`Records`] is the store's view of all four,
//! with the identity registers split from the other settings.

use heapless::vec::VecView;

use super::{Counters, IDENTITY_REGISTERS, MAX_SETTINGS, Settings, Snapshot, is_identity};
use crate::lanes::LaneFigures;
use crate::unit::Lane;

/// The layout version of every record: a record with another is ignored.
const FORMAT: u8 = 1;
/// The largest record (the settings: a 2-byte header and 3 bytes each).
pub(super) const MAX_RECORD: usize = 2 + 3 * MAX_SETTINGS;

/// The records, by their key in the store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub(super) enum Record {
    Lanes = 1,
    Counters = 2,
    Settings = 3,
    /// The registers that decide whether a printer talks to the unit: kept by `X42`.
    Identity = 4,
}

impl Record {
    /// Every record, in the order a full copy writes them.
    pub(super) const ALL: [Record; 4] = [
        Record::Identity,
        Record::Settings,
        Record::Counters,
        Record::Lanes,
    ];

    pub(super) fn from_key(key: u8) -> Option<Record> {
        Some(match key {
            1 => Record::Lanes,
            2 => Record::Counters,
            3 => Record::Settings,
            4 => Record::Identity,
            _ => return None,
        })
    }

    pub(super) fn index(self) -> usize {
        usize::from(self as u8 - 1)
    }
}

/// One record's bytes.
#[cfg(test)]
pub(super) type Bytes = heapless::Vec<u8, MAX_RECORD>;

/// A lane's code in the lanes record.
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

/// The lane of a code in the lanes record.
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

/// The little-endian field of `width` bytes at `at` in `bytes` (bytes past the end read 0).
fn field(bytes: &[u8], at: usize, width: usize) -> u32 {
    let mut value = 0;
    for at in (at..at + width).rev() {
        value = value << 8 | u32::from(bytes.get(at).copied().unwrap_or(0));
    }
    value
}

/// The fields of a record of this format after its header, when they are exactly `entries`
/// entries of `entry` bytes after `head` bytes, and `count` entries when given.
fn body(bytes: &[u8], count: Option<usize>, head: usize, entry: usize) -> Option<(&[u8], usize)> {
    let [format, entries, ref fields @ ..] = *bytes else {
        return None;
    };
    let entries = usize::from(entries);
    let fits = format == FORMAT
        && count.is_none_or(|count| count == entries)
        && fields.len() == head + entries * entry;
    fits.then_some((fields, entries))
}

/// Writes a record's fields in order into an entry's payload, in place; from the first field
/// that does not fit, nothing more is written (every record built here fits [`MAX_RECORD`]).
pub(super) struct Writer<'a> {
    out: &'a mut [u8],
    len: usize,
}

impl<'a> Writer<'a> {
    /// A writer at the start of `out`.
    pub(super) fn new(out: &'a mut [u8]) -> Self {
        Writer { out, len: 0 }
    }

    /// The bytes written.
    pub(super) fn len(&self) -> usize {
        self.len
    }

    /// Append the `width` (at most 4) low bytes of `value`, little endian; nothing if they do
    /// not fit.
    fn field(&mut self, value: u32, width: usize) {
        debug_assert!(width <= 4, "a field of {width} bytes");
        let end = self.len + width;
        let bytes = value.to_le_bytes();
        match (self.out.get_mut(self.len..end), width) {
            (Some([a]), 1) => *a = bytes[0],
            (Some([a, b]), 2) => [*a, *b] = [bytes[0], bytes[1]],
            (Some([a, b, c, d]), 4) => [*a, *b, *c, *d] = bytes,
            (Some(to), _) => to.iter_mut().zip(bytes).for_each(|(to, byte)| *to = byte),
            (None, _) => {
                // Full: a later, narrower field must not land where this one belonged.
                self.len = self.out.len();
                return;
            }
        }
        self.len = end;
    }

    /// The format byte, then the entry count's (low) byte.
    fn header(&mut self, entries: usize) {
        self.field(u32::from(FORMAT) | (entries as u32) << 8, 2);
    }
}

pub(super) fn encode_lanes<const N: usize>(lanes: &[Lane; N], out: &mut Writer) {
    out.header(N);
    for &lane in lanes {
        out.field(u32::from(lane_code(lane)), 1);
    }
}

/// The counters; the lane figures only once one is not blank (until then, the bytes an earlier
/// firmware wrote: both decode).
pub(super) fn encode_counters<const N: usize>(counters: &Counters<N>, out: &mut Writer) {
    let with_lanes = counters.lanes.iter().any(|lane| *lane != LaneFigures::default());
    out.header(N);
    out.field(u32::from(counters.drive_errors), 2);
    for slot in 0..N {
        out.field(u32::from(counters.tool_changes[slot]), 2);
        out.field(u32::from(counters.failures[slot]), 2);
        out.field(counters.fed_mm[slot], 4);
        if with_lanes {
            for (value, width) in counters.lanes[slot].fields() {
                out.field(value, width);
            }
        }
    }
}

/// Settings and identity records alike: (register, value) pairs.
pub(super) fn encode_settings(settings: &[(u8, u16)], out: &mut Writer) {
    out.header(settings.len());
    for &(address, value) in settings {
        out.field(u32::from(address), 1);
        out.field(u32::from(value), 2);
    }
}

pub(super) fn decode_lanes<const N: usize>(bytes: &[u8]) -> Option<[Lane; N]> {
    let (codes, _) = body(bytes, Some(N), 0, 1)?;
    let mut lanes = [Lane::Unknown; N];
    for (lane, &code) in lanes.iter_mut().zip(codes) {
        *lane = lane_from(code)?;
    }
    Some(lanes)
}

/// Bytes of one slot in the counters record: its counts, then its lane figures. A record of an
/// earlier firmware, without the lane figures ([`OLD_SLOT_BYTES`] a slot), still decodes.
const SLOT_BYTES: usize = 8 + LaneFigures::BYTES;
const OLD_SLOT_BYTES: usize = 8;

pub(super) fn decode_counters<const N: usize>(bytes: &[u8]) -> Option<Counters<N>> {
    let (fields, entry) = match body(bytes, Some(N), 2, SLOT_BYTES) {
        Some((fields, _)) => (fields, SLOT_BYTES),
        None => (body(bytes, Some(N), 2, OLD_SLOT_BYTES)?.0, OLD_SLOT_BYTES),
    };
    let mut counters = Counters::<N> {
        drive_errors: field(fields, 0, 2) as u16,
        ..Counters::default()
    };
    for slot in 0..N {
        let at = 2 + entry * slot;
        counters.tool_changes[slot] = field(fields, at, 2) as u16;
        counters.failures[slot] = field(fields, at + 2, 2) as u16;
        counters.fed_mm[slot] = field(fields, at + 4, 4);
        if entry == SLOT_BYTES {
            let mut next = at + 8;
            counters.lanes[slot] = LaneFigures::from_fields(|width| {
                let value = field(fields, next, width);
                next += width;
                value
            });
        }
    }
    Some(counters)
}

/// Decode a settings or identity record into `pairs` (only the identity's registers when
/// `identity`); `pairs` is left empty when it does not decode (more pairs than a unit has
/// settings, among others).
fn decode_pairs(bytes: &[u8], pairs: &mut VecView<(u8, u16)>, identity: bool) {
    pairs.clear();
    let Some((fields, entries)) = body(bytes, None, 0, 3) else {
        return;
    };
    if entries > MAX_SETTINGS {
        return;
    }
    for pair in fields.chunks_exact(3) {
        let &[address, low, high] = pair else {
            continue;
        };
        if !identity || is_identity(address) {
            // Room for every pair of a record that decodes (at most one per identity register).
            let _ = pairs.push((address, u16::from_le_bytes([low, high])));
        }
    }
}

#[cfg(test)]
pub(super) fn decode_settings(bytes: &[u8]) -> Option<Settings> {
    let mut settings = Settings::new();
    body(bytes, None, 0, 3)?;
    decode_pairs(bytes, &mut settings, false);
    Some(settings)
}

/// Every record as this store last wrote or read it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(super) struct Records<const N: usize> {
    pub(super) lanes: [Lane; N],
    pub(super) counters: Counters<N>,
    pub(super) settings: Settings,
    pub(super) identity: Identity,
}

/// The identity registers and their values (at most one entry per identity register).
type Identity = heapless::Vec<(u8, u16), { IDENTITY_REGISTERS.len() }>;

impl<const N: usize> Records<N> {
    pub(super) fn blank() -> Self {
        Records {
            lanes: [Lane::Unknown; N],
            counters: Counters::default(),
            settings: Settings::new(),
            identity: Identity::new(),
        }
    }

    /// Become the snapshot of `lanes`, `counters` and `settings`, its settings split into the
    /// identity and the rest (in place: no copy of the records on the stack).
    pub(super) fn set(&mut self, lanes: &[Lane; N], counters: &Counters<N>, settings: &[(u8, u16)]) {
        self.lanes = *lanes;
        self.counters = *counters;
        self.settings.clear();
        self.identity.clear();
        for &(address, value) in settings {
            // Each holds what a snapshot can hold (a register appears once).
            let _ = if is_identity(address) {
                self.identity.push((address, value))
            } else {
                self.settings.push((address, value))
            };
        }
    }

    pub(super) fn snapshot(&self) -> Snapshot<N> {
        let mut settings = self.settings.clone();
        for &entry in &self.identity {
            let _ = settings.push(entry);
        }
        Snapshot {
            lanes: self.lanes,
            counters: self.counters,
            settings,
        }
    }

    /// Write `record`'s bytes into `out` (an entry's payload, in place): their length.
    pub(super) fn encode(&self, record: Record, out: &mut [u8]) -> usize {
        let mut writer = Writer::new(out);
        match record {
            Record::Lanes => encode_lanes(&self.lanes, &mut writer),
            Record::Counters => encode_counters(&self.counters, &mut writer),
            Record::Settings => encode_settings(&self.settings, &mut writer),
            Record::Identity => encode_settings(&self.identity, &mut writer),
        }
        writer.len()
    }

    /// Become blank records (lanes unknown, counters zero, no settings) but for `from`'s
    /// identity, in place.
    pub(super) fn blank_but_identity(&mut self, from: &Records<N>) {
        self.lanes = [Lane::Unknown; N];
        self.counters = Counters::default();
        self.settings.clear();
        self.identity.clone_from(&from.identity);
    }

    /// Become blank records but for the identity registers among `settings`, in place.
    pub(super) fn blank_but_identity_of(&mut self, settings: &[(u8, u16)]) {
        self.set(&[Lane::Unknown; N], &Counters::default(), &[]);
        for &entry in settings.iter().filter(|(address, _)| is_identity(*address)) {
            // Room for one entry per identity register, and a register appears once.
            let _ = self.identity.push(entry);
        }
    }

    /// Become `from`, in place.
    pub(super) fn copy_from(&mut self, from: &Records<N>) {
        self.lanes = from.lanes;
        self.counters = from.counters;
        self.settings.clone_from(&from.settings);
        self.identity.clone_from(&from.identity);
    }

    /// Take `record` from `from`.
    pub(super) fn copy_record(&mut self, record: Record, from: &Records<N>) {
        match record {
            Record::Lanes => self.lanes = from.lanes,
            Record::Counters => self.counters = from.counters,
            Record::Settings => self.settings.clone_from(&from.settings),
            Record::Identity => self.identity.clone_from(&from.identity),
        }
    }

    /// Take a record's newest stored bytes (`None`: it does not decode, back to its default).
    pub(super) fn decode(&mut self, record: Record, bytes: &[u8]) {
        match record {
            Record::Lanes => self.lanes = decode_lanes(bytes).unwrap_or([Lane::Unknown; N]),
            Record::Counters => self.counters = decode_counters(bytes).unwrap_or_default(),
            // In place: no copy of a settings list on the stack.
            Record::Settings => decode_pairs(bytes, &mut self.settings, false),
            Record::Identity => decode_pairs(bytes, &mut self.identity, true),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the encoder writes, as bytes.
    fn encoded(encode: impl FnOnce(&mut Writer)) -> Bytes {
        let mut out = [0; MAX_RECORD];
        let mut writer = Writer::new(&mut out);
        encode(&mut writer);
        let len = writer.len();
        Bytes::from_slice(&out[..len]).unwrap()
    }

    #[test]
    fn records_decode_to_what_was_encoded() {
        let lanes = [Lane::Parked, Lane::Loaded, Lane::Empty];
        assert_eq!(
            decode_lanes::<3>(&encoded(|w| encode_lanes(&lanes, w))),
            Some(lanes)
        );
        let counters = Counters::<3> {
            drive_errors: 7,
            tool_changes: [1, 2, 65535],
            failures: [0, 4, 0],
            fed_mm: [0, 123_456_789, 5],
            lanes: [
                LaneFigures::default(),
                LaneFigures {
                    used_m: 12,
                    slip_permille: -3,
                    outcomes: 5,
                    attempts: 3,
                    ..LaneFigures::default()
                },
                LaneFigures::default(),
            ],
        };
        assert_eq!(
            decode_counters::<3>(&encoded(|w| encode_counters(&counters, w))),
            Some(counters)
        );
        let settings = [(0x0b, 30), (0x22, 360), (0x90, 2600)];
        assert_eq!(
            decode_settings(&encoded(|w| encode_settings(&settings, w))).as_deref(),
            Some(&settings[..])
        );
        let all: Settings = (0..MAX_SETTINGS as u8).map(|a| (a, u16::MAX)).collect();
        assert_eq!(
            encoded(|w| encode_settings(&all, w)).len(),
            MAX_RECORD,
            "the largest record fits"
        );
    }

    #[test]
    fn settings_and_identity_records_decode_in_place() {
        let mut records = Records::<3>::blank();
        let bytes = encoded(|w| encode_settings(&[(0x0b, 30), (0x52, 2), (0x22, 360)], w));
        let cut = &bytes[..bytes.len() - 1];
        records.decode(Record::Settings, &bytes);
        assert_eq!(records.settings, [(0x0b, 30), (0x52, 2), (0x22, 360)]);
        records.decode(Record::Identity, &bytes);
        assert_eq!(records.identity, [(0x52, 2)], "only the identity's registers");
        records.decode(Record::Settings, cut);
        records.decode(Record::Identity, cut);
        assert!(
            records.settings.is_empty() && records.identity.is_empty(),
            "cut short"
        );
        let all: Settings = (0..MAX_SETTINGS as u8).map(|a| (a + 0x20, 1)).collect();
        records.decode(Record::Identity, &encoded(|w| encode_settings(&all, w)));
        assert_eq!(records.identity, [(0x52, 1)], "a full settings record");
    }

    #[test]
    fn records_of_another_shape_are_refused() {
        let lanes = encoded(|w| encode_lanes(&[Lane::Parked; 3], w));
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

    #[test]
    fn a_counters_record_without_lane_figures_keeps_its_counts() {
        // An earlier firmware's record: drive errors, then 8 bytes a slot.
        let mut bytes = Bytes::new();
        bytes.extend_from_slice(&[FORMAT, 2, 7, 0]).unwrap();
        bytes.extend_from_slice(&[1, 0, 2, 0, 0x10, 0, 0, 0]).unwrap();
        bytes.extend_from_slice(&[3, 0, 4, 0, 0x20, 0, 0, 0]).unwrap();
        let counters = decode_counters::<2>(&bytes).unwrap();
        assert_eq!(counters.drive_errors, 7);
        assert_eq!(counters.tool_changes, [1, 3]);
        assert_eq!(counters.fed_mm, [0x10, 0x20]);
        assert_eq!(counters.lanes, [LaneFigures::default(); 2]);
    }

    /// Every record decodes only at its exact length: a byte too few or too many, and the unit
    /// starts that record from its defaults (the identity too).
    #[test]
    fn records_of_another_length_are_refused() {
        let counters = Counters::<3> {
            drive_errors: 1,
            tool_changes: [2, 3, 4],
            failures: [5, 6, 7],
            fed_mm: [8, 9, 70_000],
            lanes: [LaneFigures::default(); 3],
        };
        let settings = [(0x0b, 30), (0x52, 2)];
        let mut records = Records::<3>::blank();
        for record in Record::ALL {
            let bytes = encoded(|w| match record {
                Record::Lanes => encode_lanes(&[Lane::Loaded; 3], w),
                Record::Counters => encode_counters(&counters, w),
                Record::Settings | Record::Identity => encode_settings(&settings, w),
            });
            records.decode(record, &bytes);
            assert_ne!(records, Records::blank(), "{record:?} decodes");
            let mut longer = bytes.clone();
            longer.push(0).unwrap();
            for other in [&bytes[..bytes.len() - 1], &longer[..]] {
                records.decode(record, &bytes);
                records.decode(record, other);
                assert_eq!(records, Records::blank(), "{record:?} of {} bytes", other.len());
            }
        }
        assert_eq!(
            decode_counters::<3>(&encoded(|w| encode_counters(&counters, w))),
            Some(counters)
        );
    }
}
