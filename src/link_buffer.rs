//! The bytes between the printer link's tasks and the control task: what the UART received, on
//! its way into a step, and a step's answers, on their way out.
//!
//! Not embassy-sync's `Pipe`: on the step-cost harness each `try_read` or `try_write` of a pipe
//! cost about 110 instructions and a call of the copy routine, and a millisecond that receives a
//! request and answers it made five of them, about 800 of its 7 850 (`bash scripts/step-cost.sh`).
//! Neither side needs what a pipe adds: the control task never waits for bytes (it runs every
//! millisecond and takes what is there), and the transmit task is woken by a signal. So a buffer
//! is a `heapless::Vec` filled at its end and emptied from its front, one copy each way, behind
//! the tasks' blocking mutex (src/tasks.rs).

use heapless::Vec;

/// Bytes in arrival order, at most `N`.
#[derive(Debug, Default)]
pub struct LinkBuffer<const N: usize> {
    bytes: Vec<u8, N>,
}

impl<const N: usize> LinkBuffer<N> {
    /// An empty buffer.
    pub const fn new() -> Self {
        LinkBuffer { bytes: Vec::new() }
    }

    /// Appends as many of `bytes` as there is room for; returns how many.
    pub fn push(&mut self, bytes: &[u8]) -> usize {
        let count = bytes.len().min(self.room());
        // Within the room: cannot fail.
        let _ = self
            .bytes
            .extend_from_slice(bytes.get(..count).unwrap_or_default());
        count
    }

    /// Moves the oldest bytes into `out`, as many as wait and fit; returns how many.
    pub fn take(&mut self, out: &mut [u8]) -> usize {
        let count = out.len().min(self.bytes.len());
        if count == 0 {
            return 0;
        }
        if let (Some(out), Some(oldest)) = (out.get_mut(..count), self.bytes.get(..count)) {
            out.copy_from_slice(oldest);
        }
        if count == self.bytes.len() {
            // The usual case: a step takes everything that came.
            self.bytes.clear();
        } else {
            self.bytes.copy_within(count.., 0);
            self.bytes.truncate(self.bytes.len() - count);
        }
        count
    }

    /// Bytes waiting.
    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    /// Nothing waits.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// Bytes that would still fit.
    pub fn room(&self) -> usize {
        N - self.bytes.len()
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use proptest::prelude::*;

    #[test]
    fn bytes_come_out_in_the_order_they_went_in_across_partial_takes() {
        let mut buffer = LinkBuffer::<8>::new();
        assert_eq!(buffer.push(b"Q0\n"), 3);
        assert_eq!(buffer.push(b"T1\n"), 3);
        let mut out = [0; 4];
        assert_eq!(buffer.take(&mut out), 4);
        assert_eq!(&out, b"Q0\nT");
        assert_eq!(buffer.push(b"P0"), 2);
        assert_eq!(buffer.take(&mut out), 4);
        assert_eq!(&out, b"1\nP0");
        assert!(buffer.is_empty());
        assert_eq!(buffer.take(&mut out), 0);
    }

    #[test]
    fn a_full_buffer_takes_only_what_fits_and_says_how_much() {
        let mut buffer = LinkBuffer::<4>::new();
        assert_eq!(buffer.push(b"abcdef"), 4);
        assert_eq!(buffer.room(), 0);
        assert_eq!(buffer.push(b"g"), 0);
        let mut out = [0; 8];
        assert_eq!(buffer.take(&mut out), 4);
        assert_eq!(&out[..4], b"abcd");
    }

    proptest! {
        /// Any interleaving of pushes and takes passes the bytes through as a queue would.
        #[test]
        fn it_is_a_bounded_queue(ops in proptest::collection::vec((any::<bool>(), 0usize..12), 0..60)) {
            let mut buffer = LinkBuffer::<16>::new();
            let mut model = std::collections::VecDeque::new();
            let mut next = 0u8;
            for (is_push, n) in ops {
                if is_push {
                    let bytes: std::vec::Vec<u8> = (0..n).map(|k| next.wrapping_add(k as u8)).collect();
                    let pushed = buffer.push(&bytes);
                    prop_assert_eq!(pushed, n.min(16 - model.len()));
                    model.extend(&bytes[..pushed]);
                    next = next.wrapping_add(pushed as u8);
                } else {
                    let mut out = [0u8; 12];
                    let taken = buffer.take(&mut out[..n]);
                    prop_assert_eq!(taken, n.min(model.len()));
                    let expected: std::vec::Vec<u8> = model.drain(..taken).collect();
                    prop_assert_eq!(&out[..taken], &expected[..]);
                }
                prop_assert_eq!(buffer.len(), model.len());
            }
        }
    }
}
