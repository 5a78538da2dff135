// The board around the chip (chip.mjs): the multiplexer in front of ADC0 and the TB6612 inputs
// read back, driven through the chip's registers as the firmware drives them.

import assert from 'node:assert/strict';
import { test } from 'node:test';
import { MUX_CHANNEL } from '../chip.mjs';
import { ADC, RAM, armAdcDma, bareChip } from './helpers.mjs';

const SIO = 0xd0000000;
const IO_BANK0 = 0x40014000;
const PWM = 0x40050000;
const SET = 0x2000;
const CLEAR = 0x3000;

function sioOutput(rp2040, pin, high) {
  rp2040.writeUint32(IO_BANK0 + pin * 8 + 4, 5); // FUNCSEL: SIO
  rp2040.writeUint32(SIO + 0x24, 1 << pin); // GPIO_OE_SET
  rp2040.writeUint32(SIO + (high ? 0x14 : 0x18), 1 << pin); // GPIO_OUT_SET / CLR
}

function convert(rp2040) {
  rp2040.writeUint32(ADC + 0x00, 1 | (1 << 2)); // CS: EN | START_ONCE, AINSEL 0
  rp2040.clock.tick(3000);
  return rp2040.readUint32(ADC + 0x04); // RESULT
}

test('the sensor MUX_CHANNEL wiring is src/board/pico/mod.rs\'s (Gray code of the index)', async () => {
  const { readFileSync } = await import('node:fs');
  const source = readFileSync(new URL('../../../src/board/pico/mod.rs', import.meta.url), 'utf8');
  assert.match(source, /channels\[i\] = \(i \^ \(i >> 1\)\) as u8;/);
  assert.deepEqual(MUX_CHANNEL, [0, 1, 3, 2, 6, 7, 5, 4, 12]);
});

test('ADC0 reads the sensor of the multiplexer channel that GP2..GP5 select', () => {
  const chip = bareChip();
  const { rp2040 } = chip;
  chip.sensors.splice(0, 9, 100, 200, 300, 400, 500, 600, 700, 800, 900);
  for (let sensor = 0; sensor < 9; sensor++) {
    const channel = MUX_CHANNEL[sensor];
    for (let bit = 0; bit < 4; bit++) sioOutput(rp2040, 2 + bit, channel & (1 << bit));
    assert.equal(convert(rp2040), 100 * (sensor + 1), `sensor ${sensor} on channel ${channel}`);
  }
  for (let bit = 0; bit < 4; bit++) sioOutput(rp2040, 2 + bit, 15 & (1 << bit));
  assert.equal(convert(rp2040), 0, 'channel 15: no sensor');
});

test('each slot reports STBY, IN1, IN2 and its PWM duty from the slice registers', () => {
  const chip = bareChip();
  const { rp2040 } = chip;
  assert.deepEqual(chip.motors(), ['000:0', '000:0', '000:0'], 'nothing driven');
  sioOutput(rp2040, 13, true); // STBY #1
  sioOutput(rp2040, 9, true); // slot 0 IN1
  sioOutput(rp2040, 12, true); // slot 1 IN2
  sioOutput(rp2040, 16, false); // STBY #2 low
  sioOutput(rp2040, 14, true); // slot 2 IN1
  for (const pin of [6, 7, 8]) rp2040.writeUint32(IO_BANK0 + pin * 8 + 4, 4); // FUNCSEL: PWM
  rp2040.writeUint32(PWM + 3 * 0x14 + 0x10, 6249); // slice 3 TOP
  rp2040.writeUint32(PWM + 3 * 0x14 + 0x0c, (1250 << 16) | 4687); // CC: B 1250, A 4687
  rp2040.writeUint32(PWM + 3 * 0x14 + 0x00, 1); // CSR: EN
  rp2040.writeUint32(PWM + 4 * 0x14 + 0x10, 6249);
  rp2040.writeUint32(PWM + 4 * 0x14 + 0x0c, 6249);
  assert.deepEqual(chip.motors(), ['110:750', '101:200', '010:0'], 'slice 4 not enabled: 0');
  rp2040.writeUint32(PWM + 4 * 0x14 + 0x00, 1 | (1 << 2)); // EN, A_INV
  assert.equal(chip.motors()[2], '010:0', 'full compare, inverted: 0');
  rp2040.writeUint32(PWM + 4 * 0x14 + 0x00, 1);
  assert.equal(chip.motors()[2], '010:1000');
  sioOutput(rp2040, 8, true); // the PWM pin back to SIO, driven high: full duty
  assert.equal(chip.motors()[2], '010:1000');
  sioOutput(rp2040, 8, false);
  assert.equal(chip.motors()[2], '010:0');
});

