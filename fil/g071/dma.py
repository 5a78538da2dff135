"""DMA1 (0x40020000, 7 channels) and DMAMUX (0x40020800): the transfers that move the printer
UART's received bytes into the firmware's ring, the UART's transmit bytes out of RAM, and the ADC's
conversions into the scan buffer. A transfer happens when the peripheral raises its request (the
models call `request(id)` at the virtual time the datum is ready), so the DMA keeps working while
the CPU sleeps or is stalled by a flash erase.

RM0444 §10.6 (DMA registers): ISR 0x00 (per channel x, bits 4(x-1)+: GIF, TCIF, HTIF, TEIF),
IFCR 0x04 (write 1 to clear, same layout), and per channel x at 0x08 + 20(x-1): CCR (EN 0, TCIE
1, HTIE 2, TEIE 3, DIR 4 (1: memory to peripheral), CIRC 5, PINC 6, MINC 7, PSIZE [9:8], MSIZE
[11:10], MEM2MEM 14), CNDTR (+4), CPAR (+8), CMAR (+12).
§10.4.4-10.4.6: each request moves one datum, CNDTR counts down, HTIF is set at half the count,
TCIF when it reaches 0; in circular mode CNDTR reloads its programmed value and the addresses
restart from CPAR/CMAR; otherwise the channel stops transferring (EN stays set). Writing CNDTR,
CPAR, CMAR takes effect when the channel is enabled (the current addresses are internal).
RM0444 §11.3.2, Table 59 (DMAMUX requests on the G071): ADC 5, USART1_RX 50, USART1_TX 51. DMAMUX
CxCR (0x00 + 4(x-1)) DMAREQ_ID [6:0] routes request lines to channel x.
Interrupt lines (RM0444 §12.3, Table 54): channel 1 -> IRQ 9, channels 2-3 -> IRQ 10, channels
4-7 (and DMAMUX) -> IRQ 11.
Left out: memory-to-memory, the priority between channels (requests are served as they come),
the bus timing of a transfer (instantaneous), transfer errors (an access outside memory raises
TEIF and disables the channel).
"""

from regs import Block

REQ_ADC, REQ_USART1_RX, REQ_USART1_TX = 5, 50, 51
IRQ_OF_CHANNEL = {1: 9, 2: 10, 3: 10, 4: 11, 5: 11, 6: 11, 7: 11}


class Channel:
    def __init__(self, n):
        self.n = n
        self.ccr = self.cndtr = self.cpar = self.cmar = 0
        self.remaining = 0
        self.par = self.mar = 0


class Dma(Block):
    name = "DMA1"

    def __init__(self, chip=None):
        super().__init__(chip)
        self.ch = {n: Channel(n) for n in range(1, 8)}
        self.isr = 0
        self.mux = {n: 0 for n in range(1, 8)}
        self.transfers = 0  # data moved, for tests

    # ---- registers ---------------------------------------------------------------------------
    def _channel_reg(self, offset):
        if 0x08 <= offset < 0x08 + 20 * 7:
            n, r = divmod(offset - 0x08, 20)
            return self.ch[n + 1], r
        return None, None

    def read_reg(self, offset):
        if offset == 0x00:
            return self.isr
        if offset == 0x04:
            return 0
        c, r = self._channel_reg(offset)
        if c:
            return {0: c.ccr, 4: c.remaining if c.ccr & 1 else c.cndtr, 8: c.cpar, 12: c.cmar}.get(r, 0)
        return 0

    def write_reg(self, offset, value, mask):
        value &= mask
        if offset == 0x04:
            clear = value
            for n in range(1, 8):  # CGIFx clears the channel's every flag
                if clear >> (4 * (n - 1)) & 1:
                    clear |= 0xF << (4 * (n - 1))
            self.isr &= ~clear
        else:
            c, r = self._channel_reg(offset)
            if c is None:
                return
            if r == 0:
                was = c.ccr & 1
                c.ccr = value & 0x7FFF
                if c.ccr & 1 and not was:
                    c.remaining = c.cndtr
                    c.par, c.mar = c.cpar, c.cmar
            elif r == 4:
                c.cndtr = value & 0xFFFF
                if not c.ccr & 1:
                    c.remaining = c.cndtr
            elif r == 8:
                c.cpar = value
            elif r == 12:
                c.cmar = value
        self._update_gif()
        if self.chip and offset != 0x04 and (offset - 0x08) % 20 == 0:  # a CCR
            self.chip.reschedule(self)

    def _update_gif(self):
        for n in range(1, 8):
            s = 4 * (n - 1)
            if self.isr >> s & 0xE:
                self.isr |= 1 << s
            else:
                self.isr &= ~(1 << s)

    def irqs(self):
        lines = set()
        for n, c in self.ch.items():
            flags = (self.isr >> (4 * (n - 1))) & 0xE
            if flags & (c.ccr & 0xE):
                lines.add(IRQ_OF_CHANNEL[n])
        return lines

    # ---- transfers ---------------------------------------------------------------------------
    def channel_for(self, request):
        """The enabled channel serving `request` with data left to move, or None."""
        for n in range(1, 8):
            c = self.ch[n]
            if self.mux[n] == request and c.ccr & 1 and c.remaining:
                return c
        return None

    def request(self, request, read_peripheral=None, write_peripheral=None):
        """One datum for a request line. For a peripheral-to-memory channel `read_peripheral()`
        gives the datum; for memory-to-peripheral `write_peripheral(value)` takes it. Returns
        True if a channel moved a datum."""
        c = self.channel_for(request)
        if c is None:
            return False
        psize = 1 << ((c.ccr >> 8) & 3)
        msize = 1 << ((c.ccr >> 10) & 3)
        mem = self.chip.memory
        try:
            if c.ccr & (1 << 4):  # memory to peripheral
                value = int.from_bytes(mem.read(c.mar, msize), "little")
                write_peripheral(value & ((1 << (8 * psize)) - 1))
            else:
                value = read_peripheral()
                mem.write(c.mar, (value & ((1 << (8 * msize)) - 1)).to_bytes(msize, "little"))
        except MemoryError:
            self.isr |= 0x8 << (4 * (c.n - 1))
            c.ccr &= ~1
            self._update_gif()
            return False
        self.transfers += 1
        if c.ccr & (1 << 6):
            c.par += psize
        if c.ccr & (1 << 7):
            c.mar += msize
        c.remaining -= 1
        s = 4 * (c.n - 1)
        if c.remaining == c.cndtr // 2:
            self.isr |= 0x4 << s
        if c.remaining == 0:
            self.isr |= 0x2 << s
            if c.ccr & (1 << 5):
                c.remaining = c.cndtr
                c.par, c.mar = c.cpar, c.cmar
        self._update_gif()
        return True


class DmaMux(Block):
    """DMAMUX CxCR registers, channel x of DMA1 at offset 4(x-1)."""
    name = "DMAMUX"

    def __init__(self, chip=None, dma=None):
        super().__init__(chip)
        self.dma = dma

    def write_reg(self, offset, value, mask):
        super().write_reg(offset, value, mask)
        if offset < 0x1C and self.dma:
            self.dma.mux[offset // 4 + 1] = self.regs[offset] & 0x7F
