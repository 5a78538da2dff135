#!/usr/bin/env bash
# The step-cost benchmark: the unit logic (App<3>) and its persistence policy built for the MCU's
# instruction set (thumbv6m-none-eabi, the firmware's release profile) replay a recorded session
# in the Unicorn emulator, which counts the instructions of every control step and save and
# paints the stack. README, "Step cost on the MCU", explains the session and the cycle model.
#
#   scripts/step-cost.sh               # build, record, run, report; fail above the budget
#
# Needs python3 with `unicorn` (PyPI; installed here with pip when missing) and a C compiler
# for the emulator's block counter (without one Python counts, about 5x slower).
# The last line is the summary: `step cost: idle N instr median, worst M instr (P % of 1 ms at
# 64 MHz), save S instr`.
set -euo pipefail
cd "$(dirname "$0")/.."

# The budget. The goal (issue 14) is a worst step incl. a burst and a save under 25 % of 1 ms
# (7272 instructions at 2.2 cycles/instr, 64 MHz) and idle under 10 % (2909). Idle and the
# costliest step alone (a query burst, taken at most control::MAX_RX_PER_STEP bytes a step) meet
# it and are held to it; a save is one bounded piece per Keeper::update. A step with a save
# piece in the same millisecond does not meet it yet: MAX_WORST holds the current figure plus a
# margin (the counts are exact and deterministic), so a regression fails. Measured 2026-11-22:
# idle 2788, costliest step 6279, worst step + save 9064 (a lane save piece after a step that
# answered a query), save 3509.
MAX_WORST="${MAX_WORST:-9500}"
MAX_STEP="${MAX_STEP:-7272}"
MAX_IDLE="${MAX_IDLE:-2909}"
MAX_SAVE="${MAX_SAVE:-3800}"

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

# The harness for the MCU. RUSTFLAGS replaces the firmware's link scripts (.cargo/config.toml)
# with the harness's own (bench-mcu/harness/build.rs); --nmagic as in the firmware.
RUSTFLAGS="-C link-arg=--nmagic" CARGO_TARGET_DIR="$target_dir/bench-mcu" cargo build --quiet --release \
    --locked --target thumbv6m-none-eabi --manifest-path bench-mcu/harness/Cargo.toml

python3 bench-mcu/run.py "$target_dir/bench-mcu/thumbv6m-none-eabi/release/mmu-bench-mcu" \
    "$target_dir/step-cost-session.bin" --max-worst "$MAX_WORST" --max-step "$MAX_STEP" --max-idle "$MAX_IDLE" \
    --max-save "$MAX_SAVE"
