"""Shared helpers of the BMCU-C bench's tests: the import path (fil/bmcu first, then the
chip-neutral modules of fil/g071), fil/g071's test helpers (the stand-in chip, register access,
the Prusa protocol's requests), and a tiny RV32IC assembler for synthetic images."""

import importlib.util
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
BENCH = os.path.dirname(HERE)
G071 = os.path.join(os.path.dirname(BENCH), "g071")
REPO = os.path.dirname(os.path.dirname(BENCH))
for path in (G071, BENCH):
    if path in sys.path:
        sys.path.remove(path)
sys.path[:0] = [BENCH, G071]

_spec = importlib.util.spec_from_file_location("g071_support", os.path.join(G071, "tests", "support.py"))
g071_support = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(g071_support)
FakeChip, FakeMemory, r32, w32, request = (g071_support.FakeChip, g071_support.FakeMemory,
                                          g071_support.r32, g071_support.w32, g071_support.request)


def image_path():
    return os.environ.get("FIL_BMCU_IMAGE", os.path.join(REPO, "dist", "mmu-firmware-bmcu.elf"))


class Fake(FakeChip):
    """fil/g071's stand-in chip with what the BMCU-C's models ask too: the clock and the RCC."""

    hz = 120_000_000
    cycles_per_us = 120

    def __init__(self):
        super().__init__()
        from rcc import Rcc
        self.rcc = Rcc(self)
        self.extend = None


# ---- RV32IC --------------------------------------------------------------------------------
ZERO, RA, SP, T0, T1, T2, S0, S1, A0, A1, A2, A3, A4, A5, A6, A7 = 0, 1, 2, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17
S2, S3, S4 = 18, 19, 20


class Asm:
    """Just enough RV32I (and two compressed instructions) for the core's synthetic images."""

    def __init__(self, base=0x0800_0000):
        self.base = base
        self.code = bytearray()

    def here(self):
        return self.base + len(self.code)

    def w(self, insn):
        self.code += (insn & 0xFFFF_FFFF).to_bytes(4, "little")
        return self

    def h(self, half):
        self.code += (half & 0xFFFF).to_bytes(2, "little")
        return self

    def i(self, op, rd, f3, rs1, imm):
        return self.w((imm & 0xFFF) << 20 | rs1 << 15 | f3 << 12 | rd << 7 | op)

    def addi(self, rd, rs1, imm):
        return self.i(0x13, rd, 0, rs1, imm)

    def lui(self, rd, imm20):
        return self.w((imm20 & 0xFFFFF) << 12 | rd << 7 | 0x37)

    def li(self, rd, value):
        value &= 0xFFFF_FFFF
        low = value & 0xFFF
        if low >= 0x800:
            low -= 0x1000
        self.lui(rd, (value - low) >> 12 & 0xFFFFF)
        return self.addi(rd, rd, low)

    def lw(self, rd, rs1, imm=0):
        return self.i(0x03, rd, 2, rs1, imm)

    def sw(self, rs2, rs1, imm=0):
        imm &= 0xFFF
        return self.w((imm >> 5) << 25 | rs2 << 20 | rs1 << 15 | 2 << 12 | (imm & 31) << 7 | 0x23)

    def csr(self, f3, rd, csr, rs1):
        return self.w(csr << 20 | rs1 << 15 | f3 << 12 | rd << 7 | 0x73)

    def csrrw(self, rd, csr, rs1):
        return self.csr(1, rd, csr, rs1)

    def csrrs(self, rd, csr, rs1):
        return self.csr(2, rd, csr, rs1)

    def csrrc(self, rd, csr, rs1):
        return self.csr(3, rd, csr, rs1)

    def branch(self, f3, rs1, rs2, target):
        off = (target - self.here()) & 0x1FFF
        return self.w((off >> 12 & 1) << 31 | (off >> 5 & 0x3F) << 25 | rs2 << 20 | rs1 << 15 | f3 << 12
                      | (off >> 1 & 0xF) << 8 | (off >> 11 & 1) << 7 | 0x63)

    def beq(self, rs1, rs2, target):
        return self.branch(0, rs1, rs2, target)

    def bne(self, rs1, rs2, target):
        return self.branch(1, rs1, rs2, target)

    def j(self, target):
        off = (target - self.here()) & 0x1F_FFFF
        return self.w((off >> 20 & 1) << 31 | (off >> 1 & 0x3FF) << 21 | (off >> 11 & 1) << 20
                      | (off >> 12 & 0xFF) << 12 | 0x6F)

    def mret(self):
        return self.w(0x3020_0073)

    def poke(self, address, value, ra=T1, rv=T2):
        return self.li(ra, address).li(rv, value).sw(rv, ra)

    def increment(self, address):
        return self.li(T1, address).lw(T2, T1).addi(T2, T2, 1).sw(T2, T1)

    def spin(self):
        return self.j(self.here())


def image(reset, handlers=None, vectors=64):
    """A flash image: a qingke-rt-shaped vector table at 0x0800_0000 (`j reset`, then absolute
    handler addresses), the reset code and the handlers. `reset(asm)` and each
    `handlers[n](asm)` emit their code (n: the interrupt's number, 3 the exception)."""
    asm = Asm()
    asm.code += bytes(4 * vectors)
    entries = {}
    reset_at = asm.here()
    reset(asm)
    for n, emit in (handlers or {}).items():
        entries[n] = asm.here()
        emit(asm)
    table = bytearray(asm.code)
    jump = Asm()
    jump.j(reset_at)
    table[0:4] = jump.code
    for n, address in entries.items():
        table[4 * n:4 * n + 4] = address.to_bytes(4, "little")
    return [(0x0800_0000, bytes(table))]
