"""SysTick (native.py): the 64-bit counter of HCLK/8 or HCLK in virtual time, INIT, the compare
match's CNTIF and its interrupt line with STIE, SR's write-0 clear, the reload, and the 32-bit
halves the image reads high-low-high."""

import support  # noqa: F401
import unittest

from chip import Chip
from native import NEVER
from support import image

CTLR, SR, CNTL, CNTH, CMPL, CMPH = 0x00, 0x04, 0x08, 0x0C, 0x10, 0x14
STE, STIE, STCLK, STRE, MODE, INIT = 1, 2, 4, 8, 16, 32


def chip():
    return Chip(image(lambda a: a.spin()))


class SysTickTest(unittest.TestCase):
    def setUp(self):
        self.nat = chip().cpu.native

    def test_counts_hclk_over_8_from_init(self):
        nat = self.nat
        nat.st_write(CTLR, STE | INIT, 1000)
        self.assertEqual(nat.st_read(CNTL, 1000), 0)
        self.assertEqual(nat.st_read(CNTL, 1000 + 144 * 1000), 18_000)   # 1 ms: 18 MHz
        self.assertEqual(nat.st_read(CTLR, 1000) & INIT, 0)               # INIT clears itself
        nat.st_write(CTLR, STE | STCLK, 1000 + 8 * 100)
        self.assertEqual(nat.st_read(CNTL, 1000 + 8 * 100 + 50), 150)     # HCLK from then on

    def test_stopped_counter_stands(self):
        nat = self.nat
        nat.st_write(CTLR, STE | INIT, 0)
        nat.st_write(CTLR, 0, 800)
        self.assertEqual(nat.st_read(CNTL, 80_000), 100)

    def test_compare_match_sets_cntif_and_the_line_with_stie(self):
        nat = self.nat
        nat.st_write(CTLR, STE | INIT, 0)
        nat.st_write(CMPH, 0, 0)
        nat.st_write(CMPL, 1000, 0)
        self.assertEqual(nat.st_match(), 8000)
        nat.st_update(7999)
        self.assertEqual(nat.st_read(SR, 7999), 0)
        nat.st_write(CTLR, STE | STIE, 7999)
        self.assertFalse(nat.st_irq())
        self.assertEqual(nat.st_read(SR, 8000), 1)
        self.assertTrue(nat.st_irq())
        nat.st_write(SR, 0, 8001)
        self.assertEqual(nat.st_read(SR, 9000), 0)
        self.assertEqual(nat.st_match(), NEVER, "no reload: the counter passed CMP for good")

    def test_a_compare_already_passed_never_matches(self):
        nat = self.nat
        nat.st_write(CTLR, STE | INIT | STIE, 0)
        nat.st_write(CMPL, 10, 8 * 20)
        self.assertEqual(nat.st_read(SR, 8 * 1000), 0)

    def test_reload_restarts_at_zero_after_cmp(self):
        nat = self.nat
        nat.st_write(CMPL, 99, 0)
        nat.st_write(CTLR, STE | INIT | STRE | STCLK, 0)
        self.assertEqual(nat.st_match(), 99)
        self.assertEqual(nat.st_read(CNTL, 150), 50)
        self.assertEqual(nat.st_read(SR, 150), 1)
        nat.st_write(SR, 0, 150)
        self.assertEqual(nat.st_match(), 199)

    def test_the_high_word_carries(self):
        nat = self.nat
        nat.st_write(CNTL, 0xFFFF_FFFF, 0)
        nat.st_write(CTLR, STE | STCLK, 0)
        self.assertEqual((nat.st_read(CNTH, 1), nat.st_read(CNTL, 1)), (1, 0))


if __name__ == "__main__":
    unittest.main()
