"""The CRC calculation unit (0x40023000). The firmware checks it at boot on CRC-32/ISO-HDLC's
check value and uses it for the persisted state's entries (falling back to software otherwise),
so it is modelled bit for bit.

RM0444 §16.4 (CRC registers): DR 0x00 (reset 0xFFFF_FFFF; 8-, 16- or 32-bit writes feed data,
a read returns the CRC), IDR 0x04, CR 0x08 (RESET 0: DR <- INIT; POLYSIZE [4:3]: 00 32, 01 16,
10 8, 11 7 bits; REV_IN [6:5]: 00 none, 01 bit-reversed by byte, 10 by half-word, 11 by word;
REV_OUT 7: DR reads bit-reversed), INIT 0x10 (reset 0xFFFF_FFFF), POL 0x14 (reset 0x04C1_1DB7).
§16.3.2: each write of n bits is, after the input reversal, shifted in most significant bit
first: crc = crc << 1 ^ (POL if the bit shifted out xor the data bit is 1), over the polynomial's
width. Writing INIT also loads DR.
"""

from regs import Block

DR, IDR, CR, INIT, POL = 0x00, 0x04, 0x08, 0x10, 0x14


def reverse(value, bits):
    out = 0
    for _ in range(bits):
        out = (out << 1) | (value & 1)
        value >>= 1
    return out


class Crc(Block):
    name = "CRC"
    resets = {CR: 0, INIT: 0xFFFF_FFFF, POL: 0x04C1_1DB7}

    def __init__(self, chip=None):
        super().__init__(chip)
        self.crc = 0xFFFF_FFFF

    def width(self):
        return (32, 16, 8, 7)[(self.regs[CR] >> 3) & 3]

    def feed(self, value, bits):
        rev_in = (self.regs[CR] >> 5) & 3
        if rev_in:
            unit = {1: 8, 2: 16, 3: 32}[rev_in]
            unit = min(unit, bits)
            out = 0
            for i in range(0, bits, unit):
                out |= reverse((value >> i) & ((1 << unit) - 1), unit) << i
            value = out
        w = self.width()
        top = 1 << (w - 1)
        mask = (1 << w) - 1
        poly = self.regs[POL] & mask
        crc = self.crc & mask
        for i in range(bits - 1, -1, -1):
            inbit = (value >> i) & 1
            outbit = 1 if crc & top else 0
            crc = (crc << 1) & mask
            if inbit ^ outbit:
                crc ^= poly
        self.crc = crc

    def read_reg(self, offset):
        if offset == DR:
            value = self.crc
            if self.regs[CR] >> 7 & 1:
                value = reverse(value, self.width())
            return value
        return super().read_reg(offset)

    def write(self, offset, size, value):
        if offset & ~3 == DR:
            self.feed(value & ((1 << (8 * size)) - 1), 8 * size)
            return
        super().write(offset, size, value)
        if offset & ~3 == CR and self.regs[CR] & 1:
            self.regs[CR] &= ~1
            self.crc = self.regs[INIT] & ((1 << self.width()) - 1)
        elif offset & ~3 == INIT:
            self.crc = self.regs[INIT] & ((1 << self.width()) - 1)
