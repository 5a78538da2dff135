#!/usr/bin/env python3
"""NUCLEO-G071RB firmware-in-the-loop bench: runs the unchanged STM32G071RB firmware image in
Unicorn with register models (chip.py) and speaks the line protocol of fil/PROTOCOL.md on
stdin/stdout.

    python3 fil/g071/bench.py <image.elf> [--rtt FILE]

Diagnostics go to stderr. See fil/g071/README.md.
"""

import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import clock  # noqa: E402
import elf  # noqa: E402
import linebench  # noqa: E402
import scheduler  # noqa: E402
import profile as profiling  # noqa: E402
from chip import Chip  # noqa: E402
from cpu import EmulationError  # noqa: E402

PORT = {c: i for i, c in enumerate("ABCDEF")}
BOARD, SLOT_COUNT = "g071", 3


class Build:
    """What one build of the image wires where (its pin map in src/board/g071/mod.rs): the
    protocol's sensors (mmu_hal_port::Samples order) to ADC channels or, for a lane's motion in
    the `g071-n20` build, to the timer counting its encoder; each slot's TB6612FNG inputs as
    (STBY pin, IN1 pin, IN2 pin, (PWM timer, its channel, the pin and its AF number)).
    `sensors`: per protocol value, ("adc", channel) or ("encoder", timer name)."""

    def __init__(self, profile, time_driver, sensors, slots):
        self.profile, self.time_driver, self.sensors, self.slots = profile, time_driver, sensors, slots

    def sensor_max(self, index):
        """The largest value the protocol's `index`-th sensor value may take: 12 bits for a level,
        16 for an encoder count."""
        return 0xFFFF if self.sensors[index][0] == "encoder" else 4095


# The thesis build (`g071`): embassy-time on TIM2; slot0 hall PA0 IN0, slot0 filament PA1 IN1,
# slot1 hall PA4 IN4, slot1 filament PB1 IN9, slot2 hall PB11 IN15, slot2 filament PB12 IN16, hub
# filament PA6 IN6, hub tension PA7 IN7, hub cutter PB0 IN8; PWM PC6/PC7/PC8 AF1 = TIM3_CH1/2/3
# (STM32G071 datasheet, alternate function tables).
THESIS = Build(
    "thesis", "TIM2",
    tuple(("adc", c) for c in (0, 1, 4, 9, 15, 16, 6, 7, 8)),
    ((("C", 2), ("B", 3), ("B", 5), ("tim3", 0, ("C", 6), 1)),
     (("C", 2), ("B", 4), ("B", 14), ("tim3", 1, ("C", 7), 1)),
     (("C", 3), ("C", 0), ("C", 1), ("tim3", 2, ("C", 8), 1))),
)
# The `g071-n20` build: embassy-time on TIM15; each lane's motion is its encoder count, on TIM2
# (slot 0), TIM3 (slot 1), TIM1 (slot 2); the filament and hub sensors as above; PWM PA4 AF4
# TIM14_CH1, PB8 AF2 TIM16_CH1, PB9 AF2 TIM17_CH1.
N20 = Build(
    "n20-quadrature", "TIM15",
    (("encoder", "tim2"), ("adc", 1), ("encoder", "tim3"), ("adc", 9), ("encoder", "tim1"),
     ("adc", 16), ("adc", 6), ("adc", 7), ("adc", 8)),
    ((("C", 2), ("B", 3), ("B", 5), ("tim14", 0, ("A", 4), 4)),
     (("C", 2), ("B", 4), ("B", 14), ("tim16", 0, ("B", 8), 2)),
     (("C", 3), ("C", 0), ("C", 1), ("tim17", 0, ("B", 9), 2))),
)


def build_of(symbols):
    """The build the image is: the one whose embassy-time timer has an interrupt handler of its
    own (cortex-m-rt points every other vector at DefaultHandler)."""
    default = symbols.get("DefaultHandler")
    for build in (N20, THESIS):
        handler = symbols.get(build.time_driver)
        if handler is not None and handler != default:
            return build
    return THESIS


# The firmware's count of control steps (src/tasks.rs): the load counts the milliseconds in which
# it moved after the first step, the control task's, not the boot's (the store's restore, its
# repair after a power cut, the log of what it restored).
CONTROL_STEPS = "MMU_CONTROL_STEPS"
# With FIL_G071_PROFILE=K in the environment, the bench profiles every millisecond it measures
# by function and logs the K busiest ones' profiles at the end (slower: a Unicorn block hook).
PROFILE_ENV = "FIL_G071_PROFILE"
# With FIL_WORN_STORE=1 the store's pages (STORE_RANGE in src/board/g071/mod.rs) start written,
# as on a unit that has saved for a while: every page the store opens must be erased first.
WORN_STORE_ENV = "FIL_WORN_STORE"
STORE = (0x0801_8000, 0x8000)
# Functions listed for each profiled millisecond.
PROFILE_TOP = 25

