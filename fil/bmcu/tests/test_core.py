"""The QingKe core and the chip on synthetic images: the WCH CSRs, interrupt entry through the
absolute vector table with the hardware prologue/epilogue, nesting's MIE, traps, the idle
executor, resets (PFIC_CFGR's key, the watchdog with `hang`, power on) and a flash erase that
stalls the CPU while the DMA keeps receiving the UART's bytes."""

import support  # noqa: F401  (first: the import path)
import unittest

import clock
from chip import Chip
from support import A0, A1, A5, S0, S4, T0, T1, T2, ZERO, SP, Asm, image

RAM = 0x2000_0000
MARK, MARK2, COUNT, CAUSE, EPC, STATUS = (RAM + 0x100 + 4 * i for i in range(6))
QUEUE = RAM + 0x200
PFIC_IENR, PFIC_CFGR = 0xE000_E100, 0xE000_E048
STK = 0xE000_F000
IWDG = 0x4000_3000
USART3, DMA1, FLASH = 0x4000_4800, 0x4002_0000, 0x4002_2000
RSTSCKR = 0x24


def word(chip, address):
    return int.from_bytes(chip.memory.read(address, 4), "little")


def ms(n):
    return n * 1000 * clock.CYCLES_PER_US


def systick_every_ms(a, nesting=True):
    """SysTick interrupt each millisecond (HCLK/8, auto-reload), HPE (+ nesting), MIE on."""
    a.li(SP, 0x2000_5000)
    a.li(T0, 3 if nesting else 1).csrrw(ZERO, 0x804, T0)
    a.poke(STK + 0x10, 15_000 - 1).poke(STK + 0x14, 0)   # 1 ms of HCLK/8 at 120 MHz
    a.poke(STK, 1 | 2 | 8 | 0x20)                   # STE STIE STRE INIT
    a.poke(PFIC_IENR, 1 << 12)
    a.li(T0, 0x88).csrrs(ZERO, 0x800, T0)           # MIE and MPIE through gintenr


def clear_systick(a):
    a.li(T1, STK + 4).sw(ZERO, T1)


class CsrTest(unittest.TestCase):
    def test_gintenr_is_mie_and_mpie_and_the_others_are_storage(self):
        def main(a):
            a.li(T0, 0x88).csrrs(ZERO, 0x800, T0)       # enable
            a.csrrc(A0, 0x800, T0)                       # disable, read the old value
            a.csrrs(A1, 0x800, ZERO)                     # read
            a.li(T1, MARK).sw(A0, T1).li(T1, MARK2).sw(A1, T1)
            a.li(T0, 0x1F).csrrw(ZERO, 0xBC0, T0).csrrs(A0, 0xBC0, ZERO)
            a.li(T1, STATUS).sw(A0, T1)
            a.spin()

        chip = Chip(image(main))
        chip.run_until(ms(1))
        self.assertEqual((word(chip, MARK), word(chip, MARK2), word(chip, STATUS)), (0x88, 0, 0x1F))
        self.assertEqual(chip.cpu.uc.reg_read(116) & 0x88, 0)  # mstatus


