// The bench's state between protocol requests (fil/PROTOCOL.md), apart from the text protocol
// itself (bench.mjs): virtual time, the chip of the moment and its rebuilds on resets and power
// cycles, the printer line's bytes on their way in, the cumulative counters.

import { readFileSync } from 'node:fs';
import { fileURLToPath } from 'node:url';
import { Chip, FLASH_BYTES } from './chip.mjs';
import { parseElf } from './elf.mjs';
import { byFunction } from './symbols.mjs';

const BOOTROM = fileURLToPath(new URL('./bootrom-b1.bin', import.meta.url));
/** 115200 Bd, 8N1: ten bits a byte, 86.8 us. */
export const BYTE_NANOS = 86_806;
const FLASH_BASE = 0x10000000;

/** The flash contents an ELF image programs: its PT_LOAD segments at their load addresses. */
export function flashFromElf(elfBytes, { wornStore = false } = {}) {
  const flash = new Uint8Array(FLASH_BYTES).fill(0xff);
  for (const { address, data } of parseElf(elfBytes).segments) {
    if (address < FLASH_BASE || address + data.length > FLASH_BASE + FLASH_BYTES) {
      throw new Error(`segment at 0x${address.toString(16)} is not in the flash`);
    }
    flash.set(data, address - FLASH_BASE);
  }
  if (wornStore) flash.fill(0, STORE_OFFSET, STORE_OFFSET + STORE_BYTES);
  return flash;
}

/**
 * The store's sectors (STORE_RANGE in src/board/pico/mod.rs, offsets in the flash). With
 * FIL_WORN_STORE=1 they start written, as on a unit that has saved for a while: every sector the
 * store opens must be erased first.
 */
const STORE_OFFSET = 0x1f0000;
const STORE_BYTES = 0x10000;
export const WORN_STORE_ENV = 'FIL_WORN_STORE';

/**
 * The firmware's count of control steps (src/tasks.rs): the load counts the milliseconds in
 * which it moved after the first step, the control task's, not the boot's (the store's restore,
 * its repair, the log of what it restored).
 */
const CONTROL_STEPS = 'MMU_CONTROL_STEPS';
/** Cycles of the 125 MHz clk_sys in 1 ms. */
const CYCLES_PER_MS = 125_000;
/** Functions listed for each profiled millisecond (`profile` of the Bench). */
const PROFILE_TOP = 25;

export class Bench {
  /**
   * `profile`: `{ keep, nameOf }` to profile every measured millisecond by function and keep the
   * `keep` busiest (`profileReport`); `nameOf(pc)` names an address (symbols.mjs).
   */
  constructor(elfBytes, { log = () => {}, profile = null } = {}) {
    this.log = log;
    this.profile = profile;
    this.busiest = []; // [cycles, instructions, ms, wrote, counts by address] with `profile`
    this.bootrom = new Uint8Array(readFileSync(BOOTROM));
    this.counters = { erases: 0, programs: 0 };
    this.resets = 0;
    this.nanos = 0; // virtual time since the bench started
    this.rxQueue = []; // { byte, at }: bytes on the line, `at` when their stop bit ends
    this.lineFreeAt = 0;
    this.sensors = new Array(9).fill(0);
    this.load = []; // [instructions, cycles, bytes received, ms, wrote] of each control millisecond
    this.controlSteps = parseElf(elfBytes).symbols.get(CONTROL_STEPS);
    const wornStore = !['', '0', undefined].includes(process.env[WORN_STORE_ENV]);
    this.chip = this.newChip(flashFromElf(elfBytes, { wornStore }), null);
  }

  /**
   * The CPU's load in each 1 ms step in which the control task stepped, after its first step
   * (CONTROL_STEPS moved; the boot and the store's restore are not the control loop): in the milliseconds without a flash write, the
   * cycles rp2040js counts (median, 99th and 99.9th percentile, busiest, with its instructions);
   * the busiest with one. One line, for the log.
   */
  loadSummary() {
    const plain = this.load.filter((m) => !m[4]).sort((a, b) => a[1] - b[1]);
    const writing = this.load.filter((m) => m[4]);
    if (!plain.length) {
      const why = this.controlSteps === undefined ? ` (the image has no ${CONTROL_STEPS})` : '';
      return `load: no millisecond measured${why}`;
    }
    const pct = (c) => `${((100 * c) / CYCLES_PER_MS).toFixed(1)} %`;
    const at = (q) => {
      const m = plain[Math.min(plain.length - 1, Math.floor(q * plain.length))];
      return `${m[1]} (${pct(m[1])}, ${m[0]} instructions)`;
    };
    const worst = plain[plain.length - 1];
    let line = `load: ${plain.length} ms without a flash write, cycles a millisecond: median ${at(0.5)}, ` +
      `99 % ${at(0.99)}, 99.9 % ${at(0.999)}, busiest ${worst[1]} (${pct(worst[1])} of 1 ms at 125 MHz, ` +
      `${worst[0]} instructions) at ${worst[3]} ms, ${worst[2]} bytes received`;
    if (writing.length) {
      const busiest = writing.reduce((a, b) => (b[1] > a[1] ? b : a));
      line += `; ${writing.length} ms with one, busiest ${busiest[1]} (${pct(busiest[1])}) at ${busiest[3]} ms`;
    }
    return line;
  }

  /** The firmware's count of control steps on `chip`, or undefined (no such symbol, no chip). */
  stepsTaken(chip) {
    if (!chip || this.controlSteps === undefined) return undefined;
    return chip.rp2040.readUint32(this.controlSteps);
  }

  /** Keeps a measured millisecond's cycles by address if it is among the `profile.keep` busiest. */
  keepProfile([instructions, cycles, , ms, wrote], counts) {
    this.busiest.push([cycles, instructions, ms, wrote, counts]);
    this.busiest.sort((a, b) => b[0] - a[0]);
    this.busiest.length = Math.min(this.busiest.length, this.profile.keep);
  }

  /** The busiest milliseconds' cycles by function (`profile`), lines for the log. */
  profileReport() {
    return this.busiest.flatMap(([cycles, instructions, ms, wrote, counts]) => [
      `profile: ${cycles} cycles (${instructions} instructions) at ${ms} ms${wrote ? ', with a flash write' : ''}`,
      ...byFunction(counts, this.profile.nameOf)
        .slice(0, PROFILE_TOP)
        .map(([name, n]) => `profile: ${String(n).padStart(7)}  ${name}`),
    ]);
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
    const [chip, resets] = [this.chip, this.resets];
    const [executed, cycles] = chip ? [chip.executed, chip.busyCycles] : [0, 0];
    const flashOps = this.counters.erases + this.counters.programs;
    if (chip && this.profile) chip.pcCycles = new Map();
    const steps = this.stepsTaken(chip);
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
    // A millisecond of the control loop: it stepped, and had stepped before the millisecond began
    // (the first step's millisecond also holds the end of the boot).
    const stepped = steps > 0 && this.stepsTaken(chip) > steps;
    if (chip && this.chip === chip && this.resets === resets && us === 1000 && stepped) {
      const wrote = this.counters.erases + this.counters.programs !== flashOps;
      this.load.push([chip.executed - executed, chip.busyCycles - cycles, rx.length, Math.round(end / 1e6), wrote]);
      if (this.profile) this.keepProfile(this.load.at(-1), chip.pcCycles);
    }
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
