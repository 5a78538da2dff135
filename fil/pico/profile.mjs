#!/usr/bin/env node
// Where the real image's milliseconds go: runs the image on the bench with the sensors at rest
// (slot 0's filament at its sensor) for WARM ms, then counts the cycles of the next WINDOW ms by
// function (each instruction's address, named from the ELF's symbols with llvm-nm).
//
//   node fil/pico/profile.mjs <image.elf> [warm=400] [window=20] [top=40]
//
// Prints the instructions and rp2040js cycles a millisecond, and the functions (their own
// cycles, not their callees') a millisecond on average.

import { readFileSync } from 'node:fs';
import { Bench } from './bench-core.mjs';
import { byFunction, symbolNamer } from './symbols.mjs';

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

const nameOf = symbolNamer(image);

const { chip } = bench;
const counts = new Map();
chip.pcCycles = counts;
const [executed, cycles] = [chip.executed, chip.busyCycles];
for (let i = 0; i < +window; i++) bench.step(1000, levels, []);
const perMs = (n) => (n / +window).toFixed(0);
console.log(`${perMs(chip.executed - executed)} instructions, ${perMs(chip.busyCycles - cycles)} cycles a ` +
  `millisecond over ${window} ms after ${warm}`);
byFunction(counts, nameOf)
  .slice(0, +top)
  .forEach(([name, n]) => console.log(`${perMs(n).padStart(8)}  ${name}`));
