#!/usr/bin/env python3
"""Where the real image's milliseconds go: runs IMAGE on the bench with the sensors at rest
(slot 0's filament at its sensor) for WARM ms, then counts the instructions of the next WINDOW ms by
function (a Unicorn block hook on the flash, named from the ELF's symbols with llvm-nm).

    python3 fil/g071/profile.py IMAGE [--warm 400] [--window 20] [--top 40]

Prints the instructions of each millisecond of the window, their mean, and the functions (their
own instructions, not their callees') a millisecond on average. `FunctionCounts` is also what the
bench uses to profile a scenario's busiest milliseconds (FIL_G071_PROFILE, fil/g071/README.md).
"""

import argparse
import bisect
import collections
import os
import subprocess
import sys

import unicorn

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

REST, FILAMENT = 2048, 3000
LEVELS = [REST, FILAMENT] + [REST] * 7


def functions(image):
    """(start, size, name) of every function of `image`, by start."""
    out = subprocess.run(["llvm-nm", "--print-size", "--defined-only", "-C", image],
                         capture_output=True, text=True, check=True).stdout
    found = []
    for line in out.splitlines():
        parts = line.split(None, 3)
        if len(parts) == 4 and parts[2] in "tTwW" and not parts[3].startswith(".L"):  # local labels
            found.append((int(parts[0], 16) & ~1, int(parts[1], 16), parts[3]))
    return sorted(found)


class FunctionCounts:
    """Instructions executed in flash by function, counted from the moment it is attached to
    `chip` (`counts`: name -> instructions; a function's own, not its callees')."""

    def __init__(self, image, chip, bytes_per_instruction=2):
        self.named = functions(image)
        self.starts = [start for start, _, _ in self.named]
        self.counts = collections.Counter()
        self.width = bytes_per_instruction
        chip.uc.hook_add(unicorn.UC_HOOK_BLOCK, self._on_block, begin=0x0800_0000, end=0x0801_FFFF)
        chip.uc.ctl_flush_tb()  # blocks translated before the hook would not call it

    def _on_block(self, _uc, address, size, _data):
        i = bisect.bisect_right(self.starts, address) - 1
        named = self.named
        inside = i >= 0 and address < named[i][0] + max(named[i][1], 2)
        # Thumb: two bytes an instruction but for the few 32-bit ones (BL): close enough here
        # (a RISC-V image mixes 2- and 4-byte ones: its bench passes their mean).
        self.counts[named[i][2] if inside else hex(address)] += max(1, round(size / self.width))

    def snapshot(self):
        """A copy of the counts so far (subtract two snapshots for what ran between)."""
        return collections.Counter(self.counts)


class Busiest:
    """The `keep` busiest milliseconds' profiles: (instructions, ms, whether it wrote the flash,
    functions -> instructions), busiest first."""

    def __init__(self, keep, top):
        self.keep, self.top = keep, top
        self.ms = []

    def take(self, instructions, ms, wrote, functions):
        """Keeps this millisecond's profile if it is among the busiest."""
        self.ms.append((instructions, ms, wrote, functions))
        self.ms.sort(key=lambda m: m[0], reverse=True)
        del self.ms[self.keep:]

    def report(self):
        """`profile:` lines for the log."""
        lines = []
        for instructions, ms, wrote, functions in self.ms:
            with_write = ", with a flash write" if wrote else ""
            lines.append(f"profile: {instructions} instructions at {ms} ms{with_write}")
            lines += [f"profile: {n:7}  {name}" for name, n in functions.most_common(self.top)]
        return "\n".join(lines)


def main():
    import bench as bench_module  # a cycle otherwise: the bench imports this module

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("image")
    parser.add_argument("--warm", type=int, default=400, help="milliseconds run before the window")
    parser.add_argument("--window", type=int, default=20, help="milliseconds profiled")
    parser.add_argument("--top", type=int, default=40, help="functions listed")
    args = parser.parse_args()
    bench = bench_module.Bench(args.image)
    for _ in range(args.warm):
        bench.step(1000, LEVELS, b"")
    chip = bench.chip
    profile = FunctionCounts(args.image, chip)
    per_ms = []
    for _ in range(args.window):
        before = chip.cpu.native.count()
        bench.step(1000, LEVELS, b"")
        per_ms.append(chip.cpu.native.count() - before)
    print(f"instructions a millisecond: {per_ms}")
    print(f"mean {sum(per_ms) / len(per_ms):.0f} over {len(per_ms)} ms after {args.warm}")
    for name, n in profile.counts.most_common(args.top):
        print(f"{n / args.window:8.0f}  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
