"""The shared base of the register models: a block of 32-bit registers that stores what is
written and reads it back, with sub-word accesses merged into the word (the STM32G0's APB/AHB
peripherals accept byte and half-word accesses on most registers; RM0444 §2.1). Registers a model
does not handle specially behave like this, which is what the firmware needs of the configuration
registers it only writes (speed, pull, alternate function...)."""


class Block:
    """A peripheral register block. Subclasses override `read_reg`/`write_reg` for the
    registers with behaviour and call `super()` for plain storage."""

    name = "block"
    resets = {}  # offset -> reset value

    def __init__(self, chip=None):
        self.chip = chip
        self.regs = dict(self.resets)

    # Whole-register accesses, offset aligned to 4.
    def read_reg(self, offset):
        return self.regs.get(offset, 0)

    def write_reg(self, offset, value, mask):
        old = self.regs.get(offset, 0)
        self.regs[offset] = (old & ~mask) | (value & mask)

    # Accesses as the bus delivers them.
    def read(self, offset, size):
        word = self.read_reg(offset & ~3)
        shift = (offset & 3) * 8
        return (word >> shift) & ((1 << (8 * size)) - 1)

    def write(self, offset, size, value):
        shift = (offset & 3) * 8
        mask = ((1 << (8 * size)) - 1) << shift
        self.write_reg(offset & ~3, (value << shift) & mask, mask)

    # Time: models with events override these.
    def next_event(self):
        """Absolute cycle of this model's next internal event, or None."""
        return None

    def advance(self, now):
        """Processes the model's events up to `now` (cycles)."""

    def irqs(self):
        """The NVIC interrupt lines this model asserts now."""
        return ()


def bit(value, n):
    return (value >> n) & 1
