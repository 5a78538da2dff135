//! The printer UART's receive side as the boards run it: a DMA channel writes every received byte
//! into a ring in RAM, whatever the CPU does, and the control step takes them out when it runs.
//!
//! Why DMA: a flash page erase stalls the CPU (the G071 fetches its code from the flash being
//! erased, up to 40 ms; the RP2040's flash driver runs with interrupts off while the QSPI flash
//! erases a 4 KiB sector, up to 400 ms), and an interrupt-driven driver loses every byte past the
//! USART's own FIFO meanwhile. A DMA transfer needs no CPU, so the ring keeps filling.
//!
//! A board says what its DMA has written and what its UART saw go wrong ([`RingSource`]: the
//! G071's circular transfer in src/board/g071/uart_ring.rs, the Pico's ring-mode channel in
//! src/board/pico/uart_ring.rs); the simulator models the same ring. [`ReceiveRing`] reads any of
//! them for the control step ([`crate::control::ControlLoop::step`]), and [`DmaRing`] is its
//! decisions, tested below against a model of the DMA, which also holds the ring sizes to the
//! longest stall of each board ([`G071_DMA_RING`], [`PICO_DMA_RING`]): a page erase while the
//! printer sends without pause loses no byte.

use crate::control::{LINE_BYTES_PER_MS, MAX_RX_PER_STEP};

/// The receive ring a board needs so that no byte is lost while the control loop does not step
/// for `gap_ms` (a flash stall) with the printer sending without pause: what arrives meanwhile
/// plus what a step leaves waiting.
pub const fn rx_ring_needed(gap_ms: usize) -> usize {
    gap_ms * LINE_BYTES_PER_MS + MAX_RX_PER_STEP
}

/// The longest a flash page erase stalls the NUCLEO-G071RB's CPU, ms (RM0444 / the STM32G071
/// datasheet: page erase 40 ms at most). The UART's DMA keeps receiving meanwhile.
pub const G071_ERASE_STALL_MS: usize = 40;
/// The printer UART's DMA receive ring on the NUCLEO-G071RB: what arrives during the longest
/// erase with the printer sending without pause, plus a step's worth (`crate::uart` tests it).
pub const G071_DMA_RING: usize = 512;
/// The longest a 4 KiB sector erase of the Pico's QSPI flash stalls its CPU, ms (W25Q16JV
/// datasheet, sector erase: 45 ms typical, 400 ms at most; embassy-rp's flash driver runs it
/// with interrupts off).
pub const PICO_ERASE_STALL_MS: usize = 400;
/// The printer UART's DMA receive ring on the Pico, as [`G071_DMA_RING`].
pub const PICO_DMA_RING: usize = 8192;

/// The longest a store page erase stalls the BMCU-C's CH32V203, ms: four 256-byte fast erases.
/// WCH's datasheet gives no erase time that was found; this is the G071's bound, taken as an
/// assumption until a board measures it.
pub const BMCU_ERASE_STALL_MS: usize = G071_ERASE_STALL_MS;
/// The printer UART's DMA receive ring on the BMCU-C, as [`G071_DMA_RING`].
pub const BMCU_DMA_RING: usize = 512;

const _: () = assert!(G071_DMA_RING >= rx_ring_needed(G071_ERASE_STALL_MS));
const _: () = assert!(BMCU_DMA_RING >= rx_ring_needed(BMCU_ERASE_STALL_MS));
const _: () = assert!(PICO_DMA_RING >= rx_ring_needed(PICO_ERASE_STALL_MS));

/// What a receive error of the printer link counts as.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineError {
    /// Bytes lost: the USART overran.
    Overrun,
    /// A frame with a framing, noise or parity error (or a break).
    Garbled,
}

/// The bytes a circular DMA channel has written into an `N`-byte ring, from its transfer counter
/// that counts down from `N` and reloads at 0 (the STM32's and the CH32's DMA, NDTR/CNDTR).
/// Fewer than `N` bytes may arrive between two looks: a move of the counter is never a whole
/// lap.
#[derive(Debug, Clone, Copy, Default)]
pub struct CountdownRing<const N: usize> {
    /// Bytes written since the start, wrapping, as of the last look.
    written: u32,
    /// The ring's offset the DMA writes next, as of the last look.
    position: u32,
}