class InterruptTest(unittest.TestCase):
    def test_systick_through_the_vector_table_with_the_hardware_prologue(self):
        def main(a):
            systick_every_ms(a)
            a.li(A0, 0x11).li(A5, 0x55)
            loop = a.here()
            a.li(T1, MARK).sw(A0, T1).li(T1, MARK2).sw(A5, T1).j(loop)

        def systick(a):
            clear_systick(a)
            a.li(A0, 0x99).li(A5, 0x77)                  # caller-saved: the HPE restores them
            a.csrrs(A1, 0x342, ZERO).li(T1, CAUSE).sw(A1, T1)
            a.csrrs(A1, 0x300, ZERO).li(T1, STATUS).sw(A1, T1)
            a.increment(COUNT)
            a.mret()

        chip = Chip(image(main, {12: systick}))
        chip.run_until(ms(10) + ms(1) // 2)
        self.assertEqual(word(chip, COUNT), 10)
        self.assertEqual((word(chip, MARK), word(chip, MARK2)), (0x11, 0x55))
        self.assertEqual(word(chip, CAUSE), 0x8000_000C)
        self.assertTrue(word(chip, STATUS) & 0x8, "INESTEN: MIE stays set in the handler")
        self.assertEqual(chip.cpu.frames, [])

    def test_without_nesting_the_handler_runs_with_mie_clear(self):
        def main(a):
            systick_every_ms(a, nesting=False)
            a.spin()

        def systick(a):
            clear_systick(a)
            a.csrrs(A1, 0x300, ZERO).li(T1, STATUS).sw(A1, T1)
            a.increment(COUNT)
            a.mret()

        chip = Chip(image(main, {12: systick}))
        chip.run_until(ms(3) + ms(1) // 2)
        self.assertEqual(word(chip, COUNT), 3)
        self.assertEqual(word(chip, STATUS) & 0x88, 0x80)

    def test_an_illegal_instruction_traps_to_vector_3(self):
        def main(a):
            a.li(SP, 0x2000_5000)
            a.h(0x0000)                                  # c.unimp
            a.spin()

        def exception(a):
            a.csrrs(A1, 0x342, ZERO).li(T1, CAUSE).sw(A1, T1)
            a.csrrs(A1, 0x341, ZERO).li(T1, EPC).sw(A1, T1)
            a.spin()

        chip = Chip(image(main, {3: exception}))
        chip.run_until(ms(1))
        self.assertEqual(word(chip, CAUSE), 2)
        self.assertEqual(word(chip, EPC), 0x0800_0000 + 4 * 64 + 8)


class IdleTest(unittest.TestCase):
    """The spinning executor's empty poll loop: the core stops there and time jumps to the next
    interrupt (executor.py)."""

    def test_an_empty_run_queue_sleeps_until_the_interrupt_that_fills_it(self):
        def main(a):
            systick_every_ms(a)
            a.li(S0, 0x88).li(S4, QUEUE - 12)
            head = a.here()
            a.csrrc(A1, 0x800, S0).lw(A0, S4, 12).sw(ZERO, S4, 12).csrrs(ZERO, 0x800, S0)
            a.beq(A0, ZERO, head)
            a.increment(COUNT)
            a.j(head)

        def systick(a):
            clear_systick(a)
            a.li(T1, QUEUE).li(T2, 1).sw(T2, T1)
            a.mret()

        segments = image(main, {12: systick})
        head = 0x0800_0000 + 4 * 64 + len(Asm().li(0, 0).code) * 0  # found by the scan below
        symbols = {"_ZN16embassy_executor8platform6thread8Executor3run17h0E": 0x0800_0100,
                   "after": 0x0800_0000 + len(segments[0][1])}
        chip = Chip(segments, symbols)
        self.assertIsNotNone(chip.idle, head)
        chip.run_until(ms(10) + ms(1) // 2)
        self.assertEqual(word(chip, COUNT), 10)
        self.assertLess(chip.cpu.native.count(), 2_000, "10 ms of an idle loop, not executed")
        self.assertGreaterEqual(chip.cpu.native.idles(), 10)


class ResetTest(unittest.TestCase):
    def test_pfic_cfgr_with_its_key_resets_and_keeps_ram(self):
        def main(a):
            a.j(a.here() + 8)
            halt = a.here()
            a.spin()
            a.increment(COUNT)
            a.li(T0, 3).beq(T2, T0, halt)
            a.poke(PFIC_CFGR, 0x1234_0080)               # a wrong key: nothing
            a.poke(PFIC_CFGR, 0xBEEF_0080)
            a.spin()

        chip = Chip(image(main))
        chip.memory.write(0x0800_F800, b"kept")
        chip.run_until(ms(1))
        self.assertEqual(word(chip, COUNT), 3)
        self.assertEqual(chip.resets, 2)
        self.assertEqual(chip.memory.read(0x0800_F800, 4), b"kept")
        self.assertTrue(chip.rcc.regs[RSTSCKR] >> 28 & 1)  # SFTRSTF

    def test_hang_lets_the_watchdog_reset_at_40_khz(self):
        def main(a):
            a.poke(IWDG, 0x5555).poke(IWDG + 4, 0).poke(IWDG + 8, 1000)  # 1000 x 4 / 40 kHz
            a.poke(IWDG, 0xCCCC)
            a.increment(COUNT)
            loop = a.here()
            a.poke(IWDG, 0xAAAA).j(loop)

        chip = Chip(image(main))
        chip.run_until(ms(300))
        self.assertEqual(chip.resets, 0)
        chip.hung = True
        chip.run_until(ms(399))
        self.assertEqual(chip.resets, 0)
        chip.run_until(ms(401))
        self.assertEqual(chip.resets, 1)
        self.assertTrue(chip.rcc.regs[RSTSCKR] >> 29 & 1)  # IWDGRSTF
        chip.run_until(ms(402))
        self.assertEqual(word(chip, COUNT), 2)

    def test_power_on_clears_ram(self):
        def main(a):
            a.increment(COUNT)
            a.spin()

        chip = Chip(image(main))
        chip.run_until(ms(1))
        chip.power_off()
        chip.run_until(ms(2))
        chip.power_on()
        self.assertEqual(word(chip, COUNT), 0)
        self.assertEqual(chip.rcc.regs[RSTSCKR] >> 26 & 0b11, 0b11)  # PINRSTF, PORRSTF
        chip.run_until(ms(3))
        self.assertEqual(word(chip, COUNT), 1)


class EraseWhileReceivingTest(unittest.TestCase):
    def test_bytes_during_an_erase_reach_the_ring(self):
        ring = RAM + 0x400

        def main(a):
            a.poke(USART3 + 0x0C, (1 << 13) | 4 | 8)            # UE RE TE
            ch3 = DMA1 + 0x08 + 20 * 2
            a.poke(ch3 + 8, USART3 + 4).poke(ch3 + 12, ring).poke(ch3 + 4, 16)
            a.poke(ch3, 1 | (1 << 5) | (1 << 7))               # EN CIRC MINC
            a.poke(USART3 + 0x14, 1 << 6)                       # DMAR
            for key in (0x4567_0123, 0xCDEF_89AB):
                a.poke(FLASH + 0x04, key)
            for key in (0x4567_0123, 0xCDEF_89AB):
                a.poke(FLASH + 0x24, key)
            a.poke(FLASH + 0x10, 1 << 17).poke(FLASH + 0x14, 0x0800_F000)
            a.poke(FLASH + 0x10, (1 << 17) | (1 << 6))         # PAGE_ER STRT: the stall
            a.j(a.here() + 4)                                   # (it starts at a block's end)
            a.poke(MARK, 1)
            a.spin()

        chip = Chip(image(main))
        chip.memory.write(0x0800_F000, b"\x00" * 256)
        chip.run_until(ms(1))
        self.assertEqual(chip.flash.erases, 1)
        request = b"T1*a5\nS0*c6\n"
        for k, byte in enumerate(request):
            chip.usart3.deliver(ms(2) + clock.char_time(k + 1), byte)
        count = chip.cpu.native.count()
        chip.run_until(ms(8))
        self.assertEqual(chip.cpu.native.count(), count)        # not one instruction
        self.assertEqual(word(chip, MARK), 0)
        self.assertEqual(chip.memory.read(ring, len(request)), request)
        self.assertEqual(chip.dma.ch[3].remaining, 4)
        chip.run_until(ms(12))
        self.assertEqual(word(chip, MARK), 1)
        self.assertEqual(chip.memory.read(0x0800_F000, 8), bytes.fromhex("39e339e339e339e3"))


if __name__ == "__main__":
    unittest.main()
