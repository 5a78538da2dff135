"""What the Unicorn benches of fil/ share, whatever the chip (fil/g071, fil/bmcu): virtual
time's arithmetic, the pace of the printer's bytes into the chip's UART, the requests but
`step`'s values and the load accounting of the control loop's milliseconds (`LineBench`), the
speed line, and the request loop on stdin/stdout (fil/PROTOCOL.md).

A bench (a `LineBench`) gives `handle(line) -> answer` (raising ValueError for a request it
cannot parse, cpu.EmulationError for an emulation it cannot go on with), `report() -> lines`
(logged at `quit`), `virtual_ms()`, and `timer`: the seconds spent emulating.
"""

import sys
import time


class Clock:
    """Virtual time's arithmetic for a chip counting `hz` cycles a second, an instruction
    costing `cpi_num / cpi_den` cycles (each bench's clock.py says why its figures)."""

    def __init__(self, hz, cpi_num, cpi_den, baud=115_200, bits_per_char=10):
        self.hz, self.cpi_num, self.cpi_den = hz, cpi_num, cpi_den
        self.cycles_per_us = hz // 1_000_000
        self.baud, self.bits_per_char = baud, bits_per_char

    def us(self, n):
        """Cycles in n microseconds."""
        return int(n * self.cycles_per_us)

    def instructions_to_cycles(self, n):
        return n * self.cpi_num // self.cpi_den

    def cycles_to_instructions(self, c):
        return max(1, c * self.cpi_den // self.cpi_num)

    def char_time(self, k):
        """Cycles from a line's start to the end of its k-th character (k counts from 1).
        Fractional cycles are kept exact by computing from the character's index."""
        return k * self.bits_per_char * self.hz // self.baud


class Line:
    """The printer's bytes into the UART: a byte "enters" when its stop bit ends; the k-th byte
    of a run of back-to-back bytes completes at `origin + char_time(k)`, and a step's bytes
    follow what the last step left on the line (fil/g071/README.md, "freedom")."""

    def __init__(self, char_time):
        self.char_time = char_time
        self.origin = 0
        self.count = 0

    def arrivals(self, start, n):
        """The cycles at which the step's `n` bytes complete, the step starting at `start`."""
        if self.origin + self.char_time(self.count) <= start:
            self.origin, self.count = start, 0
        times = []
        for _ in range(n):
            self.count += 1
            times.append(self.origin + self.char_time(self.count))
        return times

    def restart(self, now):
        """The line dropped (power off): the next bytes start afresh."""
        self.origin, self.count = now, 0


class UartLine:
    """A UART model's side of the line: the characters the printer sends (`incoming`: (cycle
    its stop bit ends, byte), in order) and those the chip sent (`sent`), which the bench takes
    each step."""

    def deliver(self, at, byte):
        """A character the printer sends, complete at cycle `at`."""
        self.incoming.append((at, byte))

    def take_sent(self):
        sent, self.sent = self.sent, []
        return sent


class Load:
    """The instructions of each millisecond of the control loop: (instructions, bytes received,
    ms, whether a flash operation ran in it), and the bytes the UART sent in it (`sent`)."""

    def __init__(self):
        self.ms = []
        self.sent = {}

    def __iter__(self):
        return iter(self.ms)

    def __len__(self):
        return len(self.ms)

    def add(self, instructions, received, ms, wrote, sent=0):
        self.ms.append((instructions, received, ms, wrote))
        self.sent[ms] = sent

    def summary(self, symbol, cycles_per_ms, cpi, clock_label, quiet=False):
        """One `load:` line for the log: the milliseconds without a flash write (median, 99th and
        99.9th percentile, busiest) and the busiest with one; the percentage of the period at
        `cpi` cycles an instruction. `symbol`: the image's count of control steps (None if it
        has none). With `quiet`, also the most in a millisecond in which the UART sent nothing.
        """
        plain = sorted(m for m in self.ms if not m[3])
        writing = [m for m in self.ms if m[3]]
        if not plain:
            if symbol is None:
                return "load: no millisecond measured (the image has no MMU_CONTROL_STEPS)"
            return "load: no millisecond measured"

        def pct(n):
            return f"{100 * n * cpi / cycles_per_ms:.1f} %"

        def at(q):
            n = plain[min(len(plain) - 1, int(q * len(plain)))][0]
            return f"{n} ({pct(n)})"
        worst = plain[-1]
        line = (f"load: {len(plain)} ms without a flash write, instructions a millisecond: median "
                f"{at(0.5)}, 99 % {at(0.99)}, 99.9 % {at(0.999)}, busiest {worst[0]} ({pct(worst[0])} "
                f"of 1 ms at {clock_label}, {cpi:g} cycles an instruction) at {worst[2]} ms, "
                f"{worst[1]} bytes received")
        if quiet:
            silent = [m for m in plain if not self.sent.get(m[2])]
            if silent and silent[-1] != worst:
                line += (f" (in a millisecond that sent nothing at most {silent[-1][0]} "
                         f"({pct(silent[-1][0])}) at {silent[-1][2]} ms)")
        if writing:
            busiest = max(writing)
            line += f"; {len(writing)} ms with one, busiest {busiest[0]} ({pct(busiest[0])}) at {busiest[2]} ms"
        return line


class LineBench:
    """A bench's requests but `step`'s sensor values, and the accounting of each step's
    milliseconds. A subclass sets `chip` (whose `uart` is its printer UART's model: `deliver`,
    `take_sent`, `incoming`), `clock` (a Clock), `line`, `timer`, `load`, `control_steps` (the
    image's MMU_CONTROL_STEPS or None), `profile` and `busiest` (fil/g071/profile.py, or None
    and anything), and gives `step_request(words) -> answer` and `extra_request(words) ->
    answer or None`."""

    def handle(self, line):
        words = line.split()
        if not words:
            raise ValueError("empty request")
        if words[0] == "step":
            return self.step_request(words)
        if words == ["power", "off"]:
            self.chip.power_off()
            self.line.restart(self.chip.time)
            self.uart.incoming.clear()
            return "ok"
        if words == ["power", "on"]:
            if not self.chip.powered:
                self.chip.power_on()
            return "ok"
        if words == ["hang"]:
            self.chip.hung = True
            return "ok"
        answer = self.extra_request(words)
        if answer is None:
            raise ValueError(f"unknown request: {line.strip()}")
        return answer

    def extra_request(self, words):
        return None

    @property
    def uart(self):
        """The printer's UART model (the chip's: a reset builds the models anew)."""
        return self.chip.uart

    def deliver(self, start, rx):
        """The step's bytes into the UART at the line's pace, from `start`."""
        if self.chip.powered:
            for at, byte in zip(self.line.arrivals(start, len(rx)), rx):
                self.uart.deliver(at, byte)

    def run_measured(self, us, end, received, busy=lambda: 0):
        """Runs the chip to `end` and returns the bytes the UART sent meanwhile. A millisecond of
        the control loop (the image's step count moved, and had moved before the millisecond
        began: the first step's millisecond also holds the end of the boot; forward only, a reset
        keeps the RAM, so a boot's millisecond starts from the last run's count and clears it) is
        counted in `load` (and profiled): its instructions, the bytes received, whether a flash
        operation ran, and what the UART sent (plus `busy()`: a byte still going out)."""
        chip = self.chip
        with self.timer:
            resets, executed = chip.resets, chip.cpu.native.count()
            flash_ops = chip.erases() + chip.programs()
            functions = self.profile.snapshot() if self.profile else None
            steps = self.steps_taken()
            chip.run_until(end)
            sent = bytes(b for _, b in self.uart.take_sent()) if chip.powered else b""
            after = self.steps_taken()
            stepped = steps is not None and after is not None and 0 < steps < after
            if chip.resets == resets and chip.powered and us == 1000 and stepped:
                wrote = chip.erases() + chip.programs() != flash_ops
                n, ms = chip.cpu.native.count() - executed, round(end / self.clock.us(1000))
                self.load.add(n, received, ms, wrote, len(sent) + busy())
                if functions is not None:
                    self.busiest.take(n, ms, wrote, self.profile.counts - functions)
        return sent

    def answer(self, motors, sent):
        """The `step` answer."""
        chip = self.chip
        tx = sent.hex() if sent else "-"
        return f"ok {' '.join(motors)} {tx} {chip.resets} {chip.erases()} {chip.programs()}"

    def steps_taken(self):
        """The firmware's count of control steps, or None (no such symbol, or no power)."""
        if self.control_steps is None or not self.chip.powered:
            return None
        return int.from_bytes(self.chip.memory.read(self.control_steps, 4), "little")

    def virtual_ms(self):
        return self.chip.time / self.clock.us(1000)

    def stack_line(self):
        """The stack's high-water mark for the log (scheduler.StackPaint)."""
        if not self.chip.paint:
            return "stack: not measured (the image names no stack region)"
        start, top = self.chip.paint
        deepest = self.chip.measure_stack()
        return (f"stack: deepest {deepest} bytes below the top 0x{top:08x}, of {top - start} painted "
                f"from 0x{start:08x} ({top - start - deepest} never touched)")


class Timer:
    """Wall and CPU seconds spent emulating."""

    def __init__(self):
        self.wall = 0.0
        self.cpu = 0.0

    def __enter__(self):
        self.t0, self.c0 = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *_):
        self.wall += time.perf_counter() - self.t0
        self.cpu += time.process_time() - self.c0

    def speed(self, virtual_ms):
        """The bench's speed line, or None before anything ran."""
        if not self.wall:
            return None
        return (f"bench: {virtual_ms:.0f} virtual ms in {self.wall:.1f} s wall, {self.cpu:.1f} s CPU "
                f"of emulation: {virtual_ms / self.wall:.0f} virtual ms per wall second, "
                f"{virtual_ms / max(self.cpu, 1e-9):.0f} per CPU second")


def serve(make_bench, emulation_error, out=sys.stdout, inp=sys.stdin, log=sys.stderr):
    """Runs a bench on the request lines of `inp`: `make_bench()` returns (bench, ready line).
    Returns the exit status."""
    try:
        bench, ready = make_bench()
    except (OSError, ValueError, emulation_error) as e:
        print(f"error {e}", file=out, flush=True)
        return 1
    print(ready, file=out, flush=True)
    for line in inp:
        if line.strip() == "quit":
            for text in bench.report():
                print(text, file=log, flush=True)
            break
        try:
            answer = bench.handle(line)
        except (emulation_error, ValueError) as e:
            print(f"error {e}", file=out, flush=True)
            return 1
        except Exception as e:  # a fault of the bench itself: say so rather than hang the simulator
            print(f"error internal: {type(e).__name__}: {e}", file=out, flush=True)
            raise
        print(answer, file=out, flush=True)
    speed = bench.timer.speed(bench.virtual_ms())
    if speed:
        print(speed, file=log)
    return 0
