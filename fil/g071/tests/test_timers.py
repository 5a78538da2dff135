"""TIM2 as embassy-time's driver uses it and TIM3's PWM duty (RM0444 §22.3-22.4)."""

import support  # noqa: F401  (first: puts fil/g071 on the import path)
import unittest

from support import FakeChip, r32, w32
from timers import Timer

CR1, DIER, SR, EGR, CCMR1, CCMR2, CCER, CNT, PSC, ARR, CCR1, CCR2 = (
    0x00, 0x0C, 0x10, 0x14, 0x18, 0x1C, 0x20, 0x24, 0x28, 0x2C, 0x34, 0x38)


def time_driver_setup(chip, tim):
    """What embassy-stm32's time driver does: 1 MHz ticks, ARR 0xFFFF, CC1 at 0x8000, UIE and
    CC1IE, then CEN."""
    w32(tim, PSC, 63)
    w32(tim, ARR, 0xFFFF)
    w32(tim, CR1, 1 << 2)   # URS
    w32(tim, EGR, 1)        # UG: loads PSC, no UIF with URS
    w32(tim, CR1, 0)
    w32(tim, CCR1, 0x8000)
    w32(tim, DIER, 0b11)
    w32(tim, CR1, 1)


class TimerTest(unittest.TestCase):
    def setUp(self):
        self.chip = FakeChip()
        self.tim = Timer(self.chip, irq=15, bits=32)
        time_driver_setup(self.chip, self.tim)

    def at(self, cycles):
        self.chip.time = cycles
        self.tim.advance(cycles)

    def test_counter_counts_microseconds(self):
        self.at(64 * 1234 + 10)
        self.assertEqual(r32(self.tim, CNT), 1234)
        self.assertEqual(r32(self.tim, SR), 0)  # UG with URS set no UIF

    def test_compare_and_overflow_flags_and_events(self):
        self.assertEqual(self.tim.next_event(), 0x8000 * 64)
        self.at(0x8000 * 64 - 1)
        self.assertEqual(self.tim.irqs(), ())
        self.at(0x8000 * 64)
        self.assertEqual(r32(self.tim, SR) & 0b10, 0b10)
        self.assertEqual(self.tim.irqs(), (15,))
        w32(self.tim, SR, ~0b10 & 0xFFFF)  # rc_w0 clears CC1IF only
        self.assertEqual(r32(self.tim, SR), 0)
        self.assertEqual(self.tim.next_event(), 0x10000 * 64)  # the overflow
        self.at(0x10000 * 64)
        self.assertEqual(r32(self.tim, SR) & 1, 1)  # UIF
        self.assertEqual(r32(self.tim, CNT), 0)

    def test_alarm_on_cc2(self):
        w32(self.tim, CCR2, 5000)
        w32(self.tim, DIER, 0b111)
        self.assertEqual(self.tim.next_event(), 5000 * 64)
        self.at(5000 * 64)
        self.assertTrue(r32(self.tim, SR) >> 2 & 1)

    def test_flags_without_interrupt_enable_on_read(self):
        w32(self.tim, CCR2, 100)
        self.at(64 * 200)
        self.assertTrue(r32(self.tim, SR) >> 2 & 1)  # CC2IF set though CC2IE is clear


class PwmTest(unittest.TestCase):
    def test_duty_from_ccr_and_arr(self):
        tim = Timer(FakeChip(), irq=16)
        w32(tim, ARR, 3199)                 # 20 kHz at 64 MHz
        w32(tim, CCMR1, (6 << 4) | (6 << 12))  # PWM mode 1 on CH1 and CH2
        w32(tim, CCMR2, 7 << 4)              # PWM mode 2 on CH3
        w32(tim, CCER, 1 | (1 << 8))        # CH1 and CH3 enabled
        w32(tim, CCR1, 2400)
        w32(tim, 0x3C, 800)
        w32(tim, CR1, 1)
        self.assertEqual(tim.duty_permille(0), 750)
        self.assertEqual(tim.duty_permille(1), 0)     # CC2E clear
        self.assertEqual(tim.duty_permille(2), 750)   # mode 2: 1 - 800/3200
        w32(tim, CCR1, 5000)                           # above ARR: always active
        self.assertEqual(tim.duty_permille(0), 1000)


if __name__ == "__main__":
    unittest.main()


class EncoderModeTest(unittest.TestCase):
    """A lane's encoder timer as embassy-stm32's `Qei` sets it up (`g071-n20`): encoder mode 3
    (SMCR SMS = 011), ARR 0xFFFF, then CEN; CNT is the bench's count from the moment CEN is set,
    16 bits, wrapping (RM0444 §22.3.19)."""

    SMCR = 0x08

    def setUp(self):
        self.chip = FakeChip()
        self.tim = Timer(self.chip)
        self.tim.encoder_count = 500  # the lane has moved before the firmware starts counting
        w32(self.tim, self.SMCR, 3)
        w32(self.tim, ARR, 0xFFFF)
        w32(self.tim, CR1, 1)

    def test_counts_from_zero_at_enable_and_wraps_at_16_bits(self):
        self.assertEqual(r32(self.tim, CNT), 0)
        self.tim.encoder_count = 800
        self.assertEqual(r32(self.tim, CNT), 300)
        self.tim.encoder_count = 400  # backwards past the start
        self.assertEqual(r32(self.tim, CNT), 0xFFFF - 99)

    def test_a_written_cnt_shifts_the_count(self):
        w32(self.tim, CNT, 1000)
        self.tim.encoder_count = 510
        self.assertEqual(r32(self.tim, CNT), 1010)

    def test_a_stopped_timer_holds_its_count(self):
        self.tim.encoder_count = 600
        w32(self.tim, CR1, 0)
        self.tim.encoder_count = 900
        self.assertEqual(r32(self.tim, CNT), 100)


class BuildDetectionTest(unittest.TestCase):
    """bench.py tells the image's build by the timer whose interrupt vector is its own."""

    def test_the_time_drivers_timer_names_the_build(self):
        import bench
        default = {"DefaultHandler": 0x100, "TIM2": 0x100, "TIM15": 0x100}
        self.assertIs(bench.build_of({**default, "TIM2": 0x200}), bench.THESIS)
        self.assertIs(bench.build_of({**default, "TIM15": 0x200}), bench.N20)
        self.assertEqual(bench.N20.sensor_max(0), 0xFFFF)
        self.assertEqual(bench.N20.sensor_max(1), 4095)
