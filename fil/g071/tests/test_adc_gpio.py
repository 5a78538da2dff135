"""The ADC's scan by DMA as embassy-stm32 drives it on the G0 (RM0444 §15), and the GPIO output
levels the bench reports for the bridges' STBY and IN pins (RM0444 §7.4)."""

import support  # noqa: F401  (first: puts fil/g071 on the import path)
import unittest

from adc import Adc
from dma import Dma, DmaMux
from gpio import Gpio
from support import FakeChip, r32, w32

ISR, CR, CFGR1, CFGR2, SMPR, CHSELR, DR, CCR = 0x00, 0x08, 0x0C, 0x10, 0x14, 0x28, 0x40, 0x308
BUF = 0x2000_0400


class AdcTest(unittest.TestCase):
    def setUp(self):
        self.chip = FakeChip()
        self.dma = self.chip.dma = Dma(self.chip)
        self.mux = DmaMux(self.chip, self.dma)
        self.adc = Adc(self.chip)
        # The board's levels on its nine channels (bench.py's SENSOR_CHANNELS).
        self.adc.levels = {0: 100, 1: 200, 4: 300, 9: 400, 15: 500, 16: 600, 6: 700, 7: 800, 8: 900}

    def at(self, t):
        self.chip.time = t
        self.adc.advance(t)

    def board_setup(self):
        """The image's set-up: regulator, calibration, async clock / 2, 8x oversampling with a
        shift of 3, sample time 79.5 cycles, the nine channels, one-shot DMA, CONT."""
        w32(self.adc, CR, 1 << 28)
        w32(self.adc, CR, (1 << 28) | (1 << 31))
        self.assertEqual(r32(self.adc, CR) >> 31, 0)          # calibration done
        self.assertTrue(r32(self.adc, ISR) >> 11 & 1)          # EOCAL
        w32(self.adc, CCR, 1 << 18)                           # PRESC /2
        w32(self.adc, CFGR2, 1 | (2 << 2) | (3 << 5))          # OVSE, 8x, >> 3
        w32(self.adc, SMPR, 6)                                 # SMP1 = 79.5
        w32(self.adc, CR, (1 << 28) | 1)
        self.assertTrue(r32(self.adc, ISR) & 1)                # ADRDY
        mask = sum(1 << c for c in self.adc.levels)
        w32(self.adc, CHSELR, mask)
        w32(self.mux, 0x00, 5)                                 # C0CR -> channel 1: ADC
        w32(self.dma, 0x08 + 8, 0x4001_2440)
        w32(self.dma, 0x08 + 12, BUF)
        w32(self.dma, 0x08 + 4, 9)
        w32(self.dma, 0x08, 1 | 2 | (1 << 7) | (1 << 8) | (1 << 10))  # EN TCIE MINC 16-bit
        w32(self.adc, CFGR1, 1 | (1 << 13))                    # DMAEN, one-shot, CONT
        w32(self.adc, CR, (1 << 28) | 1 | 4)                   # ADSTART

    def test_scan_in_ascending_channel_order_by_dma(self):
        self.board_setup()
        per = self.adc.conversion_cycles(0)
        self.assertEqual(per, (79.5 + 12.5) * 8 * 2)           # 23 us at 64 MHz
        self.assertEqual(self.adc.next_event(), 9 * per)       # the DMA's transfer complete
        self.at(9 * per - 1)
        self.assertEqual(r32(self.dma, 0x08 + 4), 1)
        self.at(9 * per)
        raw = self.chip.memory.read(BUF, 18)
        values = [int.from_bytes(raw[2 * i:2 * i + 2], "little") for i in range(9)]
        self.assertEqual(values, [100, 200, 300, 700, 800, 900, 400, 500, 600])  # 0 1 4 6 7 8 9 15 16
        self.assertEqual(self.dma.irqs(), {9})

    def test_stop_clears_adstart(self):
        self.board_setup()
        w32(self.adc, CR, r32(self.adc, CR) | (1 << 4))
        self.assertEqual(r32(self.adc, CR) & ((1 << 2) | (1 << 4)), 0)
        self.assertIsNone(self.adc.next_event())

    def test_single_conversion_polled(self):
        w32(self.adc, CR, 1)
        w32(self.adc, CHSELR, 1 << 7)
        w32(self.adc, CR, 1 | 4)
        self.at(self.adc.conversion_cycles(7))
        self.assertTrue(r32(self.adc, ISR) >> 3 & 1)  # EOS
        self.assertEqual(r32(self.adc, DR), 800)
        self.assertEqual(r32(self.adc, CR) >> 2 & 1, 0)


class GpioTest(unittest.TestCase):
    def test_bsrr_brr_and_output_levels(self):
        port_c = Gpio(FakeChip(), port=2)
        self.assertEqual(port_c.output_level(2), 0)
        w32(port_c, 0x00, (0xFFFF_FFFF & ~(3 << 4)) | (1 << 4))  # PC2 output
        w32(port_c, 0x18, 1 << 2)
        self.assertEqual(port_c.output_level(2), 1)
        self.assertEqual(r32(port_c, 0x10) >> 2 & 1, 1)
        w32(port_c, 0x18, (1 << 18) | (1 << 2))  # set wins over reset
        self.assertEqual(port_c.output_level(2), 1)
        w32(port_c, 0x28, 1 << 2)
        self.assertEqual(port_c.output_level(2), 0)
        w32(port_c, 0x18, 1 << 3)  # PC3 still analog: not driven
        self.assertEqual(port_c.output_level(3), 0)

    def test_input_with_pull_up(self):
        port_c = Gpio(FakeChip(), port=2)
        w32(port_c, 0x00, 0xFFFF_FFFF & ~(3 << 26))  # PC13 input
        w32(port_c, 0x0C, 1 << 26)                    # pull-up
        self.assertEqual(r32(port_c, 0x10) >> 13 & 1, 1)


if __name__ == "__main__":
    unittest.main()
