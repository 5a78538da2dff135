#!/usr/bin/env python3
"""Static worst-case stack of a thumbv6m ELF, from its disassembly (stable Rust: no
`-Z emit-stack-sizes`).

    python3 scripts/stack-estimate.py ELF [--root SYMBOL_PART] [--indirect CALLER=CALLEE_PART ...]

Needs `llvm-objdump` (any recent LLVM; `LLVM_OBJDUMP` names another, e.g. rustup's llvm-tools).

Each function's frame is what its code takes from the stack: the registers it pushes (4 B each)
plus every `sub sp, #n` and `ldr rX, =-n; add sp, rX`. The call graph is every `bl` and every
branch into another function (tail calls counted as calls: an over-estimate). Paths through a
recursion are cut at the repeated function (and reported). Calls through a register (`blx`: task
polls, wakers, trait objects) have no target in the code: `--indirect` names them (an async
executor polls its tasks through a function pointer), the others are listed as unresolved.

The worst case is the deepest path from the reset handler, plus the deepest interrupt handler
on top of it (Cortex-M0+ stacks 32 B per exception entry, and one more 4 B for alignment), plus
the NMI and HardFault on top of that (they preempt everything).
"""

import argparse
import re
import struct
import subprocess
import sys
import os
from collections import defaultdict

FUNC = re.compile(r"^([0-9a-f]+) <(.+)>:$")
INSN = re.compile(r"^\s*([0-9a-f]+):\s+(\S+)\s*(.*)$")
TARGET = re.compile(r"0x([0-9a-f]+) <([^>+]+)")
LITERAL = re.compile(r"@ 0x([0-9a-f]+)")
EXCEPTION_FRAME = 32 + 4


def sections(elf):
    """(address, bytes) of the sections that hold code and constants, for reading literal pools
    and the vector table (read from the ELF32 section headers)."""
    data = open(elf, "rb").read()
    if data[:4] != b"\x7fELF" or data[4] != 1:
        sys.exit(f"stack-estimate: {elf} is not a 32-bit ELF")
    shoff, = struct.unpack_from("<I", data, 0x20)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", data, 0x2E)
    headers = [struct.unpack_from("<IIIIIIIIII", data, shoff + i * shentsize) for i in range(shnum)]
    names = headers[shstrndx][4]
    found = []
    for name, kind, _flags, addr, offset, size, *_ in headers:
        label = data[names + name:data.index(b"\0", names + name)].decode()
        if label in (".vector_table", ".text", ".rodata") and kind == 1:  # SHT_PROGBITS
            found.append((addr, data[offset:offset + size]))
    return found


def read_word(mem, address):
    for base, data in mem:
        if base <= address < base + len(data) - 3:
            return struct.unpack_from("<I", data, address - base)[0]
    return None


def analyse(elf):
    mem = sections(elf)
    objdump = os.environ.get("LLVM_OBJDUMP", "llvm-objdump")
    dis = subprocess.run([objdump, "-d", "--no-show-raw-insn", "-C", elf],
                         capture_output=True, text=True, check=True).stdout
    frame = defaultdict(int)
    calls = defaultdict(set)
    indirect = set()
    start = {}
    current = None
    literal_regs = {}
    for line in dis.splitlines():
        m = FUNC.match(line)
        if m:
            if not m.group(2).startswith("$"):
                current = m.group(2)
                start[int(m.group(1), 16) & ~1] = current
                frame[current] += 0
                literal_regs = {}
            continue
        m = INSN.match(line)
        if not m or current is None:
            continue
        op, args = m.group(2), m.group(3)
        if op == "push":
            frame[current] += 4 * len(args.split("}")[0].split(","))
        elif op == "sub" and args.startswith("sp, #"):
            frame[current] += int(args.split("#")[1].split()[0], 0)
        elif op == "ldr" and "[pc" in args:
            lit = LITERAL.search(args)
            if lit:
                literal_regs[args.split(",")[0]] = read_word(mem, int(lit.group(1), 16))
        elif op == "add" and re.match(r"sp, r\d", args):
            value = literal_regs.get(args.split(",")[1].strip())
            if value is not None and value >= 0x80000000:
                frame[current] += 0x100000000 - value
        elif op in ("bl", "b", "b.w", "beq", "bne", "bhs", "blo", "bhi", "bls", "bge", "blt", "bgt",
                    "ble", "bmi", "bpl", "bcs", "bcc"):
            t = TARGET.search(args)
            if t and t.group(2) != current and not t.group(2).startswith("$"):
                calls[current].add(t.group(2))
        elif op == "blx":
            indirect.add(current)
    return mem, frame, calls, indirect, start


