#!/usr/bin/env node
// Measures the bench's speed on an image: virtual milliseconds per wall second, with the unit
// idle (sensors at rest, filament at slot 0's sensor) and with slot 0's motor driven (an `L0` with filament at the slot
// sensor and the slot's Hall sensor turning while the bridge drives). Not a test: a figure.
//
//   node fil/pico/speed.mjs <image.elf> [idle_ms] [driving_ms]

import { readFileSync } from 'node:fs';
import { Bench } from './bench-core.mjs';

const [image, idleMs = '2000', driveMs = '1000'] = process.argv.slice(2);
if (!image) {
  console.error('usage: node fil/pico/speed.mjs <image.elf> [idle_ms] [driving_ms]');
  process.exit(2);
}
const REST = 2048;

function frame(text) {
  let crc = 0;
  const [code, value] = [text.charCodeAt(0), parseInt(text.slice(1), 16)];
  for (const byte of [code, value, 0, 0]) {
    crc ^= byte;
    for (let bit = 0; bit < 8; bit++) crc = crc & 0x80 ? ((crc << 1) ^ 0x07) & 0xff : (crc << 1) & 0xff;
  }
  return [...Buffer.from(`${text}*${crc.toString(16)}\n`)];
}

const bench = new Bench(readFileSync(image));
const sensors = new Array(9).fill(REST);
let hallPhase = 0;
let driving = 0;
const step = (rx = []) => {
  const r = bench.step(1000, sensors, rx);
  const m = r.motors[0];
  if (m[0] === '1' && m[1] !== m[2] && !m.endsWith(':0')) {
    driving++;
    hallPhase += (Number(m.split(':')[1]) / 1000) * 0.3;
  }
  sensors[0] = Math.round(REST + 700 * Math.sin(hallPhase));
  return r;
};
const timed = (ms, fn) => {
  const start = process.hrtime.bigint();
  for (let i = 0; i < ms; i++) fn(i);
  return Number(process.hrtime.bigint() - start) / 1e9;
};

for (let i = 0; i < 100; i++) step(i === 30 ? frame('S0') : []);
sensors[1] = 3000; // filament at slot 0's sensor: the unit sees a loaded slot, idle
for (let i = 0; i < 100; i++) step();
const idleWall = timed(Number(idleMs), () => step());
console.log(`idle: ${idleMs} virtual ms in ${idleWall.toFixed(2)} s: ${(Number(idleMs) / idleWall).toFixed(0)} virtual ms per wall s`);

step(frame('L0'));
driving = 0;
const driveWall = timed(Number(driveMs), (i) => step(i % 200 === 199 ? frame('Q0') : []));
console.log(`slot 0 driven in ${driving} of ${driveMs} ms: ${(Number(driveMs) / driveWall).toFixed(0)} virtual ms per wall s`);