class Bench(linebench.LineBench):
    def __init__(self, image, rtt=None):
        segments, self.symbols = elf.load(image)
        if os.environ.get(WORN_STORE_ENV, "0") not in ("", "0"):
            address, size = STORE
            segments = list(segments) + [(address, b"\x00" * size)]
        self.chip = Chip(segments, scheduler.stack_region(self.symbols))
        self.build = build_of(self.symbols)
        self.rtt = open(rtt, "ab") if rtt else None
        self.rtt_block = self.symbols.get("_SEGGER_RTT")
        self.clock = clock.CLOCK
        self.line = linebench.Line(clock.char_time)
        self.timer = linebench.Timer()
        # The instructions of each millisecond with a control step (see load_summary).
        self.load = linebench.Load()
        self.control_steps = self.symbols.get(CONTROL_STEPS)
        # (instructions, ms, functions) of the busiest milliseconds measured, with PROFILE_ENV.
        self.profile_keep = int(os.environ.get(PROFILE_ENV, "0") or 0)
        self.profile = profiling.FunctionCounts(image, self.chip) if self.profile_keep else None
        self.busiest = profiling.Busiest(self.profile_keep, PROFILE_TOP)

    # ---- outputs -----------------------------------------------------------------------------
    def level(self, pin):
        port, n = pin
        return self.chip.gpio[PORT[port]].output_level(n)

    def pwm(self, timer, channel, pin, af):
        port, n = pin
        g = self.chip.gpio[PORT[port]]
        mode = g.mode(n)
        if mode == 1:
            return 1000 * ((g.odr() >> n) & 1)
        if mode == 2:
            afr = g.regs.get(0x20 if n < 8 else 0x24, 0) >> (4 * (n % 8)) & 0xF
            if afr == af:
                return getattr(self.chip, timer).duty_permille(channel)
        return 0

    def motors(self):
        out = []
        for stby, in1, in2, pwm in self.build.slots:
            if not self.chip.powered:
                out.append("000:0")
                continue
            out.append(f"{self.level(stby)}{self.level(in1)}{self.level(in2)}:"
                       f"{self.pwm(*pwm)}")
        return out

    def pump_rtt(self):
        """Copies RTT up channel 0's new bytes to the --rtt file (SEGGER RTT control block:
        id[16], max_up, max_down, then per up buffer: name, buffer, size, write, read, flags)."""
        if not self.rtt or self.rtt_block is None or not self.chip.powered:
            return
        mem = self.chip.memory
        try:
            desc = mem.read(self.rtt_block + 24, 24)
        except MemoryError:
            return
        buf, size, wr, rd = (int.from_bytes(desc[4 * i:4 * i + 4], "little") for i in (1, 2, 3, 4))
        if not size or wr == rd or wr >= size or rd >= size:
            return
        try:
            if wr > rd:
                data = mem.read(buf + rd, wr - rd)
            else:
                data = mem.read(buf + rd, size - rd) + mem.read(buf, wr)
        except MemoryError:
            return
        self.rtt.write(data)
        self.rtt.flush()
        mem.write(self.rtt_block + 24 + 16, wr.to_bytes(4, "little"))

    # ---- requests ----------------------------------------------------------------------------
    def step(self, us, levels, rx):
        chip = self.chip
        start = chip.time
        end = start + clock.us(us)
        for value, (kind, where) in zip(levels, self.build.sensors):
            if kind == "adc":
                chip.sensor[where] = value
            else:
                chip.set_encoder(where, value)
        self.deliver(start, rx)
        sent = self.run_measured(us, end, len(rx))
        self.pump_rtt()
        return self.answer(self.motors(), sent)

    def load_summary(self):
        """The CPU's load in each 1 ms step in which the control task stepped, after its first
        step (CONTROL_STEPS moved; the boot and the store's restore are not the control loop),
        with 2.2 cycles an instruction (the flash's wait states, pessimistically) for the
        percentage. One line, for the log."""
        return self.load.summary(self.control_steps, clock.us(1000), 2.2, "64 MHz")

    def report(self):
        """The lines logged at `quit`."""
        lines = [self.load_summary(), self.stack_line()]
        if self.profile:
            lines.append(self.busiest.report())
        return lines

    def step_request(self, words):
        if len(words) != 12:
            raise ValueError(f"step takes 11 arguments, got {len(words) - 1}")
        us = int(words[1])
        levels = [int(w) for w in words[2:11]]
        if us < 0 or any(not 0 <= v <= self.build.sensor_max(i) for i, v in enumerate(levels)):
            raise ValueError("step: a value out of range")
        rx = b"" if words[11] == "-" else bytes.fromhex(words[11])
        return self.step(us, levels, rx)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("image")
    parser.add_argument("--rtt", metavar="FILE")
    args = parser.parse_args()

    def make():
        bench = Bench(args.image, args.rtt)
        return bench, f"ready {BOARD} {SLOT_COUNT} {bench.build.profile}"
    return linebench.serve(make, EmulationError)


if __name__ == "__main__":
    sys.exit(main())
