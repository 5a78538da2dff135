"""The independent watchdog (RM0444 §26) and the CRC unit (RM0444 §16)."""

import support  # noqa: F401  (first: puts fil/g071 on the import path)
import binascii
import unittest

from crc import Crc
from iwdg import Iwdg
from support import FakeChip, r32, w32


class IwdgTest(unittest.TestCase):
    def setUp(self):
        self.chip = FakeChip()
        self.wd = Iwdg(self.chip)
        w32(self.wd, 0x00, 0x5555)
        w32(self.wd, 0x04, 0)        # /4: 8 kHz
        w32(self.wd, 0x08, 800)      # 100 ms

    def test_does_not_run_before_start(self):
        self.assertIsNone(self.wd.next_event())

    def test_expiry_resets_with_watchdog_cause(self):
        w32(self.wd, 0x00, 0xCCCC)
        self.assertEqual(self.wd.next_event(), 100_000 * 64)
        self.wd.advance(100_000 * 64 - 1)
        self.assertIsNone(self.chip.reset_cause)
        self.wd.advance(100_000 * 64)
        self.assertEqual(self.chip.reset_cause, "watchdog")

    def test_reload_postpones(self):
        w32(self.wd, 0x00, 0xCCCC)
        self.chip.time = 60_000 * 64
        w32(self.wd, 0x00, 0xAAAA)
        self.assertEqual(self.wd.next_event(), 160_000 * 64)

    def test_prescaler(self):
        w32(self.wd, 0x04, 3)        # /32
        w32(self.wd, 0x08, 0xFFF)
        w32(self.wd, 0x00, 0xCCCC)
        self.assertEqual(self.wd.next_event(), 0xFFF * 32 * 2000)


def feed_bytes(unit, data):
    for b in data:
        unit.write(0x00, 1, b)


class CrcTest(unittest.TestCase):
    def test_reset_configuration_is_crc32_mpeg2(self):
        unit = Crc(FakeChip())
        unit.write(0x08, 4, 1)  # RESET
        feed_bytes(unit, b"123456789")
        self.assertEqual(r32(unit, 0x00), 0x0376E6E7)  # CRC-32/MPEG-2 check value

    def test_iso_hdlc_as_the_firmware_sets_it_up(self):
        unit = Crc(FakeChip())
        w32(unit, 0x14, 0x04C11DB7)
        w32(unit, 0x10, 0xFFFF_FFFF)
        w32(unit, 0x08, (0b01 << 5) | (1 << 7) | 1)  # REV_IN by byte, REV_OUT, RESET
        feed_bytes(unit, b"123456789")
        self.assertEqual(r32(unit, 0x00) ^ 0xFFFF_FFFF, 0xCBF43926)
        unit.write(0x08, 4, r32(unit, 0x08) | 1)
        data = bytes(range(256))
        feed_bytes(unit, data)
        self.assertEqual(r32(unit, 0x00) ^ 0xFFFF_FFFF, binascii.crc32(data))

    def test_word_writes_with_word_reversal(self):
        unit = Crc(FakeChip())
        w32(unit, 0x08, (0b11 << 5) | (1 << 7) | 1)
        w32(unit, 0x00, int.from_bytes(b"1234", "little"))
        self.assertEqual(r32(unit, 0x00) ^ 0xFFFF_FFFF, binascii.crc32(b"1234"))

    def test_big_endian_words_with_byte_reversal_as_the_firmware_feeds_them(self):
        # RM0444, CRC: a 32-bit write is processed from its most significant bit, REV_IN by byte
        # reverses each byte in place: bytes in order are the word's big-endian bytes (the
        # G071 board's HardwareCrc::add), the rest one byte a write.
        unit = Crc(FakeChip())
        w32(unit, 0x14, 0x04C11DB7)
        w32(unit, 0x10, 0xFFFF_FFFF)
        w32(unit, 0x08, (0b01 << 5) | (1 << 7) | 1)
        data = b"123456789"
        for at in range(0, 8, 4):
            w32(unit, 0x00, int.from_bytes(data[at:at + 4], "big"))
        feed_bytes(unit, data[8:])
        self.assertEqual(r32(unit, 0x00) ^ 0xFFFF_FFFF, 0xCBF43926)

    def test_16_bit_polynomial(self):
        unit = Crc(FakeChip())
        w32(unit, 0x14, 0x1021)
        w32(unit, 0x10, 0xFFFF)
        w32(unit, 0x08, (0b01 << 3) | 1)
        feed_bytes(unit, b"123456789")
        self.assertEqual(r32(unit, 0x00), 0x29B1)  # CRC-16/CCITT-FALSE check value


if __name__ == "__main__":
    unittest.main()
