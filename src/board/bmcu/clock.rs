//! The CH32V203's clocks: 120 MHz from the internal 8 MHz HSI through the PLL (the BMCU-C has
//! no crystal): the HSI undivided into the PLL (EXTEND_CTR.PLL_HSI_PRE), ×15. HCLK 120 MHz;
//! PCLK1 60 MHz, so TIM2-4 count at 120 MHz (an APB prescaler other than 1 doubles the timers'
//! clock) and USART3 runs from 60 MHz; PCLK2 60 MHz and the ADC at PCLK2 / 6 = 10 MHz (at most
//! 14 MHz).
//!
//! Not the chip's 144 MHz: above 120 MHz WCH's flash example (openwch/ch32v20x,
//! `EVT/EXAM/FLASH/FLASH_Program/User/main.c`, its note b) requires HCLK halved around every
//! flash erase and program, so that the flash's access clock (SYSCLK / 2 by FLASH_CTLR.SCKMOD's
//! reset value) stays within 60 MHz. Halving HCLK halves PCLK1 with it: the printer's UART
//! would run at half its baud rate while the store writes, and the bytes the printer sends
//! meanwhile would be lost. At 120 MHz the flash's clock is 60 MHz without touching HCLK.

use ch32_metapac as pac;
use pac::rcc::vals::{Adcpre, Hpre, PllMul, Ppre, Sw};

/// The core's clock, HCLK.
pub const HCLK_HZ: u32 = 120_000_000;
/// APB1's clock: USART3.
pub const PCLK1_HZ: u32 = HCLK_HZ / 2;
/// TIM2-4's counting clock: twice PCLK1.
pub const TIMER_HZ: u32 = 2 * PCLK1_HZ;
/// SysTick's clock: HCLK / 8.
pub const SYSTICK_HZ: u32 = HCLK_HZ / 8;

/// SysTick counts in `ns` nanoseconds, rounded to the nearest count.
pub const fn systick_counts(ns: u32) -> u64 {
    (ns as u64 * SYSTICK_HZ as u64 + 500_000_000) / 1_000_000_000
}

/// Switches the system clock from the HSI to the PLL at 120 MHz.
pub fn init() {
    let rcc = pac::RCC;
    rcc.ctlr().modify(|w| w.set_hsion(true));
    while !rcc.ctlr().read().hsirdy() {}
    pac::EXTEND.ctr().modify(|w| w.set_pll_hsi_pre(true));
    rcc.cfgr0().modify(|w| {
        w.set_hpre(Hpre::DIV1);
        w.set_ppre1(Ppre::DIV2);
        w.set_ppre2(Ppre::DIV2);
        w.set_adcpre(Adcpre::DIV6);
        // PLL source: the HSI (not the HSE).
        w.set_pllsrc(false);
        w.set_pllmul(PllMul::MUL15);
    });
    rcc.ctlr().modify(|w| w.set_pllon(true));
    while !rcc.ctlr().read().pllrdy() {}
    rcc.cfgr0().modify(|w| w.set_sw(Sw::PLL));
    while rcc.cfgr0().read().sws() != Sw::PLL {}
}
