"""Reset and clock control (RCC, 0x40021000) and the power controller (PWR, 0x40007000): the
ready flags embassy_stm32::init waits for, and the reset flags the firmware reads at boot.

RM0444 §5.4 (RCC registers):
- RCC_CR (0x00, reset 0x0000_0500): HSION (8) -> HSIRDY (10), HSEON (16) -> HSERDY (17),
  PLLON (24) -> PLLRDY (25). Each ready flag follows its enable (the oscillators' start-up
  time is not modelled).
- RCC_CFGR (0x08): SWS [5:3] follows SW [2:0] (the clock switch is immediate).
- RCC_BDCR (0x5C): LSEON (0) -> LSERDY (1). RCC_CSR (0x60): LSION (0) -> LSIRDY (1); the reset
  flags OBLRSTF 25, PINRSTF 26, PWRRSTF 27, SFTRSTF 28, IWDGRSTF 29, WWDGRSTF 30, LPWRRSTF 31,
  cleared by writing RMVF (23). Every reset also sets PINRSTF (the internal reset drives NRST,
  §5.1.2); a power-on reset sets PWRRSTF.
- The enable and reset registers (IOPENR 0x34, AHBENR 0x38, APBENR1/2 0x3C/0x40, ...) are
  stored and read back; the models do not refuse to work with their clock off.
RM0444 §4.4 (PWR registers): PWR_SR2 (0x14) VOSF (10) and REGLPF (9) read 0: the regulator is
always ready.
"""

from regs import Block

CSR_FLAGS = {"option": 25, "pin": 26, "power": 27, "software": 28, "watchdog": 29,
             "window": 30, "lowpower": 31}


class Rcc(Block):
    name = "RCC"
    resets = {0x00: 0x0000_0500, 0x0C: 0x0000_1000, 0x38: 0x0000_0100, 0x60: 0}

    def __init__(self, chip=None, csr_flags=0):
        super().__init__(chip)
        self.regs[0x60] = csr_flags

    def write_reg(self, offset, value, mask):
        super().write_reg(offset, value, mask)
        r = self.regs
        if offset == 0x00:
            cr = r[0x00] & ~((1 << 10) | (1 << 17) | (1 << 25))
            cr |= ((cr >> 8) & 1) << 10 | ((cr >> 16) & 1) << 17 | ((cr >> 24) & 1) << 25
            r[0x00] = cr
        elif offset == 0x08:
            r[0x08] = (r[0x08] & ~0x38) | ((r[0x08] & 7) << 3)
        elif offset == 0x5C:
            r[0x5C] = (r[0x5C] & ~2) | ((r[0x5C] & 1) << 1)
        elif offset == 0x60:
            csr = r[0x60]
            if csr & (1 << 23):  # RMVF
                csr &= 0x00FF_FFFF & ~(1 << 23)
            csr = (csr & ~2) | ((csr & 1) << 1)
            r[0x60] = csr

    def reset_flags(self):
        return self.regs[0x60] & 0xFF00_0000


class Pwr(Block):
    name = "PWR"
    resets = {0x00: 0x0000_0208}

    def read_reg(self, offset):
        if offset == 0x14:
            return 0
        return super().read_reg(offset)
