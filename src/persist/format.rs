//! The on-flash format against a store written by an earlier firmware: a unit updated in the
//! field must restore what the previous build kept, and keep writing the same bytes.
//!
//! The two files in `testdata/` come from the tree of commit 4579974 (before the flash cut of
//! issue 14), its own `Store` running the same sequences as this module (a scratch copy of it
//! there, not kept): `store-format-1.txt`, the flash after [`save_the_sequence`], which today's
//! `Store` must load and write again byte for byte; `cuts-format-1.txt`, what that `Store`
//! restored after a power cut at each flash operation of 40 saves, which today's must restore
//! too. A deliberate format change replaces both tests, not their data.

extern crate std;

use std::string::String;
use std::vec::Vec;

use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashErrorKind, ReadNorFlash};

use super::ram_flash::{PAGE, RamFlash};
use super::{Counters, Snapshot, Store};
use crate::time::Instant;
use crate::unit::Lane;

const PAGES: usize = 3;

fn store(flash: RamFlash) -> Store<RamFlash, 3> {
    Store::new(flash, 0..(PAGES * PAGE) as u32).unwrap()
}

/// The flash image of `testdata/store-format-1.txt`.
fn written_by_format_1() -> RamFlash {
    let mut flash = RamFlash::erased(PAGES);
    let text = include_str!("testdata/store-format-1.txt");
    for line in text.lines().filter(|line| !line.starts_with('#')) {
        let mut fields = line.split_whitespace();
        let offset = usize::from_str_radix(fields.next().unwrap(), 16).unwrap();
        for (at, byte) in fields.enumerate() {
            flash.bytes[offset + at] = u8::from_str_radix(byte, 16).unwrap();
        }
    }
    flash
}

/// The `i`-th snapshot of the sequence: every lane code, counters over their whole widths, a
/// settings list that grows and shrinks (up to 18 settings), the identity register last.
fn snapshot(i: u32) -> Snapshot<3> {
    let mut snapshot = Snapshot::<3> {
        lanes: [
            Lane::ALL[(i % 6) as usize],
            Lane::ALL[((i / 6) % 6) as usize],
            Lane::ALL[((i + 3) % 6) as usize],
        ],
        counters: Counters {
            drive_errors: (i * 7) as u16,
            tool_changes: [i as u16, (i * 300) as u16, 65_535 - i as u16],
            failures: [(i / 3) as u16, 1, 0x1234],
            fed_mm: [i * 1_000_003, 70_000 + i, u32::MAX - i],
            lanes: [crate::lanes::LaneFigures::default(); 3],
        },
        ..Snapshot::default()
    };
    snapshot.settings.push((0x0b, 300 + i as u16)).unwrap();
    if i.is_multiple_of(4) {
        for k in 0..(i % 20) as u8 {
            let value = 1000 + u16::from(k) * 257 + i as u16;
            snapshot.settings.push((0x40 + k, value)).unwrap();
        }
    }
    snapshot.settings.push((0x52, 302)).unwrap();
    snapshot
}

/// 89 saves, 400 s apart (so the counters are written each time), into a blank store; the last
/// snapshot saved.
fn save_the_sequence(store: &mut Store<RamFlash, 3>) -> Snapshot<3> {
    store.load();
    for i in 0..89 {
        let at = Instant::from_millis(u64::from(i) * 400_000);
        store.save(&snapshot(i), Some(at)).unwrap();
    }
    snapshot(88)
}

/// The image as the test data lists it.
fn listing(flash: &RamFlash) -> String {
    use core::fmt::Write as _;
    let mut out = String::new();
    for (index, word) in flash.bytes.chunks(8).enumerate() {
        if word != [0xff; 8] {
            write!(out, "{:05x}", index * 8).unwrap();
            for byte in word {
                write!(out, " {byte:02x}").unwrap();
            }
            out.push('\n');
        }
    }
    out
}

#[test]
fn a_store_written_by_the_previous_firmware_loads_whole() {
    let mut store = store(written_by_format_1());
    let expected = snapshot(88);
    assert!(expected.settings.len() > 2, "the newest settings are a long list");
    assert_eq!(store.load(), expected);
    assert!(store.damage().is_none(), "{:?}", store.damage());
}

#[test]
fn the_store_writes_the_bytes_the_previous_firmware_wrote() {
    let mut store = store(RamFlash::erased(PAGES));
    save_the_sequence(&mut store);
    let expected = listing(&written_by_format_1());
    let written = listing(store.flash());
    assert!(
        written == expected,
        "the flash image differs from the previous firmware's"
    );
}

#[test]
fn a_store_written_by_the_previous_firmware_takes_new_saves() {
    let mut store = store(written_by_format_1());
    store.load();
    let next = snapshot(89);
    store
        .save(&next, Some(Instant::from_millis(89 * 400_000)))
        .unwrap();
    let flash = store.into_flash();
    assert_eq!(self::store(flash).load(), next);
}

