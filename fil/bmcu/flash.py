"""The flash controller (FLASH, 0x4002_2000): unlocking, half-word programming, the 256-byte
fast page erase (and the 4 KB sector and mass erase), the erased state that reads 0xE339E339,
and the CPU stall while an operation runs, during which the DMA, the UART, the timers and the
watchdog go on.

Register layout and bits from ch32-metapac 0.1.2 `flash_v3` (WCH's SVD for the CH32V20x): KEYR
0x04, OBKEYR 0x08, STATR 0x0C (BSY 0, WR_BSY 1, WRPRTERR 4, EOP 5: write 1 to clear), CTLR 0x10
(PG 0, PER 1, MER 2, STRT 6, LOCK 7, EOPIE 12, FLOCK 15, PAGE_PG 16, PAGE_ER 17; reset LOCK |
FLOCK), ADDR 0x14, MODEKEYR 0x24. Keys 0x4567_0123 then 0xCDEF_89AB (src/board/bmcu/flash.rs).
- Unlock: the two keys in KEYR clear LOCK; in MODEKEYR, with LOCK clear, they clear FLOCK (fast
  mode). A wrong key keeps the controller locked until the next reset (as on the STM32F1, whose
  FPEC the chip copies: the RM's own words were not found). Setting LOCK or FLOCK in CTLR locks
  again; writing them 0 unlocks nothing. While LOCK is set CTLR ignores writes but for LOCK.
- Program (CTLR.PG): a half-word store into the flash programs it; bits only go from 1 to 0 (an
  erased half-word takes the value). A store that is not a half-word programs nothing and sets
  WRPRTERR (the bench's choice: the RM's behaviour was not found).
- Erase (STRT with PAGE_ER and FLOCK clear: the 256-byte page at ADDR; with PER: the 4 KB
  sector; with MER: the rated 64 KB). STRT clears itself. An address outside the rated 64 KB
  sets WRPRTERR.
- The erased state: a word whose bits are all ones since its erase reads 0xE339E339 (WCH's
  scrambled value of all ones, armink/EasyFlash#178, azhel12/Zhele#45, cnlohr/ch32fun#932: "in
  every word until something is programmed into it"). Which granule stops reading so once a
  half-word of it is programmed was not found: the bench takes the 32-bit word (a half-word of
  it still erased then reads 0xFFFF).
- Timing: no erase or program time of the CH32V203 was found in its datasheet's searched copies.
  The bench takes 10 ms a 256-byte page (four make a store page's 40 ms, the bound the firmware
  assumes, src/uart.rs BMCU_ERASE_STALL_MS), 40 ms a 4 KB sector or the mass erase, and 125 us a
  half-word (the G071's double-word bound as a stand-in). BSY is set meanwhile and EOP at the
  end (set whether EOPIE is or not, azhel12/Zhele#45).
- The stall: the bench stops the CPU for the whole operation (the brief's model, as the G071's).
  The CH32V203 executes from an SRAM copy of its zero-wait flash, so its core may run on while
  the array is busy; the image waits on BSY in a loop right after starting an operation, so for
  it the two differ only in that interrupts (SysTick's) wait until the operation ends here.
Counts: an erase counts one per 256-byte page (a sector 16, the mass erase 256), a program one
per half-word, when it starts. Left out: fast page programming (PAGE_PG, the 128-byte buffer),
option bytes, write protection (WPR), the EOP/error interrupt, a power loss inside an operation
(the operation is lost whole).
"""

from regs import Block

KEYR, STATR, CTLR, ADDR, MODEKEYR = 0x04, 0x0C, 0x10, 0x14, 0x24
DIE_WORD, LATER_DIE = 0x30, 0x0100_0000
KEY1, KEY2 = 0x4567_0123, 0xCDEF_89AB
BASE, SIZE, PAGE, SECTOR = 0x0800_0000, 64 * 1024, 256, 4096
ERASED = 0xE339_E339
PG, PER, MER, STRT, LOCK, FLOCK, PAGE_ER = 1, 1 << 1, 1 << 2, 1 << 6, 1 << 7, 1 << 15, 1 << 17
BSY, WRPRTERR, EOP = 1, 1 << 4, 1 << 5
PAGE_ERASE_US, SECTOR_ERASE_US, PROGRAM_US = 10_000, 40_000, 125


