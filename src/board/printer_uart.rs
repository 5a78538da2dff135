//! The printer's UART (USART3): the register access and interrupt of the driver whose decisions
//! (the rings, the error flags, the transmit interrupt) are `mmu_firmware::uart`, with host tests
//! against a model of the USART's registers.
//!
//! Not embassy-stm32's `BufferedUart`: its async machinery (wakers, futures, the configuration
//! code for every USART mode) took 1.8 KB more of the 32 KiB flash, for a line this firmware only
//! polls once a step.

use embassy_stm32::Peri;
use embassy_stm32::gpio::{AfType, Flex, OutputType, Pull, Speed};
use embassy_stm32::interrupt::{self, InterruptExt as _};
use embassy_stm32::pac;
use embassy_stm32::peripherals;
use embassy_stm32::rcc;
use embassy_stm32::usart::{RxPin, TxPin};
use mmu_firmware::uart::{Port, Uart, UsartRegisters};

/// Printer UART ring buffers. RX holds what arrives while the control loop does not step for
/// `control::RX_GAP_MS` with the printer sending without pause, plus what a step leaves waiting
/// (a step takes at most `control::MAX_RX_PER_STEP` bytes); TX more than five steps' worth of
/// responses (`mmu_firmware::TX_CAPACITY` = 48).
pub(super) const RX_RING: usize = mmu_firmware::control::RX_RING;
pub(super) const TX_RING: usize = 256;
/// The printer line's rate, 8N1.
const BAUD: u32 = 115_200;

/// The printer UART's rings, shared by its interrupt and [`Control`](super::Control).
pub(super) static PRINTER_UART: Uart<RX_RING, TX_RING> = Uart::new();

/// USART3's registers (RM0444, USART chapter), one volatile access each.
pub(super) struct PrinterUsart;

impl UsartRegisters for PrinterUsart {
    fn isr(&self) -> u32 {
        pac::USART3.isr().read().0
    }

    fn clear(&self, flags: u32) {
        pac::USART3.icr().write_value(pac::usart::regs::Icr(flags));
    }

    fn read_rdr(&self) -> u8 {
        pac::USART3.rdr().read().0 as u8
    }

    fn write_tdr(&self, byte: u8) {
        pac::USART3
            .tdr()
            .write_value(pac::usart::regs::Dr(u32::from(byte)));
    }

    fn cr1(&self) -> u32 {
        pac::USART3.cr1().read().0
    }

    fn set_cr1(&self, cr1: u32) {
        pac::USART3.cr1().write_value(pac::usart::regs::Cr1(cr1));
    }

    fn pend_interrupt(&self) {
        interrupt::USART3_4_LPUART1.pend();
    }
}

/// Runs [`Uart::on_interrupt`] for USART3.
pub(super) struct PrinterUartInterrupt;

impl interrupt::typelevel::Handler<interrupt::typelevel::USART3_4_LPUART1> for PrinterUartInterrupt {
    unsafe fn on_interrupt() {
        // SAFETY: this handler is the interrupt's only context.
        unsafe { PRINTER_UART.on_interrupt(&PrinterUsart) }
    }
}

/// USART3 at [`BAUD`] 8N1, the receive interrupt on: the register settings embassy-stm32
/// 0.6.0's `BufferedUart::new` makes for this configuration (clock on and reset, USART_BRR =
/// kernel clock / baud with oversampling by 16, USART_CR1 = UE | RE | TE | RXNEIE, the other
/// registers at their reset values), and the pins in their USART function (TX push-pull; no pull
/// on RX: the printer drives it, possibly at 5 V).
///
/// Without FIFOEN, which BufferedUart sets on every `usart_v4` USART: on the STM32G071 USART3 is
/// a basic USART without FIFO mode (RM0444, "USART implementation": FIFO only on USART1 and
/// USART2; stm32g0xx-hal builds USART3 and USART4 of the G070/G071/G081 as basic USARTs), where
/// CR1 bit 29 is reserved and must be kept at its reset value. The driver's flags sit at the same
/// positions either way (RXNE and TXE for RXFNE and TXFNF; its tests run both).
pub(super) fn start_printer_uart(
    _usart: Peri<'static, peripherals::USART3>,
    rx: Peri<'static, peripherals::PC11>,
    tx: Peri<'static, peripherals::PC10>,
) -> (Port<'static, PrinterUsart, RX_RING, TX_RING>, [Flex<'static>; 2]) {
    // The AF numbers from the HAL's pin tables, which also check that these are USART3's pins.
    let (rx_af, tx_af) = (
        RxPin::<peripherals::USART3>::af_num(&*rx),
        TxPin::<peripherals::USART3>::af_num(&*tx),
    );
    let mut rx = Flex::new(rx);
    rx.set_as_af_unchecked(rx_af, AfType::input(Pull::None));
    let mut tx = Flex::new(tx);
    tx.set_as_af_unchecked(tx_af, AfType::output(OutputType::PushPull, Speed::Medium));
    rcc::enable_and_reset::<peripherals::USART3>();
    let kernel_hz = rcc::frequency::<peripherals::USART3>().0;
    let regs = pac::USART3;
    regs.brr()
        .write_value(pac::usart::regs::Brr((kernel_hz + BAUD / 2) / BAUD));
    regs.cr1().write(|w| {
        w.set_ue(true);
        w.set_re(true);
        w.set_te(true);
        w.set_rxneie(true);
    });
    interrupt::USART3_4_LPUART1.unpend();
    // SAFETY: the handler only touches PRINTER_UART's interrupt side.
    unsafe { interrupt::USART3_4_LPUART1.enable() };
    // SAFETY: the one Port.
    (unsafe { PRINTER_UART.port(PrinterUsart) }, [rx, tx])
}
