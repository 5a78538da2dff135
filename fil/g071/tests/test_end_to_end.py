"""End to end through the line protocol (fil/PROTOCOL.md) on the real firmware image: the image
boots, answers the printer's `S0`, is reset by its watchdog after `hang` and boots again after
`power off`/`power on`. Skipped when the image is missing (FIL_G071_IMAGE, default
dist/mmu-firmware-g071.elf at the repository's root)."""

import support  # noqa: F401  (first: puts fil/g071 on the import path)
import os
import subprocess
import sys
import tempfile
import unittest

from support import BENCH, image_path, request

IMAGE = image_path()
LEVELS = " ".join(["2000"] * 9)


class BenchProcess:
    def __init__(self, *extra):
        self.proc = subprocess.Popen([sys.executable, os.path.join(BENCH, "bench.py"), IMAGE, *extra],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        self.ready = self.proc.stdout.readline().strip()

    def ask(self, line):
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()
        return self.proc.stdout.readline().strip()

    def step(self, rx=b""):
        answer = self.ask(f"step 1000 {LEVELS} {rx.hex() if rx else '-'}")
        words = answer.split()
        assert words[0] == "ok" and len(words) == 8, answer
        return words

    def until_answer(self, prefix, steps, rx):
        """Sends `rx` in the first step, then steps until the TX carries `prefix`; returns the
        number of steps it took, or None."""
        tx = b""
        for n in range(steps):
            words = self.step(rx if n == 0 else b"")
            if words[4] != "-":
                tx += bytes.fromhex(words[4])
            if prefix in tx:
                return n + 1
        return None

    def close(self):
        try:
            self.proc.stdin.write("quit\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, ValueError):
            pass
        code = self.proc.wait(timeout=30)
        self.proc.stdin.close()
        self.proc.stdout.close()
        self.proc.stderr.close()
        return code


@unittest.skipUnless(os.path.exists(IMAGE), f"no firmware image at {IMAGE} (set FIL_G071_IMAGE)")
class EndToEndTest(unittest.TestCase):
    def setUp(self):
        self.bench = BenchProcess()
        self.assertRegex(self.bench.ready, r"^ready g071 3 (thesis|n20-quadrature)$")

    def tearDown(self):
        self.assertEqual(self.bench.close(), 0)

    def boot_and_answer(self):
        for _ in range(100):  # boot
            self.bench.step()
        steps = self.bench.until_answer(b"S0 A", 300, request("S", 0))
        self.assertIsNotNone(steps, "no S0 answer within 300 ms")
        return steps

    def test_boot_answers_s0(self):
        self.boot_and_answer()
        words = self.bench.step()
        self.assertEqual(words[5], "0")  # no reset
        self.assertEqual(words[1:4], ["000:0"] * 3)  # idle: bridges in standby, no duty

    def test_hang_resets_through_the_watchdog_and_answers_again(self):
        self.boot_and_answer()
        self.assertEqual(self.bench.ask("hang"), "ok")
        resets = None
        for _ in range(200):
            resets = int(self.bench.step()[5])
            if resets:
                break
        self.assertEqual(resets, 1)
        self.boot_and_answer()

    def test_power_cycle_boots_again(self):
        self.boot_and_answer()
        self.assertEqual(self.bench.ask("power off"), "ok")
        for _ in range(5):
            words = self.bench.step(request("S", 0))
            self.assertEqual(words[4], "-")
        self.assertEqual(self.bench.ask("power on"), "ok")
        self.assertEqual(self.bench.step()[5], "1")
        self.boot_and_answer()


@unittest.skipUnless(os.path.exists(IMAGE), f"no firmware image at {IMAGE} (set FIL_G071_IMAGE)")
class ProtocolTest(unittest.TestCase):
    def test_bad_request_is_an_error_with_status_1(self):
        bench = BenchProcess()
        self.assertRegex(bench.ready, r"^ready g071 3 (thesis|n20-quadrature)$")
        self.assertTrue(bench.ask("step 1000 1 2 3").startswith("error "))
        self.assertEqual(bench.proc.wait(timeout=30), 1)
        bench.proc.stdout.close()
        bench.proc.stderr.close()
        bench.proc.stdin.close()

    def test_rtt_bytes_are_written(self):
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "rtt.bin")
            bench = BenchProcess("--rtt", path)
            for _ in range(50):
                bench.step()
            self.assertEqual(bench.close(), 0)
            self.assertGreater(os.path.getsize(path), 0)


if __name__ == "__main__":
    unittest.main()


@unittest.skipUnless(os.path.exists(IMAGE), f"no firmware image at {IMAGE} (set FIL_G071_IMAGE)")
class DeterminismTest(unittest.TestCase):
    def test_same_inputs_same_answers(self):
        import bench as bench_module
        from support import request as encode

        def run():
            bench = bench_module.Bench(IMAGE)
            answers = []
            for ms in range(120):
                rx = encode("S", 0) if ms in (30, 60) else encode("Q", 0) if ms == 90 else b""
                answers.append(bench.step(1000, [1000 + 10 * ms] * 9, rx))
            return answers, bench.chip.cpu.native.count()

        first, second = run(), run()
        self.assertEqual(first, second)
        # The `S0` was answered: its answer may straddle two steps, at the line's pace.
        sent = "".join(a.split()[4] for a in first[0] if a.split()[4] != "-")
        self.assertIn("53302041", sent)


@unittest.skipUnless(os.path.exists(IMAGE), f"no firmware image at {IMAGE} (set FIL_G071_IMAGE)")
class EraseDuringRequestTest(unittest.TestCase):
    """A page erase while the printer sends a request loses no byte, on the real image: a
    damaged store (the persisted region filled with junk) makes the firmware erase a page at
    boot; the printer's `S0` arrives while the erase stalls the CPU; the firmware answers it once
    the erase is over."""

    def test_request_during_erase_is_answered(self):
        import bench as bench_module
        from support import request as encode
        bench = bench_module.Bench(IMAGE)
        chip = bench.chip
        chip.memory.write(0x0801_8000, b"\x5a" * 0x8000)
        levels = [2000] * 9
        for _ in range(200):
            bench.step(1000, levels, b"")
            if chip.erases() and chip.stall_until is not None:
                break
        self.assertIsNotNone(chip.stall_until, "the image did not erase a page")
        stall_end = chip.stall_until
        self.assertGreater(stall_end - chip.time, 2 * 64_000)  # room for the request's 6 bytes
        answer = bench.step(1000, levels, encode("S", 0)).split()
        self.assertEqual(answer[4], "-")
        self.assertEqual(chip.usart1.received, 6)   # all six in the DMA ring during the stall
        self.assertEqual(chip.usart1.lost, 0)
        self.assertIsNotNone(chip.stall_until)       # still erasing
        tx = b""
        for _ in range(100):
            words = bench.step(1000, levels, b"").split()
            if words[4] != "-":
                tx += bytes.fromhex(words[4])
            if tx.endswith(b"\n"):
                break
        self.assertTrue(tx.startswith(b"S0 A"), tx)
        self.assertGreaterEqual(chip.time, stall_end)


@unittest.skipUnless(os.path.exists(IMAGE), f"no firmware image at {IMAGE} (set FIL_G071_IMAGE)")
class LoadTest(unittest.TestCase):
    """The bench's `load:` counts the control task's milliseconds (the firmware's
    MMU_CONTROL_STEPS moved since the first step), not the boot's (a store restore once made a
    25 605-instruction millisecond the power-cut scenario's busiest) nor those a page erase
    stalls whole."""

    def test_only_the_milliseconds_with_a_control_step_are_counted(self):
        import bench as bench_module
        bench = bench_module.Bench(IMAGE)
        bench.chip.memory.write(0x0801_8000, b"\x5a" * 0x8000)  # a damaged store: an erase
        levels = [2000] * 9
        stepped = []
        for ms in range(1, 101):
            before = bench.steps_taken()
            bench.step(1000, levels, b"")
            if bench.steps_taken() != before:
                stepped.append(ms)
        self.assertGreater(stepped[0], 1, "the boot comes before the first step")
        self.assertGreater(bench.chip.erases(), 0)
        stalled = [ms for ms in range(stepped[0], 101) if ms not in stepped]
        self.assertGreaterEqual(len(stalled), 10, "the erase stalled the loop for some ms")
        # The first step's millisecond also holds the end of the boot: counted from the next.
        self.assertEqual([m[2] for m in bench.load], stepped[1:])

    def test_a_count_that_falls_is_a_boot_and_not_counted(self):
        # A reset keeps the RAM (chip.py's system_reset, as the chip): a boot that starts late in
        # a millisecond clears the last run's count in the next one, which is not the loop's.
        import bench as bench_module
        bench = bench_module.Bench(IMAGE)
        levels = [2000] * 9
        for _ in range(50):
            bench.step(1000, levels, b"")
        for counts, counted in [([1000, 3], False), ([1000, 0], False), ([5, 5], False), ([5, 6], True)]:
            seen = iter(counts)
            bench.steps_taken = lambda: next(seen)
            before = len(bench.load)
            bench.step(1000, levels, b"")
            self.assertEqual(len(bench.load) - before, int(counted), counts)
