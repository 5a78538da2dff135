//! The printer's UART on header H1: USART3 (PB10 TX, PB11 RX, 3.3 V), 115 200 Bd 8N1 from
//! PCLK1 (60 MHz: USARTDIV 32 + 9/16, BRR 521, 0.03 % slow).
//!
//! Receiving: DMA1 channel 3 (USART3_RX in the CH32V20x's DMA1 request map) copies every byte
//! into a 512-byte ring, circularly, whatever the CPU does (a flash erase included); the control
//! step reads it ([`mmu_firmware::uart::ReceiveRing`]), as on the NUCLEO-G071RB. Sending: byte
//! by byte into DATAR whenever TXE says the register is free, sleeping on embassy-time between
//! bytes: the spinning executor would otherwise poll this task without pause while an answer
//! goes out.

use core::cell::UnsafeCell;
use core::convert::Infallible;
use core::ptr;

use ch32_metapac as pac;
use mmu_firmware::uart::{BMCU_DMA_RING, CountdownRing, LineError, ReceiveRing, RingSource};
use pac::dma::vals::{Pl, Size};
use pac::gpio::vals::{Cnf, Mode};

use super::{circular_dma, gpio_mode};

/// USART3's BRR for 115 200 Bd from 60 MHz: 521 = 32 × 16 + 9 (60 MHz / 521 = 115 163 Bd).
const BRR: u32 = 521;
const _: () = assert!(super::clock::PCLK1_HZ.abs_diff(BRR * 115_200) < BRR * 115_200 / 1000);
/// One character on the line, 10 bits at 115 200 Bd: the wait for DATAR to free up.
const CHARACTER_TIME: embassy_time::Duration = embassy_time::Duration::from_micros(87);
/// DMA1's channel for USART3's receiver (channel 3).
const DMA_CHANNEL: usize = 2;

/// The ring. Written only by the DMA, read only through volatile reads of the one [`BmcuRing`].
struct Ring(UnsafeCell<[u8; BMCU_DMA_RING]>);

// SAFETY: see above: the CPU never writes it, and reads it only where the DMA has written.
unsafe impl Sync for Ring {}

static RING: Ring = Ring(UnsafeCell::new([0; BMCU_DMA_RING]));

/// The printer UART's receive side, as the control step reads it.
pub type LinkRx = ReceiveRing<BmcuRing, BMCU_DMA_RING>;

/// USART3's receive ring: what its DMA channel has written.
pub struct BmcuRing {
    /// What NDTR's count down says was written.
    counter: CountdownRing<BMCU_DMA_RING>,
    /// Bytes written as of the last look.
    written: u32,
    /// `written` when a line error was last reported: the flags stay up until the DMA's next
    /// read of DATAR clears them, so one error is reported once.
    reported_at: Option<u32>,
}

/// Starts USART3 (both directions) and its receive DMA into the ring.
pub fn start_rx() -> LinkRx {
    pac::RCC.apb1pcenr().modify(|w| w.set_usart3en(true));
    pac::RCC.ahbpcenr().modify(|w| w.set_dma1en(true));
    gpio_mode(pac::GPIOB, 10, Mode::OUTPUT_50MHZ, Cnf::PULL_IN__AF_PUSH_PULL_OUT);
    // PB11 with its pull-up: a line left open reads idle, not a stream of breaks.
    pac::GPIOB.bshr().write(|w| w.set_bs(11, true));
    gpio_mode(pac::GPIOB, 11, Mode::INPUT, Cnf::PULL_IN__AF_PUSH_PULL_OUT);
    let usart = pac::USART3;
    usart.brr().write_value(pac::usart::regs::Brr(BRR));
    circular_dma(
        DMA_CHANNEL,
        usart.datar().as_ptr() as u32,
        RING.0.get() as u32,
        BMCU_DMA_RING as u16,
        Size::BITS8,
        Pl::VERYHIGH,
    );
    usart.ctlr3().modify(|w| w.set_dmar(true));
    usart.ctlr1().modify(|w| {
        w.set_te(true);
        w.set_re(true);
        w.set_ue(true);
    });
    ReceiveRing::new(BmcuRing {
        counter: CountdownRing::new(),
        written: 0,
        reported_at: None,
    })
}

impl RingSource<BMCU_DMA_RING> for BmcuRing {
    /// From NDTR's count down: fewer than the ring's 512 bytes arrive between two looks (the
    /// ring holds the longest flash stall's bytes and a step's, `mmu_firmware::uart`'s tests),
    /// so a move is never a whole lap.
    fn written(&mut self) -> u32 {
        let remaining = u32::from(pac::DMA1.ch(DMA_CHANNEL).ndtr().read().ndt());
        self.written = self.counter.written(remaining);
        self.written
    }

    /// USART3's receive errors (STATR PE, FE, NE, ORE). Reading STATR arms their clearing; the
    /// DMA's next read of DATAR clears them, so an error still up at the same count is the one
    /// reported already.
    fn line_error(&mut self) -> Option<LineError> {
        let status = pac::USART3.statr().read();
        if !(status.pe() || status.fe() || status.ne() || status.ore())
            || self.reported_at == Some(self.written)
        {
            return None;
        }
        self.reported_at = Some(self.written);
        Some(if status.ore() {
            LineError::Overrun
        } else {
            LineError::Garbled
        })
    }

    fn byte(&self, index: usize) -> u8 {
        // SAFETY: `index < BMCU_DMA_RING` (the trait's contract), inside the ring; a volatile
        // read, as the DMA writes it.
        unsafe { ptr::read_volatile(RING.0.get().cast::<u8>().add(index)) }
    }
}

/// The printer UART's transmit side.
pub struct LinkTx;

impl LinkTx {
    /// USART3's transmitter (started with the receiver by [`start_rx`]).
    pub fn new() -> Self {
        LinkTx
    }
}

impl embedded_io_async::ErrorType for LinkTx {
    type Error = Infallible;
}

impl embedded_io_async::Write for LinkTx {
    async fn write(&mut self, bytes: &[u8]) -> Result<usize, Infallible> {
        for &byte in bytes {
            while !pac::USART3.statr().read().txe() {
                embassy_time::Timer::after(CHARACTER_TIME).await;
            }
            pac::USART3.datar().write(|w| w.set_dr(u16::from(byte)));
        }
        Ok(bytes.len())
    }

    /// Until the last byte has left the shift register.
    async fn flush(&mut self) -> Result<(), Infallible> {
        while !pac::USART3.statr().read().tc() {
            embassy_time::Timer::after(CHARACTER_TIME).await;
        }
        Ok(())
    }
}
