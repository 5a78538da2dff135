"""The ADC (0x40012400): regulator, calibration, enable, and the scan of the selected channels,
each conversion delivered at its virtual time (sampling + 12.5 ADC clock cycles, times the
oversampling ratio) to DR and, with DMAEN, to the DMA. The bench sets each channel's level.

RM0444 §15.12 (ADC registers): ISR 0x00 (ADRDY 0, EOSMP 1, EOC 2, EOS 3, OVR 4, EOCAL 11,
CCRDY 13), IER 0x04, CR 0x08 (ADEN 0, ADDIS 1, ADSTART 2, ADSTP 4, ADVREGEN 28, ADCAL 31), CFGR1
0x0C (DMAEN 0, DMACFG 1, SCANDIR 2, OVRMOD 12, CONT 13, DISCEN 16, CHSELRMOD 21), CFGR2 0x10 (OVSE
0, OVSR [4:2], OVSS [8:5], CKMODE [31:30]), SMPR 0x14 (SMP1 [2:0], SMP2 [6:4], SMPSELx [8+x]),
CHSELR 0x28, DR 0x40, CCR 0x308 (PRESC [21:18]).
- §15.3.8/15.3.9: ADCAL completes (the bench: at once) and EOCAL is set; ADEN sets ADRDY.
- §15.4.1 (CHSELRMOD = 0): the channels whose CHSELR bit is set are converted in ascending order
  (descending with SCANDIR); EOC after each, EOS after the last; with CONT the sequence restarts,
  otherwise ADSTART clears. ADSTP stops and clears ADSTART.
- §15.6 (timing): t_conv = (sampling time + 12.5) ADC clock cycles; the ADC clock is the kernel
  clock (RCC_CCIPR ADCSEL: the image selects SYSCLK, 64 MHz) / the CCR prescaler with CKMODE = 0,
  or PCLK / 2 or / 4 or / 1 with CKMODE 1, 2, 3.
- §15.10 (oversampling): OVSE: each result sums 2^(OVSR+1) conversions, shifted right by OVSS.
- §15.5.5 (DMA): with DMAEN each result is read by the DMA (request 5), clearing EOC; in one-shot
  DMA mode (DMACFG 0) requests stop once the DMA channel has moved its last datum. A result that
  finds EOC still set sets OVR (and with OVRMOD = 0 DR keeps the old result).
Left out: the analog watchdogs, external triggers (software start only), discontinuous mode,
wait/auto-off modes, the internal channels' values (temperature, VREFINT read 0 unless set).
"""

from dma import REQ_ADC
from regs import Block

ISR, IER, CR, CFGR1, CFGR2, SMPR, CHSELR, DR, CCR = (0x00, 0x04, 0x08, 0x0C, 0x10, 0x14, 0x28,
                                                    0x40, 0x308)
SAMPLE_HALF_CYCLES = (3, 7, 15, 25, 39, 79, 159, 321)  # 1.5 .. 160.5 cycles, doubled
PRESC = (1, 2, 4, 6, 8, 10, 12, 16, 32, 64, 128, 256)
IRQ = 12  # ADC_COMP


