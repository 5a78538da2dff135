#!/usr/bin/env node
// Where the real image's milliseconds go: runs the image on the bench with the sensors at rest
// (slot 0's filament at its sensor) for WARM ms, then counts the instructions of the next WINDOW
// ms by function (each instruction's address, named from the ELF's symbols with llvm-nm).
//
//   node fil/pico/profile.mjs <image.elf> [warm=400] [window=20] [top=40]
//
// Prints the instructions and rp2040js cycles a millisecond, and the functions (their own
// instructions, not their callees') a millisecond on average.

import { execFileSync } from 'node:child_process';
import { readFileSync } from 'node:fs';
import { Bench } from './bench-core.mjs';

const [image, warm = '400', window = '20', top = '40'] = process.argv.slice(2);
if (!image) {
  console.error('usage: node fil/pico/profile.mjs <image.elf> [warm] [window] [top]');
  process.exit(2);
}
const REST = 2048;
const FILAMENT = 3000;
const levels = [REST, FILAMENT, REST, REST, REST, REST, REST, REST, REST];

const bench = new Bench(readFileSync(image));
for (let i = 0; i < +warm; i++) bench.step(1000, levels, []);

const named = execFileSync('llvm-nm', ['--print-size', '--defined-only', '-C', image], { maxBuffer: 1 << 26 })
  .toString()
  .split('\n')
  .map((line) => line.split(/\s+/))
  .filter((p) => p.length >= 4 && 'tTwW'.includes(p[2]))
  .map((p) => [parseInt(p[0], 16) & ~1, parseInt(p[1], 16), p.slice(3).join(' ')])
  .sort((a, b) => a[0] - b[0]);

/** The function at `pc`, or where it is when no symbol covers it. */
function nameOf(pc) {
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
}

const { chip } = bench;
const { core } = chip.rp2040;
const counts = new Map();
const execute = core.executeInstruction.bind(core);
core.executeInstruction = () => {
  counts.set(core.PC, (counts.get(core.PC) ?? 0) + 1);
  return execute();
};
const [executed, cycles] = [chip.executed, chip.busyCycles];
for (let i = 0; i < +window; i++) bench.step(1000, levels, []);
const perMs = (n) => (n / +window).toFixed(0);
console.log(`${perMs(chip.executed - executed)} instructions, ${perMs(chip.busyCycles - cycles)} cycles a ` +
  `millisecond over ${window} ms after ${warm}`);
const byName = new Map();
for (const [pc, n] of counts) byName.set(nameOf(pc), (byName.get(nameOf(pc)) ?? 0) + n);
[...byName]
  .sort((a, b) => b[1] - a[1])
  .slice(0, +top)
  .forEach(([name, n]) => console.log(`${perMs(n).padStart(8)}  ${name}`));
