//! The store's flash: the last 4 KB of the CH32V203's rated 64 KB, as four 1 KB store pages.
//!
//! The chip erases 4 KB sectors (standard) or 256-byte pages (fast mode, after MODEKEYR's keys)
//! and programs half-words (standard) or 256-byte pages (`ch32-metapac`'s memory map; CH32V20x
//! reference manual, FLASH). The store needs at least three pages of at least four of its
//! largest entries (864 bytes), so a store page here is four fast erases, and entries are
//! programmed a half-word at a time (CTLR.PG).
//!
//! An erased word of this flash reads 0xE339E339, not all ones, until it is programmed (WCH's
//! flash example, openwch/ch32v20x `EVT/EXAM/FLASH/FLASH_Program/User/main.c`, note a: a word
//! 0xE339E339, a half-word 0xE339; also armink/EasyFlash#178): [`StoreFlash`] reads that word as
//! 0xFFFFFFFF, which the store takes for erased. A programmed word equal to
//! 0xE339E339 would read as erased too; the store's entries carry a CRC, so such an entry (one
//! word in 2³²) is found damaged and the one before it kept.

use core::convert::Infallible;
use core::ptr;

use ch32_metapac as pac;
use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};

/// The flash's base address; store offsets count from it.
const BASE: u32 = 0x0800_0000;
/// The fast-erase page.
const FAST_PAGE: u32 = 256;
/// What an erased word reads.
const ERASED_WORD: u32 = 0xE339_E339;
/// The keys of FLASH_KEYR and FLASH_MODEKEYR.
const KEYS: [u32; 2] = [0x4567_0123, 0xCDEF_89AB];

/// Why an erase or a write failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlashError {
    /// Outside the flash, or not aligned to the write or erase size.
    Range,
    /// The flash controller reported a write-protection error.
    Protected,
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::Range => NorFlashErrorKind::OutOfBounds,
            FlashError::Protected => NorFlashErrorKind::Other,
        }
    }
}

/// The rated 64 KB, erased and programmed through the flash controller, read memory-mapped.
pub struct StoreFlash;

impl StoreFlash {
    /// The flash (locked until an erase or a write).
    pub fn new() -> Self {
        StoreFlash
    }
}

/// Unlocks standard programming, and with `fast` the fast mode's 256-byte erase too.
fn unlock(fast: bool) {
    let flash = pac::FLASH;
    if flash.ctlr().read().lock() {
        KEYS.iter()
            .for_each(|&key| flash.keyr().write(|w| w.set_keyr(key)));
    }
    if fast && flash.ctlr().read().flock() {
        KEYS.iter()
            .for_each(|&key| flash.modekeyr().write(|w| w.set_modekeyr(key)));
    }
}

/// Locks both again.
fn lock() {
    pac::FLASH.ctlr().modify(|w| {
        w.set_flock(true);
        w.set_lock(true);
    });
}

/// Waits for the operation under way; a write-protection error fails it (and is cleared).
fn finish() -> Result<(), FlashError> {
    let flash = pac::FLASH;
    while flash.statr().read().bsy() {}
    let status = flash.statr().read();
    flash.statr().write(|w| {
        w.set_eop(true);
        w.set_wrprterr(true);
    });
    if status.wrprterr() {
        Err(FlashError::Protected)
    } else {
        Ok(())
    }
}

/// Checks `offset..offset + len` lies in the rated 64 KB.
fn in_range(offset: u32, len: usize) -> Result<(), FlashError> {
    let end = offset.checked_add(u32::try_from(len).map_err(|_| FlashError::Range)?);
    match end {
        Some(end) if end as usize <= StoreFlash::CAPACITY => Ok(()),
        _ => Err(FlashError::Range),
    }
}

impl ErrorType for StoreFlash {
    type Error = FlashError;
}

impl ReadNorFlash for StoreFlash {
    const READ_SIZE: usize = 1;

    /// Memory-mapped reads, an erased word read as all ones.
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        in_range(offset, bytes.len())?;
        for (i, byte) in bytes.iter_mut().enumerate() {
            let address = BASE + offset + i as u32;
            // SAFETY: inside the flash (checked above); word-aligned reads of mapped flash.
            let word = unsafe { ptr::read_volatile((address & !3) as *const u32) };
            let word = if word == ERASED_WORD { u32::MAX } else { word };
            *byte = word.to_le_bytes()[(address & 3) as usize];
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        Self::CAPACITY
    }
}

impl StoreFlash {
    /// The rated flash.
    const CAPACITY: usize = 64 * 1024;
}

impl NorFlash for StoreFlash {
    const WRITE_SIZE: usize = 2;
    /// A store page: four fast-erase pages.
    const ERASE_SIZE: usize = 4 * FAST_PAGE as usize;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        if from > to
            || !from.is_multiple_of(Self::ERASE_SIZE as u32)
            || !to.is_multiple_of(Self::ERASE_SIZE as u32)
        {
            return Err(FlashError::Range);
        }
        in_range(from, (to - from) as usize)?;
        let flash = pac::FLASH;
        unlock(true);
        let mut result = Ok(());
        for page in (from..to).step_by(FAST_PAGE as usize) {
            flash.ctlr().modify(|w| w.set_page_er(true));
            flash.addr().write(|w| w.set_far(BASE + page));
            flash.ctlr().modify(|w| w.set_strt(true));
            result = finish();
            flash.ctlr().modify(|w| w.set_page_er(false));
            if result.is_err() {
                break;
            }
        }
        lock();
        result
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        if !offset.is_multiple_of(2) || !bytes.len().is_multiple_of(2) {
            return Err(FlashError::Range);
        }
        in_range(offset, bytes.len())?;
        let flash = pac::FLASH;
        unlock(false);
        flash.ctlr().modify(|w| w.set_pg(true));
        let mut result = Ok(());
        for (i, half) in bytes.chunks_exact(2).enumerate() {
            let address = BASE + offset + 2 * i as u32;
            // SAFETY: inside the flash (checked above), half-word aligned, with CTLR.PG set:
            // the controller programs the half-word.
            unsafe { ptr::write_volatile(address as *mut u16, u16::from_le_bytes([half[0], half[1]])) };
            result = finish();
            if result.is_err() {
                break;
            }
        }
        flash.ctlr().modify(|w| w.set_pg(false));
        lock();
        result
    }
}

impl From<Infallible> for FlashError {
    fn from(never: Infallible) -> Self {
        match never {}
    }
}
