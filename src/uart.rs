//! The printer UART's interrupt-driven byte rings for an STM32 USART: every decision the driver
//! makes, over a [`UsartRegisters`] access the board implements with volatile reads and writes
//! (`src/board/printer_uart.rs`), so that host tests run the decisions against a model of the
//! registers (`tests` below), with and without FIFOs.
//!
//! It replaces embassy-stm32's `BufferedUart` (1.8 KB more flash, measured) with the same line
//! behaviour: the interrupt moves every received byte into the receive ring, and one that finds
//! the ring full is lost (the newest, as a UART overrun loses it; [`control::RxQueue`] is the same
//! rule); the control loop takes at most the buffer it passes ([`control::MAX_RX_PER_STEP`]);
//! [`Port::send`] queues a whole response or nothing.
//!
//! The register bits are those of RM0444 (STM32G0x1 reference manual), §33.8, USART registers.
//! The board's USART3 is a basic USART without FIFO mode on the G071 (RM0444, "USART
//! implementation"); a full USART in FIFO mode has the same bits at the same positions under
//! other names, which the constants below carry: USART_CR1 (§33.8.1: RXNEIE/RXFNEIE bit 5,
//! TXEIE/TXFNFIE bit 7), USART_ISR (§33.8.9: PE 0, FE 1, NE 2, ORE 3, RXNE/RXFNE 5, TC 6,
//! TXE/TXFNF 7) and USART_ICR (§33.8.11: PECF 0, FECF 1, NECF 2, ORECF 3; writing 1 clears the
//! ISR flag at the same position). The descriptions (read as ST's SVD carries them, e.g. the
//! `stm32g0` crate's `usart1::isr_fifo_enabled`) say: ORE is set when a frame completes in the
//! shift register while the receive data register (or FIFO) is full (that frame is lost) and
//! raises the interrupt with RXNEIE, so it must be cleared or the interrupt never ends; FE and NE
//! come with the byte they concern (it is still received) and raise no interrupt of their own; TC
//! is set when the last frame has left with nothing left to send, and is cleared by a write to
//! USART_TDR.
//!
//! [`control::RxQueue`]: crate::control::RxQueue
//! [`control::MAX_RX_PER_STEP`]: crate::control::MAX_RX_PER_STEP

use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicU32, AtomicUsize, Ordering};

/// USART_ISR: parity error.
pub const ISR_PE: u32 = 1 << 0;
/// USART_ISR: framing error (a missing stop bit: a wrong baud rate, a break).
pub const ISR_FE: u32 = 1 << 1;
/// USART_ISR: noise detected on the received frame.
pub const ISR_NE: u32 = 1 << 2;
/// USART_ISR: overrun, a frame lost because the receive data register (or FIFO) was full.
pub const ISR_ORE: u32 = 1 << 3;
/// USART_ISR: the receive FIFO is not empty (RXFNE; RXNE without FIFO).
pub const ISR_RXFNE: u32 = 1 << 5;
/// USART_ISR: transmission complete.
pub const ISR_TC: u32 = 1 << 6;
/// USART_ISR: the transmit FIFO is not full (TXFNF; TXE without FIFO).
pub const ISR_TXFNF: u32 = 1 << 7;
/// USART_CR1: interrupt while RXFNE (or ORE) is set.
pub const CR1_RXFNEIE: u32 = 1 << 5;
/// USART_CR1: interrupt while TXFNF is set.
pub const CR1_TXFNFIE: u32 = 1 << 7;
/// The error flags the interrupt clears (USART_ICR has their clear bits at the same positions).
const ERRORS: u32 = ISR_PE | ISR_FE | ISR_NE | ISR_ORE;

/// The USART's registers, as the driver uses them. The board implements each with one volatile
/// access; the tests with a model of the peripheral.
pub trait UsartRegisters {
    /// Reads USART_ISR.
    fn isr(&self) -> u32;
    /// Writes USART_ICR: clears the ISR flags whose clear bits are set in `flags`.
    fn clear(&self, flags: u32);
    /// Reads USART_RDR: the oldest received byte.
    fn read_rdr(&self) -> u8;
    /// Writes USART_TDR: queues a byte to send.
    fn write_tdr(&self, byte: u8);
    /// Reads USART_CR1.
    fn cr1(&self) -> u32;
    /// Writes USART_CR1.
    fn set_cr1(&self, cr1: u32);
    /// Sets the USART interrupt pending (NVIC), so that it runs as soon as it may.
    fn pend_interrupt(&self);
}