def deepest(fn, frame, calls, memo, stack, cycles):
    """(bytes, path, cut) of the deepest call chain from `fn`; `cut` when it met a recursion (such
    a result depends on the path it was reached by, so it is not remembered)."""
    if fn in memo:
        return memo[fn]
    if fn in stack:
        cycles.add(fn)
        return (0, [], True)
    stack.add(fn)
    best, cut = (0, []), False
    for callee in sorted(calls.get(fn, ())):
        depth = deepest(callee, frame, calls, memo, stack, cycles)
        cut = cut or depth[2]
        if depth[0] > best[0]:
            best = depth[:2]
    stack.discard(fn)
    result = (frame.get(fn, 0) + best[0], [fn] + best[1], cut)
    if not cut:
        memo[fn] = result
    return result


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("elf")
    parser.add_argument("--root", default="__stext", help="thread-mode entry (symbol name part)")
    parser.add_argument("--indirect", action="append", default=[], metavar="CALLER=CALLEE",
                        help="an indirect call: CALLER's blx reaches every function whose name contains CALLEE")
    parser.add_argument("--no-interrupts", action="store_true", help="only the root's path")
    parser.add_argument("--vector-table", default="0x08000000",
                        help="address of the vector table (the G071: 0x08000000; the Pico: 0x10000100)")
    args = parser.parse_args()
    mem, frame, calls, indirect, start = analyse(args.elf)
    names = list(frame)

    def find(part):
        exact = [n for n in names if n == part]
        return exact or [n for n in names if part in n]

    for spec in args.indirect:
        caller, callee = spec.split("=", 1)
        for c in find(caller):
            calls[c].update(n for n in find(callee) if n != c)

    memo, cycles = {}, set()
    roots = find(args.root)
    if not roots:
        sys.exit(f"stack-estimate: no function named like {args.root}")
    thread = max((deepest(r, frame, calls, memo, set(), cycles) for r in roots), key=lambda d: d[0])

    def show(label, depth):
        print(f"  {label:<18} {depth[0]:6d} B  " + " > ".join(
            f"{re.sub(r'::h[0-9a-f]{16}$', '', f)[-60:]} ({frame[f]})" for f in depth[1][:12]))

    print(f"stack estimate of {args.elf} (static, from the disassembly):")
    show("thread mode", thread)
    total = thread[0]
    if not args.no_interrupts:
        # The vector table: word 1 is Reset, words 2.. the exceptions and interrupts.
        handlers = {}
        for i in range(2, 48):
            target = read_word(mem, int(args.vector_table, 0) + 4 * i)
            if target and (target & ~1) in start:
                handlers[i] = start[target & ~1]
        faults = {i: h for i, h in handlers.items() if i in (2, 3)}  # NMI, HardFault
        others = {i: h for i, h in handlers.items() if i not in (2, 3) and "DefaultHandler" not in h}
        worst_irq = max((deepest(h, frame, calls, memo, set(), cycles) for h in others.values()),
                        key=lambda d: d[0], default=(0, [], False))
        worst_fault = max((deepest(h, frame, calls, memo, set(), cycles) for h in faults.values()),
                          key=lambda d: d[0], default=(0, [], False))
        show("worst interrupt", worst_irq)
        show("NMI / HardFault", worst_fault)
        total += worst_irq[0] + worst_fault[0] + 2 * EXCEPTION_FRAME
        print(f"  + {2 * EXCEPTION_FRAME} B of exception frames (two nested entries)")
    unresolved = sorted(f for f in indirect if f in memo and not any(
        s.split("=", 1)[0] in f for s in args.indirect))
    if cycles:
        print("  recursion cut at: " + ", ".join(sorted(c[-60:] for c in cycles)))
    if unresolved:
        print(f"  {len(unresolved)} functions on the paths call through a register (not followed): "
              + ", ".join(re.sub(r"::h[0-9a-f]{16}$", "", u)[-50:] for u in unresolved[:8]))
    print(f"worst-case stack: {total} B")


if __name__ == "__main__":
    main()
