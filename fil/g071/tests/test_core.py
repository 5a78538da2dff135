"""The core and the chip on synthetic images: interrupts (entry, return, priorities), WFE/SEV,
resets (SYSRESETREQ, watchdog with `hang`, power on) and the flash erase that stalls the CPU while
the DMA keeps receiving the UART's bytes (RM0444 §3.3.2; ARMv6-M ARM B1.5)."""

import support  # noqa: F401  (first: puts fil/g071 on the import path)
import unittest

import clock
from chip import Chip
from support import image

RAM = 0x2000_0000
MARK = RAM + 0x100
COUNT = RAM + 0x104
SLOT = RAM + 0x110
TIM2, NVIC_ISER, NVIC_ISPR, NVIC_IPR0 = 0x4000_0000, 0xE000_E100, 0xE000_E200, 0xE000_E400
AIRCR = 0xE000_ED0C
IWDG_KR, IWDG_PR, IWDG_RLR = 0x4000_3000, 0x4000_3004, 0x4000_3008
USART1, DMA1, DMAMUX, FLASH = 0x4001_3800, 0x4002_0000, 0x4002_0800, 0x4002_2000


def word(chip, address):
    return int.from_bytes(chip.memory.read(address, 4), "little")


def ms(n):
    return n * 1000 * clock.CYCLES_PER_US


def increment(asm, address):
    asm.load(0, address).ldr(1, 0).adds(1, 1).str(1, 0)