/// A single-producer single-consumer byte ring: one side only pushes, the other only pops, each
/// writing only its own counter (plain loads and stores: thumbv6m has no atomic read-modify-write).
struct Ring<const N: usize> {
    bytes: [UnsafeCell<u8>; N],
    /// Bytes pushed since the start, wrapping.
    pushed: AtomicUsize,
    /// Bytes popped since the start, wrapping.
    popped: AtomicUsize,
}

impl<const N: usize> Ring<N> {
    const POWER_OF_TWO: () = assert!(N.is_power_of_two());

    const fn new() -> Self {
        let () = Self::POWER_OF_TWO;
        Ring {
            bytes: [const { UnsafeCell::new(0) }; N],
            pushed: AtomicUsize::new(0),
            popped: AtomicUsize::new(0),
        }
    }

    fn len(&self) -> usize {
        self.pushed
            .load(Ordering::Acquire)
            .wrapping_sub(self.popped.load(Ordering::Acquire))
    }

    /// The producer's side: false (the byte not stored) when full.
    fn push(&self, byte: u8) -> bool {
        let pushed = self.pushed.load(Ordering::Relaxed);
        if pushed.wrapping_sub(self.popped.load(Ordering::Acquire)) >= N {
            return false;
        }
        if let Some(cell) = self.bytes.get(pushed % N) {
            // SAFETY: the consumer reads this cell only once `pushed` counts it (stored below).
            unsafe { *cell.get() = byte };
        }
        self.pushed.store(pushed.wrapping_add(1), Ordering::Release);
        true
    }

    /// The consumer's side: the oldest byte.
    fn pop(&self) -> Option<u8> {
        let popped = self.popped.load(Ordering::Relaxed);
        if self.pushed.load(Ordering::Acquire) == popped {
            return None;
        }
        // SAFETY: the producer writes this cell again only once `popped` no longer counts it.
        let byte = self.bytes.get(popped % N).map(|cell| unsafe { *cell.get() });
        self.popped.store(popped.wrapping_add(1), Ordering::Release);
        byte
    }
}

/// What went wrong on the receive line since start-up: counts that only grow (wrapping), so that
/// the reader takes differences and the interrupt needs no atomic read-modify-write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LineErrors {
    /// Overruns in the USART: bytes arrived while its receive register was full (the interrupt
    /// could not run: a flash write stalls the CPU). One count per overrun, however many bytes
    /// it lost: ORE stays set until the interrupt clears it.
    pub overruns: u32,
    /// Frames with a framing, noise or parity error (received all the same).
    pub garbled: u32,
    /// Bytes lost because the receive ring was full (the control loop did not take them).
    pub dropped: u32,
}

impl LineErrors {
    /// What happened since `earlier`, a reading of the same counters.
    pub const fn since(&self, earlier: &LineErrors) -> LineErrors {
        LineErrors {
            overruns: self.overruns.wrapping_sub(earlier.overruns),
            garbled: self.garbled.wrapping_sub(earlier.garbled),
            dropped: self.dropped.wrapping_sub(earlier.dropped),
        }
    }

    /// Every byte lost or garbled.
    pub const fn total(&self) -> u32 {
        self.overruns
            .wrapping_add(self.garbled)
            .wrapping_add(self.dropped)
    }
}

/// A USART with a receive ring of `RX` bytes and a transmit ring of `TX` bytes, shared by the
/// interrupt handler ([`Uart::on_interrupt`]) and the control loop (the one [`Port`]).
pub struct Uart<const RX: usize, const TX: usize> {
    rx: Ring<RX>,
    tx: Ring<TX>,
    overruns: AtomicU32,
    garbled: AtomicU32,
    dropped: AtomicU32,
}

