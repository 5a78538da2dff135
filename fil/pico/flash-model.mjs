// The Pico's QSPI NOR flash (a W25Q16JV, 2 MiB) behind the RP2040's SSI, for the boot ROM's
// flash functions that embassy-rp's flash driver calls (connect_internal_flash, flash_exit_xip,
// flash_range_erase, flash_range_program, flash_flush_cache).
//
// rp2040js 1.4.1 has no flash device: its SSI answers every DR0 read with a constant (enough
// for boot2's status polls) and IO_QSPI is unimplemented, so the ROM's first erase never
// completes. The ROM selects the flash by hand: it drives the SS pin low through IO_QSPI
// GPIO_QSPI_SS_CTRL.OUTOVER = 2 (RP2040 DS 2.19.6.2) and pushes bytes through the SSI in
// standard SPI mode, one frame per byte, reading one byte back per byte sent (DS 4.10). So:
// while OUTOVER forces SS (low or high), each DR0 write clocks one byte (through the flash model
// below if SS is low; 0xff back if high) and queues the answer for DR0 reads; SR/RXFLR report
// the answers waiting. Otherwise (OUTOVER 0: boot2, and embassy's re-entry into XIP through its
// boot2 copy, where the SSI drives SS itself) the SSI keeps rp2040js's behaviour.
//
// The flash (W25Q16JV datasheet, section 8): WREN 06h / WRDI 04h, RDSR1 05h / RDSR2 35h (QE
// set), WRSR 01h / 31h (accepted, nothing changes), JEDEC ID 9Fh (EF 40 15), unique ID 4Bh,
// READ 03h, FAST READ 0Bh, sector erase 20h (4 KiB), block erase 52h (32 KiB) / D8h (64 KiB),
// page program 02h (bits only go 1 -> 0: AND; the address wraps within the 256-byte page).
// Erase and program need WEL and take effect when SS rises, which clears WEL. They complete at
// once: BUSY never reads 1 (no erase or program time).

import { BasePeripheral } from 'rp2040js';
import { disabled } from './patches.mjs';

const SSI_SR = 0x28;
const SSI_RXFLR = 0x24;
const SSI_TXFLR = 0x20;
const SSI_DR0 = 0x60;
const SR_TFNF = 1 << 1;
const SR_TFE = 1 << 2;
const SR_RFNE = 1 << 3;
const SECTOR = 4096;

/** The flash device: `memory` is the chip's flash array (rp2040js's `rp2040.flash`). */
export class NorFlash {
  constructor(memory, counters = { erases: 0, programs: 0 }, size = 2 * 1024 * 1024) {
    this.memory = memory;
    this.size = size;
    this.wel = false;
    this.selected = false;
    // erases: one per 4 KiB sector erased; programs: one per page program command. The bench
    // passes one object to every chip it builds, so they count since the bench started.
    this.counters = counters;
    this.command = null;
  }
  select() {
    this.selected = true;
    this.command = null;
    this.header = [];
    this.data = [];
  }
  /** One byte in on SI, the byte the flash drives on SO meanwhile. */
  transfer(byte) {
    if (this.command === null) {
      this.command = byte;
      return 0xff;
    }
    const cmd = this.command;
    const headerLength = { 0x03: 3, 0x0b: 4, 0x02: 3, 0x20: 3, 0x52: 3, 0xd8: 3, 0x4b: 4 }[cmd] ?? 0;
    if (this.header.length < headerLength) {
      this.header.push(byte);
      return 0xff;
    }
    const n = this.data.length;
    this.data.push(byte);
    switch (cmd) {
      case 0x05: return this.wel ? 0x02 : 0x00; // BUSY never set
      case 0x35: return 0x02; // QE
      case 0x9f: return [0xef, 0x40, 0x15][n] ?? 0xff;
      case 0x4b: return (0xe6 + n) & 0xff; // a fixed 64-bit unique ID
      case 0x03:
      case 0x0b: return this.memory[(this.address() + n) % this.size];
      default: return 0xff;
    }
  }
  address() {
    return (this.header[0] << 16) | (this.header[1] << 8) | this.header[2];
  }
  /** SS rises: write enable, erase and program take effect now. */
  deselect() {
    if (!this.selected) return;
    this.selected = false;
    const cmd = this.command;
    const complete = this.header.length === 3;
    if (cmd === 0x06) this.wel = true;
    else if (cmd === 0x04) this.wel = false;
    else if ((cmd === 0x01 || cmd === 0x31) && this.wel) this.wel = false;
    else if ((cmd === 0x20 || cmd === 0x52 || cmd === 0xd8) && this.wel && complete) {
      const length = { 0x20: SECTOR, 0x52: 32768, 0xd8: 65536 }[cmd];
      const start = (this.address() % this.size) & ~(length - 1);
      this.memory.fill(0xff, start, start + length);
      this.counters.erases += length / SECTOR;
      this.wel = false;
    } else if (cmd === 0x02 && this.wel && complete) {
      const address = this.address() % this.size;
      const page = address & ~0xff;
      this.data.forEach((byte, i) => {
        const at = page + ((address + i) & 0xff);
        this.memory[at] &= byte;
      });
      this.counters.programs++;
      this.wel = false;
    }
    this.command = null;
  }
}

