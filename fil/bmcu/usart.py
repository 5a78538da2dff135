"""USART3 (0x4000_4800), the printer's line on header H1: bytes arrive at the virtual times the
bench gives (one per 86.8 us at 115200 8N1) into DATAR and, with CTLR3.DMAR, through DMA1
channel 3 into the image's ring; bytes written to DATAR leave one per character time.

Register layout and bits from ch32-metapac 0.1.2 `usart_common` (WCH's SVD; the STM32F103's
USART, RM0008 §27, which the CH32V20x copies): STATR 0x00 (PE 0, FE 1, NE 2, ORE 3, IDLE 4,
RXNE 5, TC 6, TXE 7), DATAR 0x04, BRR 0x08, CTLR1 0x0C (RE 2, TE 3, IDLEIE 4, RXNEIE 5, TCIE 6,
TXEIE 7, UE 13), CTLR2 0x10, CTLR3 0x14 (EIE 0, DMAR 6, DMAT 7).
- Receive: a character that completes goes to DATAR and sets RXNE; with DMAR the DMA reads it at
  once (which clears RXNE). A character that finds RXNE still set is lost and sets ORE. PE, FE,
  NE, ORE and IDLE clear when STATR is read and then DATAR (the DMA's read counts: the image's
  uart.rs relies on that). IDLE is set when the line stays idle for a character after one.
- Transmit: a write to DATAR goes to the shift register at once if it is free, else waits in
  DATAR (TXE clear); a character takes 10 bit times at the rate BRR gives from PCLK1 (rcc.py;
  the image's 625 at 72 MHz: 115200 Bd, 86.8 us); TC is set when the last one has left. A write
  while TXE is clear replaces the waiting byte (the byte is lost, as on the chip).
Left out: parity and framing (the bench's line is clean; a BRR far from 115200 is not turned into
framing errors), break, the smartcard/IrDA/LIN modes, the interrupt (the image enables none),
transmit DMA (the image writes DATAR from the CPU).
"""

from collections import deque

import clock
from dma1 import USART3_RX
from linebench import UartLine
from regs import Block

STATR, DATAR, BRR, CTLR1, CTLR2, CTLR3 = 0x00, 0x04, 0x08, 0x0C, 0x10, 0x14
PE, FE, NE, ORE, IDLE, RXNE, TC, TXE = (1 << n for n in range(8))
RE, TE, UE = 1 << 2, 1 << 3, 1 << 13
DMAR = 1 << 6
IRQ = 55


class Usart(Block, UartLine):
    name = "USART3"

    def __init__(self, chip=None):
        super().__init__(chip)
        self.incoming = deque()      # (arrival cycle, byte), in order
        self.flags = 0               # PE FE NE ORE IDLE
        self.rxne = False
        self.statr_read = False      # STATR read since the last DATAR read
        self.idle_at = None
        self.waiting = None          # the byte in DATAR for the shift register
        self.shifting = None         # (byte, cycle its stop bit ends)
        self.sent = []               # (cycle, byte) transmitted, taken by the bench
        self.received = 0
        self.lost = 0
        self.now = 0

    def on(self, bit):
        ctlr1 = self.regs.get(CTLR1, 0)
        return bool(ctlr1 & UE and ctlr1 & bit)

    def char_cycles(self):
        brr = self.regs.get(BRR, 0)
        pclk1 = self.chip.rcc.pclk1() if self.chip is not None and hasattr(self.chip, "rcc") else 72_000_000
        if not brr or not pclk1:
            return clock.char_time(1)
        return clock.BITS_PER_CHAR * brr * clock.HZ // pclk1  # baud = PCLK1 / BRR

    # ---- the line ----------------------------------------------------------------------------
    def _receive(self, at, byte):
        if not self.on(RE):
            return
        if self.rxne:
            self.flags |= ORE
            self.lost += 1
        else:
            self.regs[DATAR] = byte
            self.rxne = True
            self.received += 1
            self._serve_dma()
        self.idle_at = at + clock.char_time(1)

    def _serve_dma(self):
        if self.rxne and self.regs.get(CTLR3, 0) & DMAR and self.chip is not None:
            self.chip.dma.request(USART3_RX, read_peripheral=self._read_datar)

    def _read_datar(self):
        self.rxne = False
        if self.statr_read:
            self.flags &= ~(PE | FE | NE | ORE | IDLE)
            self.statr_read = False
        return self.regs.get(DATAR, 0)

    def _shift(self, at):
        if self.shifting is None and self.waiting is not None:
            self.shifting = (self.waiting, at + self.char_cycles())
            self.waiting = None

    def advance(self, now):
        while True:
            t_rx = self.incoming[0][0] if self.incoming else None
            t_tx = self.shifting[1] if self.shifting else None
            t = min((x for x in (t_rx, t_tx, self.idle_at) if x is not None), default=None)
            if t is None or t > now:
                break
            self.now = t
            if t == t_rx:
                self._receive(*self.incoming.popleft())
            elif t == t_tx:
                self.sent.append((t, self.shifting[0]))
                self.shifting = None
                self._shift(t)
            else:
                self.idle_at = None
                if not (self.incoming and self.incoming[0][0] - clock.char_time(1) < t):
                    self.flags |= IDLE
        self.now = now

    def next_event(self):
        """A character's end, in either direction: the DMA moves a received one into memory as
        it completes (also while the CPU is stalled or asleep), and a `step` reports the sent
        ones whose stop bit ended in it."""
        times = [t for t in (self.incoming[0][0] if self.incoming else None,
                             self.shifting[1] if self.shifting else None) if t is not None]
        return min(times) if times else None

    def busy(self):
        """Whether a byte waits or is being sent."""
        return int(self.waiting is not None or self.shifting is not None)

    # ---- registers ---------------------------------------------------------------------------
    def statr(self):
        value = self.flags | (RXNE if self.rxne else 0)
        if self.waiting is None:
            value |= TXE
        if self.waiting is None and self.shifting is None:
            value |= TC
        return value

    def read_reg(self, offset):
        if offset == STATR:
            self.statr_read = True
            return self.statr()
        if offset == DATAR:
            return self._read_datar()
        return super().read_reg(offset)

    def write_reg(self, offset, value, mask):
        value &= mask
        if offset == STATR:
            # RXNE and TC clear by writing 0 (rc_w0); the bench derives them, so only the flags
            self.flags &= value | ~0x1F
        elif offset == DATAR:
            if self.on(TE):
                self.waiting = value & 0xFF
                self._shift(self.chip.now() if self.chip is not None else self.now)
        else:
            super().write_reg(offset, value, mask)
            if offset == CTLR1 and not self.regs[CTLR1] & UE:
                self.waiting = self.shifting = None
            self._serve_dma()
        if self.chip is not None:
            self.chip.reschedule(self)

    def irqs(self):
        return ()
