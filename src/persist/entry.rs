//! The layout of one entry in flash: a header double word (key, payload length, sequence number,
//! CRC-16 of those), the payload padded to double words, and a trailer double word (the CRC-32 of
//! header and payload, and its complement), programmed last. A header that checks can be trusted
//! for the entry's length even when the rest is torn; an entry counts only when its trailer
//! matches.

use crc::{CRC_16_IBM_3740, Crc, Table};

use super::crc::EntryCrc;
use super::records::{MAX_RECORD, Record};

/// The STM32G0's programming unit: a 64-bit double word.
pub(super) const DOUBLE_WORD: usize = 8;
/// The largest entry: header, the largest record padded to double words, trailer.
pub(super) const MAX_ENTRY: usize = DOUBLE_WORD + MAX_RECORD.next_multiple_of(DOUBLE_WORD) + DOUBLE_WORD;
/// The key of the entry that commits a fresh page's full copy (no payload).
pub(super) const COMMIT: u8 = 0x5c;

/// The entry header's CRC-16, by the crate's byte table.
const HEADER_CRC: Crc<u16, Table<1>> = Crc::<u16, Table<1>>::new(&CRC_16_IBM_3740);

/// The (key, payload length, sequence number) of a header double word that checks: the key is a
/// record's or [`COMMIT`].
pub(super) fn parse_header(word: &[u8; DOUBLE_WORD]) -> Option<(u8, usize, u32)> {
    let [key, len, s0, s1, s2, s3, c0, c1] = *word;
    if HEADER_CRC.checksum(&word[..6]) != u16::from_le_bytes([c0, c1]) {
        return None;
    }
    let known = Record::from_key(key).is_some() || key == COMMIT;
    (known && usize::from(len) <= MAX_RECORD).then_some((
        key,
        usize::from(len),
        u32::from_le_bytes([s0, s1, s2, s3]),
    ))
}

/// Whether `entry` (all its bytes, header to trailer) is complete: its trailer matches.
pub(super) fn is_complete(entry: &[u8], crc: &mut impl EntryCrc) -> bool {
    let Some(body) = entry.len().checked_sub(DOUBLE_WORD) else {
        return false;
    };
    crc.start();
    crc.add(&entry[..body]);
    entry[body..] == trailer(crc.value())
}

/// The bytes of an entry of `len` payload bytes.
pub(super) fn entry_size(len: usize) -> usize {
    DOUBLE_WORD + len.next_multiple_of(DOUBLE_WORD) + DOUBLE_WORD
}

/// The trailer of an entry whose header and payload have CRC `crc`: never erased, never zero.
fn trailer(crc: u32) -> [u8; DOUBLE_WORD] {
    let mut word = [0; DOUBLE_WORD];
    word[..4].copy_from_slice(&crc.to_le_bytes());
    word[4..].copy_from_slice(&(!crc).to_le_bytes());
    word
}

/// An entry being programmed a chunk at a time, in order, so that one call of a save programs
/// (and checksums) a bounded part of it. Its bytes wait in the store's buffer; the trailer is
/// computed from the running CRC (the store's [`EntryCrc`], used for nothing else meanwhile)
/// when the last chunk is handed out, so it is programmed last.
/// Until then the entry does not count (a cut between two chunks is a program cut short).
#[derive(Clone)]
pub(super) struct EntryWriter {
    size: usize,
    written: usize,
}

impl EntryWriter {
    /// The payload area of `buffer`: a record is encoded there, in place, before
    /// [`EntryWriter::new`] lays out the rest of its entry.
    pub(super) fn payload(buffer: &mut [u8; MAX_ENTRY]) -> &mut [u8] {
        &mut buffer[DOUBLE_WORD..DOUBLE_WORD + MAX_RECORD]
    }

    /// Lay out the header and the padding of an entry in `buffer` whose first `len` payload bytes
    /// are in place ([`EntryWriter::payload`]); the trailer comes with the last chunk.
    pub(super) fn new(buffer: &mut [u8; MAX_ENTRY], key: u8, sequence: u32, len: usize) -> Self {
        let len = len.min(MAX_RECORD);
        let size = entry_size(len);
        // `len` is at most MAX_RECORD: the padding is in the buffer.
        if let Some(padding) = buffer.get_mut(DOUBLE_WORD + len..size - DOUBLE_WORD) {
            padding.fill(0);
        }
        buffer[0] = key;
        buffer[1] = len as u8;
        buffer[2..6].copy_from_slice(&sequence.to_le_bytes());
        let header_crc = HEADER_CRC.checksum(&buffer[..6]);
        buffer[6..8].copy_from_slice(&header_crc.to_le_bytes());
        EntryWriter { size, written: 0 }
    }

