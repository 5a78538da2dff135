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
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import clock  # noqa: E402
import elf  # noqa: E402
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

class Bench:
    def __init__(self, image, rtt=None):
        segments, self.symbols = elf.load(image)
        if os.environ.get(WORN_STORE_ENV, "0") not in ("", "0"):
            address, size = STORE
            segments = list(segments) + [(address, b"\x00" * size)]
        self.chip = Chip(segments)
        self.build = build_of(self.symbols)
        self.rtt = open(rtt, "ab") if rtt else None
        self.rtt_block = self.symbols.get("_SEGGER_RTT")
        self.line_origin = 0    # cycle the current run of back-to-back characters started
        self.line_count = 0     # characters in that run so far
        self.wall = 0.0
        self.cpu = 0.0
        # (instructions, bytes received, ms, wrote) of each millisecond with a control step (see
        # load_summary).
        self.load = []
        self.control_steps = self.symbols.get(CONTROL_STEPS)
        # (instructions, ms, functions) of the busiest milliseconds measured, with PROFILE_ENV.
        self.profile_keep = int(os.environ.get(PROFILE_ENV, "0") or 0)
        self.profile = profiling.FunctionCounts(image, self.chip) if self.profile_keep else None
        self.busiest = []

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
        if chip.powered:
            if self.line_origin + clock.char_time(self.line_count) <= start:
                self.line_origin, self.line_count = start, 0
            for byte in rx:
                self.line_count += 1
                chip.usart1.deliver(self.line_origin + clock.char_time(self.line_count), byte)
        t0, c0 = time.perf_counter(), time.process_time()
        resets, executed = chip.resets, chip.cpu.native.count()
        flash_ops = chip.erases() + chip.programs()
        functions = self.profile.snapshot() if self.profile else None
        steps = self.steps_taken()
        chip.run_until(end)
        # A millisecond of the control loop: it stepped, and had stepped before the millisecond
        # began (the first step's millisecond also holds the end of the boot). Forward only: a
        # reset keeps the RAM, so a boot's millisecond starts from the last run's count and
        # clears it.
        after = self.steps_taken()
        stepped = steps is not None and after is not None and 0 < steps < after
        if chip.resets == resets and chip.powered and us == 1000 and stepped:
            wrote = chip.erases() + chip.programs() != flash_ops
            n, ms = chip.cpu.native.count() - executed, round(end / clock.us(1000))
            self.load.append((n, len(rx), ms, wrote))
            if functions is not None:
                self.keep_profile(n, ms, wrote, self.profile.counts - functions)
        self.wall += time.perf_counter() - t0
        self.cpu += time.process_time() - c0
        sent = bytes(b for _, b in chip.usart1.take_sent()) if chip.powered else b""
        self.pump_rtt()
        tx = sent.hex() if sent else "-"
        return f"ok {' '.join(self.motors())} {tx} {chip.resets} {chip.erases()} {chip.programs()}"

    def steps_taken(self):
        """The firmware's count of control steps, or None (no such symbol, or no power)."""
        if self.control_steps is None or not self.chip.powered:
            return None
        return int.from_bytes(self.chip.memory.read(self.control_steps, 4), "little")

    def keep_profile(self, instructions, ms, wrote, functions):
        """Keeps this millisecond's profile if it is among the busiest `profile_keep`."""
        self.busiest.append((instructions, ms, wrote, functions))
        self.busiest.sort(key=lambda m: m[0], reverse=True)
        del self.busiest[self.profile_keep:]

    def profile_report(self):
        """The busiest milliseconds' profiles (PROFILE_ENV), for the log."""
        lines = []
        for instructions, ms, wrote, functions in self.busiest:
            with_write = ", with a flash write" if wrote else ""
            lines.append(f"profile: {instructions} instructions at {ms} ms{with_write}")
            lines += [f"profile: {n:7}  {name}" for name, n in functions.most_common(PROFILE_TOP)]
        return "\n".join(lines)

    def load_summary(self):
        """The CPU's load in each 1 ms step in which the control task stepped, after its first
        step (CONTROL_STEPS moved; the boot and the store's restore are not the control loop):
        instructions executed
        in the milliseconds without a flash write (median, 99th and 99.9th percentile, busiest) and the busiest with
        one, with 2.2 cycles an instruction (the flash's wait states, pessimistically) for the
        percentage. One line, for the log."""
        plain = sorted(m for m in self.load if not m[3])
        writing = [m for m in self.load if m[3]]
        if not plain:
            if self.control_steps is None:
                return f"load: no millisecond measured (the image has no {CONTROL_STEPS})"
            return "load: no millisecond measured"

        def pct(n):
            return f"{100 * n * 2.2 / clock.us(1000):.1f} %"

        def at(q):
            n = plain[min(len(plain) - 1, int(q * len(plain)))][0]
            return f"{n} ({pct(n)})"
        worst = plain[-1]
        line = (f"load: {len(plain)} ms without a flash write, instructions a millisecond: median "
                f"{at(0.5)}, 99 % {at(0.99)}, 99.9 % {at(0.999)}, busiest {worst[0]} ({pct(worst[0])} "
                f"of 1 ms at 64 MHz, 2.2 cycles an instruction) at {worst[2]} ms, {worst[1]} bytes received")
        if writing:
            busiest = max(writing)
            line += f"; {len(writing)} ms with one, busiest {busiest[0]} ({pct(busiest[0])}) at {busiest[2]} ms"
        return line

    def handle(self, line):
        words = line.split()
        if not words:
            raise ValueError("empty request")
        if words[0] == "step":
            if len(words) != 12:
                raise ValueError(f"step takes 11 arguments, got {len(words) - 1}")
            us = int(words[1])
            levels = [int(w) for w in words[2:11]]
            if us < 0 or any(not 0 <= v <= self.build.sensor_max(i) for i, v in enumerate(levels)):
                raise ValueError("step: a value out of range")
            rx = b"" if words[11] == "-" else bytes.fromhex(words[11])
            return self.step(us, levels, rx)
        if words == ["power", "off"]:
            self.chip.power_off()
            self.line_origin, self.line_count = self.chip.time, 0
            self.chip.usart1.incoming.clear()
            return "ok"
        if words == ["power", "on"]:
            if not self.chip.powered:
                self.chip.power_on()
            return "ok"
        if words == ["hang"]:
            self.chip.hung = True
            return "ok"
        raise ValueError(f"unknown request: {line.strip()}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("image")
    parser.add_argument("--rtt", metavar="FILE")
    args = parser.parse_args()
    out = sys.stdout
    try:
        bench = Bench(args.image, args.rtt)
    except (OSError, ValueError, EmulationError) as e:
        print(f"error {e}", flush=True)
        return 1
    print(f"ready {BOARD} {SLOT_COUNT} {bench.build.profile}", file=out, flush=True)
    for line in sys.stdin:
        if line.strip() == "quit":
            print(bench.load_summary(), file=sys.stderr, flush=True)
            if bench.profile:
                print(bench.profile_report(), file=sys.stderr, flush=True)
            break
        try:
            answer = bench.handle(line)
        except EmulationError as e:
            print(f"error {e}", file=out, flush=True)
            return 1
        except ValueError as e:
            print(f"error {e}", file=out, flush=True)
            return 1
        except Exception as e:  # a fault of the bench itself: say so rather than hang the simulator
            print(f"error internal: {type(e).__name__}: {e}", file=out, flush=True)
            raise
        print(answer, file=out, flush=True)
    virtual_ms = bench.chip.time / (clock.CYCLES_PER_US * 1000)
    if bench.wall:
        print(f"bench: {virtual_ms:.0f} virtual ms in {bench.wall:.1f} s wall, {bench.cpu:.1f} s CPU "
              f"of emulation: {virtual_ms / bench.wall:.0f} virtual ms per wall second, "
              f"{virtual_ms / max(bench.cpu, 1e-9):.0f} per CPU second", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
