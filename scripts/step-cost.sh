#!/usr/bin/env bash
# The step-cost benchmark: the firmware's tasks (mmu_firmware::tasks: control, store, the
# printer link, button, LED) on Embassy's executor and embassy-time, built for the MCU's
# instruction set (thumbv6m-none-eabi, the firmware's release profile) with stand-ins for the HAL
# drivers (bench-mcu/harness), replay a recorded session in the Unicorn emulator, which counts the
# instructions of every millisecond: the link's receive task, the time driver's alarm, the
# executor, the control task's step (a 12-byte burst included), the store task's save piece and
# the link's transmit task. README / book, "Step cost on the MCU", explains the session and the
# cycle model (2.2 cycles per instruction at 64 MHz: 1 ms = 29 091 instructions).
#
#   scripts/step-cost.sh               # build, record, run, report; fail above the limits
#
# Needs python3 with `unicorn` (PyPI; installed here with pip when missing) and a C compiler
# for the emulator's block counter (without one Python counts, about 5x slower).
# Each board's last line is its summary: `step cost: idle N instr median (P %), worst millisecond
# M instr (P % of 1 ms at F MHz; the 25 % bar is B instr: within|OVER), ...`.
#
# The design bar is 25 % of 1 ms (7 272 instructions at 64 MHz; 14 204 on the Pico at 125 MHz,
# the same cycle model), and the limits below are the bar: CI fails when a millisecond goes over.
# Measured 2026-11-27 on main (book, "Step cost on the MCU", says what brought it there):
#   NUCLEO-G071RB: idle median 3 884 (13.4 %), worst millisecond 7 078 (24.3 %: a phase of a
#     tool change beginning as 7 bytes arrive), worst with a flash write 6 141;
#   Pico (the multiplexed scan by DMA, 9 wake-ups): idle median 8 966 (15.8 %), worst 12 147
#     (21.4 %), with a flash write 11 223 (6 971 and 12 065 when a save piece's chunk was 64
#     bytes, 6 550 and 11 630 at 32; 16 now).
# A step's answer goes to the transmit task at the next tick (G071 worst 7 191 -> 7 073 then);
# the Pico's scan bound registered once (`tasks::bounded`: about 130 more here, about 600 fewer
# on the emulated Pico: bench-mcu/harness's Pico scan says why), the select lines that change
# only, and the ADC stopped in the DMA's interrupt (about 870 fewer here, 1 000 on the emulated
# Pico). Before the previous round's step-cost work: G071 worst 8 211 (28.2 %), Pico 15 788
# (27.8 %). The G071's margin is 194 instructions: a change that adds to the busiest millisecond
# (a phase beginning while a request is taken) must pay for itself. `run.py ELF SESSION
# --profile N --profile-at MS` lists where a millisecond goes. The stand-ins for the HAL drivers
# cost less than the drivers: the real images on the emulated chips (`mmu fil`, each bench's
# `load:` line) run about 560 (G071) and 5 000 (Pico) instructions more an idle millisecond;
# their busiest milliseconds are within the bar but the Pico's that write the flash and one G071
# millisecond by a few tens (book: "The benchmark against the real images").
MAX_WORST="${MAX_WORST:-7272}"
MAX_STEP="${MAX_STEP:-7272}"
MAX_IDLE="${MAX_IDLE:-4000}"
MAX_SAVE="${MAX_SAVE:-7272}"
PICO_MAX_WORST="${PICO_MAX_WORST:-14204}"
PICO_MAX_IDLE="${PICO_MAX_IDLE:-10000}"

set -euo pipefail

target_dir="${CARGO_TARGET_DIR:-target}"
case "$target_dir" in
    /*) ;;
    *) target_dir="$PWD/$target_dir" ;;
esac

if ! python3 -c 'import unicorn' 2>/dev/null; then
    python3 -m pip install --quiet 'unicorn==2.1.4' >&2
fi

# The session: the host App on the physical model, played by a scripted printer.
CARGO_TARGET_DIR="$target_dir" cargo run --quiet --release --locked \
    --manifest-path bench-mcu/session/Cargo.toml -- "$target_dir/step-cost-session.bin"

# The harness for the MCU, once with the G071's DMA scan and once with the Pico's multiplexed
# scan (feature `pico`). RUSTFLAGS replaces the firmware's rustflags (.cargo/config.toml); the
# harness links with its own script (bench-mcu/harness/build.rs); --nmagic as in the firmware.
for board in g071 pico; do
    features=""
    [ "$board" = pico ] && features="--features pico"
    # shellcheck disable=SC2086 # $features is one word or none
    RUSTFLAGS="-C link-arg=--nmagic" CARGO_TARGET_DIR="$target_dir/bench-mcu-$board" cargo build --quiet --release \
        --locked --target thumbv6m-none-eabi --manifest-path bench-mcu/harness/Cargo.toml $features
done

echo "--- NUCLEO-G071RB (64 MHz)"
python3 bench-mcu/run.py "$target_dir/bench-mcu-g071/thumbv6m-none-eabi/release/mmu-bench-mcu" \
    "$target_dir/step-cost-session.bin" --max-worst "$MAX_WORST" --max-step "$MAX_STEP" --max-idle "$MAX_IDLE" \
    --max-save "$MAX_SAVE"
echo "--- Raspberry Pi Pico (125 MHz)"
python3 bench-mcu/run.py "$target_dir/bench-mcu-pico/thumbv6m-none-eabi/release/mmu-bench-mcu" \
    "$target_dir/step-cost-session.bin" --mhz 125 --exact-steps 0 --max-worst "$PICO_MAX_WORST" \
    --max-idle "$PICO_MAX_IDLE"
