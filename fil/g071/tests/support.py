"""Shared helpers of the bench's tests: the import path, a stand-in for the chip that unit tests
of one model plug into, a tiny Thumb assembler for synthetic images, and the Prusa protocol's
request encoding."""

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
BENCH = os.path.dirname(HERE)
REPO = os.path.dirname(os.path.dirname(BENCH))
if BENCH not in sys.path:
    sys.path.insert(0, BENCH)


def image_path():
    return os.environ.get("FIL_G071_IMAGE", os.path.join(REPO, "dist", "mmu-firmware-g071.elf"))


class FakeMemory:
    def __init__(self):
        self.data = {}

    def read(self, address, n):
        return bytes(self.data.get(address + i, 0xFF if address >= 0x0800_0000 and address < 0x2000_0000 else 0)
                     for i in range(n))

    def write(self, address, data):
        for i, b in enumerate(data):
            self.data[address + i] = b


class FakeChip:
    """What a model asks of the chip: the time, the DMA, memory, and its notifications."""

    def __init__(self):
        self.time = 0
        self.memory = FakeMemory()
        self.dma = None
        self.reschedules = 0
        self.stalled_until = None
        self.reset_cause = None

    def now(self):
        return self.time

    def reschedule(self, model=None):
        self.reschedules += 1

    def stall(self, until):
        self.stalled_until = until

    def request_reset(self, cause):
        self.reset_cause = cause


def w32(block, offset, value):
    block.write(offset, 4, value)


def r32(block, offset):
    return block.read(offset, 4)


class Asm:
    """Just enough Thumb (ARMv6-M) to write the synthetic images the core's tests run."""

    def __init__(self, base=0x0800_0000):
        self.base = base
        self.code = bytearray()

    def here(self):
        return self.base + len(self.code)

    def h(self, *halfwords):
        for hw in halfwords:
            self.code += (hw & 0xFFFF).to_bytes(2, "little")
        return self

    def align4(self):
        if len(self.code) % 4:
            self.h(0xBF00)  # NOP

    def word(self, value):
        self.code += (value & 0xFFFF_FFFF).to_bytes(4, "little")

    def load(self, rd, value):
        """rd <- value: LDR rd, [PC, #0]; B over the literal; the literal."""
        self.align4()
        self.h(0x4800 | (rd << 8), 0xE001)
        self.word(value)
        return self

    def movs(self, rd, imm):
        return self.h(0x2000 | (rd << 8) | imm)

    def adds(self, rd, imm):
        return self.h(0x3000 | (rd << 8) | imm)

    def str(self, rt, rn, imm=0):
        return self.h(0x6000 | ((imm // 4) << 6) | (rn << 3) | rt)

    def ldr(self, rt, rn, imm=0):
        return self.h(0x6800 | ((imm // 4) << 6) | (rn << 3) | rt)

    def poke(self, address, value, ra=6, rv=7):
        """*(u32 *)address = value, through r6/r7."""
        self.load(ra, address).load(rv, value).str(rv, ra)
        return self

    def cmp(self, rn, imm):
        return self.h(0x2800 | (rn << 8) | imm)

    def bge_to(self, target):
        offset = (target - (self.here() + 4)) // 2
        return self.h(0xDA00 | (offset & 0xFF))

    def wfe(self):
        return self.h(0xBF20)

    def wfi(self):
        return self.h(0xBF30)

    def sev(self):
        return self.h(0xBF40)

    def cpsid(self):
        return self.h(0xB672)

    def cpsie(self):
        return self.h(0xB662)

    def bx_lr(self):
        return self.h(0x4770)

    def b_self(self):
        return self.h(0xE7FE)

    def b_to(self, target):
        offset = (target - (self.here() + 4)) // 2
        return self.h(0xE000 | (offset & 0x7FF))


def image(reset, handlers=None, sp=0x2000_9000, vectors=48):
    """A flash image: the vector table, then the reset code and the handlers.
    `reset(asm)` and each `handlers[irq](asm)` emit their code."""
    asm = Asm()
    asm.code += bytes(4 * vectors)
    entries = {}
    entries[1] = asm.here()
    reset(asm)
    for irq, emit in (handlers or {}).items():
        asm.align4()
        entries[16 + irq] = asm.here()
        emit(asm)
    table = bytearray(asm.code)
    table[0:4] = sp.to_bytes(4, "little")
    for vector, address in entries.items():
        table[4 * vector:4 * vector + 4] = (address | 1).to_bytes(4, "little")
    return [(0x0800_0000, bytes(table))]


def crc8(data):
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def request(code, value):
    """A Prusa MMU protocol request as the printer sends it (protocol/src/message.rs)."""
    return f"{code}{value:x}*{crc8(bytes([ord(code), value, 0, 0])):x}\n".encode()
