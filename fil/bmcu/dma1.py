"""DMA1 (0x4002_0000) of the CH32V203: fil/g071's DMA model, whose STM32G0 register layout the
CH32V20x's DMA1 shares (INTFR 0x00, INTFCR 0x04, per channel n at 0x08 + 20 (n - 1): CFGR,
CNTR, PADDR, MADDR; CFGR's EN, TCIE, HTIE, TEIE, DIR, CIRC, PINC, MINC, PSIZE, MSIZE, PL,
MEM2MEM at the same bits: ch32-metapac 0.1.2 `dma_v1`), without the G0's DMAMUX: on the
CH32V20x a peripheral's request goes to a fixed channel (the STM32F103's map, which the chip
copies: ADC1 -> channel 1, USART3_TX -> channel 2, USART3_RX -> channel 3; src/board/bmcu/
sensors.rs and uart.rs name the same). A request is named here by its channel's number.
Interrupt lines: channel n -> interrupt 26 + n (DMA1_CHANNEL1 = 27 ... DMA1_CHANNEL7 = 33,
ch32-metapac's `Interrupt`).
"""

from dma import Dma

ADC1, USART3_TX, USART3_RX = 1, 2, 3


class Dma1(Dma):
    name = "DMA1"

    def __init__(self, chip=None):
        super().__init__(chip)
        self.mux = {n: n for n in self.ch}

    def irqs(self):
        lines = set()
        for n, c in self.ch.items():
            if (self.isr >> (4 * (n - 1))) & 0xE & (c.ccr & 0xE):
                lines.add(26 + n)
        return lines

    def skip(self, request, count):
        """Moves `count` data of `request` through its circular channel without writing them
        (the ADC's lazy conversions, adc.py): the channel's position and flags end as if they
        had been moved. Whole laps of the buffer leave the memory as it is."""
        c = self.channel_for(request)
        if c is None or not c.ccr & (1 << 5) or not c.cndtr:
            return
        laps, rest = divmod(count, c.cndtr)
        s = 4 * (c.n - 1)
        if laps:
            self.isr |= 0x6 << s
        for _ in range(rest):
            step = 1 << ((c.ccr >> 8) & 3) if c.ccr & (1 << 6) else 0
            mstep = 1 << ((c.ccr >> 10) & 3) if c.ccr & (1 << 7) else 0
            c.par += step
            c.mar += mstep
            c.remaining -= 1
            if c.remaining == c.cndtr // 2:
                self.isr |= 0x4 << s
            if c.remaining == 0:
                self.isr |= 0x2 << s
                c.remaining = c.cndtr
                c.par, c.mar = c.cpar, c.cmar
        self.transfers += count
        self._update_gif()
