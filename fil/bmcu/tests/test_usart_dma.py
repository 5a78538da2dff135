"""USART3 received by DMA1 channel 3 into a circular ring (NDTR counting down), an overrun
without the DMA and the STATR-then-DATAR clear, and sending through DATAR at the character time
BRR gives (TXE, TC)."""

import support  # noqa: F401
import unittest

import clock
from dma1 import Dma1
from support import Fake, r32, w32
from usart import Usart

STATR, DATAR, BRR, CTLR1, CTLR3 = 0x00, 0x04, 0x08, 0x0C, 0x14
ORE, RXNE, TC, TXE = 1 << 3, 1 << 5, 1 << 6, 1 << 7
RING = 0x2000_1000
CH3 = 0x08 + 20 * 2


class Rig:
    def __init__(self, dma=True):
        self.chip = Fake()
        w32(self.chip.rcc, 0x04, 4 << 8)         # PPRE1 /2 (the image's); HCLK 8 MHz here,
        self.chip.rcc.hclk = lambda: 120_000_000  # the bench's clock
        self.dma = self.chip.dma = Dma1(self.chip)
        self.usart = Usart(self.chip)
        w32(self.usart, BRR, 625)
        w32(self.usart, CTLR1, 1 << 13 | 4 | 8)  # UE RE TE
        if dma:
            w32(self.dma, CH3 + 8, 0x4000_4804)
            w32(self.dma, CH3 + 12, RING)
            w32(self.dma, CH3 + 4, 16)
            w32(self.dma, CH3, 1 | 1 << 5 | 1 << 7)
            w32(self.usart, CTLR3, 1 << 6)

    def at(self, t):
        self.chip.time = t
        self.usart.advance(t)


class ReceiveTest(unittest.TestCase):
    def test_bytes_go_round_the_ring_and_ndtr_counts_down(self):
        rig = Rig()
        data = bytes(range(20))
        for k, b in enumerate(data):
            rig.usart.deliver(clock.char_time(k + 1), b)
        rig.at(clock.char_time(3))
        self.assertEqual(r32(rig.dma, CH3 + 4), 13)
        rig.at(clock.char_time(20))
        self.assertEqual(r32(rig.dma, CH3 + 4), 12)   # 20 = 16 + 4
        self.assertEqual(rig.chip.memory.read(RING, 16), bytes(range(16, 20)) + bytes(range(4, 16)))
        self.assertEqual(rig.usart.lost, 0)

    def test_overrun_without_the_dma_and_its_clear(self):
        rig = Rig(dma=False)
        rig.usart.deliver(clock.char_time(1), 0x41)
        rig.usart.deliver(clock.char_time(2), 0x42)
        rig.at(clock.char_time(2))
        status = r32(rig.usart, STATR)
        self.assertEqual(status & (ORE | RXNE), ORE | RXNE)
        self.assertEqual(r32(rig.usart, DATAR), 0x41, "the second byte is lost")
        self.assertEqual(r32(rig.usart, STATR) & (ORE | RXNE), 0)


class TransmitTest(unittest.TestCase):
    def test_a_character_time_from_brr_txe_and_tc(self):
        rig = Rig()
        self.assertEqual(rig.usart.char_cycles(), 12_500)   # 86.8 us at 115200 Bd
        self.assertEqual(r32(rig.usart, STATR) & (TXE | TC), TXE | TC)
        w32(rig.usart, DATAR, 0x53)                          # straight to the shift register
        self.assertEqual(r32(rig.usart, STATR) & (TXE | TC), TXE)
        w32(rig.usart, DATAR, 0x30)                          # waits in DATAR
        self.assertEqual(r32(rig.usart, STATR) & (TXE | TC), 0)
        rig.at(12_500)
        self.assertEqual(rig.usart.take_sent(), [(12_500, 0x53)])
        self.assertEqual(r32(rig.usart, STATR) & (TXE | TC), TXE)
        rig.at(25_000)
        self.assertEqual(rig.usart.take_sent(), [(25_000, 0x30)])
        self.assertEqual(r32(rig.usart, STATR) & (TXE | TC), TXE | TC)


if __name__ == "__main__":
    unittest.main()
