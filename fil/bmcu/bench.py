#!/usr/bin/env python3
"""BMCU-C firmware-in-the-loop bench: runs the unchanged CH32V203 firmware image (riscv32imc,
qingke-rt) in Unicorn's RV32 with register models (chip.py) and speaks the line protocol of
fil/PROTOCOL.md (its third version) on stdin/stdout.

    python3 fil/bmcu/bench.py <image.elf>

Diagnostics go to stderr. See fil/bmcu/README.md.
"""

import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE, os.path.join(os.path.dirname(HERE), "g071")]

import clock  # noqa: E402
import elf  # noqa: E402
import linebench  # noqa: E402
from chip import Chip, EmulationError  # noqa: E402
import profile as profiling  # noqa: E402  (fil/g071/profile.py: last, it puts fil/g071 first)

BOARD, SLOT_COUNT, PROFILE, VERSION = "bmcu", 4, "bmcu-c", "v3"
PORTS = "ABCD"
# Each lane's presence and tension ADC channels (PA7-PA0: src/board/bmcu/mod.rs's pin map).
PRESENCE = tuple(7 - 2 * lane for lane in range(SLOT_COUNT))
TENSION = tuple(6 - 2 * lane for lane in range(SLOT_COUNT))
# Each lane's AT8236 IN1 and IN2: (timer, channel 0-3, pin, the AFIO_PCFR1 remap field that must
# route the channel there: (shift, mask, values)). TIM4 not remapped (PB6-PB9); TIM3 partial
# remap 10 (CH1 PB4, CH2 PB5); TIM2 remap 01 or 11 (CH1 PA15, CH2 PB3): the STM32F103's remap
# tables (RM0008 §9.3.7), which the CH32V20x copies, and ch32-metapac's AFIO fields.
TIM4_RM, TIM3_RM, TIM2_RM = (12, 1, (0,)), (10, 3, (2,)), (8, 3, (1, 3))
BRIDGES = (
    (("tim4", 2, ("B", 8), TIM4_RM), ("tim4", 3, ("B", 9), TIM4_RM)),
    (("tim4", 0, ("B", 6), TIM4_RM), ("tim4", 1, ("B", 7), TIM4_RM)),
    (("tim3", 0, ("B", 4), TIM3_RM), ("tim3", 1, ("B", 5), TIM3_RM)),
    (("tim2", 0, ("A", 15), TIM2_RM), ("tim2", 1, ("B", 3), TIM2_RM)),
)
CONTROL_STEPS = "MMU_CONTROL_STEPS"
# With FIL_WORN_STORE=1 the store's 4 KB (STORE_RANGE in src/board/bmcu/mod.rs) start written,
# as on a unit that has saved for a while: every page the store opens must be erased first.
WORN_STORE_ENV = "FIL_WORN_STORE"
STORE = (0x0800_F000, 0x1000)
ANGLE_MAX = 0xFFFF  # a 12-bit angle, or ANGLE_FAULT (0x8000) with it
# With FIL_BMCU_PROFILE=K in the environment the bench profiles every millisecond it measures by
# function and logs the K busiest ones' profiles at the end (fil/g071/profile.py; RV32IC's
# instructions counted as 3 bytes each, their mean in this image).
PROFILE_ENV = "FIL_BMCU_PROFILE"
PROFILE_TOP = 25


