"""USART1 (0x40013800), the printer's line: bytes arrive at the virtual times the bench gives
(one per 86.8 us at 115200 8N1), go through the receive FIFO to RDR and, with DMAR, straight into
the DMA ring; transmitted bytes leave one per character time and are handed to the bench.

RM0444 §33.8 (USART registers): CR1 0x00 (UE 0, RE 2, TE 3, IDLEIE 4, RXNEIE 5, TCIE 6, TXEIE 7,
PEIE 8, FIFOEN 29), CR2 0x04, CR3 0x08 (EIE 0, DMAR 6, DMAT 7), BRR 0x0C, RQR 0x18, ISR 0x1C
(PE 0, FE 1, NE 2, ORE 3, IDLE 4, RXNE/RXFNE 5, TC 6, TXE/TXFNF 7, TEACK 21, REACK 22, TXFE 23,
RXFF 24), ICR 0x20 (PECF 0, FECF 1, NECF 2, ORECF 3, IDLECF 4, TCCF 6), RDR 0x24, TDR 0x28,
PRESC 0x2C.
- Receive (§33.5.8): a received character goes to RDR (or the 8-deep RXFIFO with FIFOEN,
  §33.5.5); with DMAR set the DMA reads it at once (the DMA request, §33.5.20); a character that
  finds the FIFO/RDR full is lost and sets ORE. IDLE is set when the line stays idle for one
  character after a character was received (§33.5.8, "IDLE"), then again only after the next
  character.
- Transmit (§33.5.7): TDR (or the 8-deep TXFIFO) feeds the shift register; a character takes 10
  bit times; TXE/TXFNF is set while there is room, TC when the last character has left. With DMAT
  the DMA writes TDR whenever there is room.
- Interrupt line IRQ 27 (USART1, RM0444 Table 54): (IDLE & IDLEIE) | (RXNE & RXNEIE) |
  (TC & TCIE) | (TXE & TXEIE) | ((ORE|FE|NE) & EIE) | (PE & PEIE).
Left out: the baud rate from BRR (the bench always runs the line at 115200; the image sets it),
parity, framing/noise errors (the bench's line is clean), break, receiver timeout, hardware flow
control, the transmit FIFO thresholds.
"""

from collections import deque

import clock
from dma import REQ_USART1_RX, REQ_USART1_TX
from linebench import UartLine
from regs import Block

CR1, CR2, CR3, BRR, RQR, ISR, ICR, RDR, TDR = 0x00, 0x04, 0x08, 0x0C, 0x18, 0x1C, 0x20, 0x24, 0x28
IRQ = 27


