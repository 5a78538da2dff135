// End to end: the real Pico firmware image through `node bench.mjs`, as the simulator runs it.
// The image: $FIL_PICO_IMAGE, else ../../dist/mmu-firmware-pico.elf (scripts/build-firmware.sh
// pico dist). Skipped, saying so, when there is none.

import assert from 'node:assert/strict';
import { existsSync, readFileSync } from 'node:fs';
import { test } from 'node:test';
import { fileURLToPath } from 'node:url';
import { Bench } from '../bench-core.mjs';
import { Driver } from './driver.mjs';
import { request } from './frames.mjs';

const IMAGE = process.env.FIL_PICO_IMAGE
  ?? fileURLToPath(new URL('../../../dist/mmu-firmware-pico.elf', import.meta.url));
const skip = existsSync(IMAGE) ? false
  : `no firmware image at ${IMAGE} (set FIL_PICO_IMAGE, or: bash scripts/build-firmware.sh pico dist)`;
if (skip) console.log(`# SKIP firmware tests: ${skip}`);

/**
 * As the printer does: sends `frame`, waits up to `retryMs` for an answer containing `prefix`,
 * sends again; fails after `limitMs`. Returns when the answer arrived (ms from the call).
 */
async function exchange(bench, frame, prefix, limitMs, retryMs = 100) {
  let tx = '';
  let last;
  for (let ms = 0; ms < limitMs; ms++) {
    last = await bench.step(ms % retryMs === 0 ? frame : []);
    tx += last.tx;
    if (tx.includes(prefix)) return { ms: ms + 1, tx, last };
  }
  assert.fail(`no ${JSON.stringify(prefix)} within ${limitMs} ms; received ${JSON.stringify(tx)}`);
}

/** A bench on the image, killed when the test ends (passed or not). */
function start(t) {
  const bench = new Driver(IMAGE);
  t.after(() => bench.child.kill());
  return bench;
}

async function idle(bench, ms) {
  let last;
  for (let i = 0; i < ms; i++) last = await bench.step();
  return last;
}

test('boots and answers S0*c6 with S0 A... within 200 ms', { skip }, async (t) => {
  const bench = start(t);
  assert.equal(await bench.line(), 'ready pico 3 thesis');
  const { ms, tx, last } = await exchange(bench, request('S', 0), '\n', 200);
  assert.match(tx, /^S0 A[0-9a-f]+\*[0-9a-f]+\n$/, 'the answer and nothing else');
  assert.equal(last.resets, 0);
  assert.deepEqual(last.motors, ['000:0', '000:0', '000:0'], 'bridges off when idle');
  console.log(`# first answer after ${ms} ms of virtual time`);
  assert.equal(await bench.quit(), 0);
});

test('hang: the watchdog resets the chip and the firmware answers again', { skip }, async (t) => {
  const bench = start(t);
  await bench.line();
  await exchange(bench, request('S', 0), 'S0 A', 200);
  assert.equal(await bench.ask('hang'), 'ok');
  let ms = 0;
  let r;
  do {
    r = await bench.step();
    ms++;
    assert.equal(r.tx, '', 'a hung chip sends nothing');
  } while (r.resets === 0 && ms < 1000);
  assert.equal(r.resets, 1, 'reset by the watchdog');
  assert.ok(ms > 400 && ms <= 610, `the watchdog (600 ms) expired ${ms} ms after the hang`);
  await exchange(bench, request('S', 0), 'S0 A', 200);
  assert.equal(await bench.quit(), 0);
});

test('a setting written over the line is saved to flash and survives a power cycle', { skip }, async (t) => {
  const bench = start(t);
  await bench.line();
  const before = await exchange(bench, request('R', 0x22), 'R22 A', 200);
  assert.ok(!before.tx.includes('R22 A1f4'), 'not already 500');
  const settled = await idle(bench, 200); // the store's first save of a blank flash is done
  await exchange(bench, request('W', 0x22, 500), 'W22 A', 100);
  let r;
  for (let ms = 0; ms < 3000; ms++) {
    r = await bench.step();
    if (r.programs > settled.programs) break;
  }
  assert.ok(r.programs > settled.programs, 'the store programmed the flash');
  await idle(bench, 20); // let the save finish
  assert.equal(await bench.ask('power off'), 'ok');
  await idle(bench, 10);
  assert.equal(await bench.ask('power on'), 'ok');
  const after = await exchange(bench, request('R', 0x22), 'R22 A', 200);
  assert.match(after.tx, /R22 A1f4\*/, 'bowden_mm = 500 read back after power on');
  assert.equal(after.last.resets, 1);
  assert.equal(await bench.quit(), 0);
});

test('two runs of the same requests give identical answers', { skip }, async (t) => {
  const run = async () => {
    const bench = start(t);
    await bench.line();
    const lines = [];
    for (let ms = 0; ms < 150; ms++) {
      const rx = ms === 60 ? request('S', 0) : ms === 90 ? request('R', 0x1b) : [];
      const sensors = Array.from({ length: 9 }, (_, i) => (ms * 37 + i * 400) % 4096);
      lines.push((await bench.step(rx, { sensors })).line);
    }
    await bench.quit();
    return lines;
  };
  const [a, b] = [await run(), await run()];
  assert.deepEqual(a, b);
  assert.ok(a.some((l) => / 5330[0-9a-f]* /.test(l)), 'with an answer in them');
});

