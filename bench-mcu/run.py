#!/usr/bin/env python3
"""Runs the step-cost harness (bench-mcu/harness, thumbv6m) in the Unicorn emulator on a
recorded session and reports the instructions of every millisecond (the firmware's tasks on
Embassy's executor: the link's receive task, the timer's alarm, the control task's step, the
store task's save piece, the link's transmit task) and the stack they use.

    run.py HARNESS_ELF SESSION_BIN [--max-worst N] [--max-step N] [--max-idle N] [--exact-steps N]
    run.py HARNESS_ELF SESSION_BIN --profile STEPS          # where App::step spends its instructions
    run.py HARNESS_ELF SESSION_BIN --profile-save STEPS [--profile-writes | --profile-at STEP]
                                                          # where one Keeper::update spends them
    STEP_DIGESTS=1 run.py ...   # each millisecond's digest of what was sent, on stderr, to find
                                # where the firmware and the recording part (bench-mcu/session
                                # prints its own with SESSION_DEBUG=1)

Unicorn (PyPI `unicorn`) runs the ELF as a Cortex-M0 (ARMv6-M: an instruction the M0+ lacks
faults). Counting is exact: every translated block is counted with its instructions (16-bit
Thumb instructions, or 32-bit BL/MRS/MSR/DMB/DSB/ISB); `--exact-steps` recounts the first steps
one instruction at a time and fails if the two disagree. The harness calls `bench_mark` around
each measured call; the emulator hooks its address. The RAM below the initial stack is painted
and the lowest overwritten byte after each call gives the stack that call used.

The cycle model (README, "Step cost on the MCU"): STM32G071 at 64 MHz, Cortex-M0+, 2 flash wait
states; pessimistically 2.2 cycles per instruction, so 1 ms holds 64000 / 2.2 = 29091
instructions.
"""

import argparse
import ctypes
import hashlib
import os
import shutil
import statistics
import struct
import subprocess
import sys
import tempfile

import unicorn
from unicorn import arm_const as arm

MHZ = 64
CYCLES_PER_INSTR = 2.2
PERIOD_INSTR = MHZ * 1000 / CYCLES_PER_INSTR
SESSION = 0x6000_0000
FLASH = (0x0800_0000, 128 * 1024)
RAM = (0x2000_0000, 36 * 1024)
PAINT = 0xA5

MARKS = {
    1: "calibrate_begin", 2: "calibrate_end", 3: "boot_begin", 4: "boot_end",
    5: "step_begin", 6: "step_end", 7: "save_begin", 8: "save_end", 9: "done",
    10: "panic", 11: "bad_session", 12: "step_context",
}
STATUS = {0: "running", 1: "error", 2: "finished"}


FUNCTIONS = []  # (address, size, name) of every function, for --profile


def elf_symbols_and_segments(path):
    """PT_LOAD segments (address, bytes) and symbol addresses of a 32-bit little-endian ELF."""
    data = open(path, "rb").read()
    if data[:4] != b"\x7fELF" or data[4] != 1 or data[5] != 1:
        sys.exit(f"{path}: not a 32-bit little-endian ELF")
    (e_phoff, e_shoff) = struct.unpack_from("<II", data, 28)
    (e_phentsize, e_phnum, e_shentsize, e_shnum) = struct.unpack_from("<HHHH", data, 42)
    segments = []
    for i in range(e_phnum):
        p_type, p_offset, p_vaddr, _, p_filesz, _, _, _ = struct.unpack_from(
            "<IIIIIIII", data, e_phoff + i * e_phentsize)
        if p_type == 1 and p_filesz:
            segments.append((p_vaddr, data[p_offset:p_offset + p_filesz]))
    sections = [struct.unpack_from("<IIIIIIIIII", data, e_shoff + i * e_shentsize)
                for i in range(e_shnum)]
    symbols = {}
    for sh in sections:
        if sh[1] != 2:  # SHT_SYMTAB
            continue
        strtab = sections[sh[6]]
        strings = data[strtab[4]:strtab[4] + strtab[5]]
        for off in range(sh[4], sh[4] + sh[5], 16):
            st_name, st_value, st_size, _, _, _ = struct.unpack_from("<IIIBBH", data, off)
            name = strings[st_name:strings.index(b"\0", st_name)].decode()
            if name:
                symbols[name] = st_value
                if st_size and struct.unpack_from("<B", data, off + 12)[0] & 0xF == 2:
                    FUNCTIONS.append((st_value & ~1, st_size, name))
    return segments, symbols


