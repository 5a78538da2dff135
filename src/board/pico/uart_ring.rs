//! The printer UART's receive ring on the Pico: one DMA channel copies every byte UART0 receives
//! into an 8 KiB ring in RAM, whatever the CPU does; the control step reads it
//! ([`mmu_firmware::uart::ReceiveRing`]).
//!
//! Hand-written, in this one place, because embassy-rp 0.10 has no ring-buffered UART receiver
//! (its `UartRx::read` fills a buffer of a given length, its `BufferedUart` is interrupt-driven)
//! and the need is measured: embassy-rp's flash driver erases a 4 KiB sector with interrupts
//! off, up to 400 ms (W25Q16JV), while the UART's FIFO holds 32 bytes (2.8 ms at 115 200 Bd).
//! The decisions (how many bytes wait, what was lost) are `mmu_firmware::uart::DmaRing`, host
//! tested; this module only programs the channel (RP2040 datasheet, 2.5 DMA: CTRL.RING_SIZE and
//! RING_SEL wrap the write address on a naturally aligned ring, TREQ_SEL paces it by UART0's RX
//! request, TRANS_COUNT counts down) and UART0's DMACR.RXDMAE (4.2, UART).

use core::cell::UnsafeCell;
use core::ptr;

use embassy_rp::Peri;
use embassy_rp::pac;
use embassy_rp::pac::dma::vals::{DataSize, TreqSel};
use embassy_rp::peripherals::DMA_CH2;
use embassy_rp::uart::{Async, UartRx};
use mmu_firmware::uart::PICO_DMA_RING;
use mmu_firmware::uart::{LineError, ReceiveRing, RingSource};

/// The DMA channel of the ring (DMA_CH0 and DMA_CH1 are embassy-rp's, for the UART).
const CHANNEL: usize = 2;
/// log2 of the ring's size, CTRL.RING_SIZE.
const RING_BITS: u8 = PICO_DMA_RING.trailing_zeros() as u8;
/// The transfer count a start loads: the channel stops after this many bytes (4.3 days of a
/// line that never pauses) and is started again by [`PicoRing::written`].
const TRANSFER: u32 = u32::MAX;

/// The ring, aligned to its size as the DMA's address wrap requires. Written only by the DMA,
/// read only through volatile reads of the one [`PicoRing`] (which owns the DMA channel).
#[repr(C, align(8192))]
struct Ring(UnsafeCell<[u8; PICO_DMA_RING]>);

// SAFETY: see above: the CPU never writes it, and reads it only where the DMA has written.
unsafe impl Sync for Ring {}

const _: () = assert!(core::mem::align_of::<Ring>() == PICO_DMA_RING);

/// Not a `StaticCell`: its flag beside the ring would double the ring's footprint (8 KiB
/// alignment).
static RING: Ring = Ring(UnsafeCell::new([0; PICO_DMA_RING]));

/// The printer UART's receive ring: UART0's DMA channel and what it has written.
pub struct PicoRing {
    /// Keeps UART0's RX pin in its UART function (never read through).
    _rx: UartRx<'static, Async>,
    _channel: Peri<'static, DMA_CH2>,
    /// Bytes written by the transfers before the current one, wrapping.
    base: u32,
}

/// The receive side, as the control step reads it.
pub type RingRx = ReceiveRing<PicoRing, PICO_DMA_RING>;

impl PicoRing {
    /// Starts the channel: UART0's data register into the ring, paced by its RX request.
    pub fn start(rx: UartRx<'static, Async>, channel: Peri<'static, DMA_CH2>) -> RingRx {
        let ring = RING.0.get().cast::<u8>();
        pac::UART0.uartdmacr().modify(|w| w.set_rxdmae(true));
        let ch = pac::DMA.ch(CHANNEL);
        ch.read_addr().write_value(pac::UART0.uartdr().as_ptr() as u32);
        ch.write_addr().write_value(ring as u32);
        ch.trans_count().write_value(TRANSFER);
        Self::trigger();
        RingRx::new(PicoRing {
            _rx: rx,
            _channel: channel,
            base: 0,
        })
    }

    /// Starts (or restarts) a transfer of [`TRANSFER`] bytes; the write address goes on where
    /// the last one stopped.
    fn trigger() {
        pac::DMA.ch(CHANNEL).ctrl_trig().write(|w| {
            w.set_en(true);
            w.set_data_size(DataSize::SIZE_BYTE);
            w.set_incr_read(false);
            w.set_incr_write(true);
            w.set_ring_size(RING_BITS);
            w.set_ring_sel(true);
            // Chaining to itself means no chaining.
            w.set_chain_to(CHANNEL as u8);
            w.set_treq_sel(TreqSel::UART0_RX);
            w.set_irq_quiet(true);
        });
    }
}

impl RingSource<PICO_DMA_RING> for PicoRing {
    /// Bytes the DMA has written since the start, wrapping; restarts a finished transfer.
    fn written(&mut self) -> u32 {
        let ch = pac::DMA.ch(CHANNEL);
        let remaining = ch.trans_count().read();
        if remaining == 0 && !ch.ctrl_trig().read().busy() {
            self.base = self.base.wrapping_add(TRANSFER);
            ch.trans_count().write_value(TRANSFER);
            Self::trigger();
            return self.base;
        }
        self.base.wrapping_add(TRANSFER - remaining)
    }

    /// UART0's receive errors since the last look (UARTRSR, cleared by a write).
    fn line_error(&mut self) -> Option<LineError> {
        let rsr = pac::UART0.uartrsr().read();
        if !(rsr.oe() || rsr.be() || rsr.pe() || rsr.fe()) {
            return None;
        }
        pac::UART0.uartrsr().write_value(Default::default());
        Some(if rsr.oe() {
            LineError::Overrun
        } else {
            LineError::Garbled
        })
    }

    fn byte(&self, index: usize) -> u8 {
        // SAFETY: `index < PICO_DMA_RING` (the trait's contract), inside the ring; a volatile
        // read, as the DMA writes it.
        unsafe { ptr::read_volatile(RING.0.get().cast::<u8>().add(index)) }
    }
}
