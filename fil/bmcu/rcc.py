"""Reset and clock control (RCC, 0x4002_1000), EXTEND (0x4002_3800) and AFIO (0x4001_0000): the
ready flags the image's clock set-up waits for, the reset flags it reads at boot, and the clock
and remap settings the other models take from them.

Register layout and bits from ch32-metapac 0.1.2 `rcc_v3`, `extend_v3`, `afio_v3` (WCH's SVD for
the CH32V20x; the CH32FV2x_V3xRM reference manual itself was not found in the searched corpora):
- RCC_CTLR 0x00 (reset 0x0000_0083: HSION, HSIRDY, HSITRIM 16): HSION 0 -> HSIRDY 1, HSEON 16 ->
  HSERDY 17, PLLON 24 -> PLLRDY 25 follow their enables at once (start-up times not modelled).
- RCC_CFGR0 0x04: SWS [3:2] follows SW [1:0] at once; HPRE [7:4], PPRE1 [10:8], PPRE2 [13:11],
  ADCPRE [15:14], PLLSRC 16, PLLMUL [21:18] (0-14: x2-x16, 15: x18 on the CH32V20x).
- RCC_RSTSCKR 0x24: LSION 0 -> LSIRDY 1; the reset flags PINRSTF 26, PORRSTF 27, SFTRSTF 28,
  IWDGRSTF 29, WWDGRSTF 30, LPWRRSTF 31, cleared by writing RMVF (24). Every reset also sets
  PINRSTF (the internal reset drives NRST, as on the STM32F1 the chip follows); a power-on sets
  PORRSTF.
- The enable and reset registers (AHBPCENR 0x14, APB2PCENR 0x18, APB1PCENR 0x1C, ...) are stored;
  the models work whether their clock is on or not.
- EXTEND_CTR 0x00: PLL_HSI_PRE (bit 4): 1 feeds the PLL the HSI undivided, 0 halved (the
  image's clock.rs: "the HSI undivided into the PLL").
- AFIO_PCFR1 0x04: TIM2_RM [9:8], TIM3_RM [11:10], TIM4_RM 12, PD01_RM 15 (PD0/PD1 as GPIO
  instead of OSC_IN/OSC_OUT): read by the GPIO model and the bench's pin routing.
The bench's virtual clock counts 120 MHz whatever these say (clock.py); `hclk()` computes what
the image chose, which the bench logs once the PLL runs.
"""

from regs import Block

CTLR, CFGR0, RSTSCKR = 0x00, 0x04, 0x24
FLAGS = {"pin": 26, "power": 27, "software": 28, "watchdog": 29, "window": 30, "lowpower": 31}
RMVF = 1 << 24
HSI_HZ = 8_000_000
AHB_DIVIDERS = (2, 4, 8, 16, 64, 128, 256, 512)


class Rcc(Block):
    name = "RCC"
    resets = {CTLR: 0x0000_0083, CFGR0: 0, RSTSCKR: 0}

    def __init__(self, chip=None, flags=0):
        super().__init__(chip)
        self.regs[RSTSCKR] = flags

    def write_reg(self, offset, value, mask):
        super().write_reg(offset, value, mask)
        r = self.regs
        if offset == CTLR:
            ctlr = r[CTLR] & ~((1 << 1) | (1 << 17) | (1 << 25))
            r[CTLR] = ctlr | (ctlr & 1) << 1 | (ctlr >> 16 & 1) << 17 | (ctlr >> 24 & 1) << 25
        elif offset == CFGR0:
            r[CFGR0] = (r[CFGR0] & ~0xC) | (r[CFGR0] & 3) << 2
        elif offset == RSTSCKR:
            value = r[RSTSCKR]
            if value & RMVF:
                value &= 0x00FF_FFFF & ~RMVF
            r[RSTSCKR] = (value & ~2) | (value & 1) << 1

    def reset_flags(self):
        return self.regs[RSTSCKR] & 0xFC00_0000

    # ---- the clock tree the image set ----------------------------------------------------------
    def sysclk(self):
        cfgr = self.regs[CFGR0]
        source = cfgr >> 2 & 3
        if source == 0:
            return HSI_HZ
        if source != 2:
            return 0  # the HSE: no crystal on the BMCU-C
        extend = self.chip.extend.regs.get(0, 0) if self.chip else 0
        pll_in = HSI_HZ if extend >> 4 & 1 else HSI_HZ // 2
        if cfgr >> 16 & 1:
            return 0  # the PLL from the HSE
        mul = cfgr >> 18 & 0xF
        return pll_in * (18 if mul == 15 else mul + 2)

    def hclk(self):
        hpre = self.regs[CFGR0] >> 4 & 0xF
        return self.sysclk() // (AHB_DIVIDERS[hpre - 8] if hpre >= 8 else 1)

    def _apb(self, shift):
        ppre = self.regs[CFGR0] >> shift & 7
        return self.hclk() // (1 << (ppre - 3) if ppre >= 4 else 1)

    def pclk1(self):
        return self._apb(8)

    def pclk2(self):
        return self._apb(11)

    def adc_clock(self):
        return self.pclk2() // (2 * ((self.regs[CFGR0] >> 14 & 3) + 1))


class Afio(Block):
    """AFIO: the remaps, stored (PCFR1 at 0x04); a write tells GPIOD (PD01_RM connects PD0/PD1)."""
    name = "AFIO"

    def pcfr1(self):
        return self.regs.get(0x04, 0)

    def write_reg(self, offset, value, mask):
        super().write_reg(offset, value, mask)
        gpio = getattr(self.chip, "gpio", None)
        if gpio:
            gpio["D"].refresh()
