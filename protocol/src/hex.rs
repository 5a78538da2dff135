//! Lowercase hexadecimal digits, the only ones the protocol knows.

/// The value of a lowercase hex digit; uppercase is not a digit here.
pub(crate) const fn digit_value(byte: u8) -> Option<u8> {
    match byte {
        b'0'..=b'9' => Some(byte - b'0'),
        b'a'..=b'f' => Some(byte - b'a' + 10),
        _ => None,
    }
}

/// The lowercase digit for a nibble.
pub(crate) const fn digit(nibble: u8) -> u8 {
    b"0123456789abcdef"[(nibble & 0xf) as usize]
}
