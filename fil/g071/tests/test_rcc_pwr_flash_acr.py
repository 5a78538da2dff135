"""RCC/PWR/FLASH ACR: the ready bits embassy_stm32::init waits for (RM0444 §5.4, §4.4, §3.7.1)."""

import support  # noqa: F401  (first: puts fil/g071 on the import path)
import unittest

from support import FakeChip, r32, w32
from flash import Flash
from rcc import Pwr, Rcc


class RccTest(unittest.TestCase):
    def setUp(self):
        self.rcc = Rcc(FakeChip(), csr_flags=(1 << 27) | (1 << 26))

    def test_reset_value_has_hsi_on_and_ready(self):
        self.assertEqual(r32(self.rcc, 0x00) & 0x500, 0x500)

    def test_pll_ready_follows_pllon(self):
        self.assertFalse(r32(self.rcc, 0x00) >> 25 & 1)
        w32(self.rcc, 0x00, r32(self.rcc, 0x00) | 1 << 24)
        self.assertTrue(r32(self.rcc, 0x00) >> 25 & 1)
        w32(self.rcc, 0x00, r32(self.rcc, 0x00) & ~(1 << 24))
        self.assertFalse(r32(self.rcc, 0x00) >> 25 & 1)

    def test_hse_ready_follows_hseon(self):
        w32(self.rcc, 0x00, r32(self.rcc, 0x00) | 1 << 16)
        self.assertTrue(r32(self.rcc, 0x00) >> 17 & 1)

    def test_sws_follows_sw(self):
        w32(self.rcc, 0x08, 0b010)  # SW = PLLRCLK
        self.assertEqual(r32(self.rcc, 0x08) >> 3 & 7, 0b010)

    def test_lsi_and_lse_ready(self):
        w32(self.rcc, 0x60, r32(self.rcc, 0x60) | 1)
        self.assertTrue(r32(self.rcc, 0x60) >> 1 & 1)
        w32(self.rcc, 0x5C, 1)
        self.assertTrue(r32(self.rcc, 0x5C) >> 1 & 1)

    def test_reset_flags_cleared_by_rmvf(self):
        self.assertEqual(r32(self.rcc, 0x60) >> 24, 0b1100)  # PWRRSTF | PINRSTF
        w32(self.rcc, 0x60, r32(self.rcc, 0x60) | 1 << 23)
        self.assertEqual(r32(self.rcc, 0x60) >> 23, 0)


class PwrTest(unittest.TestCase):
    def test_voltage_scaling_done(self):
        pwr = Pwr(FakeChip())
        w32(pwr, 0x00, 0x200)  # VOS range 1
        self.assertEqual(r32(pwr, 0x14) & (1 << 10), 0)  # VOSF clear: ready


class FlashAcrTest(unittest.TestCase):
    def test_latency_reads_back(self):
        flash = Flash(FakeChip())
        self.assertEqual(r32(flash, 0x00), 0x0004_0600)
        w32(flash, 0x00, (r32(flash, 0x00) & ~7) | 2)
        self.assertEqual(r32(flash, 0x00) & 7, 2)


if __name__ == "__main__":
    unittest.main()