/// A NOR flash in RAM whose power is cut at its `ops_left`-th operation (a double-word program or
/// a page erase): the program leaves three bytes of its double word (which then reads with an
/// ECC error when `ecc`, as on the G0), the erase half its page, and every later operation fails.
struct CutFlash {
    bytes: Vec<u8>,
    ops_left: u32,
    ecc: bool,
    /// The double words that read with an ECC error.
    unreadable: Vec<u32>,
}

impl ErrorType for CutFlash {
    type Error = NorFlashErrorKind;
}

impl ReadNorFlash for CutFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let end = offset + bytes.len() as u32;
        if self
            .unreadable
            .iter()
            .any(|&word| word + 8 > offset && word < end)
        {
            return Err(NorFlashErrorKind::Other);
        }
        let from = self.bytes.get(offset as usize..end as usize);
        bytes.copy_from_slice(from.ok_or(NorFlashErrorKind::OutOfBounds)?);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.bytes.len()
    }
}

impl NorFlash for CutFlash {
    const WRITE_SIZE: usize = 8;
    const ERASE_SIZE: usize = PAGE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.ops_left = self.ops_left.checked_sub(1).ok_or(NorFlashErrorKind::Other)?;
        let page = self.bytes.get_mut(from as usize..to as usize);
        let page = page.ok_or(NorFlashErrorKind::OutOfBounds)?;
        if self.ops_left == 0 {
            let half = page.len() / 2;
            page[..half].fill(0xff);
            return Err(NorFlashErrorKind::Other);
        }
        page.fill(0xff);
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        for (k, word) in bytes.chunks(8).enumerate() {
            self.ops_left = self.ops_left.checked_sub(1).ok_or(NorFlashErrorKind::Other)?;
            let at = offset as usize + 8 * k;
            let to = self.bytes.get_mut(at..at + word.len());
            let to = to.ok_or(NorFlashErrorKind::OutOfBounds)?;
            let cut = self.ops_left == 0;
            for (to, byte) in to.iter_mut().zip(word).take(if cut { 3 } else { 8 }) {
                *to &= byte;
            }
            if cut {
                if self.ecc {
                    self.unreadable.push(at as u32);
                }
                return Err(NorFlashErrorKind::Other);
            }
        }
        Ok(())
    }
}

/// FNV-1a, 64 bits.
fn fnv1a(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |hash, byte| {
        (hash ^ u64::from(byte)).wrapping_mul(0x0100_0000_01b3)
    })
}

/// A power cut at every flash operation of 40 saves (at every 7th past the 400th), the torn
/// double word readable or not, then a restart: today's load walk restores what the previous
/// firmware's restored from the same torn flash, and counts the same damage.
#[test]
fn after_a_power_cut_the_store_restores_what_the_previous_firmware_restored() {
    let text = include_str!("testdata/cuts-format-1.txt");
    let mut expected = text.lines().filter(|line| !line.starts_with('#'));
    let mut cuts = 0;
    for ecc in [false, true] {
        cuts += cuts_until_saved(ecc, &mut expected);
    }
    assert_eq!(expected.next(), None, "as many cuts as the previous firmware met");
    assert!(cuts > 800);
}

/// Cuts the 40 saves at each operation in turn until they complete, each restored as `expected`
/// lists; how many cuts.
fn cuts_until_saved<'a>(ecc: bool, expected: &mut impl Iterator<Item = &'a str>) -> usize {
    let mut cuts = 0;
    let mut cut = 1u32;
    loop {
        let flash = CutFlash {
            bytes: std::vec![0xff; PAGES * PAGE],
            ops_left: cut,
            ecc,
            unreadable: Vec::new(),
        };
        let mut store = Store::<_, 3>::new(flash, 0..(PAGES * PAGE) as u32).unwrap();
        store.load();
        let finished = (0..40).all(|i| {
            let at = Instant::from_millis(u64::from(i) * 400_000);
            store.save(&snapshot(i), Some(at)).is_ok()
        });
        if finished {
            return cuts;
        }
        let mut flash = store.into_flash();
        flash.ops_left = u32::MAX;
        let mut restarted = Store::<_, 3>::new(flash, 0..(PAGES * PAGE) as u32).unwrap();
        let restored = restarted.load();
        let damage = restarted.damage();
        let got = std::format!(
            "{cut} {:016x} {} {}",
            fnv1a(&std::format!("{restored:?}")),
            damage.unreadable,
            damage.torn
        );
        assert_eq!(
            Some(got.as_str()),
            expected.next(),
            "cut at operation {cut} (ECC error: {ecc}): {restored:?}"
        );
        cuts += 1;
        cut += if cut < 400 { 1 } else { 7 };
    }
}