test('--rtt FILE receives the image\'s defmt frames (RTT up channel 0)', { skip }, async (t) => {
  const { mkdtempSync, readFileSync } = await import('node:fs');
  const { join } = await import('node:path');
  const { tmpdir } = await import('node:os');
  const file = join(mkdtempSync(join(tmpdir(), 'fil-pico-rtt-')), 'rtt.bin');
  const bench = new Driver(IMAGE, ['--rtt', file]);
  t.after(() => bench.child.kill());
  assert.equal(await bench.line(), 'ready pico 3 thesis');
  await idle(bench, 5);
  const bytes = readFileSync(file);
  // defmt-rtt's frames: rzCOBS-encoded, each ended by a 0 byte; the boot logs two.
  assert.ok(bytes.length > 10, `${bytes.length} bytes`);
  assert.equal(bytes.at(-1), 0, 'ends with a whole frame');
  assert.equal(await bench.quit(), 0);
});

test('each sensor level reaches the firmware as that sensor (raw registers 0x60..0x68)', { skip }, async (t) => {
  const bench = start(t);
  await bench.line();
  // Protocol order: slot0 hall, slot0 filament, slot1 hall, slot1 filament, slot2 hall,
  // slot2 filament, hub filament, hub tension, hub cutter; all healthy, none the same.
  const sensors = [2010, 2020, 2030, 2040, 2050, 2060, 2070, 2080, 2090];
  // The firmware's raw registers (src/registers.rs, SensorId::from_index): 0x60 hub filament,
  // 0x61 tension, 0x62 cutter, then per slot its filament sensor and its motor Hall.
  const register = [0x64, 0x63, 0x66, 0x65, 0x68, 0x67, 0x60, 0x61, 0x62];
  const step = (rx = []) => bench.step(rx, { sensors });
  for (let ms = 0; ms < 30; ms++) await step();
  for (let i = 0; i < 9; i++) {
    const address = register[i];
    let tx = '';
    for (let ms = 0; ms < 20 && !tx.includes('\n'); ms++) tx += (await step(ms === 0 ? request('R', address) : [])).tx;
    const m = /^R([0-9a-f]+) A([0-9a-f]+)\*/.exec(tx);
    assert.ok(m, `R${address.toString(16)}: ${JSON.stringify(tx)}`);
    assert.equal(parseInt(m[2], 16), sensors[i], `sensor ${i} read through register 0x${m[1]}`);
  }
  assert.equal(await bench.quit(), 0);
});

for (const slot of [0, 1, 2]) {
  test(`L${slot} drives slot ${slot}'s bridge forward, and only that one`, { skip }, async (t) => {
    const bench = start(t);
    await bench.line();
    const sensors = new Array(9).fill(2048);
    sensors[2 * slot + 1] = 3000; // filament at the slot's sensor
    let phase = 0;
    let driven = 0;
    let r;
    for (let ms = 0; ms < 300; ms++) {
      r = await bench.step(ms === 30 ? request('S', 0) : ms === 60 ? request('L', slot) : [], { sensors });
      const m = r.motors[slot];
      if (m.startsWith('110:') && m !== '110:0') {
        driven++;
        phase += 0.3; // the slot's motor Hall turns while it is driven
        r.motors.forEach((other, k) => {
          if (k !== slot) assert.match(other, /^[01]00:0$/, `slot ${k} while slot ${slot} drives`);
        });
      }
      sensors[2 * slot] = Math.round(2048 + 700 * Math.sin(phase));
    }
    assert.ok(driven > 100, `slot ${slot} driven forward in ${driven} of 240 ms`);
    assert.equal(await bench.quit(), 0);
  });
}

test('X0 resets the chip through AIRCR.SYSRESETREQ and the firmware answers again', { skip }, async (t) => {
  const bench = start(t);
  await bench.line();
  await exchange(bench, request('S', 0), 'S0 A', 200);
  let r = await bench.step(request('X', 0));
  for (let ms = 0; ms < 50 && r.resets === 0; ms++) r = await bench.step();
  assert.equal(r.resets, 1, 'one reset');
  await exchange(bench, request('S', 0), 'S0 A', 200);
  assert.equal(await bench.quit(), 0);
});

test('the load counts the control task\'s milliseconds: none of the boot\'s, every one after it', { skip }, () => {
  const bench = new Bench(readFileSync(IMAGE));
  const levels = [2048, 3000, 2048, 2048, 2048, 2048, 2048, 2048, 2048];
  let first;
  for (let ms = 1; ms <= 300; ms++) {
    const before = bench.stepsTaken(bench.chip);
    bench.step(1000, levels, []);
    if (first === undefined && bench.stepsTaken(bench.chip) !== before) first = ms;
  }
  assert.ok(first > 1, `the boot restores the store before the first step (at ${first} ms)`);
  // The first step's millisecond also holds the end of the boot.
  assert.equal(bench.load[0][3], first + 1, 'the first millisecond counted is the one after');
  assert.equal(bench.load.length, 300 - first, 'then every millisecond, one step each');
});