impl<const N: usize> CountdownRing<N> {
    /// No byte written yet.
    pub const fn new() -> Self {
        CountdownRing {
            written: 0,
            position: 0,
        }
    }

    /// Bytes written since the start, wrapping, with the counter now at `remaining`.
    pub fn written(&mut self, remaining: u32) -> u32 {
        let mask = N as u32 - 1;
        let position = (N as u32).wrapping_sub(remaining) & mask;
        let moved = position.wrapping_sub(self.position) & mask;
        self.position = position;
        self.written = self.written.wrapping_add(moved);
        self.written
    }
}

/// A receive ring a DMA channel fills: what the board's hardware (or the simulator's model of
/// it) tells.
pub trait RingSource<const N: usize> {
    /// Bytes the DMA has written since the start, wrapping.
    fn written(&mut self) -> u32;
    /// A receive error of the UART since the last look, if any (cleared by the look).
    fn line_error(&mut self) -> Option<LineError>;
    /// The ring's byte `index` (`index < N`), read as the DMA writes it.
    fn byte(&self, index: usize) -> u8;
}

/// The bytes the printer sent, waiting for the control step.
pub trait Received {
    /// Moves the oldest bytes waiting into `out`, as many as wait and fit; returns how many.
    fn take(&mut self, out: &mut [u8]) -> usize;
    /// What went wrong on the line since start-up.
    fn errors(&self) -> LineErrors;
}

/// The bytes the printer sent, waiting in a board's DMA ring for the control step.
pub struct ReceiveRing<S, const N: usize> {
    source: S,
    reader: DmaRing<N>,
    /// USART overruns and garbled frames seen.
    line: LineErrors,
}

impl<S: RingSource<N>, const N: usize> ReceiveRing<S, N> {
    /// The reader of `source`'s ring, from the DMA's start.
    pub const fn new(source: S) -> Self {
        ReceiveRing {
            source,
            reader: DmaRing::new(),
            line: LineErrors {
                overruns: 0,
                garbled: 0,
            },
        }
    }

    /// Bytes waiting.
    pub fn waiting(&mut self) -> usize {
        let written = self.source.written();
        self.reader.waiting(written)
    }

    /// The ring's source (the simulator writes into its model of the DMA through it).
    pub fn source_mut(&mut self) -> &mut S {
        &mut self.source
    }
}

impl<S: RingSource<N>, const N: usize> Received for ReceiveRing<S, N> {
    fn take(&mut self, out: &mut [u8]) -> usize {
        match self.source.line_error() {
            Some(LineError::Overrun) => self.line.overruns = self.line.overruns.wrapping_add(1),
            Some(LineError::Garbled) => self.line.garbled = self.line.garbled.wrapping_add(1),
            None => {}
        }
        let written = self.source.written();
        let source = &self.source;
        self.reader.take(written, |i| source.byte(i), out)
    }

    /// The USART's overruns plus the bytes the DMA overwrote before they were taken, and the
    /// garbled frames.
    fn errors(&self) -> LineErrors {
        LineErrors {
            overruns: self.line.overruns.wrapping_add(self.reader.lost()),
            garbled: self.line.garbled,
        }
    }
}

/// A DMA ring in memory, written as a board's DMA writes its ring: the simulator's and the
/// tests' receive hardware.
#[derive(Debug, Clone)]
pub struct MemoryRing<const N: usize> {
    ring: [u8; N],
    written: u32,
}

impl<const N: usize> MemoryRing<N> {
    /// An empty ring.
    pub const fn new() -> Self {
        MemoryRing {
            ring: [0; N],
            written: 0,
        }
    }

    /// Bytes that arrived from the line, each written at once (overwriting the oldest when the
    /// reader is a lap behind, as the DMA does).
    pub fn receive(&mut self, bytes: &[u8]) {
        for &byte in bytes {
            if let Some(slot) = self.ring.get_mut(self.written as usize % N) {
                *slot = byte;
            }
            self.written = self.written.wrapping_add(1);
        }
    }
}

