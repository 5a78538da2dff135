"""USART1 received by DMA into a circular ring and sent by DMA (RM0444 §33.5, §10.4, §11.3:
DMAMUX request 50 = USART1_RX, 51 = USART1_TX)."""

import support  # noqa: F401  (first: puts fil/g071 on the import path)
import unittest

import clock
from dma import Dma, DmaMux
from support import FakeChip, r32, w32
from usart import Usart

RING = 0x2000_1000
CH2 = 0x08 + 20  # channel 2's CCR
EN, TCIE, HTIE, DIR, CIRC, MINC = 1, 2, 4, 16, 32, 128


class Rig:
    def __init__(self, fifo=True):
        self.chip = FakeChip()
        self.dma = self.chip.dma = Dma(self.chip)
        self.mux = DmaMux(self.chip, self.dma)
        self.usart = Usart(self.chip)
        w32(self.usart, 0x00, 1 | 4 | 8 | (1 << 4) | ((1 << 29) if fifo else 0))  # UE RE TE IDLEIE

    def at(self, t):
        self.chip.time = t
        self.usart.advance(t)

    def ring(self, length=16):
        w32(self.mux, 0x04, 50)              # DMAMUX C1CR -> DMA1 channel 2: USART1_RX
        w32(self.dma, CH2 + 8, 0x4001_3824)  # CPAR = RDR
        w32(self.dma, CH2 + 12, RING)        # CMAR
        w32(self.dma, CH2 + 4, length)       # CNDTR
        w32(self.dma, CH2, EN | TCIE | HTIE | CIRC | MINC)
        w32(self.usart, 0x08, (1 << 6) | 1)  # DMAR, EIE

    def send(self, data, start=0):
        for k, b in enumerate(data):
            self.usart.deliver(start + clock.char_time(k + 1), b)


class RxTest(unittest.TestCase):
    def test_bytes_land_in_the_ring_and_cndtr_counts_down_and_wraps(self):
        rig = Rig()
        rig.ring(16)
        data = bytes(range(0x41, 0x41 + 20))
        rig.send(data)
        rig.at(clock.char_time(5))
        self.assertEqual(r32(rig.dma, CH2 + 4), 11)
        rig.at(clock.char_time(20))
        self.assertEqual(r32(rig.dma, CH2 + 4), 12)  # wrapped: 20 = 16 + 4
        ring = rig.chip.memory.read(RING, 16)
        self.assertEqual(ring[:4], data[16:20])
        self.assertEqual(ring[4:], data[4:16])
        self.assertEqual(rig.usart.lost, 0)

    def test_half_and_full_transfer_flags_and_line(self):
        rig = Rig()
        rig.ring(8)
        rig.send(b"abcdefgh")
        rig.at(clock.char_time(3))
        self.assertEqual(r32(rig.dma, 0x00) >> 4 & 0xF, 0)
        self.assertEqual(rig.dma.irqs(), set())
        rig.at(clock.char_time(4))
        self.assertEqual(r32(rig.dma, 0x00) >> 4 & 0xF, 0b0101)  # HTIF2 | GIF2
        self.assertEqual(rig.dma.irqs(), {10})
        w32(rig.dma, 0x04, 1 << 4)  # CGIF2
        rig.at(clock.char_time(8))
        self.assertEqual(r32(rig.dma, 0x00) >> 4 & 0xF, 0b0011)  # TCIF2 | GIF2

    def test_idle_after_one_character_time(self):
        rig = Rig()
        rig.ring(16)
        rig.send(b"S0")
        rig.at(clock.char_time(3) - 1)
        self.assertFalse(r32(rig.usart, 0x1C) >> 4 & 1)
        rig.at(clock.char_time(3))
        self.assertTrue(r32(rig.usart, 0x1C) >> 4 & 1)
        self.assertEqual(rig.usart.irqs(), (27,))
        w32(rig.usart, 0x20, 1 << 4)  # IDLECF
        self.assertEqual(rig.usart.irqs(), ())

    def test_overrun_without_dma(self):
        rig = Rig(fifo=False)
        rig.send(b"xy")
        rig.at(clock.char_time(2))
        isr = r32(rig.usart, 0x1C)
        self.assertTrue(isr >> 3 & 1)  # ORE
        self.assertEqual(r32(rig.usart, 0x24), ord("x"))
        self.assertEqual(rig.usart.lost, 1)


class TxTest(unittest.TestCase):
    def test_dma_transmit_one_character_time_each(self):
        rig = Rig()
        rig.chip.memory.write(0x2000_2000, b"S0 A3*22\n")
        w32(rig.mux, 0x08, 51)               # C2CR -> channel 3: USART1_TX
        ch3 = 0x08 + 40
        w32(rig.dma, ch3 + 8, 0x4001_3828)
        w32(rig.dma, ch3 + 12, 0x2000_2000)
        w32(rig.dma, ch3 + 4, 9)
        w32(rig.dma, ch3, EN | TCIE | DIR | MINC)
        w32(rig.usart, 0x08, 1 << 7)         # DMAT
        rig.at(clock.char_time(1))
        self.assertEqual(bytes(b for _, b in rig.usart.take_sent()), b"S")
        self.assertFalse(r32(rig.usart, 0x1C) >> 6 & 1)  # TC: more to send
        rig.at(clock.char_time(9))
        self.assertEqual(bytes(b for _, b in rig.usart.take_sent()), b"0 A3*22\n")
        self.assertTrue(r32(rig.usart, 0x1C) >> 6 & 1)
        self.assertEqual(r32(rig.dma, 0x00) >> 8 & 2, 2)  # TCIF3

    def test_tdr_write(self):
        rig = Rig()
        w32(rig.usart, 0x28, 0x55)
        rig.at(clock.char_time(1))
        self.assertEqual(rig.usart.take_sent(), [(clock.char_time(1), 0x55)])


if __name__ == "__main__":
    unittest.main()