class Usart(Block, UartLine):
    name = "USART1"

    def __init__(self, chip=None):
        super().__init__(chip)
        self.rx_fifo = deque()
        self.incoming = deque()      # (arrival cycle, byte), in order
        self.flags = 0               # PE FE NE ORE IDLE bits
        self.idle_at = None          # cycle at which IDLE gets set
        self.tx_queue = deque()      # bytes in TDR/TXFIFO + the shift register
        self.tx_done_at = None       # cycle the byte in the shift register finishes
        self.sent = []               # (cycle, byte) transmitted, taken by the bench
        self.received = 0            # characters that reached RDR/FIFO
        self.lost = 0                # characters lost to an overrun
        self.now = 0

    # ---- configuration -----------------------------------------------------------------------
    def cr1(self):
        return self.regs.get(CR1, 0)

    def depth(self):
        return 8 if self.cr1() >> 29 & 1 else 1

    def tx_capacity(self):
        return self.depth() + 1  # FIFO/TDR plus the shift register

    def enabled(self, bit):
        return self.cr1() & 1 and self.cr1() >> bit & 1

    # ---- the line ----------------------------------------------------------------------------
    def _receive(self, at, byte):
        if not self.enabled(2):  # RE
            return
        if len(self.rx_fifo) >= self.depth():
            self.flags |= 1 << 3  # ORE: the character is lost
            self.lost += 1
        else:
            self.rx_fifo.append(byte)
            self.received += 1
            self._serve_rx_dma()
        self.idle_at = at + clock.char_time(1)

    def _serve_rx_dma(self):
        if not self.regs.get(CR3, 0) >> 6 & 1:  # DMAR
            return
        dma = self.chip.dma
        while self.rx_fifo and dma.request(REQ_USART1_RX, read_peripheral=self.rx_fifo.popleft):
            pass

    def _serve_tx_dma(self):
        if not (self.regs.get(CR3, 0) >> 7 & 1 and self.enabled(3)):  # DMAT, TE
            return
        while len(self.tx_queue) < self.tx_capacity():
            if not self.chip.dma.request(REQ_USART1_TX, write_peripheral=self._push_tx):
                break

    def _push_tx(self, value):
        if not self.enabled(3):
            return
        if len(self.tx_queue) < self.tx_capacity():
            self.tx_queue.append(value & 0xFF)
            if self.tx_done_at is None:
                self.tx_done_at = self.now + clock.char_time(1)

    def advance(self, now):
        while True:
            t_rx = self.incoming[0][0] if self.incoming else None
            t_tx = self.tx_done_at
            t_idle = self.idle_at
            t = min((x for x in (t_rx, t_tx, t_idle) if x is not None), default=None)
            if t is None or t > now:
                break
            self.now = t
            if t == t_rx:
                at, byte = self.incoming.popleft()
                self._receive(at, byte)
            elif t == t_tx:
                self.sent.append((t, self.tx_queue.popleft()))
                self.tx_done_at = t + clock.char_time(1) if self.tx_queue else None
                self._serve_tx_dma()
            else:
                self.idle_at = None
                # Not idle if the next character's start bit began before this instant.
                if not (self.incoming and self.incoming[0][0] - clock.char_time(1) < t):
                    self.flags |= 1 << 4
        self.now = now
        self._serve_rx_dma()
        self._serve_tx_dma()

    def next_event(self):
        times = [t for t in (self.incoming[0][0] if self.incoming else None, self.tx_done_at,
                             self.idle_at) if t is not None]
        return min(times) if times else None

    # ---- registers ---------------------------------------------------------------------------
    def isr(self):
        value = self.flags
        if self.rx_fifo:
            value |= 1 << 5
        if len(self.rx_fifo) >= 8 and self.depth() == 8:
            value |= 1 << 24
        if self.enabled(3):
            if len(self.tx_queue) < self.tx_capacity():
                value |= 1 << 7
            if not self.tx_queue:
                value |= (1 << 6) | (1 << 23)
        else:
            value |= (1 << 6) | (1 << 7) | (1 << 23)
        if self.enabled(3):
            value |= 1 << 21
        if self.enabled(2):
            value |= 1 << 22
        return value

    def irqs(self):
        cr1 = self.regs.get(CR1, 0)
        if not cr1 & 1:
            return ()
        tx_on = cr1 >> 3 & 1
        hit = ((cr1 >> 4 & 1 and self.flags >> 4 & 1)                          # IDLE
               or (cr1 >> 5 & 1 and self.rx_fifo)                               # RXNE
               or (cr1 >> 6 & 1 and (not tx_on or not self.tx_queue))           # TC
               or (cr1 >> 7 & 1 and (not tx_on or len(self.tx_queue) < self.tx_capacity()))
               or (self.regs.get(CR3, 0) & 1 and self.flags & 0xE)              # ORE, FE, NE
               or (cr1 >> 8 & 1 and self.flags & 1))                            # PE
        return (IRQ,) if hit else ()

    def read_reg(self, offset):
        if offset == ISR:
            return self.isr()
        if offset == RDR:
            return self.rx_fifo.popleft() if self.rx_fifo else 0
        if offset in (ICR, RQR, TDR):
            return 0
        return super().read_reg(offset)

    def write_reg(self, offset, value, mask):
        value &= mask
        if offset == ICR:
            self.flags &= ~(value & 0x1F)
            if value & (1 << 6):
                pass  # TC follows the transmit queue
        elif offset == TDR:
            self._push_tx(value)
        elif offset == RQR:
            if value & (1 << 3):  # RXFRQ: flush
                self.rx_fifo.clear()
        elif offset == ISR:
            pass
        else:
            super().write_reg(offset, value, mask)
            if offset == CR1 and not self.cr1() & 1:
                self.rx_fifo.clear()
                self.tx_queue.clear()
                self.tx_done_at = None
        self._serve_rx_dma()
        self._serve_tx_dma()
        if self.chip:
            self.chip.reschedule(self)