impl<const N: usize> Default for MemoryRing<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> RingSource<N> for MemoryRing<N> {
    fn written(&mut self) -> u32 {
        self.written
    }

    fn line_error(&mut self) -> Option<LineError> {
        None
    }

    fn byte(&self, index: usize) -> u8 {
        self.ring.get(index).copied().unwrap_or(0)
    }
}

/// What went wrong on the receive line since start-up: counts that only grow (wrapping), so that
/// the reader takes differences.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LineErrors {
    /// Overruns: bytes lost because the receive ring (or the USART) was full.
    pub overruns: u32,
    /// Frames with a framing, noise or parity error.
    pub garbled: u32,
}

impl LineErrors {
    /// What happened since `earlier`, a reading of the same counters.
    pub const fn since(&self, earlier: &LineErrors) -> LineErrors {
        LineErrors {
            overruns: self.overruns.wrapping_sub(earlier.overruns),
            garbled: self.garbled.wrapping_sub(earlier.garbled),
        }
    }

    /// Every byte lost or garbled.
    pub const fn total(&self) -> u32 {
        self.overruns.wrapping_add(self.garbled)
    }
}

/// The reader of a receive ring of `N` bytes that a DMA channel fills, wrapping at its end.
///
/// The DMA tells how many bytes it has written since it started (a wrapping count: on the RP2040
/// the start value of its transfer counter minus the counter); the byte number `k` sits at
/// `k % N`. The reader keeps its own count. When the DMA has lapped it (more than `N` unread),
/// the oldest bytes were overwritten: they are counted lost and reading resumes at the oldest
/// byte still in the ring.
#[derive(Debug, Clone, Copy, Default)]
pub struct DmaRing<const N: usize> {
    /// Bytes taken (or skipped as lost) since the start, wrapping.
    read: u32,
    /// Bytes lost to the DMA lapping the reader.
    lost: u32,
}

impl<const N: usize> DmaRing<N> {
    const FITS: () = assert!(N.is_power_of_two() && N <= 1 << 16);

    /// A reader at the start of the ring.
    pub const fn new() -> Self {
        let () = Self::FITS;
        DmaRing { read: 0, lost: 0 }
    }

    /// Bytes written and not yet taken, given the DMA's count `written`.
    pub fn waiting(&self, written: u32) -> usize {
        (written.wrapping_sub(self.read) as usize).min(N)
    }

    /// Copies the oldest unread bytes into `out`, as many as wait and fit, given the DMA's count
    /// `written` and `byte(i)`, a volatile read of the ring's byte `i`; returns how many. Bytes
    /// the DMA overwrote before they were read are skipped and counted ([`DmaRing::lost`]).
    pub fn take(&mut self, written: u32, byte: impl Fn(usize) -> u8, out: &mut [u8]) -> usize {
        let unread = written.wrapping_sub(self.read) as usize;
        if unread > N {
            let lost = unread - N;
            self.lost = self.lost.wrapping_add(lost as u32);
            self.read = self.read.wrapping_add(lost as u32);
        }
        let count = unread.min(N).min(out.len());
        for (k, slot) in out.iter_mut().take(count).enumerate() {
            *slot = byte((self.read as usize).wrapping_add(k) % N);
        }
        self.read = self.read.wrapping_add(count as u32);
        count
    }

    /// Bytes lost so far.
    pub const fn lost(&self) -> u32 {
        self.lost
    }
}

#[cfg(test)]
mod tests {
    //! The DMA ring against a model of the hardware: the USART delivers bytes at the line's
    //! rate whatever the CPU does, the DMA writes each into the ring at once, and the CPU takes
    //! bytes only when it runs (not while a flash erase stalls it).

    use super::*;

    /// A count-down counter read as bytes written: across its reload, and a whole ring's worth
    /// in steps.
    #[test]
    fn a_count_down_counter_reads_as_bytes_written() {
        let mut counter = CountdownRing::<512>::new();
        assert_eq!(counter.written(512), 0);
        assert_eq!(counter.written(500), 12);
        // Past the reload: 500 -> 0 -> 512 -> 20 is 500 - 20 = 480 more.
        assert_eq!(counter.written(20), 492);
        assert_eq!(counter.written(512), 512);
        for lap in 1..=3u32 {
            for remaining in (1..512).rev().step_by(100) {
                counter.written(remaining);
            }
            assert_eq!(counter.written(512), 512 * (lap + 1));
        }
    }

