//! A NOR flash in memory that behaves like the STM32G0's (RM0444 §3.3) and can lose power in the
//! middle of any program or erase: the simulated unit's persistent store, and the test bench of
//! its crash consistency.
//!
//! What the model keeps of the chip: pages of `PAGE` bytes (2 KiB on the G0) erased to `0xff`;
//! programming by 64-bit double words, each programmable once between erases (programming a double
//! word that is not erased fails with PROGERR and changes nothing, except writing all zeros, which
//! the G0 allows); ECC per double word. A power cut stops the operation in flight
//! ([`CutModel::Torn`]): a cut program leaves its double word with a double-bit ECC error (on the
//! chip a read raises the NMI; here the read returns [`FlashError::Ecc`]), a cut erase leaves each
//! double word of the page erased, old or unreadable, at random. After the cut every operation
//! fails until [`MemFlash::power_on`].

use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};
use mmu_model::Rng;

/// Word size of a program: the STM32G0 programs 64-bit double words.
pub const WRITE_SIZE: usize = 8;
/// Page size of the STM32G0, bytes.
pub const G0_PAGE: usize = 2048;
/// The longest a page erase stalls the STM32G071's CPU, µs (datasheet: 40 ms at most).
pub const G0_ERASE_STALL_US: u64 = 40_000;
/// The longest a double-word program stalls it, µs (datasheet: 125 µs at most).
pub const G0_PROGRAM_STALL_US: u64 = 125;
/// The longest a 256-byte fast page erase stalls the BMCU-C's CH32V203, µs: no erase time of
/// the chip was found in its datasheet; a store page's four erases are taken at the 40 ms the
/// firmware assumes (`mmu_firmware::uart::BMCU_ERASE_STALL_MS`), as fil/bmcu's bench does.
pub const BMCU_ERASE_STALL_US: u64 = 10_000;
/// The longest a half-word program stalls it, µs: not found either; the G071's double-word
/// bound as a stand-in (fil/bmcu/flash.py).
pub const BMCU_PROGRAM_STALL_US: u64 = 125;

/// What a unit's flash operations could do to its filament, step by step: the figures of
/// [`FlashWear`] that only the unit, which sees its motors, can count.
#[derive(Debug, Clone, Copy, Default)]
pub struct MotionWatch {
    erases_while_driven: u64,
    most_uncommanded_um: u64,
}

impl MotionWatch {
    /// A step left `motors` as they are, then erased `erases` pages and programmed `programs`
    /// times, each stalling the CPU at most `stall_us` (erase, program) with the motors running
    /// on at their duty of `full_duty_speed` mm/s.
    pub fn step(
        &mut self,
        motors: &[mmu_firmware::MotorCommand],
        (erases, programs): (u64, u64),
        (erase_us, program_us): (u64, u64),
        full_duty_speed: u16,
    ) {
        let fastest_permille = motors
            .iter()
            .filter_map(|motor| match motor {
                mmu_firmware::MotorCommand::Drive { duty, .. } => Some(u64::from(duty.permille())),
                _ => None,
            })
            .max()
            .unwrap_or(0);
        if fastest_permille > 0 {
            self.erases_while_driven += erases;
        }
        // mm/s × µs = 10⁻³ µm.
        let stall_us = erases * erase_us + programs * program_us;
        let moved_um = fastest_permille * u64::from(full_duty_speed) * stall_us / 1_000_000;
        self.most_uncommanded_um = self.most_uncommanded_um.max(moved_um);
    }

    /// `wear` with what this watch counted.
    pub fn wear(self, wear: FlashWear) -> FlashWear {
        FlashWear {
            erases_while_driven: self.erases_while_driven,
            most_uncommanded_um: self.most_uncommanded_um,
            ..wear
        }
    }
}

/// Why an operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlashError {
    /// Out of range or not aligned.
    Invalid(NorFlashErrorKind),
    /// The power is gone.
    PowerCut,
    /// A read met a double word with a double-bit ECC error (its address).
    Ecc(u32),
    /// A program of a double word that is not erased (PROGERR), or a flash that has stopped
    /// programming and erasing ([`MemFlash::set_broken`]).
    Program(u32),
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::Invalid(kind) => *kind,
            FlashError::PowerCut | FlashError::Ecc(_) | FlashError::Program(_) => NorFlashErrorKind::Other,
        }
    }
}

/// What a power cut does to the operation in flight.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CutModel {
    /// The operation in flight never starts: the flash holds what the operations before it left.
    Clean,
    /// The operation in flight is torn: a program leaves its double word unreadable (ECC double
    /// error), an erase leaves each double word of its page erased or old at random.
    Torn,
    /// As [`CutModel::Torn`], and a torn erase also leaves some double words unreadable.
    TornUnreadable,
}