class Bench(linebench.LineBench):
    def __init__(self, image):
        segments, self.symbols = elf.load(image)
        if os.environ.get(WORN_STORE_ENV, "0") not in ("", "0"):
            address, size = STORE
            segments = list(segments) + [(address, b"\x00" * size)]
        self.chip = Chip(segments, self.symbols)
        if self.chip.idle is None:
            print("bench: no spinning executor's poll loop found: idle time runs as instructions",
                  file=sys.stderr)
        self.clock = clock.CLOCK
        self.line = linebench.Line(clock.char_time)
        self.timer = linebench.Timer()
        self.load = linebench.Load()
        self.control_steps = self.symbols.get(CONTROL_STEPS)
        keep = int(os.environ.get(PROFILE_ENV, "0") or 0)
        self.profile = profiling.FunctionCounts(image, self.chip, 3) if keep else None
        self.busiest = profiling.Busiest(keep, PROFILE_TOP)

    # ---- outputs -----------------------------------------------------------------------------
    def input_duty(self, timer, channel, pin, remap):
        """A bridge input's duty, per mille: its timer's in AF mode with the remap that routes
        the channel to the pin, its level in GPIO output mode, else 0 (the AT8236's inputs have
        pull-downs)."""
        port, n = pin
        g = self.chip.gpio[port]
        mode, cnf = g.config(n)
        if not mode:
            return 0
        if cnf & 2 == 0:
            return 1000 * g.output_level(n)
        shift, mask, values = remap
        if self.chip.afio.pcfr1() >> shift & mask not in values:
            return 0
        return getattr(self.chip, timer).duty_permille(channel)

    def motors(self):
        """Each lane's AT8236 as `<STBY><IN1><IN2>:<duty>` (PROTOCOL.md, version 3): STBY 1 (the
        AT8236 has none), IN1/IN2 1 where that input is driven (a duty above 0), the driven
        input's duty; both driven: the smaller duty (both at full: brake)."""
        out = []
        for in1, in2 in BRIDGES:
            if not self.chip.powered:
                out.append("000:0")
                continue
            d1, d2 = self.input_duty(*in1), self.input_duty(*in2)
            if d1 and d2:
                out.append(f"111:{min(d1, d2)}")
            elif d1 or d2:
                out.append(f"1{int(bool(d1))}{int(bool(d2))}:{d1 or d2}")
            else:
                out.append("100:0")
        return out

    # ---- requests ----------------------------------------------------------------------------
    def step(self, us, values, rx):
        chip = self.chip
        start = chip.time
        end = start + clock.us(us)
        for lane in range(SLOT_COUNT):
            motion, filament, tension = values[3 * lane:3 * lane + 3]
            chip.set_angle(lane, motion)
            chip.sensor[PRESENCE[lane]] = filament
            chip.sensor[TENSION[lane]] = tension
        self.deliver(start, rx)
        sent = self.run_measured(us, end, len(rx), busy=lambda: self.uart.busy())
        return self.answer(self.motors(), sent)

    def report(self):
        """The lines logged at `quit`."""
        hz = getattr(self.chip, "clock_hz", None)
        clock_line = (f"clock: the image runs its core at {hz / 1e6:g} MHz (the bench counts 120 MHz)"
                      if hz else "clock: the image never switched to the PLL")
        lines = [self.load.summary(self.control_steps, clock.us(1000), clock.CONTRACT_CPI, "120 MHz",
                                   quiet=True),
                 self.stack_line(), clock_line]
        if self.profile:
            lines.append(self.busiest.report())
        return lines

    def step_request(self, words):
        count = 3 * SLOT_COUNT + 3
        if len(words) != count + 3:
            raise ValueError(f"step takes {count + 2} arguments, got {len(words) - 1}")
        us = int(words[1])
        values = [int(w) for w in words[2:2 + count]]
        lanes = values[:3 * SLOT_COUNT]
        if us < 0 or any(not 0 <= v <= (ANGLE_MAX if i % 3 == 0 else 4095) for i, v in enumerate(lanes)):
            raise ValueError("step: a value out of range")
        rx = b"" if words[-1] == "-" else bytes.fromhex(words[-1])
        return self.step(us, lanes, rx)

    def extra_request(self, words):
        if words == ["stack"]:
            return f"ok {self.chip.measure_stack()}"
        return None


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("image")
    args = parser.parse_args()

    def make():
        return Bench(args.image), f"ready {BOARD} {SLOT_COUNT} {PROFILE} {VERSION}"
    return linebench.serve(make, EmulationError)


if __name__ == "__main__":
    sys.exit(main())
