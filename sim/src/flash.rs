//! A NOR flash in memory that keeps its contents across a simulated power loss and can lose
//! power itself at any byte of any write: the simulated unit's persistent store, and the test
//! bench of its crash consistency.
//!
//! Semantics of a real NOR flash such as the STM32G0's: erased bytes read `0xff`, a write can
//! only clear bits, writes and erases must be aligned. A power cut stops a write after the
//! bytes it was given and leaves an erase half done; after it every operation fails until
//! [`MemFlash::power_on`].

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// Word size of a write, bytes (the STM32G0 writes double words).
pub const WRITE_SIZE: usize = 8;
/// Page size of the STM32G0, bytes.
pub const G0_PAGE: usize = 2048;

/// Why an operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlashError {
    /// Out of range or not aligned.
    Invalid(NorFlashErrorKind),
    /// The power is gone.
    PowerCut,
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::Invalid(kind) => *kind,
            FlashError::PowerCut => NorFlashErrorKind::Other,
        }
    }
}

/// How much a flash has been worn.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FlashWear {
    /// Bytes written.
    pub bytes_written: u64,
    /// Page erases, all pages together.
    pub erases: u64,
    /// The most erases one page has seen.
    pub max_page_erases: u64,
}

impl FlashWear {
    /// The wear of two flashes (or two lives of one) together; the page maximum is the larger.
    pub fn combined(self, other: FlashWear) -> FlashWear {
        FlashWear {
            bytes_written: self.bytes_written + other.bytes_written,
            erases: self.erases + other.erases,
            max_page_erases: self.max_page_erases.max(other.max_page_erases),
        }
    }
}

/// The flash, with pages of `PAGE` bytes.
#[derive(Debug, Clone)]
pub struct MemFlash<const PAGE: usize> {
    bytes: Vec<u8>,
    /// Bytes that may still be written (an erase counts as one) before the power goes.
    budget: Option<usize>,
    powered: bool,
    /// Bytes written since creation.
    pub bytes_written: u64,
    /// Page erases since creation, per page.
    pub erases: Vec<u64>,
}

impl<const PAGE: usize> MemFlash<PAGE> {
    /// An erased flash of `pages` pages.
    pub fn new(pages: usize) -> Self {
        MemFlash {
            bytes: vec![0xff; pages * PAGE],
            budget: None,
            powered: true,
            bytes_written: 0,
            erases: vec![0; pages],
        }
    }

    /// Lose power after `bytes` more bytes written (an erase counts as one byte).
    pub fn cut_power_after(&mut self, bytes: usize) {
        self.budget = Some(bytes);
    }

    /// Power comes back: the contents are what the last operations left.
    pub fn power_on(&mut self) {
        self.budget = None;
        self.powered = true;
    }

    /// Whether the power is gone.
    pub fn is_cut(&self) -> bool {
        !self.powered
    }

    /// The most erases any page has seen.
    pub fn max_erases(&self) -> u64 {
        self.erases.iter().copied().max().unwrap_or(0)
    }

    /// How much it has been worn.
    pub fn wear(&self) -> FlashWear {
        FlashWear {
            bytes_written: self.bytes_written,
            erases: self.erases.iter().sum(),
            max_page_erases: self.max_erases(),
        }
    }

    fn check(&self, offset: u32, len: usize, align: usize) -> Result<std::ops::Range<usize>, FlashError> {
        if !self.powered {
            return Err(FlashError::PowerCut);
        }
        let start = offset as usize;
        if !start.is_multiple_of(align) || !len.is_multiple_of(align) {
            return Err(FlashError::Invalid(NorFlashErrorKind::NotAligned));
        }
        let end = start + len;
        if end > self.bytes.len() {
            return Err(FlashError::Invalid(NorFlashErrorKind::OutOfBounds));
        }
        Ok(start..end)
    }

    /// Take `wanted` bytes from the budget; how many may really be written.
    fn spend(&mut self, wanted: usize) -> usize {
        match &mut self.budget {
            None => wanted,
            Some(left) => {
                let granted = wanted.min(*left);
                *left -= granted;
                if granted < wanted {
                    self.powered = false;
                }
                granted
            }
        }
    }
}

impl<const PAGE: usize> ErrorType for MemFlash<PAGE> {
    type Error = FlashError;
}

impl<const PAGE: usize> ReadNorFlash for MemFlash<PAGE> {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        let range = self.check(offset, bytes.len(), 1)?;
        bytes.copy_from_slice(&self.bytes[range]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.bytes.len()
    }
}

impl<const PAGE: usize> NorFlash for MemFlash<PAGE> {
    const WRITE_SIZE: usize = WRITE_SIZE;
    const ERASE_SIZE: usize = PAGE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        let range = self.check(from, (to.saturating_sub(from)) as usize, PAGE)?;
        for page_start in range.step_by(PAGE) {
            let page = page_start..page_start + PAGE;
            if self.spend(1) == 0 {
                // Cut mid-erase: half the page is erased, the rest keeps its old bytes.
                self.bytes[page_start..page_start + PAGE / 2].fill(0xff);
                return Err(FlashError::PowerCut);
            }
            self.bytes[page].fill(0xff);
            self.erases[page_start / PAGE] += 1;
        }
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        let range = self.check(offset, bytes.len(), WRITE_SIZE)?;
        let granted = self.spend(bytes.len());
        for (cell, &byte) in self.bytes[range].iter_mut().zip(bytes).take(granted) {
            *cell &= byte;
        }
        self.bytes_written += granted as u64;
        if granted < bytes.len() {
            return Err(FlashError::PowerCut);
        }
        Ok(())
    }
}
