// `--rtt FILE`: the bench acts as the debug probe's RTT host for up channel 0 (the image's
// defmt frames, `defmt-print -e <image.elf> < FILE` decodes them). SEGGER RTT's control block
// `_SEGGER_RTT`: 16 bytes of ID, the number of up and down buffers (two i32), then per up
// buffer { name, buffer, size, write offset, read offset, flags } (six u32). The host copies
// the bytes between the read and write offsets and moves the read offset.

import { parseElf } from './elf.mjs';

export class RttReader {
  constructor(elfBytes, sink) {
    this.address = parseElf(elfBytes).symbols.get('_SEGGER_RTT');
    if (this.address === undefined) throw new Error('--rtt: the image has no _SEGGER_RTT');
    this.sink = sink;
  }

  /** Moves what the image wrote since the last poll to the sink. */
  poll(rp2040) {
    const up0 = this.address + 24;
    const buffer = rp2040.readUint32(up0 + 4);
    const size = rp2040.readUint32(up0 + 8);
    const write = rp2040.readUint32(up0 + 12);
    let read = rp2040.readUint32(up0 + 16);
    if (size === 0 || write >= size || read >= size) return; // not set up yet
    const bytes = [];
    while (read !== write) {
      bytes.push(rp2040.readUint8(buffer + read));
      read = (read + 1) % size;
    }
    if (bytes.length) {
      rp2040.writeUint32(up0 + 16, read);
      this.sink(Uint8Array.from(bytes));
    }
  }
}
