//! A NOR flash in RAM for the persistence and board tests: erased to 0xff, a program only clears
//! bits, with the geometry of the flash it stands for (by default the STM32G0's: 2 KiB pages
//! programmed by double words; `RamFlash<4096, 1>` is the Pico's QSPI flash through embassy-rp's
//! driver), and a count of the pages it erased.

extern crate std;

use std::vec::Vec;

use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashErrorKind, ReadNorFlash};

/// A page of the STM32G0's flash, bytes.
pub const PAGE: usize = 2048;

/// The flash's bytes, in pages of `ERASE` bytes programmed `WRITE` bytes at a time.
#[derive(Clone)]
pub struct RamFlash<const ERASE: usize = PAGE, const WRITE: usize = 8> {
    /// The flash's bytes.
    pub bytes: Vec<u8>,
    /// Pages erased so far.
    pub erases: u32,
}

impl<const ERASE: usize, const WRITE: usize> RamFlash<ERASE, WRITE> {
    /// A flash holding `bytes`.
    pub fn new(bytes: Vec<u8>) -> Self {
        RamFlash { bytes, erases: 0 }
    }

    /// An erased flash of `pages` pages.
    pub fn erased(pages: usize) -> Self {
        Self::new(std::vec![0xff; pages * ERASE])
    }
}

impl<const ERASE: usize, const WRITE: usize> ErrorType for RamFlash<ERASE, WRITE> {
    type Error = NorFlashErrorKind;
}

impl<const ERASE: usize, const WRITE: usize> ReadNorFlash for RamFlash<ERASE, WRITE> {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let from = self.bytes.get(offset as usize..offset as usize + bytes.len());
        bytes.copy_from_slice(from.ok_or(NorFlashErrorKind::OutOfBounds)?);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.bytes.len()
    }
}

impl<const ERASE: usize, const WRITE: usize> NorFlash for RamFlash<ERASE, WRITE> {
    const WRITE_SIZE: usize = WRITE;
    const ERASE_SIZE: usize = ERASE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if !(from as usize).is_multiple_of(ERASE) || !(to as usize).is_multiple_of(ERASE) {
            return Err(NorFlashErrorKind::NotAligned);
        }
        let pages = self.bytes.get_mut(from as usize..to as usize);
        pages.ok_or(NorFlashErrorKind::OutOfBounds)?.fill(0xff);
        self.erases += (to - from) / ERASE as u32;
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let to = self.bytes.get_mut(offset as usize..offset as usize + bytes.len());
        for (to, byte) in to.ok_or(NorFlashErrorKind::OutOfBounds)?.iter_mut().zip(bytes) {
            *to &= byte;
        }
        Ok(())
    }
}
