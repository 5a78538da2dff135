"""General-purpose I/O ports GPIOA-GPIOD (0x4001_0800 + 0x400 n): the levels the bench reads
off the motor pins, and the open-drain lines of the four AS5600 buses (as5600.py).

Register layout from ch32-metapac 0.1.2 `gpio_v3` (WCH's SVD; the STM32F103's layout): CFGLR
0x00 / CFGHR 0x04 (per pin 4 bits: MODE [1:0] 00 input, else output; CNF [3:2]: input 00
analog, 01 floating, 10 pull-up/down by OUTDR; output 00 push-pull, 01 open-drain, 10 AF
push-pull, 11 AF open-drain; reset 0x4444_4444, every pin a floating input), INDR 0x08, OUTDR
0x0C, BSHR 0x10 (bits 0-15 set, 16-31 reset; set wins), BCR 0x14 (reset), LCKR 0x18.
- A pin's level: an output drives OUTDR (push-pull) or pulls low where OUTDR is 0 and lets go
  where it is 1 (open drain); an AF output drives what its peripheral gives (the bench reads the
  timers for the PWM pins, bench.py). An input reads what drives it from outside (`external`,
  the bus wired to it: as5600.py) or its pull. An open-drain line reads low if either side pulls
  it low, else high (the sensor board's pull-ups).
- PD0/PD1 are the HSE's OSC_IN/OSC_OUT after reset: they are GPIO only with AFIO_PCFR1.PD01_RM
  set (src/board/bmcu/mod.rs). Without it the pins are not connected: they drive nothing and read 0.
Left out: the lock, the output speed, EXTI.
"""

from regs import Block

CFGLR, CFGHR, INDR, OUTDR, BSHR, BCR = 0x00, 0x04, 0x08, 0x0C, 0x10, 0x14
PORT_D = 3


class Gpio(Block):
    name = "GPIO"
    resets = {CFGLR: 0x4444_4444, CFGHR: 0x4444_4444}

    def __init__(self, chip=None, port=0):
        super().__init__(chip)
        self.port = port
        self.ext_known = 0   # pins something outside drives (the AS5600 buses' SDA)
        self.ext_level = 0   # and the level it drives them to (an open-drain release: 1)
        self.watchers = []   # called after a change of the pins' configuration or outputs
        self.pulled_low = 0  # low(), kept current by every write (and AFIO's, `refresh`)
        self._plan()

    # ---- the pins' configuration, as masks -----------------------------------------------------
    def _plan(self):
        """Masks of the pins' configuration: GPIO outputs (push-pull, open-drain), AF outputs,
        inputs with a pull; pins not connected (PD0/PD1 without their remap)."""
        self.gpio_out = self.open_drain = self.af_out = self.pulled = 0
        for pin in range(16):
            mode, cnf = self.config(pin)
            bit = 1 << pin
            if mode:
                if cnf & 2:
                    self.af_out |= bit
                else:
                    self.gpio_out |= bit
                    if cnf == 1:
                        self.open_drain |= bit
            elif cnf == 2:
                self.pulled |= bit

    def _cut(self):
        """The pins not connected: PD0/PD1 without AFIO_PCFR1.PD01_RM."""
        if self.port != PORT_D or self.chip is None or self.chip.afio.pcfr1() >> 15 & 1:
            return 0
        return 0b11

    def config(self, pin):
        """(MODE, CNF) of `pin`."""
        word = self.regs[CFGLR if pin < 8 else CFGHR] >> (4 * (pin % 8))
        return word & 3, word >> 2 & 3

    def outdr(self):
        return self.regs.get(OUTDR, 0)

    def connected(self, pin):
        return not self._cut() >> pin & 1

    def low(self):
        """The pins the chip pulls low (GPIO outputs at 0), as a mask."""
        return self.gpio_out & ~self.outdr() & ~self._cut() & 0xFFFF

    def refresh(self):
        """Something the pins depend on changed (a write, AFIO's remap): `pulled_low` anew, and
        the watchers told."""
        self.pulled_low = self.low()
        for watch in self.watchers:
            watch()

    def drive(self, pin):
        """What the chip drives on `pin`: 0 or 1, or None (an input, a released open drain, an
        AF output: the bench reads its peripheral)."""
        if not self.connected(pin) or not self.gpio_out >> pin & 1:
            return None
        level = self.outdr() >> pin & 1
        return None if level and self.open_drain >> pin & 1 else level

    def output_level(self, pin):
        """The pin's level as a load sees it: a driven level, else 0 (the bridges' inputs have
        pull-downs)."""
        return self.drive(pin) or 0

    def external(self, pin, level):
        """Something outside drives `pin` to `level` (1: it lets go of an open-drain line)."""
        self.ext_known |= 1 << pin
        self.ext_level = self.ext_level & ~(1 << pin) | level << pin

    def indr(self):
        """The pins' levels: a push-pull output its OUTDR; an open-drain one low if either side
        pulls it low, else high (the pull-ups); an input what drives it from outside, else its
        pull (OUTDR), else 0; an AF output and a pin not connected 0."""
        outdr = self.outdr()
        ext_low = self.ext_known & ~self.ext_level
        push_pull = self.gpio_out & ~self.open_drain
        inputs = ~(self.gpio_out | self.af_out)
        value = ((push_pull & outdr) | (self.open_drain & ~(~outdr & 0xFFFF | ext_low))
                 | (inputs & self.ext_known & self.ext_level) | (inputs & self.pulled & ~self.ext_known & outdr))
        return value & ~self._cut() & 0xFFFF

    def level(self, pin):
        return self.indr() >> pin & 1

    def read_reg(self, offset):
        if offset == INDR:
            return self.indr()
        if offset in (BSHR, BCR):
            return 0
        return super().read_reg(offset)

    def write_reg(self, offset, value, mask):
        value &= mask
        if offset == BSHR:
            self.regs[OUTDR] = (self.outdr() & ~(value >> 16) | value) & 0xFFFF
        elif offset == BCR:
            self.regs[OUTDR] = self.outdr() & ~value & 0xFFFF
        elif offset == INDR:
            return
        else:
            super().write_reg(offset, value, mask)
            if offset in (CFGLR, CFGHR):
                self._plan()
        self.refresh()