/**
 * IO_QSPI (0x40018000), unimplemented in rp2040js: plain storage of its registers, and the SS
 * pin's OUTOVER (GPIO_QSPI_SS_CTRL, 0x0c, bits 9:8; 2 = drive low) selects the flash.
 */
export class IoQspi extends BasePeripheral {
  constructor(rp2040, flash) {
    super(rp2040, 'IO_QSPI');
    this.flash = flash;
    this.registers = new Map();
  }
  /** GPIO_QSPI_SS_CTRL.OUTOVER: 0 the SSI drives SS, 2 forced low, 3 forced high. */
  get ssOverride() {
    return ((this.registers.get(0x0c) ?? 0) >> 8) & 3;
  }
  get csForcedLow() {
    return this.ssOverride === 2;
  }
  readUint32(offset) {
    return this.registers.get(offset) ?? 0;
  }
  writeUint32(offset, value) {
    const before = this.csForcedLow;
    this.registers.set(offset, value >>> 0);
    const after = this.csForcedLow;
    if (!before && after) this.flash.select();
    else if (before && !after) this.flash.deselect();
  }
}

/** Puts the flash behind rp2040's SSI and IO_QSPI; returns the NorFlash (counters inside). */
export function attachFlash(rp2040, counters) {
  const flash = new NorFlash(rp2040.flash, counters);
  if (disabled('flash')) return flash;
  const ioQspi = new IoQspi(rp2040, flash);
  rp2040.peripherals[0x40018] = ioQspi;
  const ssi = rp2040.peripherals[0x18000];
  const rx = [];
  const read = ssi.readUint32.bind(ssi);
  const write = ssi.writeUint32.bind(ssi);
  // SS forced either way: the ROM drives the SSI by hand, one answer byte per byte sent.
  const byHand = () => ioQspi.ssOverride >= 2 || rx.length > 0;
  ssi.readUint32 = (offset) => {
    if (!byHand()) return read(offset);
    switch (offset) {
      case SSI_SR: return SR_TFNF | SR_TFE | (rx.length ? SR_RFNE : 0);
      case SSI_RXFLR: return rx.length;
      case SSI_TXFLR: return 0;
      case SSI_DR0: return rx.length ? rx.shift() : 0;
      default: return read(offset);
    }
  };
  ssi.writeUint32 = (offset, value) => {
    if (offset !== SSI_DR0 || !byHand()) write(offset, value);
    else if (ioQspi.csForcedLow) rx.push(flash.transfer(value & 0xff));
    else rx.push(0xff); // SS high: the flash is not selected, nothing drives SO
  };
  return flash;
}