class InterruptTest(unittest.TestCase):
    def test_timer_interrupt_entered_and_returned(self):
        def main(a):
            a.poke(TIM2 + 0x28, 63).poke(TIM2 + 0x2C, 999).poke(TIM2 + 0x14, 1)
            a.poke(TIM2 + 0x10, 0).poke(TIM2 + 0x0C, 1).poke(TIM2, 1)
            a.poke(NVIC_ISER, 1 << 15)
            a.movs(5, 7)
            loop = a.here()
            a.wfi().load(0, MARK).str(5, 0).b_to(loop)

        def tim2(a):
            a.load(0, TIM2 + 0x10).movs(1, 0).str(1, 0)
            increment(a, COUNT)
            a.movs(5, 99)  # r5 is callee-saved: restored by the handler's caller? no: by us
            a.bx_lr()

        chip = Chip(image(main, {15: tim2}))
        chip.run_until(ms(10) + ms(1) // 2)
        self.assertEqual(word(chip, COUNT), 10)
        # r0-r3 come back from the frame; the loop's stores of r5 ran after each return.
        self.assertIn(word(chip, MARK), (7, 99))
        self.assertEqual(chip.cpu.active, [])

    def test_priority_order_of_pending_interrupts(self):
        def main(a):
            a.cpsid()
            a.poke(NVIC_IPR0, (0xC0 << 24) | (0x40 << 8))    # IRQ3 priority 3, IRQ1 priority 1
            a.poke(NVIC_ISER, (1 << 3) | (1 << 1))
            a.poke(NVIC_ISPR, (1 << 3) | (1 << 1))
            a.cpsie()
            a.b_self()

        def handler(n):
            def emit(a):
                increment(a, COUNT)
                a.load(0, SLOT + 4 * n).str(1, 0).bx_lr()
            return emit

        chip = Chip(image(main, {1: handler(1), 3: handler(3)}))
        chip.run_until(ms(1))
        self.assertEqual((word(chip, SLOT + 4), word(chip, SLOT + 12)), (1, 2))

    def test_sev_then_wfe_does_not_sleep(self):
        def main(a):
            a.sev().wfe()
            a.poke(MARK, 1)
            a.wfe()
            a.poke(MARK, 2)
            a.b_self()

        chip = Chip(image(main))
        chip.run_until(ms(1))
        self.assertEqual(word(chip, MARK), 1)
        self.assertEqual(chip.cpu.sleeping, "wfe")


class FaultTest(unittest.TestCase):
    def test_udf_enters_the_hardfault_handler(self):
        def main(a):
            a.h(0xDE00)  # UDF #0
            a.b_self()

        def hardfault(a):
            a.poke(MARK, 0x4646)
            a.b_self()

        # HardFault is vector 3: handlers[-13] lands on 16 - 13.
        chip = Chip(image(main, {-13: hardfault}))
        chip.run_until(ms(1))
        self.assertEqual(word(chip, MARK), 0x4646)
        self.assertEqual(chip.cpu.active, [3])


class ResetTest(unittest.TestCase):
    def test_sysresetreq_resets_and_keeps_ram(self):
        def main(a):
            a.h(0xE000)           # B over the next halfword
            halt = a.here()
            a.b_self()
            increment(a, COUNT)
            a.cmp(1, 3)
            a.bge_to(halt)
            a.poke(AIRCR, 0x05FA_0004)
            a.b_self()

        chip = Chip(image(main))
        chip.memory.write(0x0801_F800, b"kept")
        chip.run_until(ms(1))
        self.assertEqual(word(chip, COUNT), 3)
        self.assertEqual(chip.memory.read(0x0801_F800, 4), b"kept")
        self.assertEqual(chip.resets, 2)
        self.assertTrue(chip.rcc.regs[0x60] >> 28 & 1)  # SFTRSTF

    def test_hang_lets_the_watchdog_reset(self):
        def main(a):
            a.poke(IWDG_KR, 0x5555).poke(IWDG_PR, 0).poke(IWDG_RLR, 800)  # 100 ms
            a.poke(IWDG_KR, 0xCCCC)
            increment(a, COUNT)
            loop = a.here()
            a.poke(IWDG_KR, 0xAAAA).b_to(loop)

        chip = Chip(image(main))
        chip.run_until(ms(300))
        self.assertEqual(chip.resets, 0)
        chip.hung = True
        chip.run_until(ms(300) + ms(99))
        self.assertEqual(chip.resets, 0)
        chip.run_until(ms(300) + ms(101))
        self.assertEqual(chip.resets, 1)
        self.assertTrue(chip.rcc.regs[0x60] >> 29 & 1)  # IWDGRSTF
        chip.run_until(ms(402))
        self.assertEqual(word(chip, COUNT), 2)  # booted again, RAM kept

    def test_power_on_clears_ram(self):
        def main(a):
            increment(a, COUNT)
            a.b_self()

        chip = Chip(image(main))
        chip.run_until(ms(1))
        chip.memory.write(0x0801_F800, b"kept")  # what a program left in the last page
        chip.power_off()
        chip.run_until(ms(2))
        chip.power_on()
        self.assertEqual(word(chip, COUNT), 0)
        self.assertEqual(chip.memory.read(0x0801_F800, 4), b"kept")
        self.assertEqual(chip.rcc.regs[0x60] >> 24 & 0b1110, 0b1100)  # PWRRSTF | PINRSTF only
        chip.run_until(ms(3))
        self.assertEqual(word(chip, COUNT), 1)
        self.assertEqual(chip.resets, 1)


class EraseWhileReceivingTest(unittest.TestCase):
    """A page erase while the printer sends a request loses no byte: the CPU is stalled, the DMA
    moves every byte into the ring."""

    def test_bytes_during_an_erase_reach_the_ring(self):
        ring = RAM + 0x400

        def main(a):
            a.poke(USART1, 1 | 4 | 8 | (1 << 29))            # UE RE TE FIFOEN
            a.poke(DMAMUX + 4, 50)                            # channel 2 <- USART1_RX
            ch2 = DMA1 + 0x08 + 20
            a.poke(ch2 + 8, USART1 + 0x24).poke(ch2 + 12, ring).poke(ch2 + 4, 16)
            a.poke(ch2, 1 | (1 << 5) | (1 << 7))              # EN CIRC MINC
            a.poke(USART1 + 0x08, 1 << 6)                     # DMAR
            a.poke(FLASH + 0x08, 0x4567_0123).poke(FLASH + 0x08, 0xCDEF_89AB)
            a.poke(FLASH + 0x14, 2 | (60 << 3))               # PER, page 60
            a.poke(FLASH + 0x14, 2 | (60 << 3) | (1 << 16))   # STRT: the stall begins
            a.poke(MARK, 1)
            a.b_self()

        chip = Chip(image(main))
        chip.memory.write(0x0801_E000, b"\x00" * 16)
        chip.run_until(ms(1))
        self.assertEqual(chip.flash.erases, 1)
        self.assertIsNotNone(chip.stall_until)
        request = b"T1*a5\nS0*c6\n"
        for k, byte in enumerate(request):
            chip.usart1.deliver(ms(2) + clock.char_time(k + 1), byte)
        count = chip.cpu.native.count()
        chip.run_until(ms(15))
        self.assertEqual(chip.cpu.native.count(), count)      # not one instruction
        self.assertEqual(word(chip, MARK), 0)
        self.assertEqual(chip.memory.read(ring, len(request)), request)
        self.assertEqual(chip.usart1.lost, 0)
        self.assertEqual(word(chip, DMA1 + 0x08 + 20 + 4) if False else chip.dma.ch[2].remaining, 4)
        chip.run_until(ms(24))
        self.assertEqual(word(chip, MARK), 1)
        self.assertEqual(chip.memory.read(0x0801_E000, 16), b"\xff" * 16)


if __name__ == "__main__":
    unittest.main()
