//! The printer UART's receive ring on the NUCLEO-G071RB: DMA1 channel 2 copies every byte USART1
//! receives into a 512-byte ring in RAM, circularly, whatever the CPU does; the control step
//! reads it ([`mmu_firmware::uart::ReceiveRing`]).
//!
//! Not embassy-stm32 0.6's `RingBufferedUartRx`: that one wakes a task on USART1's idle line,
//! while the control step looks at the ring itself once a millisecond. The channel is still
//! embassy-stm32's (`dma::Channel`, a circular `Transfer`: DMAMUX request, addresses, CCR); this
//! module adds USART1's receiver (CR1.RE, CR3.DMAR: RM0444, USART, "Reception using DMA") and
//! reads CNDTR through the transfer.
//!
//! The DMA's count of written bytes comes from CNDTR's moves between two looks: fewer than the
//! ring's 512 bytes arrive between two (`uart::G071_DMA_RING` holds the longest flash stall's
//! bytes, 40 ms, plus a step's: the tests of `mmu_firmware::uart`), so a move is never a whole
//! lap. Before the first step the store's boot may erase more than one page (a repair) with no
//! look: a printer that sends more than 512 bytes meanwhile loses the oldest unreported (the
//! firmware ignores frames while it starts anyway; the Pico's count is exact).

use core::cell::UnsafeCell;
use core::ptr;

use embassy_stm32::dma::{self, Transfer, TransferOptions};
use embassy_stm32::gpio::{AfType, Flex, Pull};
use embassy_stm32::peripherals::{DMA1_CH2, PB7, USART1};
use embassy_stm32::usart;
use embassy_stm32::{Peri, pac};
use mmu_firmware::uart::G071_DMA_RING;
use mmu_firmware::uart::{CountdownRing, LineError, ReceiveRing, RingSource};
use static_cell::StaticCell;

use super::Irqs;

/// The ring. Written only by the DMA, read only through volatile reads of the one [`G071Ring`].
struct Ring(UnsafeCell<[u8; G071_DMA_RING]>);

// SAFETY: see above: the CPU never writes it, and reads it only where the DMA has written.
unsafe impl Sync for Ring {}

static RING: Ring = Ring(UnsafeCell::new([0; G071_DMA_RING]));

/// The printer UART's receive ring: USART1's RX DMA channel and what it has written.
pub struct G071Ring {
    transfer: Transfer<'static>,
    /// Keeps PB7 in its USART1_RX function (never read through).
    _rx: Flex<'static>,
    /// What CNDTR's count down says was written.
    counter: CountdownRing<G071_DMA_RING>,
}

impl G071Ring {
    /// Starts USART1's receiver (configured and enabled for transmission by embassy-stm32's
    /// `UartTx`) into the ring by `channel`, PB7 as its RX pin.
    pub fn start(
        rx: Peri<'static, PB7>,
        channel: Peri<'static, DMA1_CH2>,
    ) -> ReceiveRing<G071Ring, G071_DMA_RING> {
        let af = usart::RxPin::<USART1>::af_num(&*rx);
        let mut pin = Flex::new(rx);
        pin.set_as_af_unchecked(af, AfType::input(Pull::Up));
        let request = usart::RxDma::<USART1>::request(&*channel);
        static CHANNEL: StaticCell<dma::Channel<'static>> = StaticCell::new();
        let channel = CHANNEL.init(dma::Channel::new(channel, Irqs));
        let ring = RING.0.get().cast::<u8>();
        let mut options = TransferOptions::default();
        options.circular = true;
        options.half_transfer_ir = false;
        options.complete_transfer_ir = false;
        // SAFETY: the ring is static, written by nothing else, and the transfer is never dropped
        // (the receive side lives as long as the firmware).
        let transfer = unsafe {
            channel.read_raw(
                request,
                pac::USART1.rdr().as_ptr().cast::<u8>(),
                ptr::slice_from_raw_parts_mut(ring, G071_DMA_RING),
                options,
            )
        };
        pac::USART1.cr3().modify(|w| w.set_dmar(true));
        pac::USART1.cr1().modify(|w| w.set_re(true));
        ReceiveRing::new(G071Ring {
            transfer,
            _rx: pin,
            counter: CountdownRing::new(),
        })
    }
}

impl RingSource<G071_DMA_RING> for G071Ring {
    fn written(&mut self) -> u32 {
        self.counter.written(self.transfer.get_remaining_transfers())
    }

    /// USART1's receive errors since the last look (ISR PE, FE, NE, ORE; cleared through ICR).
    fn line_error(&mut self) -> Option<LineError> {
        let isr = pac::USART1.isr().read();
        if !(isr.pe() || isr.fe() || isr.ne() || isr.ore()) {
            return None;
        }
        pac::USART1.icr().write(|w| {
            w.set_pe(true);
            w.set_fe(true);
            w.set_ne(true);
            w.set_ore(true);
        });
        Some(if isr.ore() {
            LineError::Overrun
        } else {
            LineError::Garbled
        })
    }

    fn byte(&self, index: usize) -> u8 {
        // SAFETY: `index < G071_DMA_RING` (the trait's contract), inside the ring; a volatile
        // read, as the DMA writes it.
        unsafe { ptr::read_volatile(RING.0.get().cast::<u8>().add(index)) }
    }
}
