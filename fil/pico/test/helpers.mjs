// Test helpers: a Chip without firmware (blank flash, registers driven from the test), and a
// minimal ELF image whose boot2 is a few given Thumb instructions.

import { readFileSync } from 'node:fs';
import { Chip, FLASH_BYTES } from '../chip.mjs';

const BOOTROM = new Uint8Array(readFileSync(new URL('../bootrom-b1.bin', import.meta.url)));

export function bareChip() {
  const flash = new Uint8Array(FLASH_BYTES).fill(0xff);
  return new Chip({ bootrom: BOOTROM, flash, counters: { erases: 0, programs: 0 }, watchdog: null });
}

/** Puts Thumb halfwords at `address` in the chip's RAM and points the PC there. */
export function runCode(chip, address, halfwords) {
  halfwords.forEach((h, i) => chip.rp2040.writeUint16(address + 2 * i, h));
  chip.rp2040.core.PC = address;
}

/** An ELF32 image with one PT_LOAD of `code` (Thumb halfwords) at 0x10000000 (boot2). */
export function tinyElf(halfwords) {
  const code = Buffer.alloc(halfwords.length * 2);
  halfwords.forEach((h, i) => code.writeUInt16LE(h, 2 * i));
  const elf = Buffer.alloc(52 + 32 + code.length);
  elf.writeUInt32BE(0x7f454c46, 0);
  elf[4] = 1; // ELFCLASS32
  elf[5] = 1; // little-endian
  elf[6] = 1;
  elf.writeUInt16LE(2, 16); // ET_EXEC
  elf.writeUInt16LE(40, 18); // EM_ARM
  elf.writeUInt32LE(1, 20);
  elf.writeUInt32LE(0x10000001, 24); // entry
  elf.writeUInt32LE(52, 28); // phoff
  elf.writeUInt16LE(52, 40); // ehsize
  elf.writeUInt16LE(32, 42); // phentsize
  elf.writeUInt16LE(1, 44); // phnum
  elf.writeUInt16LE(40, 46); // shentsize
  const ph = 52;
  elf.writeUInt32LE(1, ph); // PT_LOAD
  elf.writeUInt32LE(84, ph + 4); // offset
  elf.writeUInt32LE(0x10000000, ph + 8); // vaddr
  elf.writeUInt32LE(0x10000000, ph + 12); // paddr
  elf.writeUInt32LE(code.length, ph + 16);
  elf.writeUInt32LE(code.length, ph + 20);
  elf.writeUInt32LE(5, ph + 24);
  code.copy(elf, 84);
  return elf;
}

/** The register blocks and the ADC's DMA request the tests drive (RP2040 datasheet 2.2). */
export const ADC = 0x4004c000;
export const DMA = 0x50000000;
export const RAM = 0x20000000;
export const DREQ_ADC = 36;

/**
 * Arms DMA channel 3 (the one src/board/pico/mod.rs takes for the scan) as embassy-rp's
 * `Adc::read_many` does: `count` halfwords from the ADC's FIFO to `to`, paced by the ADC's
 * request. Returns the channel's register block.
 */
export function armAdcDma(rp2040, to, count) {
  const ch = DMA + 3 * 0x40;
  rp2040.writeUint32(ch + 0x00, ADC + 0x0c); // READ_ADDR: FIFO
  rp2040.writeUint32(ch + 0x04, to); // WRITE_ADDR
  rp2040.writeUint32(ch + 0x08, count); // TRANS_COUNT
  // CTRL_TRIG: EN, halfword, INCR_WRITE, CHAIN_TO itself, TREQ_SEL ADC
  rp2040.writeUint32(ch + 0x0c, 1 | (1 << 2) | (1 << 5) | (3 << 11) | (DREQ_ADC << 15));
  return ch;
}

/** Thumb: `b .` (an endless loop), `wfi`. */
export const B_SELF = 0xe7fe;
export const WFI = 0xbf30;
