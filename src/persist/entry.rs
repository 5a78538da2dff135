//! The layout of one entry in flash: a header double word (key, payload length, sequence number,
//! CRC-16 of those), the payload padded to double words, and a trailer double word (the CRC-32 of
//! header and payload, and its complement), programmed last. A header that checks can be trusted
//! for the entry's length even when the rest is torn; an entry counts only when its trailer
//! matches.

use crc::{CRC_16_IBM_3740, CRC_32_ISO_HDLC, Crc};

use super::records::{MAX_RECORD, Record};

/// The STM32G0's programming unit: a 64-bit double word.
pub(super) const DOUBLE_WORD: usize = 8;
/// The largest entry: header, the largest record padded to double words, trailer.
pub(super) const MAX_ENTRY: usize = DOUBLE_WORD + MAX_RECORD.next_multiple_of(DOUBLE_WORD) + DOUBLE_WORD;
/// The key of the entry that commits a fresh page's full copy (no payload).
pub(super) const COMMIT: u8 = 0x5c;

const HEADER_CRC: Crc<u16> = Crc::<u16>::new(&CRC_16_IBM_3740);
const ENTRY_CRC: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// The (key, payload length, sequence number) of a header double word that checks: the key is a
/// record's or [`COMMIT`].
pub(super) fn parse_header(word: &[u8; DOUBLE_WORD]) -> Option<(u8, usize, u32)> {
    let [key, len, s0, s1, s2, s3, c0, c1] = *word;
    let known = Record::from_key(key).is_some() || key == COMMIT;
    let checks = HEADER_CRC.checksum(&word[..6]) == u16::from_le_bytes([c0, c1]);
    (known && checks && usize::from(len) <= MAX_RECORD).then_some((
        key,
        usize::from(len),
        u32::from_le_bytes([s0, s1, s2, s3]),
    ))
}

/// Whether `entry` (all its bytes, header to trailer) is complete: its trailer matches.
pub(super) fn is_complete(entry: &[u8]) -> bool {
    let Some(body) = entry.len().checked_sub(DOUBLE_WORD) else {
        return false;
    };
    let crc = ENTRY_CRC.checksum(&entry[..body]);
    entry[body..] == trailer(crc)
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

/// Lay out an entry in `buffer`; the bytes to program.
pub(super) fn build_entry<'b>(
    buffer: &'b mut [u8; MAX_ENTRY],
    key: u8,
    sequence: u32,
    payload: &[u8],
) -> &'b [u8] {
    let size = entry_size(payload.len());
    buffer.fill(0);
    buffer[0] = key;
    buffer[1] = payload.len() as u8;
    buffer[2..6].copy_from_slice(&sequence.to_le_bytes());
    let header_crc = HEADER_CRC.checksum(&buffer[..6]);
    buffer[6..8].copy_from_slice(&header_crc.to_le_bytes());
    buffer[DOUBLE_WORD..DOUBLE_WORD + payload.len()].copy_from_slice(payload);
    let body = size - DOUBLE_WORD;
    let crc = ENTRY_CRC.checksum(&buffer[..body]);
    buffer[body..size].copy_from_slice(&trailer(crc));
    &buffer[..size]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_entry_lays_out_header_payload_and_trailer_in_double_words() {
        let mut buffer = [0; MAX_ENTRY];
        let entry = build_entry(&mut buffer, Record::Lanes as u8, 7, &[1, 3, 2, 2, 5]).to_vec();
        assert_eq!(entry.len(), 24);
        assert_eq!(entry[..6], [1, 5, 7, 0, 0, 0]);
        let header: [u8; DOUBLE_WORD] = entry[..8].try_into().unwrap();
        assert_eq!(parse_header(&header), Some((1, 5, 7)));
        assert!(is_complete(&entry));
        let all = super::super::records::encode_settings(&[(1, 2); super::super::MAX_SETTINGS]);
        assert_eq!(entry_size(all.len()), MAX_ENTRY);
    }

    #[test]
    fn a_torn_entry_or_header_does_not_count() {
        let mut buffer = [0; MAX_ENTRY];
        let entry = build_entry(&mut buffer, Record::Lanes as u8, 7, &[1, 3, 2, 2, 5]).to_vec();
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
