"""The timers, counting virtual time: in the `g071` build TIM2 (0x40000000) is embassy-time's
driver and TIM3 (0x40000400) the motors' PWM; in the `g071-n20` build TIM15 (0x40014000) is
embassy-time's driver, TIM14/TIM16/TIM17 (0x40002000/0x40014400/0x40014800) the motors' PWM and
TIM2, TIM3, TIM1 (0x40012C00) count the lanes' encoders. The registers this models sit at the
same offsets in every one of them (RM0444 §20-§23: TIM1, TIM2/3, TIM14, TIM15/16/17).

RM0444 §22.4 (TIM2/TIM3 registers): CR1 0x00 (CEN 0, URS 2, ARPE 7), DIER 0x0C (UIE 0, CCxIE
1-4), SR 0x10 (UIF 0, CCxIF 1-4; rc_w0: writing 0 clears, 1 leaves), EGR 0x14 (UG 0: the counter
restarts at 0 and the prescaler and auto-reload take their preload values; UIF is set unless
URS = 1, §22.3.2), CCMR1/2 0x18/0x1C (OCxM), CCER 0x20 (CCxE at 4(x-1)), CNT 0x24, PSC 0x28, ARR
0x2C, CCR1-4 0x34-0x40.
Counting (§22.3.2, upcounting): the counter clock is the timer kernel clock (64 MHz) / (PSC + 1);
the counter counts 0..ARR and overflows to 0, setting UIF (the update event). Output compare
(§22.3.10): CCxIF is set when the counter equals CCRx.
The counter is computed from virtual time, never ticked: CNT = (start + ticks) mod (ARR + 1).
Encoder mode (§22.3.19; SMCR 0x08, SMS [16, 2:0] = 001, 010 or 011): the counter is the lane's
encoder count the bench sets (`encoder_count`, from the simulator's motion sample), shifted by
what the firmware last wrote to CNT; it counts only while CEN is set.
Left out: down/center-aligned counting, one-pulse mode, the other slave modes, input capture
filters and prescalers (the bench gives the count, not the edges), DMA requests,
the ARR preload (ARPE: ARR applies at once), the prescaler's preload only at UG (the
time driver writes PSC then UG, which this does).
PWM (§22.3.11): the duty of channel x is CCRx / (ARR + 1) in PWM mode 1 (OCxM 110), its complement
in PWM mode 2 (111), 100 % forced active (101), 0 forced inactive (100); 0 with CCxE clear.
"""

from regs import Block

CR1, SMCR, DIER, SR, EGR, CCMR1, CCMR2, CCER, CNT, PSC, ARR = (0x00, 0x08, 0x0C, 0x10, 0x14, 0x18,
                                                               0x1C, 0x20, 0x24, 0x28, 0x2C)
ENCODER_MODES = (1, 2, 3)  # SMS: encoder mode 1 (TI1), 2 (TI2), 3 (both)
CCR = (0x34, 0x38, 0x3C, 0x40)


