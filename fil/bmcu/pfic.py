"""The PFIC, QingKe V4's interrupt controller (0xE000_E000): enables, pendings, actives,
priorities, and the system reset by PFIC_CFGR's key.

Register layout from ch32-metapac 0.1.2 `pfic_rv4` (WCH's SVD for the CH32V20x) and qingke 0.8.3
`src/pfic.rs`: ISR1-4 0x00-0x0C (enabled, read), IPR1-4 0x20-0x2C (pending, read), ITHRESDR
0x40, CFGR 0x48 (RESETSYS bit 7, KEYCODE [31:16]: a write with the key 0xBEEF and RESETSYS resets
the system, src/board/bmcu/mod.rs `reset`), GISR 0x4C (NESTSTA [7:0]: the active levels,
GACTSTA 8, GPENDSTA 9), IENR1-4 0x100 (write 1 to enable), IRER1-4 0x180 (write 1 to disable),
IPSR1-4 0x200 (write 1 to pend), IPRR1-4 0x280 (write 1 to unpend), IACTR1-4 0x300 (active,
read), IPRIOR 0x400 (a byte per interrupt), SCTLR 0xD10 (SLEEPONEXIT 1, SLEEPDEEP 2, WFITOWFE 3,
SEVONPEND 4, SETEVENT 5, SYSRESET 31: a system reset too).
Interrupt numbers (qingke-rt 0.8.3 `CoreInterrupt`, ch32-metapac's `Interrupt`): 2 NMI, 3
exception, 12 SysTick, 14 software, 16 and up the peripherals (27-33 DMA1 channels 1-7, 55
USART3).
Left out: the priority threshold (stored, not applied), VTF (table-free) entries, the wake-up
registers, interrupts above 127 (four 32-bit words).
"""

from regs import Block

CFGR, GISR, SCTLR = 0x48, 0x4C, 0xD10
KEY = 0xBEEF
RESETSYS = 1 << 7
SYSRESET = 1 << 31


class Pfic(Block):
    name = "PFIC"

    def __init__(self, chip=None):
        super().__init__(chip)
        self.enabled = 0
        self.pending = 0
        self.active = 0
        self.priorities = bytearray(128)

    def priority(self, n):
        return self.priorities[n] if n < len(self.priorities) else 0

    def enter(self, n):
        self.pending &= ~(1 << n)
        self.active |= 1 << n

    def leave(self, n):
        self.active &= ~(1 << n)

    @staticmethod
    def _word(value, offset, base):
        return (value >> (32 * ((offset - base) // 4))) & 0xFFFF_FFFF

    def read_reg(self, offset):
        if offset < 0x10:
            return self._word(self.enabled, offset, 0)
        if 0x20 <= offset < 0x30:
            return self._word(self.pending, offset, 0x20)
        if 0x300 <= offset < 0x310:
            return self._word(self.active, offset, 0x300)
        if 0x100 <= offset < 0x110:
            return self._word(self.enabled, offset, 0x100)
        if 0x400 <= offset < 0x480:
            n = offset - 0x400
            return int.from_bytes(self.priorities[n:n + 4], "little")
        if offset == GISR:
            levels = bin(self.active).count("1")
            return levels | (bool(self.active) << 8) | (bool(self.pending & self.enabled) << 9)
        if offset in (CFGR, 0x180, 0x184, 0x188, 0x18C, 0x200, 0x204, 0x208, 0x20C,
                      0x280, 0x284, 0x288, 0x28C):
            return 0
        return super().read_reg(offset)

    def write_reg(self, offset, value, mask):
        value &= mask
        group = 32 * ((offset & 0xF) // 4)
        if 0x100 <= offset < 0x110:
            self.enabled |= value << group
        elif 0x180 <= offset < 0x190:
            self.enabled &= ~(value << group)
        elif 0x200 <= offset < 0x210:
            self.pending |= value << group
        elif 0x280 <= offset < 0x290:
            self.pending &= ~(value << group)
        elif 0x400 <= offset < 0x480:
            n = offset - 0x400
            for i in range(4):
                if mask >> (8 * i) & 0xFF:
                    self.priorities[n + i] = value >> (8 * i) & 0xFF
        elif offset == CFGR:
            if value >> 16 == KEY and value & RESETSYS and self.chip:
                self.chip.request_reset("software")
        elif offset == SCTLR:
            super().write_reg(offset, value & ~SYSRESET, mask)
            if value & SYSRESET and self.chip:
                self.chip.request_reset("software")
        else:
            super().write_reg(offset, value, mask)
        if self.chip and offset < 0x300:
            self.chip.reschedule()
