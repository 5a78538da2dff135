"""The PWM of TIM2-4 as the image sets it (20 kHz, PWM mode 1, a compare of the period for 100 %,
a stopped counter), each lane's AT8236 inputs as the bench reports them (pins, AF mode, AFIO's
remaps), and ADC1's scan: the RSQR order, 21 us a conversion with the image's
settings, DMA1 channel 1 circular, and the lazy rounds that leave the same memory."""

import support  # noqa: F401
import unittest

from adc import Adc
from dma1 import Dma1
from pwm import PwmTimer
from support import Fake, w32
from regs import Block

CTLR1, SWEVGR, CHCTLR1, CCER, ATRLR, CH1CVR = 0x00, 0x14, 0x18, 0x20, 0x2C, 0x34
STATR, ACTLR1, ACTLR2, SAMPTR2, RSQR1, RSQR2, RSQR3 = 0x00, 0x04, 0x08, 0x10, 0x2C, 0x30, 0x34
BUFFER = 0x2000_0100


class PwmTest(unittest.TestCase):
    def timer(self):
        t = PwmTimer(Fake())
        w32(t, ATRLR, 7199)
        w32(t, CHCTLR1, 0x6060)                  # CH1, CH2: PWM mode 1
        w32(t, CCER, 0x11)
        w32(t, SWEVGR, 1)
        w32(t, CTLR1, 1 | 1 << 7)                # CEN, ARPE
        return t

    def test_duty_from_the_compare(self):
        t = self.timer()
        w32(t, CH1CVR, 5400)
        self.assertEqual((t.duty_permille(0), t.duty_permille(1)), (750, 0))
        w32(t, CH1CVR + 4, 7200)                 # the image's brake: held high
        self.assertEqual(t.duty_permille(1), 1000)

    def test_a_stopped_counter_gives_a_steady_level(self):
        t = self.timer()
        w32(t, CH1CVR, 100)
        w32(t, CTLR1, 0)
        self.assertEqual(t.duty_permille(0), 1000, "CNT 0 < 100: high")
        w32(t, CH1CVR, 0)
        self.assertEqual(t.duty_permille(0), 0)


class BridgeTest(unittest.TestCase):
    """bench.py's `<STBY><IN1><IN2>:<duty>` per lane from the pins and their timers."""

    def bench(self):
        import bench
        from chip import Chip
        from support import image
        b = bench.Bench.__new__(bench.Bench)
        b.chip = Chip(image(lambda a: a.spin()))
        for timer in (b.chip.tim2, b.chip.tim3, b.chip.tim4):
            w32(timer, ATRLR, 7199)
            w32(timer, CHCTLR1, 0x6060)
            w32(timer, CHCTLR1 + 4, 0x6060)
            w32(timer, CCER, 0x1111)
            w32(timer, CTLR1, 1)
        return b

    def test_lanes_follow_their_timers_in_af_mode_with_the_remaps(self):
        b = self.bench()
        chip = b.chip
        w32(chip.gpio["B"], 0x04, 0x4444_44BB)        # PB8, PB9: AF push-pull 50 MHz
        w32(chip.gpio["B"], 0x00, 0xBBBB_B444)         # PB3-PB7 likewise
        w32(chip.gpio["A"], 0x04, 0xB444_4444)         # PA15
        w32(chip.tim4, CH1CVR + 8, 5400)               # lane 0 IN1: TIM4 CH3
        w32(chip.tim4, CH1CVR, 7200)                   # lane 1: both inputs held high
        w32(chip.tim4, CH1CVR + 4, 7200)
        w32(chip.tim3, CH1CVR + 4, 3600)               # lane 2 IN2: TIM3 CH2, not remapped yet
        w32(chip.tim2, CH1CVR, 720)                    # lane 3 IN1: TIM2 CH1 (PA15)
        self.assertEqual(b.motors(), ["110:750", "111:1000", "100:0", "100:0"])
        w32(chip.afio, 0x04, 0b10 << 10 | 0b11 << 8)   # TIM3 partial, TIM2 full remap
        self.assertEqual(b.motors(), ["110:750", "111:1000", "101:500", "110:100"])

    def test_gpio_outputs_low_coast_and_no_power_reads_zero(self):
        b = self.bench()
        w32(b.chip.gpio["B"], 0x04, 0x4444_4422)       # PB8, PB9: push-pull outputs, low
        self.assertEqual(b.motors()[0], "100:0")
        w32(b.chip.gpio["B"], 0x10, 1 << 8)
        self.assertEqual(b.motors()[0], "110:1000")
        b.chip.powered = False
        self.assertEqual(b.motors(), ["000:0"] * 4)


class AdcTest(unittest.TestCase):
    def rig(self):
        chip = Fake()
        chip.extend = Block()
        w32(chip.extend, 0, 1 << 4)
        w32(chip.rcc, 0x04, (4 << 8) | (4 << 11) | (2 << 14) | (13 << 18) | 2)  # clock.rs's: x15
        chip.dma = Dma1(chip)
        adc = Adc(chip)
        adc.levels = {c: 100 * c for c in range(8)}
        order = (7, 6, 5, 4, 3, 2, 1, 0)          # sensors.rs: lane by lane, presence then tension
        w32(adc, RSQR3, sum(c << 5 * i for i, c in enumerate(order[:6])))
        w32(adc, RSQR2, order[6] | order[7] << 5)
        w32(adc, RSQR1, 7 << 20)
        w32(adc, SAMPTR2, 0o77777777)            # 239.5 cycles
        w32(adc, ACTLR1, 1 << 8)                  # SCAN
        w32(adc, ACTLR2, 1 | 2 | 1 << 8 | 7 << 17 | 1 << 20)  # ADON CONT DMA SWSTART-trigger
        ch1 = 0x08
        w32(chip.dma, ch1 + 8, 0x4001_244C)
        w32(chip.dma, ch1 + 12, BUFFER)
        w32(chip.dma, ch1 + 4, 8)
        w32(chip.dma, ch1, 1 | 1 << 5 | 1 << 7 | 1 << 8 | 1 << 10)  # EN CIRC MINC 16-bit
        w32(adc, ACTLR2, 1 | 2 | 1 << 8 | 7 << 17 | 1 << 20 | 1 << 22)  # SWSTART
        return chip, adc

    def values(self, chip):
        data = chip.memory.read(BUFFER, 16)
        return [int.from_bytes(data[2 * i:2 * i + 2], "little") for i in range(8)]

    def test_the_scan_in_rsqr_order_into_the_dma_buffer(self):
        chip, adc = self.rig()
        self.assertEqual(adc.conversion_cycles(7), 3024)          # 252 ADC clocks at 10 MHz: 25 us
        adc.advance(8 * 3024 - 1)
        self.assertEqual(adc.conversions, 7)
        adc.advance(8 * 3024)
        self.assertEqual(self.values(chip), [700, 600, 500, 400, 300, 200, 100, 0])
        self.assertEqual(chip.dma.ch[1].remaining, 8)

    def test_many_rounds_at_once_leave_what_converting_each_would(self):
        chip, adc = self.rig()
        adc.advance(8 * 3024)
        adc.levels[3] = 4000
        adc.advance(8 * 3024 * 1000 + 5 * 3024)
        self.assertEqual(adc.conversions, 8 * 1000 + 5)  # one each 3024 cycles
        self.assertEqual(self.values(chip)[4], 4000)
        self.assertEqual(chip.dma.ch[1].remaining, 3)
        self.assertLess(chip.dma.transfers - adc.conversions, 1)


if __name__ == "__main__":
    unittest.main()
