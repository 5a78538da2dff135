"""The four lanes' AS5600 angle sensors, each an I2C slave at 0x36 on its own bit-banged bus
(SCL PB15/PB14/PB13/PB12, SDA PD0/PC15/PC14/PC13 for lanes 0-3, src/board/bmcu/as5600.rs),
answering what the simulator sends as the lane's motion sample.

The bus (I2C specification, UM10204 §3.1): both lines open drain, high unless a side pulls them
low. A START is SDA falling while SCL is high, a STOP SDA rising while SCL is high; a bit is
sampled while SCL is high and changed while it is low; each byte is followed by an acknowledge
bit the receiver pulls low. The slave changes its output on SCL's falling edge.
The AS5600 (ams AS5600 datasheet, "I2C interface" and "Register map"): address 0x36; a write
sets the address pointer (then data bytes would write registers: acknowledged and ignored here);
a read returns the register at the pointer and increments it after each byte (automatic
increment). STATUS 0x0B: MD (bit 5) magnet detected, ML (4) too weak, MH (3) too strong; RAW
ANGLE 0x0C (bits 11:8) and 0x0D (7:0). A sample with ANGLE_FAULT (0x8000, mmu_hal_port) set is
a lane without its magnet: MD clear, the angle 0. Other registers read 0. The sensor's own
timing (its 150 us start-up, a bus at any speed is accepted) is not modelled.
"""

ADDRESS = 0x36
STATUS, RAW_ANGLE = 0x0B, 0x0C
MD = 1 << 5
ANGLE_FAULT = 0x8000
IDLE, ADDR, POINTER, WRITE, READ, IGNORE = range(6)


class As5600:
    """One sensor on its bus. `sample` is the simulator's motion value for the lane."""

    def __init__(self):
        self.sample = ANGLE_FAULT
        self.scl = self.sda = 1       # the lines as they were at the last update
        self.out = 1                  # the slave's SDA: 1 released, 0 pulled low
        self.state = IDLE
        self.bits = 0
        self.byte = 0
        self.pointer = 0
        self.acking = False           # the 9th clock of a byte the slave receives
        self.master_ack = False       # the 9th clock of a byte the slave sends
        self.reads = 0                # complete bytes sent, for tests

    def register(self, address):
        angle = 0 if self.sample & ANGLE_FAULT else self.sample & 0xFFF
        if address == STATUS:
            return 0 if self.sample & ANGLE_FAULT else MD
        if address == RAW_ANGLE:
            return angle >> 8
        if address == RAW_ANGLE + 1:
            return angle & 0xFF
        return 0

    def update(self, scl, sda):
        """The lines' levels now (each the AND of both sides)."""
        if scl and self.scl and sda != self.sda:
            if not sda:       # START (or a repeated one)
                self.state, self.bits, self.byte, self.out = ADDR, 0, 0, 1
                self.acking = self.master_ack = False
            else:             # STOP
                self.state, self.out = IDLE, 1
        elif scl and not self.scl:
            self._rising(sda)
        elif not scl and self.scl:
            self._falling()
        self.scl, self.sda = scl, sda

    def _rising(self, sda):
        if self.state in (IDLE, IGNORE) or self.acking:
            return
        if self.state == READ:
            if self.master_ack:
                if sda:       # not acknowledged: the master ends the read
                    self.state = IGNORE
                return
            return
        self.byte = (self.byte << 1 | sda) & 0xFF
        self.bits += 1

    def _falling(self):
        if self.state in (IDLE, IGNORE):
            self.out = 1
            return
        if self.state == READ:
            self._falling_read()
            return
        if self.acking:       # the acknowledge bit is over
            self.acking = False
            self.out = 1
            if self.state == READ:
                return
            if self.state == ADDR and self.byte & 1:
                self.state = READ
                self._load()
            elif self.state == ADDR:
                self.state = POINTER
            elif self.state == POINTER:
                self.pointer = self.byte
                self.state = WRITE
            self.bits, self.byte = 0, 0
            if self.state == READ:
                self._send_bit()
            return
        if self.bits == 8:
            if self.state == ADDR and self.byte >> 1 != ADDRESS:
                self.state, self.out = IGNORE, 1
                return
            self.acking = True
            self.out = 0

    def _load(self):
        self.shift = self.register(self.pointer)
        self.bits = 0

    def _send_bit(self):
        self.out = self.shift >> (7 - self.bits) & 1
        self.bits += 1

    def _falling_read(self):
        if self.master_ack:   # the master's acknowledge is over: the next byte
            self.master_ack = False
            self.pointer = (self.pointer + 1) & 0xFF
            self._load()
            self._send_bit()
            return
        if self.bits < 8:
            self._send_bit()
        else:                 # the 8th bit has been sampled: let the master acknowledge
            self.out = 1
            self.master_ack = True
            self.reads += 1


class AngleBuses:
    """The four buses on the GPIO ports: SCL on GPIOB, SDA on GPIOD/GPIOC. Only a change of a
    line's level reaches a sensor (a GPIO write that moves no line costs one comparison)."""

    SCL = (("B", 15), ("B", 14), ("B", 13), ("B", 12))
    SDA = (("D", 0), ("C", 15), ("C", 14), ("C", 13))

    def __init__(self, gpio):
        self.gpio = gpio      # port letter -> Gpio
        self.sensors = [As5600() for _ in self.SCL]
        self.levels = None
        for port in "BCD":
            gpio[port].watchers.append(self.update)

    def update(self):
        gpio = self.gpio
        b, c, d = gpio["B"].pulled_low, gpio["C"].pulled_low, gpio["D"].pulled_low
        key = (b & 0xF000, c & 0xE000, d & 1)
        if key == self.levels:
            return
        self.levels = key
        for lane, sensor in enumerate(self.sensors):
            scl = 0 if b >> self.SCL[lane][1] & 1 else 1
            port, n = self.SDA[lane]
            sda = 0 if (d if port == "D" else c) >> n & 1 else 1
            if scl == sensor.scl and sda & sensor.out == sensor.sda:
                continue
            for _ in range(2):  # once more if the slave's output changed with this edge
                out = sensor.out
                sensor.update(scl, sda & sensor.out)
                if sensor.out == out:
                    break
            self.gpio[port].external(n, sensor.out)
