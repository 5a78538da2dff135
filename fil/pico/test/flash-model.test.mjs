// The QSPI flash model (flash-model.mjs): the W25Q16JV's commands on their own, and through the
// SSI and IO_QSPI as the boot ROM drives them. The second group fails with the model left out
// (FIL_PICO_DISABLE=flash): rp2040js's SSI answers every read with a constant.

import assert from 'node:assert/strict';
import { test } from 'node:test';
import { NorFlash } from '../flash-model.mjs';
import { bareChip } from './helpers.mjs';

function command(flash, bytes) {
  flash.select();
  const out = bytes.map((b) => flash.transfer(b));
  flash.deselect();
  return out;
}

function newFlash() {
  const memory = new Uint8Array(2 * 1024 * 1024).fill(0xff);
  return { memory, flash: new NorFlash(memory) };
}

test('flash: JEDEC ID, status registers (QE set, WEL follows WREN/WRDI)', () => {
  const { flash } = newFlash();
  assert.deepEqual(command(flash, [0x9f, 0, 0, 0]).slice(1), [0xef, 0x40, 0x15]);
  assert.equal(command(flash, [0x35, 0])[1], 0x02, 'QE');
  assert.equal(command(flash, [0x05, 0])[1], 0x00);
  command(flash, [0x06]);
  assert.equal(command(flash, [0x05, 0])[1], 0x02, 'WEL');
  command(flash, [0x04]);
  assert.equal(command(flash, [0x05, 0])[1], 0x00);
});

test('flash: page program ANDs into the page, wraps within it, needs WREN, counts one', () => {
  const { memory, flash } = newFlash();
  command(flash, [0x02, 0x1f, 0x00, 0xfe, 0x0f, 0xf0, 0xaa]); // no WREN: ignored
  assert.equal(memory[0x1f00fe], 0xff);
  assert.equal(flash.counters.programs, 0);
  command(flash, [0x06]);
  command(flash, [0x02, 0x1f, 0x00, 0xfe, 0x0f, 0xf0, 0xaa]);
  assert.deepEqual([...memory.subarray(0x1f00fe, 0x1f0100)], [0x0f, 0xf0]);
  assert.equal(memory[0x1f0000], 0xaa, 'wrapped to the start of the page');
  assert.equal(memory[0x1f0100], 0xff, 'not into the next page');
  command(flash, [0x06]);
  command(flash, [0x02, 0x1f, 0x00, 0xfe, 0xf0]);
  assert.equal(memory[0x1f00fe], 0x00, 'program only clears bits');
  assert.equal(flash.counters.programs, 2);
  assert.equal(command(flash, [0x05, 0])[1], 0x00, 'WEL cleared');
  assert.deepEqual(command(flash, [0x03, 0x1f, 0x00, 0xfe, 0, 0, 0]).slice(4), [0x00, 0xf0, 0xff]);
});

test('flash: sector and block erases set their aligned range to 0xff, counted per 4 KiB', () => {
  const { memory, flash } = newFlash();
  memory.fill(0, 0x1e0000, 0x200000);
  command(flash, [0x20, 0x1f, 0x12, 0x34]); // no WREN
  assert.equal(memory[0x1f1000], 0);
  command(flash, [0x06]);
  command(flash, [0x20, 0x1f, 0x12, 0x34]);
  assert.equal(memory[0x1f0fff], 0);
  assert.ok(memory.subarray(0x1f1000, 0x1f2000).every((b) => b === 0xff));
  assert.equal(memory[0x1f2000], 0);
  command(flash, [0x06]);
  command(flash, [0xd8, 0x1e, 0x80, 0x00]); // 64 KiB block 0x1e0000
  assert.ok(memory.subarray(0x1e0000, 0x1f0000).every((b) => b === 0xff));
  assert.equal(flash.counters.erases, 1 + 16);
});

test('flash behind the SSI: with SS forced low by IO_QSPI, DR0 clocks bytes through the flash', () => {
  const chip = bareChip();
  const { rp2040 } = chip;
  const ssCtrl = 0x4001800c;
  const dr0 = 0x18000060;
  const transfer = (bytes) => {
    bytes.forEach((b) => rp2040.writeUint32(dr0, b));
    assert.equal(rp2040.readUint32(0x18000024), bytes.length, 'RXFLR');
    return bytes.map(() => rp2040.readUint32(dr0));
  };
  rp2040.writeUint32(ssCtrl, 3 << 8); // SS forced high: nothing selected, bytes still clock
  assert.deepEqual(transfer([0x9f, 0]), [0xff, 0xff]);
  rp2040.writeUint32(ssCtrl, 2 << 8); // SS low
  assert.deepEqual(transfer([0x9f, 0, 0, 0]), [0xff, 0xef, 0x40, 0x15]);
  rp2040.writeUint32(ssCtrl, 3 << 8);
  // Write enable, erase the sector at 0x1ff000 of a flash whose bytes there are 0, program.
  rp2040.flash.fill(0, 0x1ff000, 0x200000);
  for (const cmd of [[0x06], [0x20, 0x1f, 0xf0, 0x00], [0x06], [0x02, 0x1f, 0xf0, 0x10, 0x5a]]) {
    rp2040.writeUint32(ssCtrl, 2 << 8);
    transfer(cmd);
    rp2040.writeUint32(ssCtrl, 3 << 8);
  }
  assert.equal(rp2040.readUint8(0x101ff010), 0x5a, 'XIP reads what was programmed');
  assert.equal(rp2040.readUint8(0x101ff011), 0xff, 'and erased');
  assert.deepEqual([chip.flash.counters.erases, chip.flash.counters.programs], [1, 1]);
});
