"""GPIO (CFGLR/CFGHR, INDR, OUTDR, BSHR, BCR, open drain, PD0/PD1 behind PD01_RM) and the four
AS5600s on their bit-banged buses: a read of STATUS then RAW ANGLE with auto-increment as the
image does it (src/board/bmcu/as5600.rs), NACK for another address, no magnet."""

import support  # noqa: F401
import unittest

from as5600 import AngleBuses
from gpio import Gpio
from rcc import Afio
from support import Fake, r32, w32

CFGLR, CFGHR, INDR, OUTDR, BSHR, BCR = 0x00, 0x04, 0x08, 0x0C, 0x10, 0x14
OPEN_DRAIN_OUT = 0b0101  # MODE 01 (10 MHz), CNF 01


class Bus:
    """The image's master on all four buses at once."""

    SCL = (15, 14, 13, 12)
    SDA = (("D", 0), ("C", 15), ("C", 14), ("C", 13))

    def __init__(self, remap=True):
        self.chip = Fake()
        self.chip.afio = Afio()
        if remap:
            w32(self.chip.afio, 0x04, 1 << 15)
        self.gpio = {p: Gpio(self.chip, i) for i, p in enumerate("ABCD")}
        self.buses = AngleBuses(self.gpio)
        self.sda(1)
        self.scl(1)
        w32(self.gpio["B"], CFGHR, 0x4444 | OPEN_DRAIN_OUT << 16 | OPEN_DRAIN_OUT << 20
            | OPEN_DRAIN_OUT << 24 | OPEN_DRAIN_OUT << 28)
        w32(self.gpio["C"], CFGHR, 0x44444 | OPEN_DRAIN_OUT << 20 | OPEN_DRAIN_OUT << 24
            | OPEN_DRAIN_OUT << 28)
        w32(self.gpio["D"], CFGLR, 0x4444_4440 | OPEN_DRAIN_OUT)

    def scl(self, level):
        w32(self.gpio["B"], BSHR if level else BCR, 0xF000)

    def sda(self, level):
        for port, pin in self.SDA:
            w32(self.gpio[port], BSHR if level else BCR, 1 << pin)

    def read_sda(self):
        c, d = r32(self.gpio["C"], INDR), r32(self.gpio["D"], INDR)
        return [(d if port == "D" else c) >> pin & 1 for port, pin in self.SDA]

    def start(self):
        self.sda(1)
        self.scl(1)
        self.sda(0)
        self.scl(0)

    def stop(self):
        self.sda(0)
        self.scl(1)
        self.sda(1)

    def pulse(self):
        self.scl(1)
        bits = self.read_sda()
        self.scl(0)
        return bits

    def write(self, byte):
        for bit in range(7, -1, -1):
            self.sda(byte >> bit & 1)
            self.pulse()
        self.sda(1)
        return [not b for b in self.pulse()]  # acknowledged

    def read(self, ack):
        self.sda(1)
        values = [0] * 4
        for _ in range(8):
            values = [v << 1 | b for v, b in zip(values, self.pulse())]
        self.sda(0 if ack else 1)
        self.pulse()
        return values

    def transaction(self):
        self.start()
        acks = self.write(0x36 << 1)
        self.write(0x0B)
        self.start()
        self.write(0x36 << 1 | 1)
        status, high, low = self.read(True), self.read(True), self.read(False)
        self.stop()
        return acks, status, [(h & 0xF) << 8 | lo for h, lo in zip(high, low)]


class GpioTest(unittest.TestCase):
    def test_push_pull_outputs_bshr_bcr_and_pulled_inputs(self):
        g = Gpio(Fake(), 1)
        w32(g, CFGLR, 0x4444_4483)             # PB0 push-pull output 50 MHz, PB1 input with pull
        w32(g, BSHR, 0b11)
        self.assertEqual(r32(g, INDR) & 3, 0b11)
        w32(g, BSHR, 1 << 16 | 1)              # set wins over reset
        self.assertEqual(r32(g, OUTDR) & 1, 1)
        w32(g, BCR, 0b11)
        self.assertEqual(r32(g, INDR) & 3, 0)
        self.assertEqual(g.output_level(0), 0)

    def test_pd0_pd1_are_gpio_only_with_their_remap(self):
        bus = Bus(remap=False)
        bus.sda(0)
        self.assertEqual(bus.gpio["D"].drive(0), None, "OSC_IN: the pin drives nothing")
        bus.sda(1)
        self.assertEqual(bus.read_sda(), [0, 1, 1, 1], "not connected: PD0 reads 0, released")
        w32(bus.chip.afio, 0x04, 1 << 15)
        self.assertEqual(bus.read_sda(), [1, 1, 1, 1])
        bus.sda(0)
        self.assertEqual(bus.gpio["D"].drive(0), 0)


class As5600Test(unittest.TestCase):
    def test_status_and_raw_angle_of_every_lane_in_one_transaction(self):
        bus = Bus()
        for lane, sample in enumerate((0, 1234, 4095, 0x8000 | 77)):
            bus.buses.sensors[lane].sample = sample
        acks, status, angles = bus.transaction()
        self.assertEqual(acks, [True] * 4)
        self.assertEqual(status, [0x20, 0x20, 0x20, 0x00])   # MD, but no magnet on lane 3
        self.assertEqual(angles, [0, 1234, 4095, 0])
        self.assertEqual(bus.transaction()[2], [0, 1234, 4095, 0], "again")

    def test_open_drain_low_wins(self):
        bus = Bus()
        bus.start()
        bus.write(0x36 << 1)
        # The slaves pull SDA low during their acknowledge even where the master lets go.
        bus.sda(1)
        for byte in range(8):
            bus.sda(1)
            bus.pulse()
        bus.scl(1)
        self.assertEqual(bus.read_sda(), [0, 0, 0, 0])

    def test_another_address_is_not_acknowledged(self):
        bus = Bus()
        bus.start()
        self.assertEqual(bus.write(0x37 << 1), [False] * 4)


if __name__ == "__main__":
    unittest.main()