/**
 * One sensor as src/board/pico/mod.rs reads it with embassy-rp's `Adc::read_many` (DMA_CH3):
 * stop a free run and drain the FIFO, FIFO and DREQ on (THRESH 1), the DMA channel armed for
 * `count` halfwords, START_MANY at divider 0 (back to back, 2 us each); at the DMA's last
 * transfer the board's interrupt handler (StopConversions) clears START_MANY, so the conversion
 * under way ends during the wake-up and no other starts: read_many's guard finds READY at once,
 * and that one conversion stays in the FIFO; then FIFO and DREQ off.
 */
function readMany(rp2040, count) {
  rp2040.writeUint32(ADC + CLEAR, 1 << 3); // CS: START_MANY off
  rp2040.clock.tick(3000);
  while (!(rp2040.readUint32(ADC + 0x08) & (1 << 8))) rp2040.readUint32(ADC + 0x0c); // drain
  rp2040.writeUint32(ADC + 0x08, (1 << 24) | (1 << 3) | 1); // FCS: THRESH 1, DREQ_EN, EN
  const to = RAM + 0x400;
  const ch = armAdcDma(rp2040, to, count);
  rp2040.writeUint32(ADC + 0x10, 0); // DIV
  rp2040.writeUint32(ADC + SET, 1 << 3); // CS: START_MANY
  let us = 0;
  while (rp2040.readUint32(ch + 0x0c) & (1 << 24)) { // BUSY
    rp2040.clock.tick(1000);
    assert.ok(++us < 100, 'the DMA completes');
  }
  rp2040.writeUint32(ADC + CLEAR, 1 << 3); // the DMA's interrupt: START_MANY off
  rp2040.clock.tick(8000); // the wake-up
  rp2040.writeUint32(ADC + CLEAR, 1 << 3); // read_many's guard: START_MANY off, READY polled
  assert.ok(rp2040.readUint32(ADC + 0x00) & (1 << 8), 'READY: the ADC stopped during the wake-up');
  assert.equal((rp2040.readUint32(ADC + 0x08) >> 16) & 0xf, 1, 'one conversion after the last transfer');
  rp2040.writeUint32(ADC + 0x08 + CLEAR, (1 << 3) | (1 << 1) | 1); // FCS: DREQ_EN, SHIFT, EN off
  return { us, samples: Array.from({ length: count }, (_, i) => rp2040.readUint16(to + 2 * i)) };
}

test('ADC0 by DMA: free-running conversions reach RAM with the sensor the multiplexer selects', () => {
  const chip = bareChip();
  const { rp2040 } = chip;
  chip.sensors.splice(0, 9, 100, 200, 300, 400, 500, 600, 700, 800, 900);
  rp2040.writeUint32(ADC + 0x00, 1); // CS: EN, AINSEL 0
  for (let sensor = 0; sensor < 9; sensor++) {
    const channel = MUX_CHANNEL[sensor];
    for (let bit = 0; bit < 4; bit++) sioOutput(rp2040, 2 + bit, channel & (1 << bit));
    const { us, samples } = readMany(rp2040, 9);
    assert.deepEqual(samples, new Array(9).fill(100 * (sensor + 1)), `sensor ${sensor} on channel ${channel}`);
    assert.ok(us >= 17 && us <= 19, `nine conversions of 2 us, not at once (${us} us)`);
  }
});
