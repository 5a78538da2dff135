// The bench's state between protocol requests (fil/PROTOCOL.md), apart from the text protocol
// itself (bench.mjs): virtual time, the chip of the moment and its rebuilds on resets and power
// cycles, the printer line's bytes on their way in, the cumulative counters.

import { readFileSync } from 'node:fs';
import { fileURLToPath } from 'node:url';
import { Chip, FLASH_BYTES } from './chip.mjs';
import { parseElf } from './elf.mjs';

const BOOTROM = fileURLToPath(new URL('./bootrom-b1.bin', import.meta.url));
/** 115200 Bd, 8N1: ten bits a byte, 86.8 us. */
export const BYTE_NANOS = 86_806;
const FLASH_BASE = 0x10000000;

/** The flash contents an ELF image programs: its PT_LOAD segments at their load addresses. */
export function flashFromElf(elfBytes) {
  const flash = new Uint8Array(FLASH_BYTES).fill(0xff);
  for (const { address, data } of parseElf(elfBytes).segments) {
    if (address < FLASH_BASE || address + data.length > FLASH_BASE + FLASH_BYTES) {
      throw new Error(`segment at 0x${address.toString(16)} is not in the flash`);
    }
    flash.set(data, address - FLASH_BASE);
  }
  return flash;
}

export class Bench {
  constructor(elfBytes, { log = () => {} } = {}) {
    this.log = log;
    this.bootrom = new Uint8Array(readFileSync(BOOTROM));
    this.counters = { erases: 0, programs: 0 };
    this.resets = 0;
    this.nanos = 0; // virtual time since the bench started
    this.rxQueue = []; // { byte, at }: bytes on the line, `at` when their stop bit ends
    this.lineFreeAt = 0;
    this.sensors = new Array(9).fill(0);
    this.chip = this.newChip(flashFromElf(elfBytes), null);
  }

  newChip(flash, watchdog) {
    const chip = new Chip({ bootrom: this.bootrom, flash, counters: this.counters, watchdog, log: this.log });
    chip.base = this.nanos; // bench time at the chip's clock zero
    chip.sensors = this.sensors;
    return chip;
  }

  /** A reset the chip asked for: a fresh chip from its flash; a watchdog keeps its registers. */
  resetChip() {
    const old = this.chip;
    this.nanos = old.base + old.nanos;
    const carry = old.watchdogState;
    if (old.resetRequest === 'sysresetreq') carry.reason = 0; // REASON: 0 for other resets
    this.log(`reset (${old.resetRequest}) at ${(this.nanos / 1e6).toFixed(3)} ms`);
    this.chip = this.newChip(old.rp2040.flash, carry);
    this.resets++;
  }

  /** Runs the chip (if powered) until bench time `until`, across any resets on the way. */
  runUntil(until) {
    while (this.chip) {
      const chip = this.chip;
      chip.run(until - chip.base);
      if (chip.error) throw new Error(chip.error);
      if (!chip.resetRequest) break;
      this.resetChip();
    }
  }

  /**
   * One `step`: `us` of virtual time with these sensor levels and these bytes from the printer.
   * Returns { motors, tx, resets, erases, programs }.
   */
  step(us, sensors, rx) {
    const start = this.nanos;
    const end = start + us * 1000;
    sensors.forEach((value, i) => { this.sensors[i] = value; });
    if (this.chip) {
      for (const byte of rx) {
        const at = Math.max(this.lineFreeAt, start) + BYTE_NANOS;
        this.lineFreeAt = at;
        this.rxQueue.push({ byte, at });
      }
    }
    const tx = [];
    const collect = () => {
      if (this.chip) tx.push(...this.chip.tx.splice(0));
    };
    while (this.rxQueue.length && this.rxQueue[0].at <= end) {
      const { byte, at } = this.rxQueue.shift();
      this.runUntil(at);
      collect();
      this.chip?.receive(byte);
    }
    this.runUntil(end);
    collect();
    this.nanos = end;
    const motors = this.chip ? this.chip.motors() : ['000:0', '000:0', '000:0'];
    return { motors, tx, resets: this.resets, ...this.counters };
  }

  /** `power off`: no chip; bytes on the line are lost. */
  powerOff() {
    if (!this.chip) return;
    this.flash = this.chip.rp2040.flash;
    this.chip = null;
    this.rxQueue = [];
    this.lineFreeAt = this.nanos;
  }

  /** `power on`: a fresh chip from the flash as left (a power-on reset: REASON and SCRATCH 0). */
  powerOn() {
    const flash = this.chip ? this.chip.rp2040.flash : this.flash;
    this.rxQueue = [];
    this.lineFreeAt = this.nanos;
    this.chip = this.newChip(flash, null);
    this.resets++;
  }

  /** `hang`: the CPU stops; timers, DMA and the watchdog go on. */
  hang() {
    if (this.chip) this.chip.hung = true;
  }
}
