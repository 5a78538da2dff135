// Names for the real image's instruction addresses, from the ELF's symbols (llvm-nm), for the
// profiles of profile.mjs and of the bench's busiest milliseconds (FIL_PICO_PROFILE).

import { execFileSync } from 'node:child_process';

/** `nameOf(pc)`: the function of `image` at `pc`, or where the address is when none covers it. */
export function symbolNamer(image) {
  const named = execFileSync('llvm-nm', ['--print-size', '--defined-only', '-C', image], { maxBuffer: 1 << 26 })
    .toString()
    .split('\n')
    .map((line) => line.split(/\s+/))
    .filter((p) => p.length >= 4 && 'tTwW'.includes(p[2]))
    .map((p) => [parseInt(p[0], 16) & ~1, parseInt(p[1], 16), p.slice(3).join(' ')])
    .sort((a, b) => a[0] - b[0]);
  return (pc) => {
    let [lo, hi, found] = [0, named.length - 1, null];
    while (lo <= hi) {
      const mid = (lo + hi) >> 1;
      if (named[mid][0] <= pc) {
        found = named[mid];
        lo = mid + 1;
      } else hi = mid - 1;
    }
    if (found && pc < found[0] + Math.max(found[1], 2)) return found[2];
    return pc < 0x10000000 ? 'boot ROM' : `0x${pc.toString(16)}`;
  };
}

/** Counts (cycles, instructions) by function name from counts by address, largest first. */
export function byFunction(counts, nameOf) {
  const byName = new Map();
  for (const [pc, n] of counts) byName.set(nameOf(pc), (byName.get(nameOf(pc)) ?? 0) + n);
  return [...byName].sort((a, b) => b[1] - a[1]);
}
