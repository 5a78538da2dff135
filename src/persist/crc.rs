//! The CRC-32 of the store's entries behind a trait, so that the store stays hardware-agnostic:
//! the firmware computes it on the STM32G0's CRC unit (`board::HardwareCrc`: no 1 KiB table in
//! flash, one register write per byte), the host and the benchmark in software ([`SoftwareCrc`],
//! table-driven). Both compute CRC-32/ISO-HDLC, so a store written by one reads with the other;
//! and whichever a unit uses, it both writes and checks its own entries with it, so its store is
//! consistent by itself (an entry counts only when its trailer matches what the same unit
//! computes over it).

use crc::{CRC_32_ISO_HDLC, Crc, Digest, NoTable, Table};

/// CRC-32/ISO-HDLC (the CRC of zip and Ethernet), as the STM32G0's CRC unit is set up for it
/// (RM0444, "Cyclic redundancy check calculation unit"): the polynomial (`CRC_POL`, 32 bits),
/// the initial value (`CRC_INIT`), input bit-reversed by byte (`REV_IN` = 01), output
/// bit-reversed (`REV_OUT`), and the final XOR, which the unit does not do, in software.
pub mod iso_hdlc {
    /// The polynomial, in the unit's (MSB first) form.
    pub const POLY: u32 = 0x04c1_1db7;
    /// The initial value.
    pub const INIT: u32 = 0xffff_ffff;
    /// XORed with the unit's output.
    pub const FINAL_XOR: u32 = 0xffff_ffff;
    /// Each input byte is bit-reversed (`REV_IN` = 01, by byte).
    pub const REVERSE_INPUT_BYTES: bool = true;
    /// The output is bit-reversed (`REV_OUT`).
    pub const REVERSE_OUTPUT: bool = true;
    /// The CRC of the ASCII bytes `123456789` (the catalogue's check value): what a unit set up
    /// with these values computes.
    pub const CHECK: u32 = 0xcbf4_3926;
}

/// The CRC-32/ISO-HDLC of one entry, computed a chunk at a time: started, fed the entry's bytes
/// in order (possibly over several calls of a save), then read. One entry at a time.
pub trait EntryCrc {
    /// Start a new CRC.
    fn start(&mut self);
    /// Add `bytes` to it.
    fn add(&mut self, bytes: &[u8]);
    /// The CRC of the bytes added since [`EntryCrc::start`].
    fn value(&mut self) -> u32;
}

/// An [`EntryCrc`] on a running digest of the `crc` crate's CRC-32/ISO-HDLC with the table
/// implementation `$table`, kept in the static `$crc`.
macro_rules! software_crc {
    ($(#[$doc:meta])* $name:ident, $crc:ident, $table:ty) => {
        static $crc: Crc<u32, $table> = Crc::<u32, $table>::new(&CRC_32_ISO_HDLC);

        $(#[$doc])*
        #[derive(Clone)]
        pub struct $name(Digest<'static, u32, $table>);

        impl Default for $name {
            fn default() -> Self {
                $name($crc.digest())
            }
        }

        impl EntryCrc for $name {
            fn start(&mut self) {
                self.0 = $crc.digest();
            }

            fn add(&mut self, bytes: &[u8]) {
                self.0.update(bytes);
            }

            fn value(&mut self) -> u32 {
                self.0.clone().finalize()
            }
        }
    };
}

software_crc!(
    /// CRC-32/ISO-HDLC in software, with the `crc` crate's 1 KiB table: the Pico, the host and
    /// the benchmark.
    SoftwareCrc,
    TABLE_CRC,
    Table<1>
);

software_crc!(
    /// CRC-32/ISO-HDLC in software bit by bit (eight shifts a byte where the table takes one
    /// lookup): the fallback of a board whose CRC unit failed its check at boot
    /// (`crate::port::CheckedCrc`). Correct and slower, for a fault that should never happen,
    /// without a 1 KiB table in the flash of every unit that has a CRC unit.
    BitwiseCrc,
    BITWISE_CRC,
    NoTable
);

#[cfg(test)]
mod tests {
    use super::*;

    /// CRC-32/ISO-HDLC bit by bit, from its definition (reflected: polynomial 0xedb88320,
    /// init and final XOR 0xffffffff).
    fn reference(bytes: &[u8]) -> u32 {
        let mut crc = 0xffff_ffffu32;
        for &byte in bytes {
            crc ^= u32::from(byte);
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xedb8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    /// The STM32G0's CRC unit as RM0444 describes it, set up with [`iso_hdlc`]: a 32-bit MSB-first
    /// shift register loaded with `CRC_INIT`, each byte written to `CRC_DR` bit-reversed first
    /// (`REV_IN` by byte), the register read bit-reversed (`REV_OUT`), then the final XOR.
    fn unit_model(bytes: &[u8]) -> u32 {
        let mut register = iso_hdlc::INIT;
        for &byte in bytes {
            let byte = if iso_hdlc::REVERSE_INPUT_BYTES {
                byte.reverse_bits()
            } else {
                byte
            };
            register ^= u32::from(byte) << 24;
            for _ in 0..8 {
                register = if register & 0x8000_0000 != 0 {
                    (register << 1) ^ iso_hdlc::POLY
                } else {
                    register << 1
                };
            }
        }
        let register = if iso_hdlc::REVERSE_OUTPUT {
            register.reverse_bits()
        } else {
            register
        };
        register ^ iso_hdlc::FINAL_XOR
    }

    fn software<C: EntryCrc + Default>(chunks: &[&[u8]]) -> u32 {
        let mut crc = C::default();
        crc.add(b"left over from a previous entry");
        crc.start();
        for chunk in chunks {
            crc.add(chunk);
        }
        crc.value()
    }

    #[test]
    fn the_software_crcs_are_crc32_iso_hdlc() {
        software_crc_is_crc32_iso_hdlc::<SoftwareCrc>();
        software_crc_is_crc32_iso_hdlc::<BitwiseCrc>();
    }

    fn software_crc_is_crc32_iso_hdlc<C: EntryCrc + Default>() {
        // The catalogue's check value: the CRC of "123456789".
        assert_eq!(software::<C>(&[b"123456789"]), iso_hdlc::CHECK);
        assert_eq!(CRC_32_ISO_HDLC.check, iso_hdlc::CHECK);
        let mut state = 0x1234_5678u32;
        let data: [u8; 200] = core::array::from_fn(|_| {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 24) as u8
        });
        for len in [0, 1, 7, 8, 24, 64, 200] {
            let bytes = &data[..len];
            assert_eq!(software::<C>(&[bytes]), reference(bytes), "{len} bytes");
            for split in [0, 1.min(len), len / 2, len] {
                let (a, b) = bytes.split_at(split);
                assert_eq!(
                    software::<C>(&[a, b]),
                    reference(bytes),
                    "{len} bytes split at {split}"
                );
            }
        }
    }

    /// The hardware's set-up (not the hardware: there is no board here; the board checks
    /// [`iso_hdlc::CHECK`] on its unit at boot) gives the same CRC.
    #[test]
    fn the_crc_unit_set_up_as_the_board_does_computes_crc32_iso_hdlc() {
        assert_eq!(unit_model(b"123456789"), iso_hdlc::CHECK);
        let data: [u8; 64] = core::array::from_fn(|i| (i * 37 + 11) as u8);
        for len in [1, 5, 8, 64] {
            assert_eq!(unit_model(&data[..len]), reference(&data[..len]), "{len} bytes");
        }
    }
}