def erased_bytes(n):
    """n bytes of erased flash as it reads (whole words)."""
    return ERASED.to_bytes(4, "little") * (n // 4)


class Flash(Block):
    name = "FLASH"

    def __init__(self, chip=None):
        super().__init__(chip)
        self.ctlr = LOCK | FLOCK
        self.statr = 0
        self.keys = {KEYR: 0, MODEKEYR: 0}
        self.key_error = False
        self.busy_until = None
        self.pending = None        # ("program", address, half-word) or ("erase", address, size)
        self.erases = 0
        self.programs = 0

    # ---- registers ---------------------------------------------------------------------------
    # The word at 0x40022030 that WCH's GPIO driver reads to tell an early CH32V203 die (bits
    # 27:24 zero: PC13-PC15 at GPIOC bits 0-2, `ch32v20x_gpio.c` `GPIO_Init`) from a later one;
    # the bench is a later die. Its real value on either was not found.
    def read_reg(self, offset):
        if offset == STATR:
            return self.statr | (BSY if self.busy_until is not None else 0)
        if offset == CTLR:
            return self.ctlr
        if offset in (KEYR, MODEKEYR):
            return 0
        if offset == DIE_WORD:
            return LATER_DIE
        return super().read_reg(offset)

    def _key(self, offset, value):
        lock = LOCK if offset == KEYR else FLOCK
        if self.key_error or (offset == MODEKEYR and self.ctlr & LOCK) or not self.ctlr & lock:
            self.key_error = self.key_error or bool(self.ctlr & lock)
            return
        if self.keys[offset] == 0 and value == KEY1:
            self.keys[offset] = 1
        elif self.keys[offset] == 1 and value == KEY2:
            self.ctlr &= ~lock
            self.keys[offset] = 0
        else:
            self.key_error = True

    def write_reg(self, offset, value, mask):
        value &= mask
        if offset in (KEYR, MODEKEYR):
            self._key(offset, value)
        elif offset == STATR:
            self.statr &= ~(value & (WRPRTERR | EOP))
        elif offset == CTLR:
            if self.ctlr & LOCK:
                self.ctlr |= value & LOCK
                return
            locks = self.ctlr & (LOCK | FLOCK)  # writing 0 unlocks nothing: only the keys do
            self.ctlr = (self.ctlr & ~mask) | value | locks
            if self.ctlr & STRT:
                self.ctlr &= ~STRT
                self._start_erase()
        else:
            super().write_reg(offset, value, mask)
        if self.chip:
            self.chip.reschedule(self)

    # ---- operations --------------------------------------------------------------------------
    def _begin(self, us, op):
        now = self.chip.now() if self.chip else 0
        self.busy_until = now + us * (self.chip.cycles_per_us if self.chip else 120)
        self.pending = op
        if self.chip:
            self.chip.stall(self.busy_until)

    def _start_erase(self):
        if self.busy_until is not None:
            return
        address = self.regs.get(ADDR, 0)
        if self.ctlr & PAGE_ER and not self.ctlr & FLOCK:
            start, size, us = address & ~(PAGE - 1), PAGE, PAGE_ERASE_US
        elif self.ctlr & PER:
            start, size, us = address & ~(SECTOR - 1), SECTOR, SECTOR_ERASE_US
        elif self.ctlr & MER:
            start, size, us = BASE, SIZE, SECTOR_ERASE_US
        else:
            return
        if not BASE <= start < BASE + SIZE:
            self.statr |= WRPRTERR
            return
        self.erases += size // PAGE
        self._begin(us, ("erase", start, size))

    def store(self, address, size, value):
        """A CPU store into the flash's address range."""
        if not self.ctlr & PG or self.ctlr & LOCK or self.busy_until is not None:
            return
        if size != 2 or address & 1:
            self.statr |= WRPRTERR
            return
        self.programs += 1
        self._begin(PROGRAM_US, ("program", address, value & 0xFFFF))

    def next_event(self):
        return self.busy_until

    def advance(self, now):
        if self.busy_until is None or now < self.busy_until:
            return
        op, self.busy_until, self.pending = self.pending, None, None
        mem = self.chip.memory
        if op[0] == "program":
            address = op[1]
            word_at = address & ~3
            word = int.from_bytes(mem.read(word_at, 4), "little")
            logical = 0xFFFF_FFFF if word == ERASED else word
            shift = 8 * (address & 2)
            logical &= ~(0xFFFF << shift) | (op[2] << shift)
            stored = ERASED if logical == 0xFFFF_FFFF else logical
            mem.write(word_at, stored.to_bytes(4, "little"))
        else:
            mem.write(op[1], erased_bytes(op[2]))
        self.statr |= EOP

    def power_loss(self):
        """Power off while busy: the operation is lost (see the module's notes)."""
        self.busy_until = self.pending = None