impl CutModel {
    /// Every model, for tests that try them all.
    pub const ALL: [CutModel; 3] = [CutModel::Clean, CutModel::Torn, CutModel::TornUnreadable];
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
    /// Page erases while a motor was driven: each would have stalled the CPU with the motor
    /// running on, moving filament nobody commanded. Counted by the simulated unit.
    pub erases_while_driven: u64,
    /// The most filament one step's flash operations could have moved uncommanded at the
    /// chip's longest stall ([`uncommanded_um`]), µm.
    pub most_uncommanded_um: u64,
}

impl FlashWear {
    /// The wear of two flashes (or two lives of one) together; the page maximum is the larger.
    pub fn combined(self, other: FlashWear) -> FlashWear {
        FlashWear {
            bytes_written: self.bytes_written + other.bytes_written,
            erases: self.erases + other.erases,
            max_page_erases: self.max_page_erases.max(other.max_page_erases),
            erases_while_driven: self.erases_while_driven + other.erases_while_driven,
            most_uncommanded_um: self.most_uncommanded_um.max(other.most_uncommanded_um),
        }
    }
}

/// A planned power cut.
#[derive(Debug, Clone)]
struct Cut {
    /// Operations (double-word programs and page erases) still allowed before the cut.
    after_ops: u64,
    model: CutModel,
    rng: Rng,
}

/// The flash, with pages of `PAGE` bytes.
#[derive(Debug, Clone)]
pub struct MemFlash<const PAGE: usize> {
    bytes: Vec<u8>,
    /// Per double word: it reads with a double-bit ECC error.
    unreadable: Vec<bool>,
    cut: Option<Cut>,
    powered: bool,
    /// Programs and erases fail (a worn-out or faulty flash).
    broken: bool,
    /// Bytes written since creation.
    pub bytes_written: u64,
    /// Page erases since creation, per page (cut ones too: they wear the page as well).
    pub erases: Vec<u64>,
    /// Double-word programs and page erases started since creation.
    pub operations: u64,
    /// The [`MemFlash::operations`] index of each page erase started.
    pub erase_operations: Vec<u64>,
}

impl<const PAGE: usize> MemFlash<PAGE> {
    const DOUBLE_WORDS_PER_PAGE: usize = PAGE / WRITE_SIZE;

    /// An erased flash of `pages` pages.
    pub fn new(pages: usize) -> Self {
        MemFlash {
            bytes: vec![0xff; pages * PAGE],
            unreadable: vec![false; pages * PAGE / WRITE_SIZE],
            cut: None,
            powered: true,
            broken: false,
            bytes_written: 0,
            erases: vec![0; pages],
            operations: 0,
            erase_operations: Vec::new(),
        }
    }

    /// Lose power at the operation (double-word program or page erase) `ops` from now: that many
    /// complete, the next one is cut as `model` says (`seed` decides a torn erase's mix).
    pub fn cut_power_at(&mut self, ops: u64, model: CutModel, seed: u64) {
        self.cut = Some(Cut {
            after_ops: ops,
            model,
            rng: Rng::new(seed),
        });
    }

    /// Power comes back: the contents are what the last operations left.
    pub fn power_on(&mut self) {
        self.cut = None;
        self.powered = true;
    }

    /// Whether the power is gone.
    pub fn is_cut(&self) -> bool {
        !self.powered
    }

    /// From now on every program and erase fails (`true`; reads still work), or works again.
    pub fn set_broken(&mut self, broken: bool) {
        self.broken = broken;
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
            erases_while_driven: 0,
            most_uncommanded_um: 0,
        }
    }

    /// Whether any double word reads with an ECC error.
    pub fn has_ecc_errors(&self) -> bool {
        self.unreadable.iter().any(|&bad| bad)
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

    /// Start one operation: `Some(model)` when the power goes during it.
    fn begin(&mut self) -> Option<(CutModel, Rng)> {
        self.operations += 1;
        let cut = self.cut.as_mut()?;
        if cut.after_ops > 0 {
            cut.after_ops -= 1;
            return None;
        }
        self.powered = false;
        self.cut.take().map(|cut| (cut.model, cut.rng))
    }

    fn program(&mut self, double_word: usize, data: &[u8]) -> Result<(), FlashError> {
        let range = double_word * WRITE_SIZE..(double_word + 1) * WRITE_SIZE;
        let address = range.start as u32;
        let erased = !self.unreadable[double_word] && self.bytes[range.clone()].iter().all(|&b| b == 0xff);
        let zeros = data.iter().all(|&b| b == 0);
        if let Some((model, mut rng)) = self.begin() {
            if model != CutModel::Clean && (erased || zeros) {
                // Half-programmed cells: some bits of the new value, and an ECC double error.
                for (cell, &byte) in self.bytes[range].iter_mut().zip(data) {
                    *cell &= byte | rng.next_u64() as u8;
                }
                self.unreadable[double_word] = true;
            }
            return Err(FlashError::PowerCut);
        }
        if self.broken || !(erased || zeros) {
            return Err(FlashError::Program(address));
        }
        self.bytes[range].copy_from_slice(data);
        self.bytes_written += WRITE_SIZE as u64;
        Ok(())
    }

    fn erase_page(&mut self, page: usize) -> Result<(), FlashError> {
        let range = page * PAGE..(page + 1) * PAGE;
        let words = page * Self::DOUBLE_WORDS_PER_PAGE..(page + 1) * Self::DOUBLE_WORDS_PER_PAGE;
        self.erase_operations.push(self.operations);
        let cut = self.begin();
        self.erases[page] += 1;
        match cut {
            None if self.broken => Err(FlashError::Program(range.start as u32)),
            None => {
                self.bytes[range].fill(0xff);
                self.unreadable[words].fill(false);
                Ok(())
            }
            Some((CutModel::Clean, _)) => {
                self.erases[page] -= 1;
                Err(FlashError::PowerCut)
            }
            Some((model, mut rng)) => {
                let outcomes = if model == CutModel::Torn { 2 } else { 3 };
                for word in words {
                    match rng.next_u64() % outcomes {
                        0 => {
                            self.bytes[word * WRITE_SIZE..(word + 1) * WRITE_SIZE].fill(0xff);
                            self.unreadable[word] = false;
                        }
                        1 => {}
                        _ => self.unreadable[word] = true,
                    }
                }
                Err(FlashError::PowerCut)
            }
        }
    }
}

