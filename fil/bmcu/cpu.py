"""The QingKe V4B core around Unicorn 2.1.4's RV32 (`UC_ARCH_RISCV`, `UC_MODE_RISCV32`, which
runs rv32imc): Unicorn executes the instructions, native.py counts them and emulates the WCH
CSRs, and this module adds what Unicorn leaves out of a QingKe core: the PFIC's interrupt entry
with the hardware prologue and epilogue, and the traps of the image's exception handler.

- Interrupt entry (QingKe V4, as qingke-rt 0.8.3 relies on it, `src/lib.rs`): mtvec mode 3,
  "vectored, absolute addresses": the word at `table + 4 * n` is the handler's address, the
  table at `_start` (qingke-rt's `.vector_table`: `j handle_reset`, then the core interrupts 1-15
  and the external ones from 16). Unicorn ignores mtvec mode 3 (QEMU keeps mtvec unchanged for a
  reserved mode), so the bench takes the table at the image's `_start` and enters the handler
  itself: mepc = the interrupted instruction, mcause = 0x8000_0000 | n, mstatus.MPIE = MIE,
  MPP = machine.
- Hardware prologue/epilogue (HPE, intsyscr bit 0): the core, not the handler, saves the
  caller-saved registers x1, x5-x7, x10-x17, x28-x31 on entry and restores them on `mret`
  (qingke-rt's handlers save only `ra`, around their call: `SysTick:` in the image). Here they go
  to a stack of the bench's (the chip's own is internal, not memory). Nesting (intsyscr bit 1,
  INESTEN, which qingke-rt sets): with it the core leaves mstatus.MIE set inside the handler and
  the PFIC lets only a more urgent interrupt (a lower IPRIOR byte) preempt, two levels deep; that
  MIE stays set in a handler with INESTEN is what ch32-rs/qingke PR #25 describes, measured on a
  CH32V203C8T6 ("MIE and MPIE move together inside an ISR body"). Without INESTEN, MIE is cleared
  on entry (the RISC-V privileged spec). The QingKe V4 processor manual itself was not found in
  the searched corpora: the nesting depth (2, the V4B's HPE levels per the CH32V203 datasheet's
  "hardware interrupt stack") and the priority comparison are taken from the crate and the
  datasheet's overview, not from the manual.
- `mret` (native.py stops before it): mstatus.MIE = MPIE, MPIE = 1, PC = mepc, and for the
  innermost interrupt the HPE registers, mepc and mcause of the interrupted level come back.
- Exceptions (a real illegal instruction, ecall, ebreak, misaligned access): vector 3 with
  mcause = the cause, mepc = the faulting instruction; qingke-rt's `_exception_handler` then
  dispatches on mcause to the image's `ExceptionHandler`, which stops the motors and resets.
- Reset: the core starts at `_start` (the ELF's entry point; the chip boots from 0x0000_0000,
  flash's alias, where the same instruction lies), every register 0, mstatus 0.
Left out: the VTF (table-free) interrupts, the PFIC's priority threshold (ITHRESDR), interrupt
entry and return timing (0 cycles), user mode (qingke-rt runs the image in machine mode).
"""

import unicorn
from unicorn import riscv_const as rv

import clock
import native
from scheduler import FlashStores

FLASH_BASE, FLASH_SIZE = 0x0800_0000, 64 * 1024
RAM_BASE, RAM_SIZE = 0x2000_0000, 20 * 1024
ENTRY = FLASH_BASE
HPE_REGS = tuple(rv.UC_RISCV_REG_X0 + n for n in (1, 5, 6, 7, 10, 11, 12, 13, 14, 15, 16, 17, 28, 29,
                                                  30, 31))
MSTATUS_MIE, MSTATUS_MPIE, MSTATUS_MPP = 1 << 3, 1 << 7, 3 << 11
EXCEPTION_VECTOR = 3
NEST_LEVELS = 2


class EmulationError(Exception):
    """The bench cannot go on (PROTOCOL.md: answered `error ...`)."""


class Frame:
    """What the core keeps of an interrupted level: the interrupt, the HPE registers, mepc and
    mcause."""

    def __init__(self, number, saved, mepc, mcause):
        self.number, self.saved, self.mepc, self.mcause = number, saved, mepc, mcause