// SAFETY: the rings are single-producer single-consumer and each side is one execution context:
// the interrupt handler (`on_interrupt`) and the holder of the one `Port` (both `unsafe` to get).
unsafe impl<const RX: usize, const TX: usize> Sync for Uart<RX, TX> {}

impl<const RX: usize, const TX: usize> Default for Uart<RX, TX> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const RX: usize, const TX: usize> Uart<RX, TX> {
    /// Empty rings, no error counted.
    pub const fn new() -> Self {
        Uart {
            rx: Ring::new(),
            tx: Ring::new(),
            overruns: AtomicU32::new(0),
            garbled: AtomicU32::new(0),
            dropped: AtomicU32::new(0),
        }
    }

    /// The control loop's side.
    ///
    /// # Safety
    ///
    /// At most one `Port` of this `Uart` exists at any time.
    pub unsafe fn port<'a, R: UsartRegisters>(&'a self, regs: R) -> Port<'a, R, RX, TX> {
        Port { uart: self, regs }
    }

    /// The USART interrupt's work: clears and counts the receive errors, moves every received
    /// byte into the receive ring (the newest lost when it is full), fills the transmit FIFO from
    /// the transmit ring, and keeps the transmit interrupt enabled exactly while bytes wait. The
    /// receive interrupt stays enabled (set up at init), as BufferedUart keeps it.
    ///
    /// # Safety
    ///
    /// Called from one execution context only: the USART's interrupt handler.
    pub unsafe fn on_interrupt(&self, regs: &impl UsartRegisters) {
        let isr = regs.isr();
        let errors = isr & ERRORS;
        if errors != 0 {
            regs.clear(errors);
            if errors & ISR_ORE != 0 {
                bump(&self.overruns);
            }
            if errors & (ISR_PE | ISR_FE | ISR_NE) != 0 {
                bump(&self.garbled);
            }
        }
        while regs.isr() & ISR_RXFNE != 0 {
            // Read even when the ring is full: that empties the FIFO and ends the interrupt.
            if !self.rx.push(regs.read_rdr()) {
                bump(&self.dropped);
            }
        }
        while regs.isr() & ISR_TXFNF != 0 {
            match self.tx.pop() {
                Some(byte) => regs.write_tdr(byte),
                None => break,
            }
        }
        let cr1 = regs.cr1();
        let waiting = self.tx.len() > 0;
        if waiting != (cr1 & CR1_TXFNFIE != 0) {
            regs.set_cr1(if waiting {
                cr1 | CR1_TXFNFIE
            } else {
                cr1 & !CR1_TXFNFIE
            });
        }
    }

    /// The receive errors so far.
    pub fn errors(&self) -> LineErrors {
        LineErrors {
            overruns: self.overruns.load(Ordering::Relaxed),
            garbled: self.garbled.load(Ordering::Relaxed),
            dropped: self.dropped.load(Ordering::Relaxed),
        }
    }
}

/// Counts one more (only the interrupt handler writes the counters).
fn bump(counter: &AtomicU32) {
    counter.store(counter.load(Ordering::Relaxed).wrapping_add(1), Ordering::Relaxed);
}

/// The control loop's side of a [`Uart`]: takes the received bytes, queues responses.
pub struct Port<'a, R, const RX: usize, const TX: usize> {
    uart: &'a Uart<RX, TX>,
    regs: R,
}

impl<R: UsartRegisters, const RX: usize, const TX: usize> Port<'_, R, RX, TX> {
    /// Moves the oldest received bytes into `buf`, as many as wait and fit; returns how many.
    pub fn receive(&mut self, buf: &mut [u8]) -> usize {
        let mut taken = 0;
        for slot in buf.iter_mut() {
            match self.uart.rx.pop() {
                Some(byte) => *slot = byte,
                None => break,
            }
            taken += 1;
        }
        taken
    }

    /// Queues `bytes` to send and starts sending. Returns false, with nothing queued, when the
    /// transmit ring has no room for all of them: a response is never sent in part.
    pub fn send(&mut self, bytes: &[u8]) -> bool {
        if TX.saturating_sub(self.uart.tx.len()) < bytes.len() {
            return false;
        }
        for &byte in bytes {
            // Cannot fail: checked above, and the interrupt only makes room.
            self.uart.tx.push(byte);
        }
        // The interrupt handler writes the FIFO and enables its own interrupt: CR1 is then only
        // ever modified there, so this side needs no critical section.
        self.regs.pend_interrupt();
        true
    }

    /// True once every queued byte has left the USART: the ring is empty and the last frame is
    /// complete (TC).
    pub fn sent(&self) -> bool {
        self.uart.tx.len() == 0 && self.regs.isr() & ISR_TC != 0
    }
}

