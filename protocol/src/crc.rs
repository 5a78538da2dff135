//! The protocol's CRC-8: polynomial 0x07, initial value 0, no reflection, no final XOR
//! (the CRC-8/SMBUS catalogue entry), computed over the binary form of a message, never its text.

use crc::{CRC_8_SMBUS, Crc};

const CRC8: Crc<u8> = Crc::<u8>::new(&CRC_8_SMBUS);

/// CRC of a request: code byte, value, then `value2` as a little-endian word.
///
/// `value2` is the written value of a `W` request and 0 for every other code; its two bytes are
/// always fed.
pub fn request_crc(code: u8, value: u8, value2: u16) -> u8 {
    let [lo, hi] = value2.to_le_bytes();
    CRC8.checksum(&[code, value, lo, hi])
}

/// CRC of a response: the echoed request with `value2` forced to 0, then the parameter code and
/// the parameter value as a little-endian word (0 when the frame prints no value).
pub fn response_crc(code: u8, value: u8, param: u8, param_value: u16) -> u8 {
    let [lo, hi] = param_value.to_le_bytes();
    CRC8.checksum(&[code, value, 0, 0, param, lo, hi])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn catalogue_check_value() {
        assert_eq!(CRC8.checksum(b"123456789"), 0xf4);
    }

    #[test]
    fn request_and_response_crcs_match_the_spec() {
        assert_eq!(request_crc(b'L', 0, 0), 0x73);
        assert_eq!(request_crc(b'W', 0x0b, 5), 0x33);
        assert_eq!(response_crc(b'S', 0, b'A', 3), 0x22);
        assert_eq!(response_crc(b'W', 0x1b, b'A', 0), 0xc2);
    }
}
