// The bench's time and life cycle (bench-core.mjs) on a tiny image that loops at boot2: the
// printer's bytes paced at 115200 Bd and carried into the next step, resets rebuilding the chip
// with what survives them, `hang`, and the power cycle.

import assert from 'node:assert/strict';
import { test } from 'node:test';
import { BYTE_NANOS, Bench } from '../bench-core.mjs';
import { B_SELF, tinyElf } from './helpers.mjs';

const IDLE = new Array(9).fill(0);
const WATCHDOG = 0x40058000;

function arrivals(bench) {
  const seen = [];
  const chip = bench.chip;
  chip.receive = (byte) => seen.push([byte, chip.base + chip.nanos]);
  return seen;
}

test('rx bytes enter one per 86.8 us from the step start; the rest go first in the next step', () => {
  const bench = new Bench(tinyElf([B_SELF]));
  const seen = arrivals(bench);
  bench.step(1000, IDLE, [...Array(12).keys()]);
  assert.equal(seen.length, 11, '11 bytes fit into 1000 us');
  seen.forEach(([byte, at], i) => {
    assert.equal(byte, i);
    const due = (i + 1) * BYTE_NANOS;
    assert.ok(at >= due && at < due + 100, `byte ${i} at ${at} ns, due ${due}`);
  });
  bench.step(1000, IDLE, [0x40]);
  assert.deepEqual(seen.slice(11).map(([b]) => b), [11, 0x40]);
  assert.ok(Math.abs(seen[11][1] - 12 * BYTE_NANOS) < 100, 'the carried byte keeps its place');
  assert.ok(Math.abs(seen[12][1] - 13 * BYTE_NANOS) < 100, 'the next follows it on the line');
  bench.step(1000, IDLE, []);
  bench.step(1000, IDLE, [0x41]);
  assert.ok(Math.abs(seen[13][1] - (3_000_000 + BYTE_NANOS)) < 100, 'an idle line starts at the step');
});

test('each step runs exactly its microseconds of virtual time', () => {
  const bench = new Bench(tinyElf([B_SELF]));
  for (let i = 0; i < 5; i++) bench.step(1000, IDLE, []);
  bench.step(250, IDLE, []);
  assert.equal(bench.nanos, 5_250_000);
  const chipTime = bench.chip.base + bench.chip.nanos;
  assert.ok(chipTime >= 5_250_000 && chipTime < 5_250_100, `chip at ${chipTime} ns`);
});

test('a watchdog reset rebuilds the chip keeping flash, REASON and SCRATCH; power on clears them', () => {
  const bench = new Bench(tinyElf([B_SELF]));
  let rp2040 = bench.chip.rp2040;
  rp2040.writeUint32(WATCHDOG + 0x0c, 0x1234); // SCRATCH0
  rp2040.flash[0x1f0000] = 0x42; // as if the image had stored something
  rp2040.writeUint32(WATCHDOG + 0x04, 4000); // LOAD: 2 ms
  rp2040.writeUint32(WATCHDOG, 1 << 30); // ENABLE
  let r = bench.step(1000, IDLE, []);
  assert.equal(r.resets, 0);
  r = bench.step(2000, IDLE, []);
  assert.equal(r.resets, 1);
  assert.notEqual(bench.chip.rp2040, rp2040, 'a fresh chip');
  rp2040 = bench.chip.rp2040;
  assert.equal(rp2040.readUint32(WATCHDOG + 0x08), 1, 'REASON: TIMER');
  assert.equal(rp2040.readUint32(WATCHDOG + 0x0c), 0x1234);
  assert.equal(rp2040.flash[0x1f0000], 0x42);
  assert.equal(bench.chip.base, 2_000_000, 'the new chip started at the expiry');

  bench.powerOff();
  r = bench.step(1000, IDLE, [0x53]);
  assert.deepEqual([r.motors, r.tx, r.resets], [['000:0', '000:0', '000:0'], [], 1]);
  bench.powerOn();
  const seen = arrivals(bench);
  r = bench.step(1000, IDLE, []);
  assert.equal(r.resets, 2);
  assert.deepEqual(seen, [], 'the byte sent while off is lost');
  rp2040 = bench.chip.rp2040;
  assert.equal(rp2040.readUint32(WATCHDOG + 0x08), 0, 'REASON: power-on');
  assert.equal(rp2040.readUint32(WATCHDOG + 0x0c), 0);
  assert.equal(rp2040.flash[0x1f0000], 0x42, 'flash kept across the power cycle');
});

test('a software reset request (AIRCR.SYSRESETREQ) counts and boots a fresh chip', () => {
  const bench = new Bench(tinyElf([B_SELF]));
  const first = bench.chip;
  bench.step(1000, IDLE, []);
  first.rp2040.writeUint32(0xe000ed0c, 0x05fa0004);
  const r = bench.step(1000, IDLE, []);
  assert.equal(r.resets, 1);
  assert.notEqual(bench.chip, first);
});

test('hang: no instruction runs; the watchdog still expires and the chip boots again', () => {
  const bench = new Bench(tinyElf([B_SELF]));
  const { rp2040 } = bench.chip;
  rp2040.writeUint32(WATCHDOG + 0x04, 6000); // 3 ms
  rp2040.writeUint32(WATCHDOG, 1 << 30);
  bench.step(1000, IDLE, []);
  bench.hang();
  const cycles = rp2040.core.cycles;
  let r = bench.step(1000, IDLE, []);
  assert.equal(rp2040.core.cycles, cycles, 'no instruction executed');
  assert.equal(r.resets, 0);
  r = bench.step(2000, IDLE, []);
  assert.equal(r.resets, 1);
  assert.equal(bench.chip.hung, false);
  const after = bench.chip.rp2040.core.cycles;
  bench.step(1000, IDLE, []);
  assert.ok(bench.chip.rp2040.core.cycles > after, 'the new chip runs');
});