# The block counter in C: a Python callback per translated block makes a session take minutes.
# It decodes the block from a copy of the flash image exactly as `Bench.on_block` does.
COUNTER_C = r"""
#include <stdint.h>
static const uint8_t *image;
static uint64_t base, length, count;
void counter_init(const uint8_t *image_, uint64_t base_, uint64_t length_) {
    image = image_; base = base_; length = length_; count = 0;
}
uint64_t counter_value(void) { return count; }
void counter_on_block(void *uc, uint64_t address, uint32_t size, void *user) {
    (void)uc; (void)user;
    uint64_t offset = address - base;
    uint32_t i = 0;
    if (address < base || offset + size > length) { count += size / 2; return; }
    while (i < size) {
        uint16_t top = (uint16_t)(image[offset + i] | (image[offset + i + 1] << 8)) >> 11;
        i += (top == 0x1d || top == 0x1e || top == 0x1f) ? 4 : 2;
        count++;
    }
}
"""


def cortex_m0(segments):
    """A Cortex-M0 in Unicorn with the G071's flash and RAM mapped and the ELF's segments loaded."""
    uc = unicorn.Uc(unicorn.UC_ARCH_ARM, unicorn.UC_MODE_THUMB | unicorn.UC_MODE_MCLASS)
    uc.ctl_set_cpu_model(arm.UC_CPU_ARM_CORTEX_M0)
    uc.mem_map(FLASH[0], FLASH[1])
    uc.mem_map(RAM[0], RAM[1])
    for address, data in segments:
        uc.mem_write(address, data)
    return uc


def native_counter():
    """The compiled block counter and unicorn's C library, or None (then Python counts)."""
    try:
        from unicorn.unicorn_py3.unicorn import uclib, uc_hook_h
    except ImportError:
        return None
    compiler = shutil.which(os.environ.get("CC", "cc"))
    if not compiler:
        return None
    digest = hashlib.sha256(COUNTER_C.encode()).hexdigest()[:12]
    path = os.path.join(tempfile.gettempdir(), f"mmu-bench-counter-{digest}.so")
    if not os.path.exists(path):
        source = path[:-3] + ".c"
        with open(source, "w") as f:
            f.write(COUNTER_C)
        built = subprocess.run([compiler, "-O2", "-shared", "-fPIC", "-o", path + ".tmp", source])
        if built.returncode != 0:
            return None
        os.replace(path + ".tmp", path)
    lib = ctypes.CDLL(path)
    lib.counter_value.restype = ctypes.c_uint64
    lib.counter_init.argtypes = [ctypes.c_void_p, ctypes.c_uint64, ctypes.c_uint64]
    return lib, uclib, uc_hook_h


