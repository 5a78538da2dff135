// bench.mjs's line protocol (fil/PROTOCOL.md) on a tiny image: the greeting, the answer
// formats, errors (exit status 1) and quit / end of input (exit status 0).

import assert from 'node:assert/strict';
import { mkdtempSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { test } from 'node:test';
import { Driver } from './driver.mjs';
import { B_SELF, tinyElf } from './helpers.mjs';

const image = join(mkdtempSync(join(tmpdir(), 'fil-pico-')), 'tiny.elf');
writeFileSync(image, tinyElf([B_SELF]));

test('ready, step, power, hang, quit', async () => {
  const bench = new Driver(image);
  assert.equal(await bench.line(), 'ready pico 3 thesis');
  assert.equal(await bench.ask('step 1000 0 0 0 0 0 0 0 0 4095 -'), 'ok 000:0 000:0 000:0 - 0 0 0');
  assert.equal(await bench.ask('step 1000 1 2 3 4 5 6 7 8 9 53300a'), 'ok 000:0 000:0 000:0 - 0 0 0');
  assert.equal(await bench.ask('power off'), 'ok');
  assert.equal(await bench.ask('step 1000 0 0 0 0 0 0 0 0 0 -'), 'ok 000:0 000:0 000:0 - 0 0 0');
  assert.equal(await bench.ask('power on'), 'ok');
  assert.equal(await bench.ask('step 1000 0 0 0 0 0 0 0 0 0 -'), 'ok 000:0 000:0 000:0 - 1 0 0');
  assert.equal(await bench.ask('hang'), 'ok');
  assert.equal(await bench.quit(), 0);
});

test('end of input exits 0', async () => {
  const bench = new Driver(image);
  assert.equal(await bench.line(), 'ready pico 3 thesis');
  bench.child.stdin.end();
  assert.equal(await bench.exit, 0);
});

for (const bad of [
  'step 1000 0 0 0 0 0 0 0 0 -',
  'step 1000 0 0 0 0 0 0 0 0 4096 -',
  'step 1000 0 0 0 0 0 0 0 0 0 5G',
  'step 1000 0 0 0 0 0 0 0 0 0 ABCD',
  'step 1000 0 0 0 0 0 0 0 0 0 abc',
  'power up',
  'jump',
]) {
  test(`'${bad}' is answered error and the bench exits 1`, async () => {
    const bench = new Driver(image);
    assert.equal(await bench.line(), 'ready pico 3 thesis');
    assert.match(await bench.ask(bad), /^error \S/);
    assert.equal(await bench.exit, 1);
  });
}

test('an image that cannot be read: error, exit 1', async () => {
  const bench = new Driver(join(tmpdir(), 'no-such-image.elf'));
  assert.match(await bench.line(), /^error /);
  assert.equal(await bench.exit, 1);
});

test('an instruction at an unmapped address is an error of the bench', async () => {
  const unmapped = join(mkdtempSync(join(tmpdir(), 'fil-pico-')), 'unmapped.elf');
  // ldr r0, [pc, #4]; ldr r0, [r0]; b .; b .; .word 0x30000000 (nothing is mapped there)
  writeFileSync(unmapped, tinyElf([0x4801, 0x6800, B_SELF, B_SELF, 0x0000, 0x3000]));
  const bench = new Driver(unmapped);
  assert.equal(await bench.line(), 'ready pico 3 thesis');
  assert.match(await bench.ask('step 1000 0 0 0 0 0 0 0 0 0 -'), /^error .*invalid memory address/);
  assert.equal(await bench.exit, 1);
});

test('--rtt on an image without _SEGGER_RTT: error, exit 1', async () => {
  const bench = new Driver(image, ['--rtt', join(tmpdir(), 'unused-rtt.bin')]);
  assert.match(await bench.line(), /^error --rtt: the image has no _SEGGER_RTT/);
  assert.equal(await bench.exit, 1);
});