class Adc(Block):
    name = "ADC"

    def __init__(self, chip=None):
        super().__init__(chip)
        self.isr = 0
        self.levels = {}           # channel -> 12-bit level from the bench
        self.sequence = []         # channels left in the current sequence
        self.next_at = None        # cycle the current conversion completes
        self.dma_done = False      # one-shot DMA finished
        self.conversions = 0

    def cr(self):
        return self.regs.get(CR, 0)

    # ---- timing ------------------------------------------------------------------------------
    def adc_clock_hz(self):
        ckmode = self.regs.get(CFGR2, 0) >> 30
        if ckmode == 0:
            presc = (self.regs.get(CCR, 0) >> 18) & 0xF
            return 64_000_000 // PRESC[min(presc, 11)]
        return 64_000_000 // {1: 2, 2: 4, 3: 1}[ckmode]

    def conversion_cycles(self, channel):
        smpr = self.regs.get(SMPR, 0)
        code = (smpr >> 4) & 7 if smpr >> (8 + channel) & 1 else smpr & 7
        half_cycles = SAMPLE_HALF_CYCLES[code] + 25
        cfgr2 = self.regs.get(CFGR2, 0)
        ratio = 1 << (((cfgr2 >> 2) & 7) + 1) if cfgr2 & 1 else 1
        return half_cycles * ratio * 64_000_000 // (2 * self.adc_clock_hz())

    def _channels(self):
        sel = self.regs.get(CHSELR, 0) & 0x7FFFF
        chans = [c for c in range(19) if sel >> c & 1]
        if self.regs.get(CFGR1, 0) >> 2 & 1:
            chans.reverse()
        return chans

    def _start(self, now):
        self.sequence = self._channels()
        self.dma_done = False
        self.next_at = now + self.conversion_cycles(self.sequence[0]) if self.sequence else None

    def _result(self, channel):
        level = self.levels.get(channel, 0) & 0xFFF
        cfgr2 = self.regs.get(CFGR2, 0)
        if cfgr2 & 1:
            n = 1 << (((cfgr2 >> 2) & 7) + 1)
            return min(0xFFFF, (level * n) >> ((cfgr2 >> 5) & 0xF))
        return level

    def _convert(self, now):
        channel = self.sequence.pop(0)
        value = self._result(channel)
        self.conversions += 1
        cfgr1 = self.regs.get(CFGR1, 0)
        if self.isr & (1 << 2):
            self.isr |= 1 << 4  # OVR
            if cfgr1 >> 12 & 1:
                self.regs[DR] = value
        else:
            self.regs[DR] = value
            self.isr |= 1 << 2
        if cfgr1 & 1 and not self.dma_done:
            if self.chip.dma.request(REQ_ADC, read_peripheral=self._dma_read):
                ch = self.chip.dma.channel_for(REQ_ADC)
                if ch is None and not cfgr1 >> 1 & 1:
                    self.dma_done = True
        if not self.sequence:
            self.isr |= 1 << 3  # EOS
            if cfgr1 >> 13 & 1:
                self.sequence = self._channels()
            else:
                self.regs[CR] = self.cr() & ~(1 << 2)
        self.next_at = now + self.conversion_cycles(self.sequence[0]) if self.sequence else None

    def _dma_read(self):
        self.isr &= ~(1 << 2)
        return self.regs.get(DR, 0)

    def advance(self, now):
        while self.next_at is not None and self.next_at <= now:
            self._convert(self.next_at)

    def next_event(self):
        """The next conversion that can raise an interrupt: any, with an ADC interrupt enabled;
        else the one that brings the DMA channel to its half/complete point when that channel
        has the matching interrupt enabled. Conversions in between are carried out lazily
        (`advance` runs before any access to the ADC or the DMA), which gives the same result
        since nothing else can observe them."""
        if self.next_at is None:
            return None
        if self.regs.get(IER, 0) & 0x3FFF:
            return self.next_at
        if not self.regs.get(CFGR1, 0) & 1 or self.dma_done:
            return None
        ch = self.chip.dma.channel_for(REQ_ADC) if self.chip else None
        if ch is None or not ch.ccr & 0x6:
            return None
        points = []
        if ch.ccr & 4 and ch.remaining > ch.cndtr // 2:
            points.append(ch.remaining - ch.cndtr // 2)
        if ch.ccr & 2:
            points.append(ch.remaining)
        n = min(points) if points else 1
        at, seq = self.next_at, list(self.sequence)
        cont = self.regs.get(CFGR1, 0) >> 13 & 1
        for _ in range(min(n, 256) - 1):
            seq.pop(0)
            if not seq:
                if not cont:
                    return at
                seq = self._channels()
            at += self.conversion_cycles(seq[0])
        return at

    def irqs(self):
        return (IRQ,) if self.isr & self.regs.get(IER, 0) & 0x3FFF else ()

    # ---- registers ---------------------------------------------------------------------------
    def read_reg(self, offset):
        if offset == ISR:
            return self.isr
        if offset == DR:
            self.isr &= ~(1 << 2)
            return self.regs.get(DR, 0)
        return super().read_reg(offset)

    def write_reg(self, offset, value, mask):
        value &= mask
        if offset == ISR:
            self.isr &= ~value
        elif offset == CR:
            cr = (self.cr() & ~mask) | value
            if cr >> 31 & 1:  # ADCAL: done at once
                cr &= ~(1 << 31)
                self.isr |= 1 << 11
            if cr & 2:  # ADDIS
                cr &= ~0x7
                self.sequence, self.next_at = [], None
            if cr & 1 and not self.cr() & 1:
                self.isr |= 1  # ADRDY
            if cr >> 4 & 1:  # ADSTP
                cr &= ~((1 << 4) | (1 << 2))
                self.sequence, self.next_at = [], None
            if cr >> 2 & 1 and not self.cr() >> 2 & 1 and cr & 1:
                self.regs[CR] = cr
                self._start(self.chip.now() if self.chip else 0)
            self.regs[CR] = cr
        else:
            super().write_reg(offset, value, mask)
        # Only a start (CR) or an interrupt enable (IER) can bring an earlier event or a line;
        # clearing flags and stopping cannot.
        if self.chip and offset in (CR, IER) and (offset == IER or self.next_at is not None):
            self.chip.reschedule(self)