#[cfg(test)]
mod tests {
    //! The driver against a model of the USART's registers and the NVIC, written from RM0444's
    //! register descriptions quoted in the module header, with and without FIFOs.

    use super::*;
    use crate::control::{MAX_RX_PER_STEP, RX_RING, RxQueue};
    use core::cell::RefCell;
    use proptest::prelude::*;

    extern crate std;
    use std::collections::VecDeque;
    use std::vec::Vec;

    /// The receive and transmit buffer depths the driver meets: 1, the data registers of a basic
    /// USART such as the G071's USART3 (no FIFO, RM0444 "USART implementation"), and 8, the FIFOs
    /// of a full one (USART1, USART2).
    const DEPTHS: [usize; 2] = [1, 8];

    /// The peripheral: FIFOs, the flags, CR1, and whether the NVIC has the interrupt pending.
    #[derive(Default)]
    struct Usart {
        /// How many frames each FIFO holds (1: no FIFO, the data register).
        depth: usize,
        rx_fifo: VecDeque<u8>,
        tx_fifo: VecDeque<u8>,
        /// PE, FE, NE, ORE and TC; RXFNE and TXFNF follow from the FIFOs.
        flags: u32,
        cr1: u32,
        pended: bool,
        /// USART_ISR reads in the current interrupt: a handler that spins on a flag fails.
        isr_reads: u32,
        /// Bytes that left on the line.
        line: Vec<u8>,
    }

    struct Model(RefCell<Usart>);

    impl Model {
        fn new(depth: usize) -> Self {
            // After reset TC is set (no transmission); the board enables RXFNEIE at init.
            Model(RefCell::new(Usart {
                depth,
                flags: ISR_TC,
                cr1: CR1_RXFNEIE,
                ..Usart::default()
            }))
        }

        /// A frame arrives; `flags` are the errors detected on it (FE, NE, PE).
        fn arrive(&self, byte: u8, flags: u32) {
            let mut u = self.0.borrow_mut();
            if u.rx_fifo.len() == u.depth {
                u.flags |= ISR_ORE;
            } else {
                u.rx_fifo.push_back(byte);
                u.flags |= flags;
            }
        }

        /// One frame leaves the transmit FIFO; TC once it is empty.
        fn shift_out(&self) {
            let mut u = self.0.borrow_mut();
            if let Some(byte) = u.tx_fifo.pop_front() {
                u.line.push(byte);
                if u.tx_fifo.is_empty() {
                    u.flags |= ISR_TC;
                }
            }
        }

        /// Whether the USART requests its interrupt (RM0444, USART interrupt mapping).
        fn requests(&self) -> bool {
            let u = self.0.borrow();
            let isr = u.isr();
            (u.cr1 & CR1_RXFNEIE != 0 && isr & (ISR_RXFNE | ISR_ORE) != 0)
                || (u.cr1 & CR1_TXFNFIE != 0 && isr & ISR_TXFNF != 0)
        }

        fn line(&self) -> Vec<u8> {
            self.0.borrow().line.clone()
        }
    }

    impl Usart {
        fn isr(&self) -> u32 {
            let mut isr = self.flags;
            if !self.rx_fifo.is_empty() {
                isr |= ISR_RXFNE;
            }
            if self.tx_fifo.len() < self.depth {
                isr |= ISR_TXFNF;
            }
            isr
        }
    }

    impl UsartRegisters for &Model {
        fn isr(&self) -> u32 {
            let mut u = self.0.borrow_mut();
            u.isr_reads += 1;
            assert!(u.isr_reads < 1000, "the interrupt handler spins on USART_ISR");
            u.isr()
        }

        fn clear(&self, flags: u32) {
            self.0.borrow_mut().flags &= !(flags & (ERRORS | ISR_TC));
        }

