#!/usr/bin/env python3
"""Checks the firmware's own run-time routines as linked in the ELF, in the Unicorn emulator (a
Cortex-M0), against Python:
- memcpy and memclr (src/mem.rs): every length 0..=40 at every destination and source alignment
  within a word, through every entry point (memcpy, __aeabi_memcpy/4/8, __aeabi_memclr/4/8). It
  fails if a byte outside the destination changes, the source changes, the copy or clear is
  wrong, or memcpy does not return the destination;
- division (src/div.rs): __aeabi_uidivmod, __aeabi_idivmod, __aeabi_uldivmod, __aeabi_ldivmod on
  edge values (0, 1, powers of two and their neighbours, the extremes) crossed with each other
  and on random operands of every width, quotient and remainder (Rust's truncating semantics);
- every call: the callee-saved registers (r4-r11) and the stack pointer restored, no halfword
  or word access at an unaligned address (the Cortex-M0+ faults on one; Unicorn does not), and
  every entry (also from another routine) with the stack 8-byte aligned (AAPCS).

    check-runtime-routines.py ELF

Run by scripts/firmware-size.sh on every build. Needs python3 with `unicorn` (PyPI).
"""

import random
import sys
from pathlib import Path

import unicorn
from unicorn import arm_const as arm

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench-mcu"))
from run import FLASH, cortex_m0, elf_symbols_and_segments  # noqa: E402 (bench-mcu/run.py)

RETURN = 0x2000_8000  # a `b .` the routines return to (LR); the emulation stops there
STACK_TOP = 0x2000_7000
DST = 0x2000_1000
SRC = 0x2000_3000
GUARD = 16  # bytes checked on each side of the destination
MAX_LEN = 40
DIVISIONS = ("__aeabi_uidiv", "__aeabi_uidivmod", "__aeabi_idiv", "__aeabi_idivmod",
             "__aeabi_uldivmod", "__aeabi_ldivmod")
# The signed 64-bit division is linked only while some code divides signed 64-bit numbers (the
# linker drops an entry point nothing calls, with its section): checked when it is there.
OPTIONAL = ("__aeabi_ldivmod",)
COPIES = ("memcpy", "__aeabi_memcpy", "__aeabi_memcpy4", "__aeabi_memcpy8")
CLEARS = ("__aeabi_memclr", "__aeabi_memclr4", "__aeabi_memclr8")
CALLEE_SAVED = [arm.UC_ARM_REG_R4, arm.UC_ARM_REG_R5, arm.UC_ARM_REG_R6, arm.UC_ARM_REG_R7,
                arm.UC_ARM_REG_R8, arm.UC_ARM_REG_R9, arm.UC_ARM_REG_R10, arm.UC_ARM_REG_R11]


def load(path):
    """The ELF's flash segments (address, bytes) and its symbol addresses, read by the step-cost
    benchmark's ELF reader."""
    segments, symbols = elf_symbols_and_segments(path)
    return [(a, b) for a, b in segments if FLASH[0] <= a < FLASH[0] + FLASH[1]], symbols


def truncating(n, d):
    """Rust's (and C's) signed division: quotient toward zero, remainder with n's sign."""
    q = abs(n) // abs(d)
    if (n < 0) != (d < 0):
        q = -q
    return q, n - q * d


def edge_values(bits):
    """0, 1, 2, the powers of two with their neighbours, the extremes, as unsigned `bits` wide."""
    mask = (1 << bits) - 1
    values = {0, 1, 2, 3, mask, mask - 1, 1000, 100, 10}
    for shift in range(bits):
        for delta in (-1, 0, 1):
            values.add(((1 << shift) + delta) & mask)
    return sorted(values)


