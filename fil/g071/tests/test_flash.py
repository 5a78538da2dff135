"""The FLASH controller: unlock, double-word program, page erase, busy flags and the CPU stall
(RM0444 §3.3.5-3.3.8, §3.7)."""

import support  # noqa: F401  (first: puts fil/g071 on the import path)
import unittest

from flash import ERASE_CYCLES, PROGRAM_CYCLES, Flash
from support import FakeChip, r32, w32

KEYR, SR, CR = 0x08, 0x10, 0x14
PG, PER, STRT, EOPIE, LOCK = 1, 2, 1 << 16, 1 << 24, 1 << 31
PAGE60 = 0x0801_E000


class FlashTest(unittest.TestCase):
    def setUp(self):
        self.chip = FakeChip()
        self.flash = Flash(self.chip)

    def unlock(self):
        w32(self.flash, KEYR, 0x4567_0123)
        w32(self.flash, KEYR, 0xCDEF_89AB)

    def finish(self):
        self.chip.time = self.flash.busy_until
        self.flash.advance(self.chip.time)

    def test_locked_at_reset_and_unlock_sequence(self):
        self.assertTrue(r32(self.flash, CR) & LOCK)
        w32(self.flash, CR, PG)
        self.assertFalse(r32(self.flash, CR) & PG)  # ignored while locked
        self.unlock()
        self.assertFalse(r32(self.flash, CR) & LOCK)
        w32(self.flash, CR, r32(self.flash, CR) | LOCK)
        self.assertTrue(r32(self.flash, CR) & LOCK)

    def test_wrong_key_locks_until_reset(self):
        w32(self.flash, KEYR, 0x1234_5678)
        self.unlock()
        self.assertTrue(r32(self.flash, CR) & LOCK)

    def test_program_double_word_with_stall(self):
        self.unlock()
        w32(self.flash, CR, PG)
        self.flash.store(PAGE60, 4, 0x1122_3344)
        self.assertIsNone(self.flash.busy_until)  # the first word only latches
        self.flash.store(PAGE60 + 4, 4, 0x5566_7788)
        self.assertTrue(r32(self.flash, SR) >> 16 & 1)  # BSY1
        self.assertEqual(self.chip.stalled_until, PROGRAM_CYCLES)
        self.assertEqual(self.chip.memory.read(PAGE60, 8), b"\xff" * 8)  # not yet
        self.finish()
        self.assertFalse(r32(self.flash, SR) >> 16 & 1)
        self.assertEqual(self.chip.memory.read(PAGE60, 8), bytes.fromhex("4433221188776655"))
        self.assertEqual(self.flash.programs, 1)

    def test_program_over_data_is_refused_except_zeros(self):
        self.chip.memory.write(PAGE60, b"\x00\x01" + b"\xff" * 6)
        self.unlock()
        w32(self.flash, CR, PG)
        self.flash.store(PAGE60, 4, 0)
        self.flash.store(PAGE60 + 4, 4, 1)
        self.assertTrue(r32(self.flash, SR) >> 3 & 1)  # PROGERR
        self.assertEqual(self.flash.programs, 0)
        w32(self.flash, SR, 1 << 3)
        self.flash.store(PAGE60, 4, 0)
        self.flash.store(PAGE60 + 4, 4, 0)
        self.finish()
        self.assertEqual(self.chip.memory.read(PAGE60, 8), bytes(8))

    def test_alignment_size_and_sequence_errors(self):
        self.unlock()
        w32(self.flash, CR, PG)
        self.flash.store(PAGE60 + 4, 4, 0)
        self.assertTrue(r32(self.flash, SR) >> 5 & 1)  # PGAERR
        w32(self.flash, SR, 0xFFFF)
        self.flash.store(PAGE60, 2, 0)
        self.assertTrue(r32(self.flash, SR) >> 6 & 1)  # SIZERR
        w32(self.flash, SR, 0xFFFF)
        w32(self.flash, CR, 0)
        self.flash.store(PAGE60, 4, 0)
        self.assertTrue(r32(self.flash, SR) >> 7 & 1)  # PGSERR: no PG

    def test_page_erase(self):
        self.chip.memory.write(PAGE60, b"\x00" * 2048)
        self.chip.memory.write(PAGE60 + 2048, b"\x00")
        self.unlock()
        w32(self.flash, CR, PER | (60 << 3) | EOPIE)
        w32(self.flash, CR, r32(self.flash, CR) | STRT)
        self.assertTrue(r32(self.flash, SR) >> 16 & 1)
        self.assertEqual(self.chip.stalled_until, ERASE_CYCLES)
        self.assertEqual(ERASE_CYCLES, 22_000 * 64)
        self.assertEqual(self.flash.irqs(), ())
        self.finish()
        self.assertEqual(self.chip.memory.read(PAGE60, 2048), b"\xff" * 2048)
        self.assertEqual(self.chip.memory.read(PAGE60 + 2048, 1), b"\x00")  # next page kept
        self.assertTrue(r32(self.flash, SR) & 1)  # EOP
        self.assertEqual(self.flash.irqs(), (3,))
        self.assertEqual(self.flash.erases, 1)


if __name__ == "__main__":
    unittest.main()