        fn read_rdr(&self) -> u8 {
            // Reading an empty RDR returns stale data: the driver must not rely on it.
            self.0.borrow_mut().rx_fifo.pop_front().unwrap_or(0xEE)
        }

        fn write_tdr(&self, byte: u8) {
            let mut u = self.0.borrow_mut();
            assert!(
                u.tx_fifo.len() < u.depth,
                "TDR written with the transmit FIFO full"
            );
            u.tx_fifo.push_back(byte);
            u.flags &= !ISR_TC;
        }

        fn cr1(&self) -> u32 {
            self.0.borrow().cr1
        }

        fn set_cr1(&self, cr1: u32) {
            self.0.borrow_mut().cr1 = cr1;
        }

        fn pend_interrupt(&self) {
            self.0.borrow_mut().pended = true;
        }
    }

    type TestUart = Uart<RX_RING, 64>;

    /// Runs the interrupt handler as the NVIC would while it is requested or pended. A request
    /// that handling does not end is an interrupt storm: the MCU would never leave it.
    fn service(uart: &TestUart, model: &Model) {
        for _ in 0..4 {
            let pended = core::mem::take(&mut model.0.borrow_mut().pended);
            if !pended && !model.requests() {
                return;
            }
            model.0.borrow_mut().isr_reads = 0;
            // SAFETY: the test is the only context.
            unsafe { uart.on_interrupt(&model) };
        }
        panic!("the USART interrupt stays requested after it was handled");
    }

