"""TIM2, TIM3 and TIM4 (0x4000_0000, 0x4000_0400, 0x4000_0800) as the bridges' PWM: fil/g071's
timer model, whose registers the CH32V20x's general-purpose timers have at the same offsets
(CTLR1 0x00 CEN 0, ARPE 7; SMCFGR 0x08; DMAINTENR 0x0C; INTFR 0x10; SWEVGR 0x14 UG 0; CHCTLR1/2
0x18/0x1C OCxM [6:4] and [14:12]; CCER 0x20 CCxE at 4(x-1); CNT 0x24; PSC 0x28; ATRLR 0x2C;
CH1CVR-CH4CVR 0x34-0x40: ch32-metapac 0.1.2 `timer_v3`). The counting clock does not enter a
duty (a share of the period).
- Duty (PWM mode 1, OCxM 110: the output is high while CNT < CHxCVR): CHxCVR / (ATRLR + 1), 100 %
  when CHxCVR > ATRLR (the image's brake, src/board/bmcu/motors.rs); mode 2 its complement; 0
  with CCxE clear. With CEN clear the counter stands: the output is the level the standing count
  gives, 0 % or 100 %.
- The preloads (ARPE, OCxPE, which the image sets): a new CHxCVR or ATRLR takes effect at the
  next update event, within a PWM period (50 us at 20 kHz); the bench applies it at once, well
  within the 1 ms the bench reports at.
Left out: everything but PWM output (the timers raise no interrupt the image enables),
center-aligned modes, the break and dead time (general-purpose timers have none).
"""

from timers import CCER, CCMR1, CCMR2, CCR, CR1, Timer


class PwmTimer(Timer):
    name = "TIM"

    def duty_permille(self, ch):
        duty = super().duty_permille(ch)
        if self.regs.get(CR1, 0) & 1 or not self.regs.get(CCER, 0) >> (4 * ch) & 1:
            return duty
        mode = self.regs.get(CCMR1 if ch < 2 else CCMR2, 0) >> (8 * (ch % 2) + 4) & 7
        high = self.counter() < self.regs.get(CCR[ch], 0)
        if mode == 6:
            return 1000 if high else 0
        if mode == 7:
            return 0 if high else 1000
        return duty