    use crate::control::LINE_BYTES_PER_S;

    extern crate std;
    use std::vec::Vec;

    /// The DMA and its ring: every byte written at once, the count growing (wrapping).
    struct Dma<const N: usize> {
        ring: Vec<u8>,
        written: u32,
    }

    impl<const N: usize> Dma<N> {
        fn new() -> Self {
            Dma {
                ring: std::vec![0; N],
                written: 0,
            }
        }

        fn receive(&mut self, byte: u8) {
            self.ring[self.written as usize % N] = byte;
            self.written = self.written.wrapping_add(1);
        }
    }

    /// The printer sending without pause for `ms` (11.52 bytes a ms, 115 200 Bd), the CPU taking
    /// at most a step's bytes each millisecond except while a flash erase stalls it from
    /// `stall_at` for `stall_ms`; returns what the CPU received and what the reader lost.
    fn session<const N: usize>(
        ms: usize,
        stall_at: usize,
        stall_ms: usize,
        start: u32,
    ) -> (Vec<u8>, Vec<u8>, u32) {
        let mut dma = Dma::<N>::new();
        dma.written = start;
        let mut reader = DmaRing::<N>::new();
        reader.read = start;
        let sent: Vec<u8> = (0..ms * LINE_BYTES_PER_S / 1000)
            .map(|i| (i * 7 + 3) as u8)
            .collect();
        let mut received = Vec::new();
        let mut at = 0;
        for step in 0..ms + 2 * N {
            let due = ((step + 1) * LINE_BYTES_PER_S / 1000).min(sent.len());
            while at < due {
                dma.receive(sent[at]);
                at += 1;
            }
            let stalled = (stall_at..stall_at + stall_ms).contains(&step);
            if !stalled {
                // A step's worth each millisecond, also after a stall.
                let mut out = [0u8; MAX_RX_PER_STEP];
                let n = reader.take(dma.written, |i| dma.ring[i], &mut out);
                received.extend_from_slice(&out[..n]);
            }
        }
        (sent, received, reader.lost())
    }

    #[test]
    fn a_page_erase_on_the_g071_while_the_printer_sends_loses_no_byte() {
        let (sent, received, lost) = session::<G071_DMA_RING>(2_000, 700, G071_ERASE_STALL_MS, 0);
        assert_eq!(lost, 0);
        assert!(received == sent, "{} of {} bytes", received.len(), sent.len());
    }

    #[test]
    fn a_sector_erase_on_the_pico_while_the_printer_sends_loses_no_byte() {
        let (sent, received, lost) = session::<PICO_DMA_RING>(3_000, 900, PICO_ERASE_STALL_MS, 0);
        assert_eq!(lost, 0);
        assert!(received == sent, "{} of {} bytes", received.len(), sent.len());
    }

    #[test]
    fn the_counts_wrap_around_without_losing_a_byte() {
        let (sent, received, lost) =
            session::<G071_DMA_RING>(1_000, 300, G071_ERASE_STALL_MS, u32::MAX - 2_000);
        assert_eq!(lost, 0);
        assert!(received == sent);
    }

    #[test]
    fn a_ring_too_small_for_the_stall_loses_the_oldest_bytes_and_counts_them() {
        // The model can fail: 256 bytes hold 22 ms of a printer that never pauses, not 40.
        let (sent, received, lost) = session::<256>(2_000, 700, G071_ERASE_STALL_MS, 0);
        assert!(lost > 0);
        assert_eq!(received.len() + lost as usize, sent.len());
        // What was received is the line with a gap, in order: the newest bytes were kept.
        let gap = sent
            .iter()
            .zip(&received)
            .position(|(a, b)| a != b)
            .unwrap_or(received.len());
        assert_eq!(&received[gap..], &sent[gap + lost as usize..]);
    }
}
