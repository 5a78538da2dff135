"""The real image through the protocol (version 3): the `ready` line; `S0` answered; `hang` -> the watchdog resets the chip -> it answers again; power off/on;
a bad request -> `error` and status 1; the same inputs give the same outputs; the stack's
high-water mark and the load line at `quit`; a worn store erased. Skipped without the image
(`dist/mmu-firmware-bmcu.elf`, or FIL_BMCU_IMAGE)."""

import os
import subprocess
import sys
import unittest

from support import BENCH, image_path, request

IMAGE = image_path()
REST = "2048 3000 2048 "  # a lane: angle 2048, filament at its sensor, tension at rest
IDLE = "step 1000 " + REST * 4 + "0 0 0 -"


def step(rx=b""):
    return "step 1000 " + REST * 4 + "0 0 0 " + (rx.hex() if rx else "-")


@unittest.skipUnless(os.path.exists(IMAGE), f"no image at {IMAGE}: scripts/build-firmware.sh bmcu dist")
class EndToEndTest(unittest.TestCase):
    def run_bench(self, lines, env=None):
        proc = subprocess.run([sys.executable, os.path.join(BENCH, "bench.py"), IMAGE],
                              input="\n".join(lines) + "\n", capture_output=True, text=True,
                              timeout=600, env={**os.environ, **(env or {})})
        return proc.returncode, proc.stdout.splitlines(), proc.stderr

    def test_ready_then_s0_answered(self):
        lines = [IDLE] * 40 + [step(request("S", 0))] + [IDLE] * 5 + ["quit"]
        code, out, err = self.run_bench(lines)
        self.assertEqual(code, 0, err)
        self.assertEqual(out[0], "ready bmcu 4 bmcu-c v3")
        self.assertEqual(out[1], "ok 100:0 100:0 100:0 100:0 - 0 0 0")
        sent = bytes.fromhex("".join(a.split()[5] for a in out[1:] if a.split()[5] != "-"))
        self.assertEqual(sent, b"S0 A3*22\n")
        self.assertIn("stack: deepest", err)
        self.assertIn("load: ", err)
        self.assertIn("clock: the image runs its core at 120 MHz", err)

    def test_hang_watchdog_reset_and_answers_again(self):
        lines = ([IDLE] * 40 + ["hang"] + [IDLE] * 520
                 + [step(request("S", 0))] + [IDLE] * 5 + ["quit"])
        code, out, err = self.run_bench(lines)
        self.assertEqual(code, 0, err)
        resets = [int(a.split()[6]) for a in out if a.startswith("ok ") and len(a.split()) > 6]
        self.assertEqual(resets[0], 0)
        self.assertEqual(resets[-1], 1)
        first = resets.index(1)
        self.assertIn(first, range(40 + 490, 40 + 510), "500 ms of the watchdog")
        self.assertIn("53302041332a32320a", "".join(a.split()[5] for a in out[-6:]))

    def test_power_off_on_boots_again(self):
        lines = [IDLE] * 30 + ["power off"] + [IDLE] * 5 + ["power on"] + [IDLE] * 40 + [
            step(request("S", 0))] + [IDLE] * 5 + ["quit"]
        code, out, err = self.run_bench(lines)
        self.assertEqual(code, 0, err)
        self.assertIn("ok 000:0 000:0 000:0 000:0 - 0 0 0", out)
        self.assertIn("53302041332a32320a", "".join(a.split()[5] for a in out[-7:] if a.startswith("ok ")))

    def test_a_bad_request_is_an_error(self):
        code, out, _ = self.run_bench(["step 1000 1 2 3"])
        self.assertEqual(code, 1)
        self.assertTrue(out[-1].startswith("error "), out)

    def test_the_same_inputs_give_the_same_outputs(self):
        lines = [IDLE] * 30 + [step(request("S", 0))] + [IDLE] * 20 + ["quit"]
        self.assertEqual(self.run_bench(lines)[1], self.run_bench(lines)[1])

    def test_a_worn_store_is_erased_at_boot(self):
        code, out, err = self.run_bench([IDLE] * 300 + ["quit"], env={"FIL_WORN_STORE": "1"})
        self.assertEqual(code, 0, err)
        erases = int(out[-1].split()[7])
        self.assertGreater(erases, 0, out[-1])


if __name__ == "__main__":
    unittest.main()
