"""The independent watchdog (IWDG, 0x4000_3000): fil/g071's model, whose registers the CH32V20x's
IWDG has at the same offsets (CTLR 0x00: 0xCCCC starts, 0xAAAA reloads, 0x5555 unlocks; PSCR
0x04: LSI / (4 << PR), /256 for 6 and 7; RLDR 0x08, 12 bits; STATR 0x0C: PVU, RVU read 0:
ch32-metapac 0.1.2 `iwdg_v00x`), clocked by the CH32V203's 40 kHz LSI (the image's
src/board/bmcu/mod.rs: "40 kHz (CH32V20x datasheet)") instead of the G0's 32 kHz. Expiry resets
the chip with RSTSCKR.IWDGRSTF, also while the CPU is stalled or hung.
Left out: the LSI's inaccuracy (exactly 40 kHz here), the write protection of PSCR/RLDR.
"""

from iwdg import PR, RLR, Iwdg

LSI_HZ = 40_000


class Watchdog(Iwdg):
    name = "IWDG"

    def timeout_cycles(self):
        divider = 4 << min(self.regs.get(PR, 0) & 7, 6)
        hz = self.chip.hz if self.chip is not None and hasattr(self.chip, "hz") else 120_000_000
        return (self.regs.get(RLR, 0xFFF) & 0xFFF) * divider * hz // LSI_HZ
