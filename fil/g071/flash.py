"""The embedded flash controller (FLASH, 0x40022000): ACR's wait states, unlocking, double-word
programming and page erase, and the CPU stall while the single bank is busy, during which the DMA,
the UART, the timers and the watchdog carry on (the property the store's design relies on).

RM0444 §3.7 (FLASH registers): ACR 0x00 (reset 0x0004_0600; LATENCY [2:0] reads back what was
written, §3.3.4), KEYR 0x08, SR 0x10 (EOP 0 and the error flags OPERR 1, PROGERR 3, WRPERR 4,
PGAERR 5, SIZERR 6, PGSERR 7, MISERR 8, FASTERR 9: write 1 to clear; BSY1 16, CFGBSY 18), CR
0x14 (reset 0xC000_0000; PG 0, PER 1, MER1 2, PNB [9:3], STRT 16, EOPIE 24, ERRIE 25, OPTLOCK
30, LOCK 31), ECCR 0x18.
- §3.3.5 unlock: KEY1 0x4567_0123 then KEY2 0xCDEF_89AB into KEYR clears LOCK; any other write
  keeps CR locked until the next reset. Setting LOCK locks again.
- §3.3.7 program: with PG set, the first word goes to a double-word-aligned address and the
  second to the next word; the second write starts the programming (BSY1). A double word that
  is not erased (all ones) is not programmed and sets PROGERR, unless the data is all zeros; a
  second word elsewhere sets PGAERR; a write that is not 32 bits sets SIZERR; a write without PG
  or with an error flag still set sets PGSERR. Programming takes 85 us (datasheet t_prog typical).
- §3.3.6 page erase: PER, PNB and STRT start it (BSY1); a page is 2 KiB; it takes 22 ms
  (datasheet t_ERASE typical; 40 ms at most).
- EOP is set at the end when EOPIE is set (§3.7.5); FLASH interrupt IRQ 3 on EOP & EOPIE.
- §3.3.2: while BSY1 is set, a fetch or read from the bank stalls the CPU: here the CPU executes
  nothing until the operation ends (the vectors are in flash too, so no interrupt runs either).
Left out: option bytes, fast programming, mass erase timing, ECC errors (an interrupted program
is not modelled: power off during BSY loses the operation entirely), write protection, PCROP,
securable memory.
"""

from regs import Block

ACR, KEYR, SR, CR, ECCR = 0x00, 0x08, 0x10, 0x14, 0x18
KEY1, KEY2 = 0x4567_0123, 0xCDEF_89AB
BASE, SIZE, PAGE = 0x0800_0000, 128 * 1024, 2048
PROGRAM_CYCLES = 85 * 64
ERASE_CYCLES = 22_000 * 64
IRQ = 3
ERRORS = 0x3FA  # OPERR..FASTERR


class Flash(Block):
    name = "FLASH"
    resets = {ACR: 0x0004_0600}

    def __init__(self, chip=None):
        super().__init__(chip)
        self.cr = 0xC000_0000
        self.sr = 0
        self.key_state = 0           # 1 after KEY1
        self.key_error = False       # locked until reset
        self.first_word = None       # (address, value) of the double word in progress
        self.busy_until = None
        self.pending = None          # ("program", address, bytes) or ("erase", page)
        self.erases = 0
        self.programs = 0

    # ---- registers ---------------------------------------------------------------------------
    def read_reg(self, offset):
        if offset == SR:
            return self.sr | ((1 << 16) if self.busy_until is not None else 0)
        if offset == CR:
            return self.cr
        if offset in (KEYR, ECCR):
            return 0
        return super().read_reg(offset)

    def write_reg(self, offset, value, mask):
        value &= mask
        if offset == KEYR:
            if self.key_error or not self.cr >> 31:
                self.key_error = True
            elif self.key_state == 0 and value == KEY1:
                self.key_state = 1
            elif self.key_state == 1 and value == KEY2:
                self.cr &= ~(1 << 31)
                self.key_state = 0
            else:
                self.key_error = True
        elif offset == SR:
            self.sr &= ~(value & (ERRORS | 1 | (1 << 14) | (1 << 15)))
        elif offset == CR:
            if self.cr >> 31:
                return  # locked
            self.cr = (self.cr & ~mask) | value
            if self.cr >> 16 & 1:
                self.cr &= ~(1 << 16)
                self._start_erase()
        else:
            super().write_reg(offset, value, mask)
        if self.chip:
            self.chip.reschedule(self)

    # ---- operations --------------------------------------------------------------------------
    def _begin(self, cycles, op):
        now = self.chip.now() if self.chip else 0
        self.busy_until = now + cycles
        self.pending = op
        if self.chip:
            self.chip.stall(self.busy_until)

    def _start_erase(self):
        if self.busy_until is not None or self.sr & ERRORS:
            self.sr |= 1 << 7  # PGSERR
            return
        if self.cr & 2:  # PER
            page = (self.cr >> 3) & 0x7F
            if page * PAGE >= SIZE:
                self.sr |= 1 << 4  # WRPERR: outside the bank
                return
            self.erases += 1
            self._begin(ERASE_CYCLES, ("erase", page))
        elif self.cr & 4:  # MER1
            self.erases += SIZE // PAGE
            self._begin(ERASE_CYCLES, ("mass",))
        else:
            self.sr |= 1 << 7

    def store(self, address, size, value):
        """A CPU store into the flash's address range."""
        if size != 4:
            self.sr |= 1 << 6  # SIZERR
            self.first_word = None
            return
        if not self.cr & 1 or self.cr >> 31 or self.busy_until is not None or self.sr & ERRORS:
            self.sr |= 1 << 7  # PGSERR
            self.first_word = None
            return
        if self.first_word is None:
            if address & 7:
                self.sr |= 1 << 5  # PGAERR
                return
            self.first_word = (address, value)
            return
        first, low = self.first_word
        self.first_word = None
        if address != first + 4:
            self.sr |= 1 << 5
            return
        data = low | (value << 32)
        current = int.from_bytes(self.chip.memory.read(first, 8), "little")
        if current != 0xFFFF_FFFF_FFFF_FFFF and data != 0:
            self.sr |= 1 << 3  # PROGERR
            return
        self.programs += 1
        self._begin(PROGRAM_CYCLES, ("program", first, data.to_bytes(8, "little")))

    def next_event(self):
        return self.busy_until

    def advance(self, now):
        if self.busy_until is None or now < self.busy_until:
            return
        op = self.pending
        self.busy_until = self.pending = None
        mem = self.chip.memory
        if op[0] == "program":  # bits only go from 1 to 0
            old = int.from_bytes(mem.read(op[1], 8), "little")
            new = old & int.from_bytes(op[2], "little")
            mem.write(op[1], new.to_bytes(8, "little"))
        elif op[0] == "erase":
            mem.write(BASE + op[1] * PAGE, b"\xff" * PAGE)
        else:
            mem.write(BASE, b"\xff" * SIZE)
        if self.cr >> 24 & 1:
            self.sr |= 1  # EOP

    def power_loss(self):
        """Power off while busy: the operation is lost (see the module's notes)."""
        self.busy_until = self.pending = None

    def irqs(self):
        if (self.sr & 1 and self.cr >> 24 & 1) or (self.sr & 2 and self.cr >> 25 & 1):
            return (IRQ,)
        return ()