class Timer(Block):
    name = "TIM"

    def __init__(self, chip=None, irq=None, bits=16):
        super().__init__(chip)
        self.irq = irq
        self.top = (1 << bits) - 1
        self.regs[ARR] = self.top
        self.psc = 0          # the prescaler in use (PSC's preload applies at an update)
        self.start_cnt = 0    # counter value at start_time
        self.start_time = 0   # cycle the count started from (a tick boundary)
        self.synced = 0       # ticks since start_time already scanned for flags
        self.now = 0
        self._due = None      # cached: tick of the next flag to set (None: none / stopped)
        self._next = None     # cached: cycle of the next flag with its interrupt enabled
        self._dirty = True
        self.encoder_count = 0  # the lane's count the bench sets, used in encoder mode
        self.encoder_shift = 0  # CNT written by the firmware less the count at that moment

    # ---- counting ----------------------------------------------------------------------------
    def running(self):
        return self.regs.get(CR1, 0) & 1

    def period(self):
        return (self.regs[ARR] & self.top) + 1

    def encoder_mode(self):
        smcr = self.regs.get(SMCR, 0)
        return ((smcr & 7) | ((smcr >> 13) & 8)) in ENCODER_MODES

    def counter(self):
        if not self.regs.get(CR1, 0) & 1:
            return self.start_cnt
        if self.encoder_mode():
            return (self.encoder_count + self.encoder_shift) % self.period()
        ticks = (self.now - self.start_time) // (self.psc + 1)
        return (self.start_cnt + ticks) % ((self.regs[ARR] & self.top) + 1)

    def rebase(self, cnt):
        self.start_cnt = cnt
        self.start_time = self.now
        self.synced = 0
        self._dirty = True

    def _first_match(self, after, value):
        """The first tick k > after at which the counter equals `value`."""
        p = self.period()
        return after + 1 + ((value - (self.start_cnt + after + 1)) % p)

    def _sources(self):
        """(flag bit, counter value that sets it) of the update and compare events."""
        out = [(0, 0)]
        p = self.period()
        for ch in range(4):
            ccr = self.regs.get(CCR[ch], 0)
            if ccr < p:
                out.append((ch + 1, ccr))
        return out

    def _plan(self):
        """Recomputes the tick of the next flag to set, and the cycle of the next one that can
        raise the interrupt."""
        self._dirty = False
        self._due = self._next = None
        if not self.running():
            return
        sr = self.regs.get(SR, 0)
        dier = self.regs.get(DIER, 0)
        irq_tick = None
        for flag, value in self._sources():
            if not (sr >> flag) & 1:
                k = self._first_match(self.synced, value)
                if self._due is None or k < self._due:
                    self._due = k
                if (dier >> flag) & 1 and (irq_tick is None or k < irq_tick):
                    irq_tick = k
        if irq_tick is not None:
            self._next = self.start_time + irq_tick * (self.psc + 1)

    def _scan(self):
        """Sets the flags of the events between the last scan and now."""
        if self._dirty:
            self._plan()
        if self._due is None:
            return
        t = (self.now - self.start_time) // (self.psc + 1)
        if t < self._due:
            return
        sr = self.regs.get(SR, 0)
        for flag, value in self._sources():
            if not (sr >> flag) & 1 and self._first_match(self.synced, value) <= t:
                sr |= 1 << flag
        self.regs[SR] = sr
        self.synced = t
        self._plan()

    def advance(self, now):
        self.now = now
        if self.regs.get(DIER, 0) & 0x1F:
            self._scan()

    def next_event(self):
        if self.irq is None or not self.regs.get(DIER, 0) & 0x1F:
            return None
        if self._dirty:
            self._plan()
        return self._next

    def irqs(self):
        if self.irq is not None and self.regs.get(SR, 0) & self.regs.get(DIER, 0) & 0x1F:
            return (self.irq,)
        return ()

    # ---- registers ---------------------------------------------------------------------------
    def read_reg(self, offset):
        if offset == CNT:
            return self.counter()
        if offset == SR:
            self._scan()
        return super().read_reg(offset)

    def write_reg(self, offset, value, mask):
        self._scan()
        if offset == CR1:
            was = self.running()
            cnt = self.counter()
            super().write_reg(offset, value, mask)
            if was != self.running():
                self.rebase(cnt)
                if self.encoder_mode():
                    self.encoder_shift = cnt - self.encoder_count
        elif offset == SR:
            # rc_w0
            self.regs[SR] = self.regs.get(SR, 0) & (value | ~mask)
        elif offset == EGR:
            if value & 1:  # UG
                self.psc = self.regs.get(PSC, 0) & 0xFFFF
                self.rebase(0)
                if not (self.regs.get(CR1, 0) >> 2) & 1:
                    self.regs[SR] = self.regs.get(SR, 0) | 1
        elif offset == CNT:
            super().write_reg(offset, value, mask)
            self.rebase(self.regs[CNT] & self.top)
            self.encoder_shift = (self.regs[CNT] & self.top) - self.encoder_count
        elif offset == ARR:
            cnt = self.counter()
            super().write_reg(offset, value, mask)
            self.rebase(cnt % self.period())
        else:
            super().write_reg(offset, value, mask)
        self._dirty = True
        if self.chip and self.irq is not None and offset in (CR1, DIER, EGR, CNT, ARR) + CCR:
            self.chip.reschedule(self)

    # ---- PWM ---------------------------------------------------------------------------------
    def duty_permille(self, ch):
        """Duty of channel ch (0-based) in per mille."""
        if not (self.regs.get(CCER, 0) >> (4 * ch)) & 1:
            return 0
        ccmr = self.regs.get(CCMR1 if ch < 2 else CCMR2, 0)
        shift = 8 * (ch % 2)
        mode = ((ccmr >> (shift + 4)) & 7) | (((ccmr >> (shift + 16)) & 1) << 3)
        ccr = self.regs.get(CCR[ch], 0)
        high = min(1000, ccr * 1000 // self.period())
        if mode == 6:
            return high
        if mode == 7:
            return 1000 - high
        if mode == 5:
            return 1000
        return 0
