//! The protocol's CRC-8: polynomial 0x07, initial value 0, no reflection, no final XOR
//! (the CRC-8/SMBUS catalogue entry), computed over the binary form of a message, never its text.
//!
//! The `crc` crate's, with its 256-byte table.

use crc::{CRC_8_SMBUS, Crc, Table};

const CRC8: Crc<u8, Table<1>> = Crc::<u8, Table<1>>::new(&CRC_8_SMBUS);

/// The CRC-8/SMBUS of `data`.
fn crc8(data: &[u8]) -> u8 {
    CRC8.checksum(data)
}

/// CRC of a request: code byte, value, then `value2` as a little-endian word.
///
/// `value2` is the written value of a `W` request and 0 for every other code; its two bytes are
/// always fed.
pub fn request_crc(code: u8, value: u8, value2: u16) -> u8 {
    let [lo, hi] = value2.to_le_bytes();
    crc8(&[code, value, lo, hi])
}

/// CRC of a response: the echoed request with `value2` forced to 0, then the parameter code and
/// the parameter value as a little-endian word (0 when the frame prints no value).
pub fn response_crc(code: u8, value: u8, param: u8, param_value: u16) -> u8 {
    let [lo, hi] = param_value.to_le_bytes();
    crc8(&[code, value, 0, 0, param, lo, hi])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `crc` crate's CRC-8/SMBUS bit by bit: the reference for the table.
    const REFERENCE: crc::Crc<u8, crc::NoTable> = crc::Crc::<u8, crc::NoTable>::new(&CRC_8_SMBUS);

    #[test]
    fn catalogue_check_value() {
        assert_eq!(crc8(b"123456789"), 0xf4);
        assert_eq!(REFERENCE.checksum(b"123456789"), 0xf4);
    }

    #[test]
    fn every_byte_in_every_state_gives_the_crates_crc() {
        // The first byte takes the register to each of its 256 states (CRC-8 of one byte is a
        // bijection), the second is every byte in each: every step the computation can take.
        for first in 0..=u8::MAX {
            assert_eq!(crc8(&[first]), REFERENCE.checksum(&[first]));
            for second in 0..=u8::MAX {
                let data = [first, second];
                assert_eq!(crc8(&data), REFERENCE.checksum(&data), "{data:?}");
            }
        }
        assert_eq!(crc8(&[]), REFERENCE.checksum(&[]));
    }

    #[test]
    fn request_and_response_crcs_match_the_spec() {
        assert_eq!(request_crc(b'L', 0, 0), 0x73);
        assert_eq!(request_crc(b'W', 0x0b, 5), 0x33);
        assert_eq!(response_crc(b'S', 0, b'A', 3), 0x22);
        assert_eq!(response_crc(b'W', 0x1b, b'A', 0), 0xc2);
    }
}
