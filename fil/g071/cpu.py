"""The Cortex-M0+ core: Unicorn's Cortex-M0 model runs the instructions, and this module adds
what Unicorn leaves out of an M-profile core (it has no NVIC and no exception entry):

- exception entry (ARMv6-M ARM B1.5.6): the 8-word frame r0-r3, r12, lr, return address, xPSR
  pushed on the main stack, aligned to 8 bytes (bit 9 of the stacked xPSR records the padding),
  LR = EXC_RETURN (0xFFFFFFF9 to thread mode, 0xFFFFFFF1 to a handler), PC = the vector;
- exception return (B1.5.8): a branch to 0xFFFFFFFx, which Unicorn stops on, pops the frame;
- priorities and preemption (B1.5.4): the pending enabled interrupt of the highest priority (the
  lowest IPR value, then the lowest number) preempts when it is more urgent than the running
  exception; PRIMASK masks them all; nesting is kept on a stack of active exceptions;
- WFE/WFI/SEV/CPSIE through native.py's hooks;
- virtual time: the native instruction counter (clock.py's cost per instruction).
"""

import unicorn
from unicorn import arm_const as arm

import clock
import native
from scheduler import FlashStores

FLASH_BASE, FLASH_SIZE = 0x0800_0000, 128 * 1024
RAM_BASE, RAM_SIZE = 0x2000_0000, 36 * 1024
SYSMEM_BASE, SYSMEM_SIZE = 0x1FFF_0000, 0x8000  # system memory + engineering bytes
FLASHSIZE_REG = 0x1FFF_75E0  # flash size in KiB (RM0444 §40.1)

THREAD = 256  # execution priority of thread mode: below every exception

FRAME_REGS = (arm.UC_ARM_REG_R0, arm.UC_ARM_REG_R1, arm.UC_ARM_REG_R2, arm.UC_ARM_REG_R3,
              arm.UC_ARM_REG_R12, arm.UC_ARM_REG_LR, arm.UC_ARM_REG_PC)


class EmulationError(Exception):
    """The bench cannot go on (PROTOCOL.md: answered `error ...`)."""


