"""Where the image's spinning executor idles: embassy-executor 0.10's `platform-spin` executor
(`Executor::run`: `loop { self.inner.poll() }`, src/platform/spin.rs) polls its run queue
without end, taking the queue's head inside a critical section:

    head:  csrrc  rX, 0x800, rM      (critical section: MIE and MPIE off)
           lw     rH, OFF(rQ)        (the run queue's head)
           ...    sw zero, OFF(rQ)   (taken: the queue is empty again)
           ...    beqz rH, head      (nothing to run: poll again)

When the head is null with interrupts enabled, the loop changes nothing until an interrupt
wakes a task: the bench stops the core there and skips to the next event (native.py
`nat_idle`), which leaves the image's behaviour as it is and its busy instructions countable.
This finds `head` and (rQ, OFF) in `Executor::run`'s code: the csrrc on CSR 0x800 that a later
branch jumps back to, followed by a word load whose base and offset a `sw zero` of the next few
instructions stores to. None when the image has no such loop (then the bench runs the spin as
instructions, correct but slow, and says so).
"""

RUN = "Executor3run"
PLATFORM = "platform"


def _instructions(image, base, start, end):
    off = start - base
    while start < end and off + 2 <= len(image):
        half = image[off] | image[off + 1] << 8
        if half & 3 == 3:
            yield start, int.from_bytes(image[off:off + 4], "little"), 4
            start, off = start + 4, off + 4
        else:
            yield start, half, 2
            start, off = start + 2, off + 2


def _sext(value, bits):
    return value - (1 << bits) if value >> (bits - 1) & 1 else value


def _branch_target(pc, insn, size):
    if size == 4 and insn & 0x7F == 0x63:
        imm = (insn >> 31 & 1) << 12 | (insn >> 7 & 1) << 11 | (insn >> 25 & 0x3F) << 5 | (insn >> 8 & 0xF) << 1
        return pc + _sext(imm, 13)
    if size == 2 and insn & 3 == 1 and insn >> 13 in (6, 7):  # c.beqz, c.bnez
        imm = ((insn >> 12 & 1) << 8 | (insn >> 5 & 3) << 6 | (insn >> 2 & 1) << 5
               | (insn >> 10 & 3) << 3 | (insn >> 3 & 3) << 1)
        return pc + _sext(imm, 9)
    if size == 2 and insn & 3 == 1 and insn >> 13 == 5:  # c.j
        imm = ((insn >> 12 & 1) << 11 | (insn >> 8 & 1) << 10 | (insn >> 9 & 3) << 8 | (insn >> 6 & 1) << 7
               | (insn >> 7 & 1) << 6 | (insn >> 2 & 1) << 5 | (insn >> 11 & 1) << 4 | (insn >> 3 & 7) << 1)
        return pc + _sext(imm, 12)
    return None


def _load(insn, size):
    """(base register, offset) of a word load, or None."""
    if size == 4 and insn & 0x7F == 0x03 and insn >> 12 & 7 == 2:
        return insn >> 15 & 31, _sext(insn >> 20, 12)
    if size == 2 and insn & 3 == 0 and insn >> 13 == 2:  # c.lw
        return 8 + (insn >> 7 & 7), (insn >> 10 & 7) << 3 | (insn >> 6 & 1) << 2 | (insn >> 5 & 1) << 6
    return None


def _store_zero(insn, size):
    """(base register, offset) of `sw zero, OFF(base)`, or None."""
    if size == 4 and insn & 0x7F == 0x23 and insn >> 12 & 7 == 2 and insn >> 20 & 31 == 0:
        return insn >> 15 & 31, _sext((insn >> 25) << 5 | (insn >> 7 & 31), 12)
    return None


def idle_loop(image, base, symbols):
    """(head pc, rQ, OFF) of the executor's poll loop, or None."""
    starts = [v for n, v in symbols.items() if RUN in n and PLATFORM in n]
    if not starts:
        return None
    start = starts[0] & ~1
    later = [v for v in symbols.values() if v > start and base <= v < base + len(image)]
    end = min(later) if later else start + 0x1000
    code = list(_instructions(image, base, start, end))
    targets = {t for pc, insn, size in code if (t := _branch_target(pc, insn, size)) is not None and t < pc}
    for i, (pc, insn, size) in enumerate(code):
        csrrc = size == 4 and insn & 0x7F == 0x73 and insn >> 12 & 7 == 3 and insn >> 20 == 0x800
        if not csrrc or pc not in targets or i + 1 >= len(code):
            continue
        load = _load(code[i + 1][1], code[i + 1][2])
        if load and any(_store_zero(c[1], c[2]) == load for c in code[i + 2:i + 5]):
            return pc, load[0], load[1]
    return None