class Bench:
    def __init__(self, elf, session, exact_steps=None):
        segments, self.symbols = elf_symbols_and_segments(elf)
        for name in ("bench_main", "bench_mark", "_stack_start"):
            if name not in self.symbols:
                sys.exit(f"{elf}: no symbol {name}")
        uc = cortex_m0(segments)
        # The persisted state's region (0x08018000..) is erased flash.
        uc.mem_write(0x0801_8000, b"\xff" * 0x8000)
        blob = struct.pack("<I", len(session)) + session
        uc.mem_map(SESSION, (len(blob) + 0xFFFF) & ~0xFFFF, unicorn.UC_PROT_READ)
        uc.mem_write(SESSION, blob)
        self.stack_top = self.symbols["_stack_start"]
        self.ram_low = RAM[0] + 64  # .data/.bss are empty in the harness; keep a margin anyway
        if self.symbols.get("_bss_end", RAM[0]) > self.ram_low:
            self.ram_low = self.symbols["_bss_end"]
        uc.mem_write(self.ram_low, bytes([PAINT]) * (self.stack_top - self.ram_low))
        uc.reg_write(arm.UC_ARM_REG_SP, self.stack_top)
        self.uc = uc
        self.count = 0
        self.block_cache = {}
        self.exact = exact_steps is not None
        self.exact_steps = exact_steps
        self.profile = None
        self.profile_call = "step"  # the calls --profile looks into: "step" or "save"
        self.profile_writes_only = False  # profile only saves that wrote
        self.profile_at = None  # profile only the save of this step
        self.call_profile = {}  # one call's counts, while profiling saves
        self.worst_call = (0, None, {})  # (instr, index, counts) of the costliest profiled save
        self.in_step = False
        mark_at = self.symbols["bench_mark"] & ~1
        self.native = None
        if self.exact:
            uc.hook_add(unicorn.UC_HOOK_CODE, self.on_instruction)
        else:
            native = native_counter()
            if native:
                lib, uclib, uc_hook_h = native
                image = bytearray(FLASH[1])
                for address, data in segments:
                    if FLASH[0] <= address < FLASH[0] + FLASH[1]:
                        image[address - FLASH[0]:address - FLASH[0] + len(data)] = data
                self.image = (ctypes.c_uint8 * len(image)).from_buffer(image)
                lib.counter_init(self.image, FLASH[0], len(image))
                self.handle = uc_hook_h()
                callback = ctypes.cast(lib.counter_on_block, ctypes.c_void_p)
                status = uclib.uc_hook_add(uc._uch, ctypes.byref(self.handle), unicorn.UC_HOOK_BLOCK,
                                           callback, None, ctypes.c_uint64(1), ctypes.c_uint64(0))
                if status != 0:
                    sys.exit(f"uc_hook_add failed: {status}")
                self.native = lib
            else:
                uc.hook_add(unicorn.UC_HOOK_BLOCK, self.on_block)
            uc.hook_add(unicorn.UC_HOOK_CODE, self.on_mark_hook, begin=mark_at, end=mark_at)
        self.mark_at = mark_at
        self.open = {}
        self.calibration = 0
        self.steps = []  # (index, step instr, info, code, step stack)
        self.saves = []  # (index, instr, wrote, stack)
        self.boot = None
        self.done = None
        self.failure = None

    def on_block(self, uc, address, size, _):
        n = self.block_cache.get((address, size))
        if n is None:
            code = uc.mem_read(address, size)
            n, i = 0, 0
            while i < size:
                hw = code[i] | (code[i + 1] << 8)
                i += 4 if (hw >> 11) in (0b11101, 0b11110, 0b11111) else 2
                n += 1
            self.block_cache[(address, size)] = n
        self.count += n

    def on_instruction(self, uc, address, size, _):
        self.count += 1
        if self.profile is not None and self.in_step:
            counts = self.call_profile if self.profile_call == "save" else self.profile
            counts[address] = counts.get(address, 0) + 1
        if address == self.mark_at:
            self.on_mark(uc)

    def on_mark_hook(self, uc, address, size, _):
        self.on_mark(uc)

    def stack_used(self, sp):
        """Bytes below `sp` written since the last paint; repaints them."""
        # A window first (a call rarely uses more); the whole painted area when it was all used.
        low = max(self.ram_low, sp - 4096)
        data = bytes(self.uc.mem_read(low, sp - low))
        if data[:1] != bytes([PAINT]) and low > self.ram_low:
            low = self.ram_low
            data = bytes(self.uc.mem_read(low, sp - low))
        untouched = len(data) - len(data.lstrip(bytes([PAINT])))
        lowest = low + untouched
        if lowest < sp:
            self.uc.mem_write(lowest, bytes([PAINT]) * (sp - lowest))
        return sp - lowest

    def on_mark(self, uc):
        if self.native:
            self.count = self.native.counter_value()
        kind, a, b, c = (uc.reg_read(r) for r in (arm.UC_ARM_REG_R0, arm.UC_ARM_REG_R1,
                                                  arm.UC_ARM_REG_R2, arm.UC_ARM_REG_R3))
        name = MARKS.get(kind, f"mark {kind}")
        sp = uc.reg_read(arm.UC_ARM_REG_SP)
        self.in_step = name == f"{self.profile_call}_begin" and (
            self.profile_call != "step" or self.profile_at is None or a == self.profile_at)
        if name.endswith("_begin"):
            self.stack_used(sp)
            self.open[name[:-6]] = (self.count, sp)
            return
        if name.endswith("_end"):
            what = name[:-4]
            start, sp0 = self.open.pop(what, (self.count, sp))
            instr = max(0, self.count - start - self.calibration)
            stack = self.stack_used(sp0)
            if what == "calibrate":
                self.calibration = self.count - start
            elif what == "boot":
                self.boot = (instr, stack)
            elif what == "step":
                self.steps.append((a, instr, b, c, stack))
                if self.exact and len(self.steps) >= self.exact_steps and self.profile_call == "step":
                    uc.emu_stop()
            elif what == "save":
                self.saves.append((a, instr, b, stack))
                if self.profile is not None and self.profile_call == "save":
                    if self.profile_at is not None:
                        if a == self.profile_at:
                            self.worst_call = (instr, a, self.call_profile)
                    elif instr > self.worst_call[0] and (b or not self.profile_writes_only):
                        self.worst_call = (instr, a, self.call_profile)
                    self.call_profile = {}
                    if self.exact and len(self.steps) >= self.exact_steps:
                        uc.emu_stop()
            return
        if name == "step_context":
            if self.steps:
                index, instr, _, _, stack = self.steps[-1]
                self.steps[-1] = (index, instr, a, b, stack)
                if os.environ.get("STEP_DIGESTS"):
                    print(f"step {index} digest {c:08x}", file=sys.stderr)
            return
        if name == "done":
            self.done = (a, b, c)
        else:
            self.failure = f"harness stopped: {name} ({a}, {b}, {c})"
        uc.emu_stop()

    def run(self):
        self.uc.emu_start(self.symbols["bench_main"] | 1, 0xFFFF_FFFF)