    /// The entry's bytes.
    pub(super) fn size(&self) -> usize {
        self.size
    }

    /// The next chunk to program, at most `max` bytes (a multiple of [`DOUBLE_WORD`]): its
    /// offset in the entry and its bytes in `buffer`; `None` once every chunk was handed out.
    pub(super) fn next_chunk<'b>(
        &mut self,
        buffer: &'b mut [u8; MAX_ENTRY],
        max: usize,
        crc: &mut impl EntryCrc,
    ) -> Option<(usize, &'b [u8])> {
        let start = self.written;
        if start >= self.size {
            return None;
        }
        let end = self.size.min(start + max.max(DOUBLE_WORD));
        let body = self.size - DOUBLE_WORD;
        if start == 0 {
            crc.start();
        }
        // Always in the buffer (the entry is at most MAX_ENTRY); were it not, the trailer would
        // not match and the entry would not count.
        crc.add(buffer.get(start..end.min(body)).unwrap_or_default());
        if end == self.size {
            *buffer.get_mut(body..)?.first_chunk_mut()? = trailer(crc.value());
        }
        self.written = end;
        Some((start, buffer.get(start..end)?))
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::super::crc::SoftwareCrc;
    use super::*;
    use std::vec::Vec;

    fn is_complete(entry: &[u8]) -> bool {
        super::is_complete(entry, &mut SoftwareCrc::default())
    }

    /// The entry's bytes, in the chunks a save programs them in.
    fn build_entry(key: u8, sequence: u32, payload: &[u8], chunk: usize) -> Vec<u8> {
        // Whatever an earlier entry left in the buffer must not show in this one.
        let mut buffer = [0xa5; MAX_ENTRY];
        EntryWriter::payload(&mut buffer)[..payload.len()].copy_from_slice(payload);
        let mut writer = EntryWriter::new(&mut buffer, key, sequence, payload.len());
        let mut entry = Vec::new();
        let mut crc = SoftwareCrc::default();
        while let Some((offset, bytes)) = writer.next_chunk(&mut buffer, chunk, &mut crc) {
            assert_eq!(offset, entry.len(), "in order");
            assert!(bytes.len() <= chunk.max(DOUBLE_WORD) && bytes.len() % DOUBLE_WORD == 0);
            entry.extend_from_slice(bytes);
        }
        assert_eq!(entry.len(), writer.size());
        entry
    }

    #[test]
    fn an_entry_lays_out_header_payload_and_trailer_in_double_words() {
        let entry = build_entry(Record::Lanes as u8, 7, &[1, 3, 2, 2, 5], 64);
        assert_eq!(entry.len(), 24);
        assert_eq!(entry[..6], [1, 5, 7, 0, 0, 0]);
        let header: [u8; DOUBLE_WORD] = entry[..8].try_into().unwrap();
        assert_eq!(parse_header(&header), Some((1, 5, 7)));
        assert!(is_complete(&entry));
        let mut all = [0; MAX_RECORD];
        let mut writer = super::super::records::Writer::new(&mut all);
        super::super::records::encode_settings(&[(1, 2); super::super::MAX_SETTINGS], &mut writer);
        assert_eq!(writer.len(), MAX_RECORD);
        assert_eq!(entry_size(all.len()), MAX_ENTRY);
        let whole = build_entry(3, 9, &all, MAX_ENTRY);
        for chunk in [8, 16, 64] {
            assert_eq!(build_entry(3, 9, &all, chunk), whole, "{chunk}-byte chunks");
        }
        assert!(is_complete(&whole));
    }

    #[test]
    fn a_torn_entry_or_header_does_not_count() {
        let entry = build_entry(Record::Lanes as u8, 7, &[1, 3, 2, 2, 5], 8);
        let mut torn = entry.clone();
        torn[16..].fill(0xff);
        assert!(!is_complete(&torn), "trailer never written");
        torn = entry.clone();
        torn[9] ^= 1;
        assert!(!is_complete(&torn), "a payload bit");
        let mut header: [u8; DOUBLE_WORD] = entry[..8].try_into().unwrap();
        header[2] ^= 0x10;
        assert_eq!(parse_header(&header), None, "a sequence bit");
        assert_eq!(parse_header(&[0; DOUBLE_WORD]), None, "not a key");
    }
}
