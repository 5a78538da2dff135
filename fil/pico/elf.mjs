// A minimal ELF32 little-endian reader: the bench needs the image's loadable segments (to
// program them into the emulated QSPI flash at their load addresses) and one symbol's address
// (`_SEGGER_RTT`, for `--rtt`). Nothing else of the ELF format is used.

const PT_LOAD = 1;
const SHT_SYMTAB = 2;

/** Parses `bytes` (a Buffer or Uint8Array of an ELF file). Throws on anything but ELF32 LE. */
export function parseElf(bytes) {
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  if (view.getUint32(0, false) !== 0x7f454c46) throw new Error('not an ELF file');
  if (bytes[4] !== 1 || bytes[5] !== 1) throw new Error('not a 32-bit little-endian ELF');
  const u16 = (o) => view.getUint16(o, true);
  const u32 = (o) => view.getUint32(o, true);

  const entry = u32(24);
  const phoff = u32(28);
  const shoff = u32(32);
  const phentsize = u16(42);
  const phnum = u16(44);
  const shentsize = u16(46);
  const shnum = u16(48);

  // Program headers: PT_LOAD with file bytes, placed at their physical (load) address, which
  // is where the flash holds them (.data's initial values sit in flash, copied to RAM at start).
  const segments = [];
  for (let i = 0; i < phnum; i++) {
    const o = phoff + i * phentsize;
    if (u32(o) !== PT_LOAD) continue;
    const offset = u32(o + 4);
    const paddr = u32(o + 12);
    const filesz = u32(o + 16);
    if (filesz === 0) continue;
    segments.push({ address: paddr, data: bytes.subarray(offset, offset + filesz) });
  }

  // Symbols, from the first SHT_SYMTAB and its string table.
  const symbols = new Map();
  for (let i = 0; i < shnum; i++) {
    const o = shoff + i * shentsize;
    if (u32(o + 4) !== SHT_SYMTAB) continue;
    const symOff = u32(o + 16);
    const symSize = u32(o + 20);
    const strSection = shoff + u32(o + 24) * shentsize;
    const strOff = u32(strSection + 16);
    for (let s = symOff; s + 16 <= symOff + symSize; s += 16) {
      const nameOff = strOff + u32(s);
      let end = nameOff;
      while (bytes[end] !== 0) end++;
      const name = Buffer.from(bytes.subarray(nameOff, end)).toString('latin1');
      if (name) symbols.set(name, u32(s + 4));
    }
    break;
  }
  return { entry, segments, symbols };
}