class Cpu(FlashStores):
    def __init__(self, chip, image, idle=None):
        self.chip = chip
        uc = unicorn.Uc(unicorn.UC_ARCH_RISCV, unicorn.UC_MODE_RISCV32)
        uc.mem_map(FLASH_BASE, FLASH_SIZE)
        uc.mem_map(RAM_BASE, RAM_SIZE)
        self.uc = uc
        self.native = native.Native(uc, image, FLASH_BASE, (clock.CPI_NUM, clock.CPI_DEN),
                                    native.special_instructions(image, FLASH_BASE), idle)
        self.flash_writes = []
        uc.hook_add(unicorn.UC_HOOK_MEM_WRITE, self._on_flash_write,
                    begin=FLASH_BASE, end=FLASH_BASE + FLASH_SIZE - 1)
        self.frames = []          # interrupted levels, innermost last
        self.sleeping = False     # "idle" (the executor found nothing to do) or "wfi"
        self.count_base = 0
        self.traps = 0            # exceptions taken (not interrupts)

    # ---- reset -------------------------------------------------------------------------------
    def reset(self):
        uc = self.uc
        for n in range(1, 32):
            uc.reg_write(rv.UC_RISCV_REG_X0 + n, 0)
        for reg in (rv.UC_RISCV_REG_MSTATUS, rv.UC_RISCV_REG_MEPC, rv.UC_RISCV_REG_MCAUSE):
            uc.reg_write(reg, 0)
        uc.reg_write(rv.UC_RISCV_REG_PC, ENTRY)
        self.native.reset_core()
        self.frames = []
        self.sleeping = False

    # ---- state -------------------------------------------------------------------------------
    def reg(self, reg):
        return self.uc.reg_read(reg)

    def mie(self):
        return bool(self.reg(rv.UC_RISCV_REG_MSTATUS) & MSTATUS_MIE)

    def intsyscr(self):
        return self.native.csr(native.CSR_INTSYSCR)

    def active(self):
        return [f.number for f in self.frames]

    # ---- interrupts --------------------------------------------------------------------------
    def ready_interrupt(self, ignore_mie=False):
        """The interrupt number the PFIC would have the core take now, or None."""
        pfic = self.chip.pfic
        ready = pfic.pending & pfic.enabled
        if not ready or (not ignore_mie and not self.mie()):
            return None
        best = min((pfic.priority(n), n) for n in range(256) if ready >> n & 1)
        if not self.frames:
            return best[1]
        if (self.intsyscr() & 2 and len(self.frames) < NEST_LEVELS
                and best[0] < min(pfic.priority(f.number) for f in self.frames)):
            return best[1]
        return None

    def _enter(self, number, mcause, mepc, vector):
        uc = self.uc
        saved = uc.reg_read_batch(HPE_REGS) if self.intsyscr() & 1 else None
        self.frames.append(Frame(number, saved, self.reg(rv.UC_RISCV_REG_MEPC),
                                 self.reg(rv.UC_RISCV_REG_MCAUSE)))
        mstatus = self.reg(rv.UC_RISCV_REG_MSTATUS)
        mie = mstatus & MSTATUS_MIE
        mstatus = (mstatus & ~MSTATUS_MPIE) | (MSTATUS_MPIE if mie else 0) | MSTATUS_MPP
        if not self.intsyscr() & 2:
            mstatus &= ~MSTATUS_MIE
        table = self.chip.vector_table
        try:
            handler = int.from_bytes(uc.mem_read(table + 4 * vector, 4), "little")
        except unicorn.UcError as e:
            raise EmulationError(f"vector {vector}: table at 0x{table:08x} not readable ({e})")
        uc.reg_write_batch(((rv.UC_RISCV_REG_MEPC, mepc), (rv.UC_RISCV_REG_MCAUSE, mcause),
                            (rv.UC_RISCV_REG_MSTATUS, mstatus), (rv.UC_RISCV_REG_PC, handler)))
        self.sleeping = False

    def take_interrupt(self, number):
        self.chip.pfic.enter(number)
        self._enter(number, 0x8000_0000 | number, self.reg(rv.UC_RISCV_REG_PC), number)

    def take_exception(self, cause, epc):
        self.traps += 1
        self._enter(EXCEPTION_VECTOR, cause, epc, EXCEPTION_VECTOR)

    def mret(self):
        uc = self.uc
        mstatus = self.reg(rv.UC_RISCV_REG_MSTATUS)
        pc = self.reg(rv.UC_RISCV_REG_MEPC)
        mstatus = (mstatus & ~MSTATUS_MIE) | (MSTATUS_MIE if mstatus & MSTATUS_MPIE else 0) | MSTATUS_MPIE
        writes = [(rv.UC_RISCV_REG_MSTATUS, mstatus), (rv.UC_RISCV_REG_PC, pc)]
        if self.frames:
            frame = self.frames.pop()
            if frame.saved is not None:
                writes += list(zip(HPE_REGS, frame.saved))
            writes += [(rv.UC_RISCV_REG_MEPC, frame.mepc), (rv.UC_RISCV_REG_MCAUSE, frame.mcause)]
            if frame.number != EXCEPTION_VECTOR or frame.mcause & 0x8000_0000:
                self.chip.pfic.leave(frame.number)
        uc.reg_write_batch(writes)
        # A line still asserted is pending again (chip.update_irqs).
        self.chip.update_irqs()

    # ---- running -----------------------------------------------------------------------------
    def run(self, instructions):
        """Runs up to `instructions` (block granular); returns the number executed."""
        uc = self.uc
        nat = self.native
        try:
            self._emulate(instructions, self.reg(rv.UC_RISCV_REG_PC), 0xFFFF_FFFE,
                          self.ready_interrupt(ignore_mie=True) is not None)
        except unicorn.UcError as e:
            self._apply_flash_writes()
            raise EmulationError(f"{e} at pc 0x{self.reg(rv.UC_RISCV_REG_PC):08x}")
        self._apply_flash_writes()
        stop = nat.stopped_by()
        if stop == native.STOP_MRET:
            self.mret()
        elif stop == native.STOP_IDLE:
            self.sleeping = "idle"
        elif stop == native.STOP_WFI:
            uc.reg_write(rv.UC_RISCV_REG_PC, self.reg(rv.UC_RISCV_REG_PC) + 4)
            self.sleeping = "wfi"
        elif stop == native.STOP_EXCEPTION:
            self.take_exception(nat.exc_cause(), self._faulting_pc(nat.exc_pc()))
        return self.executed()

    @staticmethod
    def _faulting_pc(pc):
        """The trapping instruction's address from the PC Unicorn 2.1.4 reports in its interrupt
        hook: 4 bytes past it, whatever its length (measured: c.unimp, a 32-bit illegal
        instruction and ecall alike)."""
        return pc - 4

    def wakes(self):
        """Whether a sleeping core wakes: an interrupt ready (WFI wakes on a pending one even
        with MIE clear, the RISC-V privileged spec §3.3.3)."""
        return self.ready_interrupt(ignore_mie=self.sleeping == "wfi") is not None
