//! The CH32V203's clocks: 144 MHz from the internal 8 MHz HSI through the PLL (the BMCU-C has
//! no crystal), as WCH's own start-up code sets them (`SystemInit`, `SYSCLK_FREQ_144MHz_HSI`):
//! the HSI undivided into the PLL (EXTEND_CTR.PLL_HSI_PRE), ×18. HCLK 144 MHz; PCLK1 72 MHz,
//! so TIM2-4 count at 144 MHz (an APB prescaler other than 1 doubles the timers' clock) and
//! USART3 runs from 72 MHz; PCLK2 72 MHz and the ADC at PCLK2 / 6 = 12 MHz (at most 14 MHz).

use ch32_metapac as pac;
use pac::rcc::vals::{Adcpre, Hpre, PllMul, Ppre, Sw};

/// The core's clock, HCLK.
pub const HCLK_HZ: u32 = 144_000_000;
/// APB1's clock: USART3.
pub const PCLK1_HZ: u32 = HCLK_HZ / 2;
/// TIM2-4's counting clock: twice PCLK1.
pub const TIMER_HZ: u32 = 2 * PCLK1_HZ;

/// Switches the system clock from the HSI to the PLL at 144 MHz.
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
        w.set_pllmul(PllMul::MUL18);
    });
    rcc.ctlr().modify(|w| w.set_pllon(true));
    while !rcc.ctlr().read().pllrdy() {}
    rcc.cfgr0().modify(|w| w.set_sw(Sw::PLL));
    while rcc.cfgr0().read().sws() != Sw::PLL {}
}