class Cpu(FlashStores):
    def __init__(self, chip, image, segments):
        self.chip = chip
        uc = unicorn.Uc(unicorn.UC_ARCH_ARM, unicorn.UC_MODE_THUMB | unicorn.UC_MODE_MCLASS)
        uc.ctl_set_cpu_model(arm.UC_CPU_ARM_CORTEX_M0)
        uc.mem_map(FLASH_BASE, FLASH_SIZE)
        uc.mem_map(RAM_BASE, RAM_SIZE)
        uc.mem_map(SYSMEM_BASE, SYSMEM_SIZE, unicorn.UC_PROT_READ)
        uc.mem_write(FLASHSIZE_REG, (FLASH_SIZE // 1024).to_bytes(2, "little"))
        self.uc = uc
        self.native = native.Native(uc, image, FLASH_BASE,
                                    native.special_instructions([(FLASH_BASE, image)], FLASH_BASE,
                                                                FLASH_SIZE))
        # Stores to the flash go to the FLASH controller model (flash.py), not to the memory.
        self.flash_writes = []
        uc.hook_add(unicorn.UC_HOOK_MEM_WRITE, self._on_flash_write,
                    begin=FLASH_BASE, end=FLASH_BASE + FLASH_SIZE - 1)
        self.active = []  # active exception numbers, innermost last
        self.sleeping = False
        self.count_base = 0

    # ---- reset -------------------------------------------------------------------------------
    def reset(self):
        uc = self.uc
        for r in range(arm.UC_ARM_REG_R0, arm.UC_ARM_REG_R12 + 1):
            uc.reg_write(r, 0)
        uc.reg_write(arm.UC_ARM_REG_PRIMASK, 0)
        uc.reg_write(arm.UC_ARM_REG_LR, 0xFFFFFFFF)
        sp, pc = (int.from_bytes(uc.mem_read(FLASH_BASE + i, 4), "little") for i in (0, 4))
        uc.reg_write(arm.UC_ARM_REG_SP, sp)
        uc.reg_write(arm.UC_ARM_REG_PC, pc & ~1)
        self.active = []
        self.sleeping = False
        self.native.set_event(0)

    # ---- exceptions --------------------------------------------------------------------------
    def active_vector(self):
        return self.active[-1] if self.active else 0

    def execution_priority(self):
        if not self.active:
            return THREAD
        return min(self.chip.scs.exception_priority(v) for v in self.active)

    def ready_interrupt(self, ignore_primask=False):
        """The IRQ number that would be taken now, or None."""
        scs = self.chip.scs
        ready = scs.pending & scs.enabled
        if not ready:
            return None
        if not ignore_primask and self.uc.reg_read(arm.UC_ARM_REG_PRIMASK) & 1:
            return None
        best = None
        for n in range(32):
            if ready >> n & 1:
                p = scs.priority[n]
                if best is None or p < best[0]:
                    best = (p, n)
        if best[0] < self.execution_priority():
            return best[1]
        return None

    def take_interrupt(self, irq):
        self.chip.scs.pending &= ~(1 << irq)
        self.take_exception(16 + irq)

    def take_exception(self, vector):
        uc = self.uc
        scs = self.chip.scs
        values = uc.reg_read_batch(FRAME_REGS + (arm.UC_ARM_REG_SP, arm.UC_ARM_REG_XPSR))
        frame, sp = list(values[:7]), values[7]
        xpsr = (values[8] & 0xFF00_FC00) | self.active_vector()
        sp -= 32
        if sp & 4:
            sp -= 4
            xpsr |= 1 << 9
        data = b"".join(v.to_bytes(4, "little") for v in frame + [xpsr | (1 << 24)])
        try:
            uc.mem_write(sp, data)
        except unicorn.UcError as e:
            raise EmulationError(f"exception entry: stack at 0x{sp:08x} not writable ({e})")
        vtor = scs.regs.get(0xD08, 0) or FLASH_BASE
        handler = int.from_bytes(uc.mem_read(vtor + 4 * vector, 4), "little")
        uc.reg_write_batch(((arm.UC_ARM_REG_SP, sp),
                            (arm.UC_ARM_REG_LR, 0xFFFFFFF1 if self.active else 0xFFFFFFF9),
                            (arm.UC_ARM_REG_PC, handler & ~1)))
        self.active.append(vector)
        self.sleeping = False

    def exception_return(self):
        uc = self.uc
        if not self.active:
            raise EmulationError("exception return in thread mode")
        sp = uc.reg_read(arm.UC_ARM_REG_SP)
        words = uc.mem_read(sp, 32)
        values = [int.from_bytes(words[4 * i:4 * i + 4], "little") for i in range(8)]
        xpsr = values[7]
        sp += 32 + (4 if xpsr & (1 << 9) else 0)
        values[6] &= ~1
        uc.reg_write_batch(tuple(zip(FRAME_REGS, values[:7])) +
                           ((arm.UC_ARM_REG_SP, sp),
                            (arm.UC_ARM_REG_XPSR, (xpsr & 0xF000_0000) | (1 << 24))))
        self.active.pop()
        # The line is a level: still asserted, it is pending again (chip.update_irqs).
        self.chip.update_irqs()

    # ---- running -----------------------------------------------------------------------------
    def run(self, instructions):
        """Runs up to `instructions` (block granular); returns the number executed."""
        uc = self.uc
        nat = self.native
        pc = uc.reg_read(arm.UC_ARM_REG_PC)
        try:
            self._emulate(instructions, pc | 1, 0xFFFF_FFFF,
                          self.ready_interrupt(ignore_primask=True) is not None)
        except unicorn.UcError as e:
            pc = uc.reg_read(arm.UC_ARM_REG_PC)
            if pc >= 0xFFFF_FFF0 or (e.errno == unicorn.UC_ERR_FETCH_UNMAPPED and pc >= 0xFFFF_FF00):
                self._apply_flash_writes()
                self.exception_return()
                return self.executed()
            if e.errno == unicorn.UC_ERR_INSN_INVALID and self._is_udf(pc):
                # UDF: the chip takes a HardFault (ARMv6-M ARM A6.7.72, B1.5.6); the image's
                # handler runs (a panic in the firmware ends here and resets).
                self._apply_flash_writes()
                self.take_exception(3)
                return self.executed()
            raise EmulationError(f"{e} at pc 0x{pc:08x}")
        self._apply_flash_writes()
        stop = nat.stopped_by()
        pc = uc.reg_read(arm.UC_ARM_REG_PC)
        if stop == native.STOP_WFE:
            uc.reg_write(arm.UC_ARM_REG_PC, pc + 2)
            self.sleeping = "wfe"
        elif stop == native.STOP_WFE_CONSUMED:
            uc.reg_write(arm.UC_ARM_REG_PC, pc + 2)
        elif stop == native.STOP_WFI:
            uc.reg_write(arm.UC_ARM_REG_PC, pc + 2)
            self.sleeping = "wfi"
        elif stop == native.STOP_CPSIE:
            uc.reg_write(arm.UC_ARM_REG_PRIMASK, 0)
            uc.reg_write(arm.UC_ARM_REG_PC, pc + 2)
        return self.executed()

    def _is_udf(self, pc):
        try:
            return self.uc.mem_read(pc, 2)[1] == 0xDE
        except unicorn.UcError:
            return False

    def wakes(self):
        """Whether a sleeping core wakes now: an interrupt that would preempt if PRIMASK were
        clear (WFI and WFE, ARMv6-M B1.5.18), or the event register (WFE)."""
        if self.ready_interrupt(ignore_primask=True) is not None:
            return True
        if self.sleeping == "wfe" and self.native.event():
            self.native.set_event(0)
            return True
        return False
