// Test helper: the Prusa MMU protocol's request frames as a printer sends them (protocol/src:
// code byte, value in lowercase hex, for `W` a space and the written value, `*`, the CRC-8
// (polynomial 0x07, initial 0) over [code, value, value2 low, value2 high] in hex, `\n`).

export function crc8(bytes) {
  let crc = 0;
  for (const byte of bytes) {
    crc ^= byte;
    for (let bit = 0; bit < 8; bit++) crc = crc & 0x80 ? ((crc << 1) ^ 0x07) & 0xff : (crc << 1) & 0xff;
  }
  return crc;
}

/** The request `code` (a letter) with `value` (and `value2`, written by `W`). */
export function request(code, value, value2 = 0) {
  const c = code.charCodeAt(0);
  const crc = crc8([c, value, value2 & 0xff, value2 >> 8]);
  const text = code === 'W' ? `${code}${value.toString(16)} ${value2.toString(16)}` : `${code}${value.toString(16)}`;
  return [...Buffer.from(`${text}*${crc.toString(16)}\n`)];
}