impl<const PAGE: usize> ErrorType for MemFlash<PAGE> {
    type Error = FlashError;
}

impl<const PAGE: usize> ReadNorFlash for MemFlash<PAGE> {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        let range = self.check(offset, bytes.len(), 1)?;
        let words = range.start / WRITE_SIZE..range.end.div_ceil(WRITE_SIZE);
        if let Some(bad) = words.clone().find(|&word| self.unreadable[word]) {
            return Err(FlashError::Ecc((bad * WRITE_SIZE) as u32));
        }
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

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        let range = self.check(from, (to.saturating_sub(from)) as usize, PAGE)?;
        for page_start in range.step_by(PAGE) {
            self.erase_page(page_start / PAGE)?;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        let range = self.check(offset, bytes.len(), WRITE_SIZE)?;
        for (index, data) in bytes.chunks_exact(WRITE_SIZE).enumerate() {
            self.program(range.start / WRITE_SIZE + index, data)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type Flash = MemFlash<64>;

    fn read(flash: &mut Flash, offset: u32) -> Result<[u8; 8], FlashError> {
        let mut word = [0; 8];
        flash.read(offset, &mut word).map(|()| word)
    }

    #[test]
    fn a_double_word_is_programmed_once_between_erases() {
        let mut flash = Flash::new(2);
        flash.write(8, &[1; 8]).unwrap();
        assert_eq!(flash.write(8, &[1; 8]), Err(FlashError::Program(8)), "PROGERR");
        assert_eq!(
            read(&mut flash, 8),
            Ok([1; 8]),
            "a failed program changes nothing"
        );
        flash.write(8, &[0; 8]).unwrap();
        assert_eq!(read(&mut flash, 8), Ok([0; 8]), "all zeros may be written over");
        flash.erase(0, 64).unwrap();
        flash.write(8, &[2; 8]).unwrap();
        assert_eq!(read(&mut flash, 8), Ok([2; 8]));
    }

    #[test]
    fn a_cut_program_leaves_an_unreadable_double_word_until_the_page_is_erased() {
        let mut flash = Flash::new(2);
        flash.cut_power_at(1, CutModel::Torn, 1);
        assert_eq!(flash.write(0, &[3; 24]), Err(FlashError::PowerCut));
        assert_eq!(read(&mut flash, 0), Err(FlashError::PowerCut), "no power");
        flash.power_on();
        assert_eq!(read(&mut flash, 0), Ok([3; 8]), "the first double word completed");
        assert_eq!(read(&mut flash, 8), Err(FlashError::Ecc(8)));
        assert_eq!(read(&mut flash, 16), Ok([0xff; 8]), "never started");
        assert_eq!(flash.write(8, &[4; 8]), Err(FlashError::Program(8)));
        flash.erase(0, 64).unwrap();
        assert_eq!(read(&mut flash, 8), Ok([0xff; 8]));
    }

    #[test]
    fn a_cut_erase_leaves_a_mix_of_erased_old_and_unreadable_double_words() {
        let mut flash = Flash::new(1);
        flash.write(0, &[0; 64]).unwrap();
        flash.cut_power_at(0, CutModel::TornUnreadable, 7);
        assert_eq!(flash.erase(0, 64), Err(FlashError::PowerCut));
        flash.power_on();
        let words: Vec<_> = (0..8).map(|w| read(&mut flash, w * 8)).collect();
        assert!(words.contains(&Ok([0xff; 8])), "{words:?}");
        assert!(words.contains(&Ok([0; 8])), "{words:?}");
        assert!(words.iter().any(Result::is_err), "{words:?}");
    }
}
