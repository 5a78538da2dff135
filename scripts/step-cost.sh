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
# the same cycle model). Measured 2026-11-27 on the Embassy firmware (after merging main):
#   NUCLEO-G071RB: idle median 4 724 (16.2 %), worst millisecond 9 691 (33.3 %: a 12-byte burst
#     of requests answered in an error), worst millisecond with a flash write 7 652 (26.3 %);
#   Pico (its multiplexed scan: nine settling timers, 36 blocking conversions): idle median
#     12 351 (21.7 % at 125 MHz), worst millisecond 17 311 (30.5 %), with a flash write 15 279.
# Both worst milliseconds are OVER the bar: the executor, the tasks and their glue (the link's
# pipes, the Ticker's and the scan's timers, the wakers) cost about 1 900 instructions a
# millisecond over the logic's own step (the old loop's idle step was 2 839), compiler-builtins'
# memcpy about 1 000 in a burst, and the logic's burst step about 6 000. The session's bytes
# reach the UART at the line's rate (12 a millisecond at most). The limits below are regression
# guards at the measured figures plus about 3 %, not the bar; lower them as the cost comes down.
# Filament left and lane health (src/lanes) cost about 100 instructions an idle millisecond and
# 330-400 one in which a command runs or bytes arrive (its moves' tallies, the load watched); the
# worst millisecond moved to a stall's error step with a burst (measured 2026-11-27 on branch
# lanes against 9 727 / 4 749 / 7 680 before it): G071 idle 4 844, worst 10 311, with a flash write
# 8 372; Pico idle 12 473, worst 17 933. The guards below follow, plus about 3 %.
MAX_WORST="${MAX_WORST:-10600}"
MAX_STEP="${MAX_STEP:-10600}"
MAX_IDLE="${MAX_IDLE:-4990}"
MAX_SAVE="${MAX_SAVE:-8600}"
PICO_MAX_WORST="${PICO_MAX_WORST:-18500}"
PICO_MAX_IDLE="${PICO_MAX_IDLE:-12800}"

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
