"""The Cortex-M0+ System Control Space (0xE000E000): the NVIC's enable/pending/priority registers,
the SCB's AIRCR (software reset), SCR, ICSR, and SysTick as plain storage. Unicorn's Cortex-M0
model has no NVIC; the bench takes the interrupts itself (cpu.py) from the state kept here.

References: ARMv6-M Architecture Reference Manual (ARM DDI 0419) B3.4 (NVIC: ISER 0xE000E100,
ICER 0xE000E180, ISPR 0xE000E200, ICPR 0xE000E280, IPR 0xE000E400..0xE000E41C, 2 priority bits
on the STM32G0, bits [7:6] of each byte: RM0444 §12.1), B3.2 (SCB: CPUID 0xE000ED00, ICSR
0xE000ED04, VTOR 0xE000ED08, AIRCR 0xE000ED0C with VECTKEY 0x05FA and SYSRESETREQ bit 2, SCR
0xE000ED10, SHPR2/3 0xE000ED1C/20).
"""

from regs import Block

CPUID = 0x410CC601  # Cortex-M0+ r0p1


class Scs(Block):
    name = "SCS"

    def __init__(self, chip=None):
        super().__init__(chip)
        self.enabled = 0
        self.pending = 0
        self.priority = [0] * 32
        self.shpr = {0xD1C: 0, 0xD20: 0}

    def read_reg(self, offset):
        if offset == 0x100:
            return self.enabled
        if offset == 0x180:
            return self.enabled
        if offset in (0x200, 0x280):
            return self.pending
        if 0x400 <= offset < 0x420:
            n = (offset - 0x400)
            return sum(self.priority[n + i] << (8 * i) for i in range(4))
        if offset == 0xD00:
            return CPUID
        if offset == 0xD04:  # ICSR: VECTACTIVE from the bench's active exception
            return self.chip.cpu.active_vector() if self.chip else 0
        if offset == 0xD0C:
            return 0xFA050000
        return super().read_reg(offset)

    def write_reg(self, offset, value, mask):
        value &= mask
        if offset == 0x100:
            self.enabled |= value
        elif offset == 0x180:
            self.enabled &= ~value
        elif offset == 0x200:
            self.pending |= value
        elif offset == 0x280:
            self.pending &= ~value
        elif 0x400 <= offset < 0x420:
            n = offset - 0x400
            for i in range(4):
                if (mask >> (8 * i)) & 0xFF:
                    self.priority[n + i] = (value >> (8 * i)) & 0xC0
        elif offset == 0xD0C:
            if (value >> 16) == 0x05FA and value & 4 and self.chip:
                self.chip.request_reset("software")
        else:
            super().write_reg(offset, value, mask)
        if self.chip and offset not in (0x180, 0x280):
            self.chip.reschedule()

    def exception_priority(self, vector):
        """Priority of an exception number (16 + IRQ for interrupts); lower is more urgent."""
        if vector >= 16:
            return self.priority[vector - 16]
        if vector == 11:  # SVCall: SHPR2 [31:30]
            return (self.shpr[0xD1C] >> 24) & 0xC0
        if vector in (14, 15):  # PendSV, SysTick: SHPR3
            return (self.regs.get(0xD20, 0) >> (16 if vector == 14 else 24)) & 0xC0
        return -1
