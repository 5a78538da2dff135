"""ADC1 (0x4001_2400): calibration, and the endless scan of the regular sequence into DMA1
channel 1, each conversion at its virtual time. The bench sets each channel's level.

Register layout and bits from ch32-metapac 0.1.2 `adc_v3` (WCH's SVD; the STM32F103's ADC):
STATR 0x00 (EOC 1, STRT 4), CTLR1 0x04 (SCAN 8), CTLR2 0x08 (ADON 0, CONT 1, CAL 2, RSTCAL 3,
DMA 8, EXTSEL [19:17] (111 SWSTART), EXTTRIG 20, SWSTART 22), SAMPTR1 0x0C (channels 10-17) and
SAMPTR2 0x10 (channels 0-9), 3 bits a channel: 1.5, 7.5, 13.5, 28.5, 41.5, 55.5, 71.5, 239.5
cycles; RSQR1 0x2C (L [23:20]: L + 1 conversions; SQ13-16), RSQR2 0x30 (SQ7-12), RSQR3 0x34
(SQ1-6), 5 bits each; RDATAR 0x4C.
- RSTCAL and CAL clear themselves at once (the image waits for them).
- SWSTART with ADON, EXTTRIG and EXTSEL = SWSTART starts the regular sequence: the channels of
  SQ1..SQ(L+1) in that order with SCAN (only SQ1 without); with CONT it starts again at once.
  A conversion takes (sampling + 12.5) ADC clocks, the ADC clock PCLK2 / ADCPRE (RCC,
  rcc.py): with the image's settings 239.5 + 12.5 cycles at 12 MHz, 21 us; a round of eight
  168 us (src/board/bmcu/sensors.rs).
- With CTLR2.DMA each result goes to DMA1 channel 1 (the ADC1 request, sensors.rs), which
  clears EOC. Conversions nobody can observe in between (no interrupt enabled, the results
  going to a circular DMA buffer of whole rounds) are carried out lazily when something looks
  (a slice boundary, a DMA register access); when many rounds have passed only the last two
  are converted and the DMA channel's position moved past the others (`Dma1.skip`), which leaves
  the same memory and counters.
Left out: injected channels, the analog watchdog, external triggers other than SWSTART, dual
mode (ADC2 is not modelled: the image uses ADC1 alone), interrupts, the temperature sensor and
VREFINT (read 0), noise (the bench passes the simulator's levels as they are).
"""

from regs import Block

STATR, CTLR1, CTLR2, SAMPTR1, SAMPTR2, RSQR1, RSQR2, RSQR3, RDATAR = (0x00, 0x04, 0x08, 0x0C,
                                                                      0x10, 0x2C, 0x30, 0x34, 0x4C)
ADON, CONT, CAL, RSTCAL, DMA, SWSTART = 1, 1 << 1, 1 << 2, 1 << 3, 1 << 8, 1 << 22
EXTTRIG, EXTSEL_SWSTART = 1 << 20, 7 << 17
EOC, STRT = 1 << 1, 1 << 4
SAMPLE_HALF_CYCLES = (3, 15, 27, 57, 83, 111, 143, 479)  # 1.5 .. 239.5 cycles, doubled
REQUEST = 1  # DMA1 channel 1


class Adc(Block):
    name = "ADC1"

    def __init__(self, chip=None):
        super().__init__(chip)
        self.statr = 0
        self.levels = {}           # channel -> 12-bit level from the bench
        self.position = 0          # index in the sequence of the conversion under way
        self.next_at = None        # cycle the conversion under way completes
        self.conversions = 0

    # ---- the sequence ------------------------------------------------------------------------
    def sequence(self):
        length = (self.regs.get(RSQR1, 0) >> 20 & 0xF) + 1 if self.regs.get(CTLR1, 0) >> 8 & 1 else 1
        slots = []
        for i in range(length):
            reg, shift = (RSQR3, 5 * i) if i < 6 else (RSQR2, 5 * (i - 6)) if i < 12 else (RSQR1, 5 * (i - 12))
            slots.append(self.regs.get(reg, 0) >> shift & 0x1F)
        return slots

    def conversion_cycles(self, channel):
        reg, shift = (SAMPTR2, 3 * channel) if channel < 10 else (SAMPTR1, 3 * (channel - 10))
        half_cycles = SAMPLE_HALF_CYCLES[self.regs.get(reg, 0) >> shift & 7] + 25
        chip = self.chip
        adc_hz = chip.rcc.adc_clock() if chip is not None and hasattr(chip, "rcc") else 12_000_000
        hz = chip.hz if chip is not None and hasattr(chip, "hz") else 120_000_000
        return half_cycles * hz // (2 * max(adc_hz, 1))

    def _convert(self, at):
        seq = self.sequence()
        channel = seq[self.position % len(seq)]
        value = self.levels.get(channel, 0) & 0xFFF
        self.conversions += 1
        self.regs[RDATAR] = value
        self.statr |= EOC
        if self.regs.get(CTLR2, 0) & DMA and self.chip is not None:
            if self.chip.dma.request(REQUEST, read_peripheral=self._dma_read):
                pass
        self.position += 1
        if self.position >= len(seq):
            self.position = 0
            if not self.regs.get(CTLR2, 0) & CONT:
                self.next_at = None
                self.statr &= ~STRT
                return
        self.next_at = at + self.conversion_cycles(seq[self.position])

    def _dma_read(self):
        self.statr &= ~EOC
        return self.regs.get(RDATAR, 0)

    def _round_cycles(self, seq):
        return sum(self.conversion_cycles(c) for c in seq)

    def advance(self, now):
        if self.next_at is None or self.next_at > now:
            return
        seq = self.sequence()
        if self.regs.get(CTLR2, 0) & CONT and self.position == 0:
            period = self._round_cycles(seq)
            rounds = (now - self.next_at) // period - 1 if period else 0
            if rounds > 0 and self.chip is not None and self.regs.get(CTLR2, 0) & DMA:
                self.chip.dma.skip(REQUEST, rounds * len(seq))
                self.conversions += rounds * len(seq)
                self.next_at += rounds * period
        while self.next_at is not None and self.next_at <= now:
            self._convert(self.next_at)

    def next_event(self):
        return None  # no ADC or DMA interrupt is enabled by the image: see the module's notes

    # ---- registers ---------------------------------------------------------------------------
    def read_reg(self, offset):
        if offset == STATR:
            return self.statr
        if offset == RDATAR:
            self.statr &= ~EOC
            return self.regs.get(RDATAR, 0)
        return super().read_reg(offset)

    def write_reg(self, offset, value, mask):
        value &= mask
        if offset == STATR:
            self.statr &= value | ~0x1F
            return
        old = self.regs.get(CTLR2, 0)
        super().write_reg(offset, value, mask)
        if offset != CTLR2:
            return
        ctlr2 = self.regs[CTLR2] & ~(CAL | RSTCAL)  # calibration: done at once
        if not ctlr2 & ADON:
            self.next_at = None
            self.statr &= ~STRT
        start = (ctlr2 & SWSTART and ctlr2 & ADON and old & ADON and ctlr2 & EXTTRIG
                 and ctlr2 & EXTSEL_SWSTART == EXTSEL_SWSTART)
        self.regs[CTLR2] = ctlr2 & ~SWSTART
        if start and self.next_at is None:
            self.position = 0
            self.statr |= STRT
            now = self.chip.now() if self.chip is not None else 0
            self.next_at = now + self.conversion_cycles(self.sequence()[0])
