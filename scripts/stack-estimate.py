#!/usr/bin/env python3
"""Static worst-case stack of a thumbv6m ELF, from its disassembly (stable Rust: no
`-Z emit-stack-sizes`).

    python3 scripts/stack-estimate.py ELF [--root SYMBOL_PART] [--indirect CALLER=CALLEE_PART ...]

Needs `llvm-objdump` (any recent LLVM; `LLVM_OBJDUMP` names another, e.g. rustup's llvm-tools).

Each function's frame is what its code takes from the stack: the registers it pushes (4 B each)
plus every `sub sp, #n` and `ldr rX, =-n; add sp, rX`. The call graph is every `bl` and every
branch to another function's entry (tail calls counted as calls: an over-estimate), in the code
reachable from the function's entry within its symbol's size (see `parse`). Paths through a
recursion are cut at the repeated function (and reported). Calls through a register (`blx`: task
polls, wakers, trait objects) have no target in the code: `--indirect` names them (an async
executor polls its tasks through a function pointer), the others are listed as unresolved.

The worst case is the deepest path from the reset handler, plus the deepest interrupt handler
on top of it (Cortex-M0+ stacks 32 B per exception entry, and one more 4 B for alignment), plus
the NMI and HardFault on top of that (they preempt everything). Nothing calls the reset handler:
a branch into it is ignored (and reported).
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
DATA = re.compile(r"(^|\s)\.(word|short|byte|long)\b")
SYMBOL = re.compile(r"^([0-9a-f]+) (.{7}) (\S+)\t([0-9a-f]+) (?:\.hidden )?(.+)$")
TARGET = re.compile(r"^(?:0x)?([0-9a-f]+)\b")
LITERAL = re.compile(r"@ 0x([0-9a-f]+)")
CONDITIONS = {"eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt",
              "gt", "le", "al"}
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


def branch(op):
    """'b', 'bl' or 'bcc' (conditional) for a direct branch mnemonic, else None."""
    op = op.split(".")[0]
    if op in ("b", "bl"):
        return op
    return "bcc" if op[:1] == "b" and op[1:] in CONDITIONS else None


def parse(dis, symtab, mem=()):
    """Frames and call graph from `llvm-objdump -d` and `llvm-objdump -t` text.

    A function is the code reachable from its entry, within its extent: its symbol's size (the
    largest of the symbols at that address), or up to the next function when the size is 0. The
    bytes after the extent are the linker's padding (lld fills with 0xd4d4, which decodes as
    `bmi .-88`), and code after a return (`pop {.., pc}`, `bx`), an unconditional `b` or a `udf`
    runs only if a branch reaches it: neither may add frames or calls. A computed jump (`add pc` /
    `mov pc`: a jump table) makes the whole extent reachable. A branch is a call only to a
    function's entry; one into the middle of another function is decoding gone wrong (reported).
    """
    sizes, names, untyped = {}, defaultdict(list), []
    for line in symtab.splitlines():
        m = SYMBOL.match(line)
        if not m or m.group(5).startswith("$"):
            continue
        address = int(m.group(1), 16) & ~1
        if "F" in m.group(2):
            sizes[address] = max(sizes.get(address, 0), int(m.group(4), 16))
            names[address].append(m.group(5))
        else:
            untyped.append((address, m.group(5)))
    labels, insns, following = {}, {}, {}
    code, previous = True, None
    for line in dis.splitlines():
        m = FUNC.match(line)
        if m:
            address, name = int(m.group(1), 16) & ~1, m.group(2)
            code = not name.startswith("$d")
            if not name.startswith("$"):
                labels[address] = name
            continue
        m = INSN.match(line)
        if not m:
            continue
        address = int(m.group(1), 16)
        if previous is not None:
            following[previous] = address
        previous = address
        if code and not DATA.search(m.group(3)):
            insns[address] = (m.group(2), m.group(3))
    starts = sorted(set(sizes) | set(labels))
    for address, name in untyped:  # e.g. `__stext`, an alias of `Reset`
        if address in starts:
            names[address].append(name)
    start = {a: labels.get(a) or names[a][0] for a in starts}
    aliases = {start[a]: set(names[a]) | {start[a]} for a in starts}

    frame, calls, indirect, stray = {}, defaultdict(set), set(), []
    for i, entry in enumerate(starts):
        fn = start[entry]
        end = entry + sizes[entry] if sizes.get(entry) else (
            starts[i + 1] if i + 1 < len(starts) else float("inf"))
        reach, todo, table = set(), [entry], False
        while todo:
            a = todo.pop()
            while a is not None and entry <= a < end and a in insns and a not in reach:
                reach.add(a)
                op, args = insns[a]
                kind, regs = branch(op), args.replace(" ", "")
                if kind:
                    t = TARGET.match(args)
                    t = int(t.group(1), 16) if t else None
                    if t is not None and entry <= t < end:
                        todo.append(t)  # a local branch (`bl` too: Thumb-1's far branch)
                    if kind != "bcc" and (kind == "b" or (t is not None and entry <= t < end)):
                        break
                elif (op == "pop" and "pc}" in regs) or op in ("bx", "udf") or op.startswith("udf"):
                    break
                elif op in ("mov", "add") and regs.startswith("pc,"):
                    table = regs != "pc,lr"
                    break
                a = following.get(a)
        if table:
            reach |= {a for a in insns if entry <= a < end}
        total, literal_regs = 0, {}
        for a in sorted(reach):
            op, args = insns[a]
            if op == "push":
                total += 4 * len(args.split("}")[0].split(","))
            elif op == "sub" and args.startswith("sp, #"):
                total += int(args.split("#")[1].split()[0], 0)
            elif op == "ldr" and "[pc" in args:
                lit = LITERAL.search(args)
                if lit:
                    literal_regs[args.split(",")[0]] = read_word(mem, int(lit.group(1), 16))
            elif op == "add" and re.match(r"sp, r\d", args):
                value = literal_regs.get(args.split(",")[1].strip())
                if value is not None and value >= 0x80000000:
                    total += 0x100000000 - value
            elif branch(op):
                t = TARGET.match(args)
                t = int(t.group(1), 16) if t else None
                if t is None or entry <= t < end:
                    continue
                if t in start:
                    calls[fn].add(start[t])
                else:
                    stray.append((fn, a, t))
            elif op == "blx" or (op == "bx" and args.split()[0] != "lr"):
                indirect.add(fn)
        frame[fn] = total
    return frame, calls, indirect, start, aliases, stray


def analyse(elf):
    mem = sections(elf)
    objdump = os.environ.get("LLVM_OBJDUMP", "llvm-objdump")
    dis, symtab = (subprocess.run([objdump, flag, "--no-show-raw-insn", "-C", elf],
                                  capture_output=True, text=True, check=True).stdout
                   for flag in ("-d", "-t"))
    return (mem, *parse(dis, symtab, mem))


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
    mem, frame, calls, indirect, start, aliases, stray = analyse(args.elf)

    def find(part):
        exact = [f for f, names in aliases.items() if part in names]
        return exact or [f for f, names in aliases.items() if any(part in n for n in names)]

    for spec in args.indirect:
        caller, callee = spec.split("=", 1)
        for c in find(caller):
            calls[c].update(n for n in find(callee) if n != c)

    memo, cycles = {}, set()
    roots = find(args.root)
    if not roots:
        sys.exit(f"stack-estimate: no function named like {args.root}")
    # Nothing calls the reset handler (it is entered from reset and never returns): a branch into
    # it is a misread, and would stack the thread's path on top of an interrupt's.
    reset = set(roots)
    if not args.no_interrupts:
        target = read_word(mem, int(args.vector_table, 0) + 4)
        if target and (target & ~1) in start:
            reset.add(start[target & ~1])
    into_reset = sorted(f for f in calls if calls[f] & reset)
    for f in into_reset:
        calls[f] -= reset
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
        others = {i: h for i, h in handlers.items()
                  if i not in (2, 3) and not any("DefaultHandler" in n for n in aliases[h])}
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
    if into_reset:
        print("  branches into the reset handler ignored, from: "
              + ", ".join(re.sub(r"::h[0-9a-f]{16}$", "", f)[-50:] for f in into_reset[:8]))
    if stray:
        print(f"  {len(stray)} branches into the middle of another function (not followed): "
              + ", ".join(f"{re.sub(r'::h[0-9a-f]{16}$', '', f)[-40:]} {a:#x} > {t:#x}"
                          for f, a, t in stray[:8]))
    if cycles:
        print("  recursion cut at: " + ", ".join(sorted(c[-60:] for c in cycles)))
    if unresolved:
        print(f"  {len(unresolved)} functions on the paths call through a register (not followed): "
              + ", ".join(re.sub(r"::h[0-9a-f]{16}$", "", u)[-50:] for u in unresolved[:8]))
    print(f"worst-case stack: {total} B")


if __name__ == "__main__":
    main()
