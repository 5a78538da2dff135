"""General-purpose I/O ports (GPIOA..GPIOF, 0x50000000 + 0x400 n): the output levels the bench
reports for the motor bridges' STBY and IN pins, and the input levels the firmware reads.

RM0444 §7.4 (GPIO registers): MODER (0x00; reset 0xEBFF_FFFF on port A, 0xFFFF_FFFF on the
others: analog), OTYPER 0x04, OSPEEDR 0x08, PUPDR 0x0C (port A reset 0x2400_0000), IDR 0x10,
ODR 0x14, BSRR 0x18 (bits 0-15 set, 16-31 reset; set wins when both, §7.4.7), AFRL/AFRH
0x20/0x24, BRR 0x28 (reset bits).
IDR: a pin in output mode reads its ODR level; an input reads its pull (up 1, down 0) or, with
no pull, the level `external` gives (the bench leaves inputs at 0 except the NUCLEO's B1 on PC13,
released = 1).
Left out: open-drain, the lock register's lock, alternate-function inputs (the USART and TIM3
are modelled at their registers, not at the pins).
"""

from regs import Block


class Gpio(Block):
    name = "GPIO"

    def __init__(self, chip=None, port=0):
        self.resets = {0x00: 0xEBFF_FFFF if port == 0 else 0xFFFF_FFFF,
                       0x08: 0x0C00_0000 if port == 0 else 0,
                       0x0C: 0x2400_0000 if port == 0 else 0}
        super().__init__(chip)
        self.port = port
        self.external = 0  # levels driven from outside on pins without a pull

    def mode(self, pin):
        return (self.regs[0x00] >> (2 * pin)) & 3

    def odr(self):
        return self.regs.get(0x14, 0)

    def output_level(self, pin):
        """The pin's level as a load sees it: ODR in output mode, else 0 (the bench's loads have
        pull-downs or are CMOS inputs the bench reads as low)."""
        return (self.odr() >> pin) & 1 if self.mode(pin) == 1 else 0

    def read_reg(self, offset):
        if offset == 0x10:
            value = 0
            pupd = self.regs[0x0C]
            for pin in range(16):
                mode = self.mode(pin)
                if mode == 1 or mode == 2:
                    level = (self.odr() >> pin) & 1
                else:
                    pull = (pupd >> (2 * pin)) & 3
                    level = 1 if pull == 1 else 0 if pull == 2 else (self.external >> pin) & 1
                value |= level << pin
            return value
        if offset in (0x18, 0x28):
            return 0
        return super().read_reg(offset)

    def write_reg(self, offset, value, mask):
        value &= mask
        if offset == 0x18:
            odr = self.odr()
            odr &= ~(value >> 16)
            odr |= value & 0xFFFF
            self.regs[0x14] = odr & 0xFFFF
        elif offset == 0x28:
            self.regs[0x14] = self.odr() & ~(value & 0xFFFF)
        elif offset == 0x10:
            pass  # IDR is read-only
        else:
            super().write_reg(offset, value, mask)
