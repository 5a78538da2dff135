#!/usr/bin/env python3
"""Measures the bench's speed (virtual ms per wall second) on the real image: idle, and with a
motor running under a crude plant (not the simulator's physical model: just enough feedback for
the firmware to keep its motor on: a Hall sine from the motor's revolutions and the slot/hub
filament sensors from the filament tip's position, model/src/config.rs's defaults).

    python3 fil/g071/speed.py <image.elf> [--ms N] [--command L0]
"""

import argparse
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "tests"))

import bench as bench_module  # noqa: E402
from support import request  # noqa: E402

REST, FILAMENT, HALL = 2048, 3000, 700
SLOT_SENSOR_MM, HUB_MM, MM_PER_REV, MAX_MM_S = -95.0, 0.0, 2.0, 150.0


class Plant:
    def __init__(self):
        self.tip = [-15.0] * 3

    def levels(self):
        out = []
        for slot in range(3):
            revs = self.tip[slot] / MM_PER_REV
            out.append(int(REST + HALL * math.sin(2 * math.pi * revs)))
            out.append(FILAMENT if self.tip[slot] >= SLOT_SENSOR_MM else REST)
        hub = any(t >= HUB_MM for t in self.tip)
        out += [FILAMENT if hub else REST, REST, REST]
        return out

    def move(self, motors, ms=1.0):
        """motors: the bench's `<STBY><IN1><IN2>:<duty>` per slot."""
        running = 0
        for slot, m in enumerate(motors):
            levels, duty = m.split(":")
            stby, in1, in2 = (c == "1" for c in levels)
            if stby and in1 != in2 and int(duty) > 80:
                speed = int(duty) / 1000 * MAX_MM_S * (1 if in1 else -1)
                self.tip[slot] += speed * ms / 1000
                running += 1
        return running


def run(path, steps, command):
    b = bench_module.Bench(path)
    plant = Plant()
    motor_ms = 0
    motor_cpu = 0.0
    t0 = time.perf_counter()
    c0 = time.process_time()
    answers = []
    for ms in range(steps):
        rx = b""
        if command and ms >= 200 and ms % 400 == 0:
            rx = request(command[0], int(command[1:]))  # again as soon as the last one is done
        elif command and ms > 200 and ms % 400 == 200:
            rx = request("Q", 0)
        c1 = time.process_time()
        words = b.step(1000, plant.levels(), rx).split()
        if plant.move(words[1:4]):
            motor_ms += 1
            motor_cpu += time.process_time() - c1
        if words[4] != "-":
            answers.append(bytes.fromhex(words[4]))
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    return wall, cpu, motor_ms, motor_cpu, b"".join(answers)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("image")
    parser.add_argument("--ms", type=int, default=5000)
    parser.add_argument("--command", default="L0")
    args = parser.parse_args()
    for label, command in (("idle", None), (f"{args.command} with the crude plant", args.command)):
        wall, cpu, motor_ms, motor_cpu, tx = run(args.image, args.ms, command)
        print(f"{label}: {args.ms} virtual ms in {wall:.2f} s wall ({cpu:.2f} s CPU): "
              f"{args.ms / wall:.0f} virtual ms per wall second ({args.ms / cpu:.0f} per CPU "
              f"second); a motor ran {motor_ms} ms"
              + (f", at {motor_ms / motor_cpu:.0f} virtual ms per CPU second" if motor_cpu else ""))
        if command:
            print(f"  the unit sent (end): {tx[-120:]!r}")


if __name__ == "__main__":
    main()