def describe(info, code):
    code, waiting = code & 0xFFFF, code >> 16
    request = chr(info & 0xFF) + str((info >> 8) & 0xFF)
    status = STATUS.get((info >> 16) & 0xFF, "?")
    rx = info >> 24
    detail = {"running": f"progress {code}", "error": f"error 0x{code:04x}", "finished": "done"}[status] \
        if status in ("running", "error", "finished") else ""
    left = f", {waiting - rx} left waiting" if waiting > rx else ""
    return f"{request} {status} ({detail}), {rx} bytes received{left}"


def percent(instr):
    return 100.0 * instr / PERIOD_INSTR


def main():
    global MHZ, PERIOD_INSTR
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("elf")
    parser.add_argument("session")
    parser.add_argument("--max-worst", type=int, help="fail if the worst step + save exceeds this")
    parser.add_argument("--max-idle", type=int, help="fail if the idle median exceeds this")
    parser.add_argument("--max-step", type=int,
                        help="fail if the costliest App::step (a query burst included) exceeds this")
    parser.add_argument("--max-save", type=int, help="fail if the costliest save exceeds this")
    parser.add_argument("--profile", type=int, metavar="STEPS",
                        help="only list the functions App::step spends its instructions in over the first STEPS steps")
    parser.add_argument("--profile-save", type=int, metavar="STEPS",
                        help="only list the functions the costliest Keeper::update of the first STEPS steps spends its instructions in")
    parser.add_argument("--profile-writes", action="store_true",
                        help="with --profile-save: only the saves that wrote to the flash")
    parser.add_argument("--profile-at", type=int, metavar="STEP",
                        help="with --profile-save: only the save of this step; with --profile: only this step")
    parser.add_argument("--mhz", type=float, default=MHZ,
                        help="the MCU's clock for the percentages (the G071: 64; the Pico: 125)")
    parser.add_argument("--exact-steps", type=int, default=300,
                        help="recount this many first steps instruction by instruction (0: skip)")
    args = parser.parse_args()
    MHZ = args.mhz
    PERIOD_INSTR = MHZ * 1000 / CYCLES_PER_INSTR
    session = open(args.session, "rb").read()
    if args.profile or args.profile_save:
        bench = Bench(args.elf, session, exact_steps=args.profile or args.profile_save)
        bench.profile = {}
        bench.profile_at = args.profile_at
        if args.profile_save:
            bench.profile_call = "save"
            bench.profile_writes_only = args.profile_writes
            bench.profile_at = args.profile_at
        bench.run()
        if args.profile_save:
            instr, index, bench.profile = bench.worst_call
            print(f"the profiled Keeper::update of the first {len(bench.steps)} steps: {instr} instr at step {index}")
        demangle = shutil.which("rustfilt")
        totals = {}
        functions = sorted(FUNCTIONS)
        import bisect
        starts = [f[0] for f in functions]
        for address, n in bench.profile.items():
            i = bisect.bisect_right(starts, address) - 1
            name = functions[i][2] if i >= 0 and address < starts[i] + functions[i][1] else hex(address)
            totals[name] = totals.get(name, 0) + n
        total = sum(totals.values())
        if args.profile_save:
            for name, n in sorted(totals.items(), key=lambda t: -t[1])[:25]:
                print(f"  {100 * n / max(1, total):5.1f} %  {n:7}  {name[:110]}")
            return
        print(f"App::step over {len(bench.steps)} steps: {total / max(1, len(bench.steps)):.0f} instr per step")
        for name, n in sorted(totals.items(), key=lambda t: -t[1])[:25]:
            print(f"  {100 * n / total:5.1f} %  {n / max(1, len(bench.steps)):7.0f}  {name[:110]}")
        return

    bench = Bench(args.elf, session)
    bench.run()
    if bench.failure:
        sys.exit(bench.failure)
    if not bench.done:
        sys.exit("the harness did not finish")
    steps_done, digest, expected = bench.done
    if digest != expected:
        sys.exit(f"the thumbv6m App sent other bytes than the host App that recorded the session "
                 f"(digest {digest:08x}, recorded {expected:08x})")

    if args.exact_steps:
        exact = Bench(args.elf, session, exact_steps=args.exact_steps)
        exact.run()
        got = [s[1] for s in bench.steps[:args.exact_steps]]
        want = [s[1] for s in exact.steps[:args.exact_steps]]
        if got != want or len(want) < min(args.exact_steps, len(bench.steps)):
            sys.exit(f"block counting disagrees with instruction-by-instruction counting "
                     f"over the first {args.exact_steps} steps")

    saves = {index: (instr, wrote, stack) for index, instr, wrote, stack in bench.saves}
    idle = [s[1] for s in bench.steps if (s[2] >> 16) & 0xFF == 2 and s[2] >> 24 == 0]
    running = [s[1] for s in bench.steps if (s[2] >> 16) & 0xFF == 0 and s[2] >> 24 == 0]
    failed = [s[1] for s in bench.steps if (s[2] >> 16) & 0xFF == 1 and s[2] >> 24 == 0]
    with_rx = [s for s in bench.steps if s[2] >> 24 > 0]
    # Steps that left received bytes waiting for the next ones (a burst taken a share at a time).
    bursts = [s for s in bench.steps if (s[3] >> 16) > s[2] >> 24]
    written = [(i, v[0]) for i, v in saves.items() if v[1]]
    checks = [v[0] for v in saves.values() if not v[1]]

    def summary(label, values):
        if values:
            print(f"  {label:<30} median {statistics.median(values):>7.0f}  max {max(values):>7}  "
                  f"({len(values)} steps)")

    ticks = [(s[1] + saves.get(s[0], (0, 0, 0))[0], s) for s in bench.steps]
    worst_tick, worst = max(ticks, key=lambda t: t[0])
    worst_step = max(bench.steps, key=lambda s: s[1])
    idle_median = int(statistics.median(idle)) if idle else 0
    save_max = max((v for _, v in written), default=0)
    print(f"step cost: {steps_done} steps of {args.session} on a Cortex-M0 (Unicorn "
          f"{unicorn.__version__}), counted exactly (checked over the first {args.exact_steps} "
          f"steps instruction by instruction), instructions per call:")
    summary("millisecond, unit idle", idle)
    summary("millisecond, command running", running)
    summary("millisecond, unit in an error", failed)
    summary("millisecond with bytes received", [s[1] for s in with_rx])
    summary("millisecond, more bytes waiting", [s[1] for s in bursts])
    summary("millisecond in which the store wrote", [s[1] for s in bench.steps if saves.get(s[0], (0, 0, 0))[1]])
    print(f"  costliest millisecond: {worst_step[1]} instr at step {worst_step[0]} "
          f"({describe(worst_step[2], worst_step[3])})")
    written_ms = [s[1] for s in bench.steps if saves.get(s[0], (0, 0, 0))[1]]
    if written_ms:
        print(f"  costliest millisecond in which the store wrote: {max(written_ms)} instr")
    print(f"  cycle model: {CYCLES_PER_INSTR} cycles/instr at {MHZ} MHz: 1 ms = {PERIOD_INSTR:.0f} instr; "
          f"idle {percent(idle_median):.1f} %, worst {percent(worst_tick):.1f} %")
    step_stack = max(s[4] for s in bench.steps)
    save_stack = max(v[2] for v in saves.values())
    boot_instr, boot_stack = bench.boot
    print(f"  stack (painted): a millisecond {step_stack} B, the boot {boot_stack} B ({boot_instr} instr), "
          f"below the harness's frame")

    status = 0
    save_max = max(written_ms, default=0)
    for limit, value, what in ((args.max_worst, worst_tick, "worst millisecond"),
                               (args.max_step, worst_step[1], "costliest millisecond"),
                               (args.max_idle, idle_median, "idle median"),
                               (args.max_save, save_max, "costliest millisecond with a flash write")):
        if limit is not None and value > limit:
            print(f"step-cost: FAIL: {what} {value} instr is over its budget of {limit}", file=sys.stderr)
            status = 1
    bar = PERIOD_INSTR / 4
    print(f"step cost: idle {idle_median} instr median ({percent(idle_median):.1f} %), worst millisecond "
          f"{worst_tick} instr ({percent(worst_tick):.1f} % of 1 ms at {MHZ:g} MHz; the 25 % bar is {bar:.0f} instr: "
          f"{'within' if worst_tick <= bar else 'OVER'}), worst with a flash write {save_max} instr")
    sys.exit(status)


if __name__ == "__main__":
    main()