    /// Runs `test` at each FIFO depth ([`DEPTHS`]) on a fresh model, driver and port.
    fn at_each_depth(test: impl Fn(usize, &Model, &TestUart, &mut Port<'_, &Model, RX_RING, 64>)) {
        for depth in DEPTHS {
            let model = Model::new(depth);
            let uart = TestUart::new();
            // SAFETY: the one port; the interrupt side runs only through `service`.
            let mut port = unsafe { uart.port(&model) };
            test(depth, &model, &uart, &mut port);
        }
    }

    #[test]
    fn received_bytes_reach_the_loop_in_order_at_most_a_buffer_a_step() {
        at_each_depth(|_, model, uart, port| {
            let sent: Vec<u8> = (0..40).collect();
            for &byte in &sent {
                model.arrive(byte, 0);
                service(uart, model);
            }
            let mut got = Vec::new();
            let mut buf = [0u8; MAX_RX_PER_STEP];
            loop {
                let n = port.receive(&mut buf);
                assert!(n <= MAX_RX_PER_STEP);
                if n == 0 {
                    break;
                }
                got.extend_from_slice(&buf[..n]);
            }
            assert_eq!(got, sent);
            assert_eq!(uart.errors(), LineErrors::default());
        });
    }

    #[test]
    fn a_full_ring_loses_the_newest_bytes_and_counts_them_without_an_interrupt_storm() {
        at_each_depth(|_, model, uart, port| {
            for i in 0..RX_RING + 5 {
                model.arrive(i as u8, 0);
                service(uart, model);
            }
            assert_eq!(uart.errors().dropped, 5);
            let mut buf = [0u8; RX_RING];
            assert_eq!(port.receive(&mut buf), RX_RING);
            assert!(
                buf.iter().enumerate().all(|(i, &b)| b == i as u8),
                "the oldest bytes kept"
            );
            model.arrive(0xAB, 0);
            service(uart, model);
            assert_eq!(port.receive(&mut buf[..1]), 1);
            assert_eq!(buf[0], 0xAB, "reception goes on once the loop took bytes");
        });
    }

    #[test]
    fn an_overrun_while_the_interrupt_cannot_run_is_cleared_counted_and_reception_goes_on() {
        at_each_depth(|depth, model, uart, port| {
            // A flash erase stalls the CPU: the FIFO fills, the next frame is lost (ORE).
            for byte in 0..depth as u8 + 2 {
                model.arrive(byte, 0);
            }
            service(uart, model);
            assert_eq!(model.0.borrow().flags & ISR_ORE, 0, "ORE cleared");
            assert_eq!(uart.errors().overruns, 1);
            model.arrive(b'Q', 0);
            service(uart, model);
            let mut buf = [0u8; 16];
            let n = port.receive(&mut buf);
            let mut expected: Vec<u8> = (0..depth as u8).collect();
            expected.push(b'Q');
            assert_eq!(&buf[..n], &expected[..]);
        });
    }

    #[test]
    fn framing_and_noise_errors_keep_the_byte_and_are_cleared_and_counted() {
        at_each_depth(|_, model, uart, port| {
            model.arrive(b'a', ISR_FE);
            service(uart, model);
            model.arrive(b'b', ISR_NE);
            service(uart, model);
            assert_eq!(model.0.borrow().flags & ERRORS, 0);
            assert_eq!(uart.errors().garbled, 2);
            assert_eq!(uart.errors().total(), 2);
            let mut buf = [0u8; 4];
            assert_eq!(port.receive(&mut buf), 2);
            assert_eq!(&buf[..2], b"ab");
        });
    }

    #[test]
    fn a_response_goes_out_whole_in_order_and_the_transmit_interrupt_ends_with_it() {
        at_each_depth(|_, model, uart, port| {
            let response = b"Q0 A0*4f\nR8 A1*23\n";
            assert!(port.send(response));
            service(uart, model);
            assert!(!port.sent());
            for sent in 1..=response.len() {
                assert!(!port.sent(), "a byte waits in the ring or the FIFO");
                model.shift_out();
                service(uart, model);
                assert_eq!(model.line(), response[..sent]);
            }
            assert_eq!(model.0.borrow().cr1 & CR1_TXFNFIE, 0, "transmit interrupt off");
            assert!(port.sent());
        });
    }

    #[test]
    fn a_response_that_does_not_fit_is_refused_whole() {
        at_each_depth(|depth, model, uart, port| {
            // The line does not move: the FIFO takes `depth` and the rest wait in the ring of 64.
            assert!(port.send(&[b'x'; 60]));
            service(uart, model);
            let room = 64 - (60 - depth);
            assert!(
                !port.send(&std::vec![b'z'; room + 1]),
                "one byte too many: refused"
            );
            assert!(port.send(&std::vec![b'y'; room]));
            service(uart, model);
            assert!(!port.send(&[b'z'; 1]), "ring full: refused");
            for _ in 0..100 {
                model.shift_out();
                service(uart, model);
            }
            let mut expected = std::vec![b'x'; 60];
            expected.extend_from_slice(&std::vec![b'y'; room]);
            assert_eq!(model.line(), expected, "nothing of the refused response sent");
            assert!(port.sent());
        });
    }

    /// What the line does in one step of the loop.
    #[derive(Debug, Clone)]
    enum Event {
        /// Bytes arrive, each serviced by the interrupt at once.
        Arrive(Vec<u8>),
        /// The loop takes a step's bytes.
        Take,
    }

    proptest! {
        /// The board's UART hands the loop exactly what the host's RxQueue (the simulator's and
        /// the benchmark's stand-in for it) hands it, and loses the same bytes.
        #[test]
        fn the_driver_hands_out_what_the_rx_queue_hands_out(
            events in proptest::collection::vec(
                prop_oneof![
                    proptest::collection::vec(any::<u8>(), 0..40).prop_map(Event::Arrive),
                    Just(Event::Take),
                ],
                0..60,
            ),
            depth in proptest::sample::select(DEPTHS.to_vec()),
        ) {
            let model = Model::new(depth);
            let uart = TestUart::new();
            let mut port = unsafe { uart.port(&model) };
            let mut queue = RxQueue::<RX_RING>::new();
            for event in events {
                match event {
                    Event::Arrive(bytes) => {
                        for &byte in &bytes {
                            model.arrive(byte, 0);
                            service(&uart, &model);
                        }
                        queue.receive(&bytes);
                    }
                    Event::Take => {
                        let mut buf = [0u8; MAX_RX_PER_STEP];
                        let n = port.receive(&mut buf);
                        let expected = queue.take_step();
                        prop_assert_eq!(&buf[..n], expected.as_slice());
                    }
                }
                prop_assert_eq!(uart.errors().dropped, queue.lost());
            }
        }
    }
}
