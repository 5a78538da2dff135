//! An encoded frame, in a fixed buffer.

use core::fmt;

use crate::hex;

/// Room for the longest frame either side sends, with its newline (Prusa: 13 and 14 bytes).
pub const MAX_FRAME_LEN: usize = 16;

/// One frame exactly as on the wire, ending in `\n`.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Frame {
    bytes: [u8; MAX_FRAME_LEN],
    len: usize,
}

impl Frame {
    pub(crate) const fn new() -> Self {
        Frame {
            bytes: [0; MAX_FRAME_LEN],
            len: 0,
        }
    }

    /// The bytes to send, newline included.
    pub fn as_bytes(&self) -> &[u8] {
        self.bytes.get(..self.len).unwrap_or(&[])
    }

    /// The frame without its newline, as text (frames are ASCII).
    pub fn as_str(&self) -> &str {
        let bytes = self.as_bytes();
        let text = bytes.strip_suffix(b"\n").unwrap_or(bytes);
        core::str::from_utf8(text).unwrap_or("")
    }

    pub(crate) fn push(&mut self, byte: u8) {
        // Every frame the encoders build fits; a longer one would be a bug, so it is cut, not a panic.
        if let Some(slot) = self.bytes.get_mut(self.len) {
            *slot = byte;
            self.len += 1;
        }
    }

    /// Lowercase hex without leading zeros (`0` for zero).
    pub(crate) fn push_hex(&mut self, value: u16) {
        // The digits written from the last, straight into the buffer.
        let digits = match value {
            0x1000.. => 4,
            0x100.. => 3,
            0x10.. => 2,
            _ => 1,
        };
        let end = self.len + digits;
        if let Some(out) = self.bytes.get_mut(self.len..end) {
            let mut rest = value;
            for slot in out.iter_mut().rev() {
                *slot = hex::digit((rest & 0xf) as u8);
                rest >>= 4;
            }
            self.len = end;
            return;
        }
        // Not enough room (an encoder's bug): as many digits as fit, as `push` cuts a frame.
        let mut started = false;
        for shift in [12u32, 8, 4, 0] {
            let nibble = ((value >> shift) & 0xf) as u8;
            if started || nibble != 0 || shift == 0 {
                started = true;
                self.push(hex::digit(nibble));
            }
        }
    }

    pub(crate) fn push_crc(&mut self, crc: u8) {
        self.push(b'*');
        self.push_hex(crc.into());
        self.push(b'\n');
    }
}

impl fmt::Display for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl fmt::Debug for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Frame({:?})", self.as_str())
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for Frame {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(f, "{=str}", self.as_str())
    }
}
