"""RCC (ready flags, SWS, reset flags and RMVF, the clock tree the image sets: 120 MHz), and the
flash controller: unlock and fast-mode unlock, a wrong key, half-word programs (1 -> 0 only),
the erased state read as 0xE339E339, the 256-byte page and 4 KB sector erases, BSY/EOP, the
stall's length and the counts."""

import support  # noqa: F401
import unittest

import flash as flash_model
from flash import Flash
from rcc import Rcc
from support import Fake, r32, w32

KEYR, STATR, CTLR, ADDR, MODEKEYR = 0x04, 0x0C, 0x10, 0x14, 0x24
KEYS = (0x4567_0123, 0xCDEF_89AB)
PG, PER, STRT, LOCK, FLOCK, PAGE_ER = 1, 2, 1 << 6, 1 << 7, 1 << 15, 1 << 17
PAGE = 0x0800_F000


class RccTest(unittest.TestCase):
    def test_ready_flags_follow_their_enables_and_sws_follows_sw(self):
        rcc = Rcc()
        self.assertEqual(r32(rcc, 0x00) & 3, 3)  # HSION, HSIRDY at reset
        w32(rcc, 0x00, r32(rcc, 0x00) | 1 << 24)
        self.assertTrue(r32(rcc, 0x00) >> 25 & 1)
        w32(rcc, 0x04, 2)
        self.assertEqual(r32(rcc, 0x04) >> 2 & 3, 2)

    def test_reset_flags_clear_with_rmvf(self):
        rcc = Rcc(flags=(1 << 29) | (1 << 26))
        self.assertEqual(r32(rcc, 0x24) >> 26, 0b1001)
        w32(rcc, 0x24, 1 << 24)
        self.assertEqual(r32(rcc, 0x24) >> 24, 0)

    def test_the_images_settings_give_120_mhz(self):
        chip = Fake()
        from regs import Block
        chip.extend = Block()
        w32(chip.extend, 0x00, 1 << 4)                       # PLL_HSI_PRE: the HSI undivided
        rcc = Rcc(chip)
        # HPRE /1, PPRE1 /2, PPRE2 /2, ADCPRE /6, PLLSRC HSI, PLLMUL x15, SW PLL (clock.rs)
        w32(rcc, 0x04, (4 << 8) | (4 << 11) | (2 << 14) | (13 << 18) | 2)
        self.assertEqual((rcc.hclk(), rcc.pclk1(), rcc.pclk2(), rcc.adc_clock()),
                         (120_000_000, 60_000_000, 60_000_000, 10_000_000))
        # PLLMUL's last value is x18 on this chip, not x16.
        w32(rcc, 0x04, (4 << 8) | (4 << 11) | (2 << 14) | (15 << 18) | 2)
        self.assertEqual(rcc.hclk(), 144_000_000)
        w32(chip.extend, 0x00, 0)
        self.assertEqual(rcc.hclk(), 72_000_000)


class Rig:
    def __init__(self):
        self.chip = Fake()
        self.chip.memory.write(PAGE, flash_model.erased_bytes(4096))
        self.flash = self.chip.flash = Flash(self.chip)

    def unlock(self, fast=True):
        for key in KEYS:
            w32(self.flash, KEYR, key)
        if fast:
            for key in KEYS:
                w32(self.flash, MODEKEYR, key)

    def finish(self):
        self.chip.time = self.flash.busy_until
        self.flash.advance(self.chip.time)

    def word(self, address):
        return int.from_bytes(self.chip.memory.read(address, 4), "little")


class FlashTest(unittest.TestCase):
    def test_keys_unlock_then_lock_again(self):
        rig = Rig()
        self.assertEqual(r32(rig.flash, CTLR), LOCK | FLOCK)
        rig.unlock()
        self.assertEqual(r32(rig.flash, CTLR), 0)
        w32(rig.flash, CTLR, LOCK | FLOCK)
        self.assertEqual(r32(rig.flash, CTLR), LOCK | FLOCK)

    def test_a_wrong_key_keeps_it_locked_until_reset(self):
        rig = Rig()
        w32(rig.flash, KEYR, KEYS[1])
        for key in KEYS:
            w32(rig.flash, KEYR, key)
        self.assertTrue(r32(rig.flash, CTLR) & LOCK)

    def test_fast_mode_needs_its_own_keys_after_the_first(self):
        rig = Rig()
        for key in KEYS:
            w32(rig.flash, MODEKEYR, key)
        self.assertEqual(r32(rig.flash, CTLR) & FLOCK, FLOCK, "LOCK still set")

    def test_program_a_half_word_into_an_erased_word(self):
        rig = Rig()
        self.assertEqual(rig.word(PAGE), 0xE339_E339)
        rig.unlock()
        w32(rig.flash, CTLR, PG)
        rig.flash.store(PAGE, 2, 0x1234)
        self.assertEqual(r32(rig.flash, STATR) & 1, 1)                   # BSY
        self.assertEqual(rig.chip.stalled_until, 125 * 120)              # 125 us
        self.assertEqual(rig.word(PAGE), 0xE339_E339, "applied at the end")
        rig.finish()
        self.assertEqual(rig.word(PAGE), 0xFFFF_1234)
        self.assertEqual(r32(rig.flash, STATR), 1 << 5)                  # EOP
        rig.flash.store(PAGE, 2, 0xFF00)                                 # only 1 -> 0
        rig.finish()
        self.assertEqual(rig.word(PAGE), 0xFFFF_1200)
        self.assertEqual(rig.flash.programs, 2)

    def test_a_store_that_is_not_a_half_word_programs_nothing(self):
        rig = Rig()
        rig.unlock()
        w32(rig.flash, CTLR, PG)
        rig.flash.store(PAGE, 4, 0)
        self.assertIsNone(rig.flash.busy_until)
        self.assertTrue(r32(rig.flash, STATR) >> 4 & 1)                  # WRPRTERR

    def test_fast_page_erase_clears_256_bytes_in_10_ms(self):
        rig = Rig()
        rig.chip.memory.write(PAGE, bytes(512))
        rig.unlock()
        w32(rig.flash, CTLR, PAGE_ER)
        w32(rig.flash, ADDR, PAGE + 0x10)
        w32(rig.flash, CTLR, PAGE_ER | STRT)
        self.assertEqual(rig.flash.busy_until, 10_000 * 120)
        self.assertEqual(r32(rig.flash, CTLR) & STRT, 0)
        rig.finish()
        self.assertEqual(rig.chip.memory.read(PAGE, 256), flash_model.erased_bytes(256))
        self.assertEqual(rig.chip.memory.read(PAGE + 256, 4), bytes(4))
        self.assertEqual(rig.flash.erases, 1)

    def test_page_erase_needs_fast_mode_and_sector_erase_counts_16_pages(self):
        rig = Rig()
        rig.unlock(fast=False)
        w32(rig.flash, ADDR, PAGE)
        w32(rig.flash, CTLR, PAGE_ER | STRT)
        self.assertIsNone(rig.flash.busy_until)
        w32(rig.flash, CTLR, PER | STRT)
        self.assertEqual(rig.flash.erases, 16)

    def test_outside_the_rated_64_kb_is_a_write_protection_error(self):
        rig = Rig()
        rig.unlock()
        w32(rig.flash, ADDR, 0x0801_0000)
        w32(rig.flash, CTLR, PAGE_ER | STRT)
        self.assertTrue(r32(rig.flash, STATR) >> 4 & 1)
        self.assertEqual(rig.flash.erases, 0)


if __name__ == "__main__":
    unittest.main()
