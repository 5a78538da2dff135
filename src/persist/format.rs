//! The on-flash format against a store written by an earlier firmware: a unit updated in the
//! field must restore what the previous build kept, and keep writing the same bytes.
//!
//! `testdata/store-format-1.txt` was written by the firmware of commit 4579974 (before the flash
//! cut of issue 14) running [`save_the_sequence`] with its own `Store`: the test loads it with
//! today's `Store` and writes the same sequence again, byte for byte.

extern crate std;

use std::string::String;
use std::vec::Vec;

use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashErrorKind, ReadNorFlash};

use super::{Counters, Snapshot, Store};
use crate::time::Instant;
use crate::unit::Lane;

const PAGE: usize = 2048;
const PAGES: usize = 3;

/// A NOR flash in RAM: erased to 0xff, programmed by double words that only clear bits.
#[derive(Clone)]
struct RamFlash(Vec<u8>);

impl ErrorType for RamFlash {
    type Error = NorFlashErrorKind;
}

impl ReadNorFlash for RamFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let from = self.0.get(offset as usize..offset as usize + bytes.len());
        bytes.copy_from_slice(from.ok_or(NorFlashErrorKind::OutOfBounds)?);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.0.len()
    }
}

impl NorFlash for RamFlash {
    const WRITE_SIZE: usize = 8;
    const ERASE_SIZE: usize = PAGE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let page = self.0.get_mut(from as usize..to as usize);
        page.ok_or(NorFlashErrorKind::OutOfBounds)?.fill(0xff);
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let to = self.0.get_mut(offset as usize..offset as usize + bytes.len());
        for (to, byte) in to.ok_or(NorFlashErrorKind::OutOfBounds)?.iter_mut().zip(bytes) {
            *to &= byte;
        }
        Ok(())
    }
}

fn store(flash: RamFlash) -> Store<RamFlash, 3> {
    Store::new(flash, 0..(PAGES * PAGE) as u32).unwrap()
}

/// The flash image of `testdata/store-format-1.txt`.
fn written_by_format_1() -> RamFlash {
    let mut flash = RamFlash(std::vec![0xff; PAGES * PAGE]);
    let text = include_str!("testdata/store-format-1.txt");
    for line in text.lines().filter(|line| !line.starts_with('#')) {
        let mut fields = line.split_whitespace();
        let offset = usize::from_str_radix(fields.next().unwrap(), 16).unwrap();
        for (at, byte) in fields.enumerate() {
            flash.0[offset + at] = u8::from_str_radix(byte, 16).unwrap();
        }
    }
    flash
}

const LANES: [Lane; 6] = [
    Lane::Unknown,
    Lane::Empty,
    Lane::Parked,
    Lane::InHub,
    Lane::AtFsensor,
    Lane::Loaded,
];

/// The `i`-th snapshot of the sequence: every lane code, counters over their whole widths, a
/// settings list that grows and shrinks (up to 18 settings), the identity register last.
fn snapshot(i: u32) -> Snapshot<3> {
    let mut snapshot = Snapshot::<3> {
        lanes: [
            LANES[(i % 6) as usize],
            LANES[((i / 6) % 6) as usize],
            LANES[((i + 3) % 6) as usize],
        ],
        counters: Counters {
            drive_errors: (i * 7) as u16,
            tool_changes: [i as u16, (i * 300) as u16, 65_535 - i as u16],
            failures: [(i / 3) as u16, 1, 0x1234],
            fed_mm: [i * 1_000_003, 70_000 + i, u32::MAX - i],
        },
        ..Snapshot::default()
    };
    snapshot.settings.push((0x0b, 300 + i as u16)).unwrap();
    if i % 4 == 0 {
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
    for (index, word) in flash.0.chunks(8).enumerate() {
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
    let mut store = store(RamFlash(std::vec![0xff; PAGES * PAGE]));
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