def check_division(call, reg, rng, failures, linked):
    """Every linked division entry point against Python on edge and random operands."""
    def signed(value, bits):
        return value - (1 << bits) if value >> (bits - 1) else value

    for bits, names in ((32, DIVISIONS[:4]), (64, DIVISIONS[4:])):
        mask = (1 << bits) - 1
        edges = edge_values(bits)
        pairs = [(n, d) for n in edges[::3] for d in edges[::3]]
        for _ in range(3000):
            n_bits, d_bits = rng.randint(1, bits), rng.randint(1, bits)
            pairs.append((rng.getrandbits(n_bits), rng.getrandbits(d_bits)))
        for n, d in pairs:
            if d == 0:
                continue  # Rust panics before it divides by zero
            for name in (name for name in names if name in linked):
                is_signed = name in ("__aeabi_idiv", "__aeabi_idivmod", "__aeabi_ldivmod")
                if is_signed:
                    sn, sd = signed(n, bits), signed(d, bits)
                    if sn == -(1 << (bits - 1)) and sd == -1:
                        continue  # MIN / -1 overflows: Rust panics first
                    q, r = truncating(sn, sd)
                else:
                    q, r = n // d, n % d
                q, r = q & mask, r & mask
                if bits == 32:
                    call(name, n, d)
                    got_q = reg(arm.UC_ARM_REG_R0)
                    got_r = reg(arm.UC_ARM_REG_R1)
                    wants_r = name.endswith("mod")
                else:
                    call(name, n & 0xFFFF_FFFF, n >> 32, d & 0xFFFF_FFFF, d >> 32)
                    got_q = reg(arm.UC_ARM_REG_R0) | reg(arm.UC_ARM_REG_R1) << 32
                    got_r = reg(arm.UC_ARM_REG_R2) | reg(arm.UC_ARM_REG_R3) << 32
                    wants_r = True
                if got_q != q or (wants_r and got_r != r):
                    failures.append(f"{name}({n:#x}, {d:#x}): got {got_q:#x} rem {got_r:#x}, "
                                    f"expected {q:#x} rem {r:#x}")


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    segments, symbols = load(sys.argv[1])
    missing = [name for name in COPIES + CLEARS + DIVISIONS
               if name not in symbols and name not in OPTIONAL]
    if missing:
        sys.exit(f"check-runtime-routines: FAIL: not in the ELF: {', '.join(missing)}")

    uc = cortex_m0(segments)
    uc.mem_write(RETURN, b"\xfe\xe7")  # b .

    rng = random.Random(14)
    failures = []
    calls = 0

    # The Cortex-M0+ faults on a halfword or word access (ldm/stm included) at an address that is
    # not a multiple of its size; Unicorn's Cortex-M0 carries it out. So every access is checked.
    def on_access(uc_, access, address, size, value, data):
        if size > 1 and address % size:
            failures.append(f"unaligned {size}-byte access at {address:#x} "
                            f"(pc {uc_.reg_read(arm.UC_ARM_REG_PC):#x}): a HardFault on the MCU")
    uc.hook_add(unicorn.UC_HOOK_MEM_READ | unicorn.UC_HOOK_MEM_WRITE, on_access)

    # Every entry, also from another routine (the 64-bit division calls the 32-bit one), finds
    # the stack 8-byte aligned, as the AAPCS requires at a public interface.
    def on_entry(uc_, address, size, data):
        sp = uc_.reg_read(arm.UC_ARM_REG_SP)
        if sp % 8:
            failures.append(f"entered {data} with the stack at {sp:#x}, not 8-byte aligned")
    for name in (name for name in COPIES + CLEARS + DIVISIONS if name in symbols):
        entry = symbols[name] & ~1
        uc.hook_add(unicorn.UC_HOOK_CODE, on_entry, name, entry, entry)

    def call(name, *args):
        """Runs `name(args)`; returns r0, after checking the registers it must restore."""
        nonlocal calls
        calls += 1
        saved = [rng.getrandbits(32) for _ in CALLEE_SAVED]
        for reg, value in zip(CALLEE_SAVED, saved):
            uc.reg_write(reg, value)
        for reg, value in zip((arm.UC_ARM_REG_R0, arm.UC_ARM_REG_R1, arm.UC_ARM_REG_R2,
                               arm.UC_ARM_REG_R3), args):
            uc.reg_write(reg, value)
        uc.reg_write(arm.UC_ARM_REG_SP, STACK_TOP)
        uc.reg_write(arm.UC_ARM_REG_LR, RETURN | 1)
        uc.emu_start(symbols[name] | 1, RETURN, count=1_000_000)
        if uc.reg_read(arm.UC_ARM_REG_PC) != RETURN:
            failures.append(f"{name}{args}: did not return")
        if uc.reg_read(arm.UC_ARM_REG_SP) != STACK_TOP:
            failures.append(f"{name}{args}: stack pointer not restored")
        if [uc.reg_read(reg) for reg in CALLEE_SAVED] != saved:
            failures.append(f"{name}{args}: a callee-saved register changed")
        return uc.reg_read(arm.UC_ARM_REG_R0)
    for dst_align in range(4):
        for src_align in range(4):
            for length in range(MAX_LEN + 1):
                dst, src = DST + dst_align, SRC + src_align
                around = bytes(rng.getrandbits(8) for _ in range(MAX_LEN + 2 * GUARD))
                source = bytes(rng.getrandbits(8) for _ in range(MAX_LEN + 2 * GUARD))
                for name in COPIES:
                    if name.endswith(("4", "8")) and (dst_align or src_align):
                        continue  # the ABI promises word alignment to these entry points
                    uc.mem_write(dst - GUARD, around)
                    uc.mem_write(src - GUARD, source)
                    returned = call(name, dst, src, length)
                    case = f"{name}(dst+{dst_align}, src+{src_align}, {length})"
                    expected = (around[:GUARD] + source[GUARD:GUARD + length]
                                + around[GUARD + length:])
                    if bytes(uc.mem_read(dst - GUARD, len(around))) != expected:
                        failures.append(f"{case}: wrong bytes")
                    if bytes(uc.mem_read(src - GUARD, len(source))) != source:
                        failures.append(f"{case}: source changed")
                    if name == "memcpy" and returned != dst:
                        failures.append(f"{case}: returned {returned:#x}")
            for length in range(MAX_LEN + 1):
                if src_align:
                    break  # memclr has no source
                dst = DST + dst_align
                around = bytes(rng.getrandbits(8) | 1 for _ in range(MAX_LEN + 2 * GUARD))
                for name in CLEARS:
                    if name.endswith(("4", "8")) and dst_align:
                        continue
                    uc.mem_write(dst - GUARD, around)
                    call(name, dst, length)
                    expected = around[:GUARD] + bytes(length) + around[GUARD + length:]
                    if bytes(uc.mem_read(dst - GUARD, len(around))) != expected:
                        failures.append(f"{name}(dst+{dst_align}, {length}): wrong bytes")

    check_division(call, uc.reg_read, rng, failures, symbols)

    if failures:
        for failure in failures[:20]:
            print(f"check-runtime-routines: {failure}", file=sys.stderr)
        sys.exit(f"check-runtime-routines: FAIL: {len(failures)} of {calls} calls")
    print(f"check-runtime-routines: memcpy, memclr and division correct in {calls} calls")


if __name__ == "__main__":
    main()
