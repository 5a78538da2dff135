"""The independent watchdog (IWDG, 0x40003000): started by the firmware, fed by it, and resetting
the chip when it is not fed in time, also while the CPU is stalled or hung (`hang`).

RM0444 §26.4 (IWDG registers): KR 0x00 (0xCCCC starts the watchdog, 0xAAAA reloads the counter
with RLR, 0x5555 unlocks PR/RLR/WINR), PR 0x04 (prescaler /4 << PR, /256 for 6 and 7), RLR 0x08
(12 bits, reset 0xFFF), SR 0x0C (PVU, RVU, WVU: read 0, updates are immediate), WINR 0x10.
§26.3: the down-counter runs on the 32 kHz LSI; when it reaches 0 the chip resets and RCC_CSR's
IWDGRSTF is set. Once started it cannot be stopped (until a reset).
Left out: the window option, the LSI's inaccuracy (exactly 32 kHz here), write protection of
PR/RLR (writes are taken whether unlocked or not).
"""

from regs import Block

KR, PR, RLR, SR, WINR = 0x00, 0x04, 0x08, 0x0C, 0x10
LSI_HZ = 32_000
CYCLES_PER_LSI = 64_000_000 // LSI_HZ


class Iwdg(Block):
    name = "IWDG"
    resets = {RLR: 0xFFF, WINR: 0xFFF}

    def __init__(self, chip=None):
        super().__init__(chip)
        self.running = False
        self.expires_at = None
        self.feeds = 0

    def timeout_cycles(self):
        pr = min(self.regs.get(PR, 0) & 7, 6)
        divider = 4 << pr
        return (self.regs.get(RLR, 0xFFF) & 0xFFF) * divider * CYCLES_PER_LSI

    def write_reg(self, offset, value, mask):
        value &= mask
        if offset == KR:
            key = value & 0xFFFF
            now = self.chip.now() if self.chip else 0
            if key == 0xCCCC:
                if not self.running:
                    self.running = True
                    self.expires_at = now + self.timeout_cycles()
            elif key == 0xAAAA:
                if self.running:
                    self.feeds += 1
                    self.expires_at = now + self.timeout_cycles()
            if self.chip and key == 0xCCCC:
                self.chip.reschedule(self)
        elif offset == SR:
            pass
        else:
            super().write_reg(offset, value, mask)

    def read_reg(self, offset):
        if offset in (KR, SR):
            return 0
        return super().read_reg(offset)

    def next_event(self):
        return self.expires_at if self.running else None

    def advance(self, now):
        if self.running and now >= self.expires_at:
            self.running = False
            if self.chip:
                self.chip.request_reset("watchdog")
