//! The printer UART's receive side on both boards: a DMA channel copies every received byte into
//! a ring in RAM, whatever the CPU does (a flash erase stalls it: `mmu_firmware::uart`), and
//! [`RingRx`] takes them out, looking at the ring at each control tick. The board says how many
//! bytes its DMA has written and what its UART saw go wrong ([`RingSource`]); the decisions (how
//! many bytes wait, what was lost) are `mmu_firmware::uart::DmaRing`, host tested.
//!
//! Why once a step and not on an interrupt: the DMA raises none per byte, and the UART's receive
//! timeout or idle-line interrupt would wake a task per message. On the emulated G071,
//! embassy-stm32's `RingBufferedUartRx` (woken by the idle line; its ring divides once per byte
//! read) cost about 2 400 instructions in a millisecond in which a message arrived. Woken by the
//! control task's [`tasks::TICKED`] rather than a timer at the next tick: the timer cost the
//! G071 about 400 instructions a millisecond more (the time driver's queue and alarm, and the
//! next tick's 64-bit division). The bytes wait a step longer for it (the control task takes
//! them at its next step): the printer waits up to 2 s for an answer.

use mmu_firmware::tasks;
use mmu_firmware::uart::DmaRing;

/// A board's receive DMA ring of `N` bytes.
pub trait RingSource<const N: usize> {
    /// A receive error of the board's UART.
    type Error: embedded_io_async::Error;
    /// The error a lapped ring (bytes lost) is reported as.
    const LOST: Self::Error;
    /// Bytes the DMA has written since the start, wrapping.
    fn written(&mut self) -> u32;
    /// A receive error of the UART since the last look, if any (cleared by the look).
    fn line_error(&mut self) -> Option<Self::Error>;
    /// The ring's byte `index` (`index < N`), read as the DMA writes it.
    fn byte(&self, index: usize) -> u8;
}

/// The receive side as `tasks::run_link_rx` reads it.
pub struct RingRx<S, const N: usize> {
    source: S,
    reader: DmaRing<N>,
    /// Lost bytes already reported.
    reported_lost: u32,
}

impl<S: RingSource<N>, const N: usize> RingRx<S, N> {
    /// The reader of `source`'s ring, from the DMA's start.
    pub fn new(source: S) -> Self {
        RingRx {
            source,
            reader: DmaRing::new(),
            reported_lost: 0,
        }
    }
}

impl<S: RingSource<N>, const N: usize> embedded_io_async::ErrorType for RingRx<S, N> {
    type Error = S::Error;
}

impl<S: RingSource<N>, const N: usize> embedded_io_async::Read for RingRx<S, N> {
    /// The bytes waiting, as many as fit (at least one: waits for it). An error is reported
    /// once, with no bytes: the ring lapped (bytes lost, reported at the read after the one that
    /// found it) or the UART saw a bad frame.
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, S::Error> {
        if self.reader.lost() != self.reported_lost {
            self.reported_lost = self.reader.lost();
            return Err(S::LOST);
        }
        loop {
            if let Some(error) = self.source.line_error() {
                return Err(error);
            }
            let written = self.source.written();
            if self.reader.waiting(written) > 0 {
                let source = &self.source;
                return Ok(self.reader.take(written, |i| source.byte(i), buf));
            }
            // Looked at again once the control task has stepped again (a look every 500 µs
            // between the ticks cost the emulated Pico about 770 instructions a millisecond
            // more); the control task takes a step's worth a tick.
            tasks::TICKED.wait().await;
        }
    }
}
