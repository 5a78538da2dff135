#!/usr/bin/env bash
# Builds the release firmware ELF of one board (thumbv6m-none-eabi; the BMCU-C: riscv32imc, at
# opt-level "z", the `bmcu` profile).
#
# The one place the firmware build steps live: the Dockerfile RUNs this script and CI runs it, so
# the image cannot drift from what CI checks.
#
#   scripts/build-firmware.sh [g071|g071-n20|pico|bmcu] [OUT_DIR]     (default: g071, the NUCLEO-G071RB;
#                                                             g071-n20: the same board, N20 encoder motors;
#                                                             bmcu: the BMCU-C kit's CH32V203)
#
# Prints the path of the built ELF on stdout (cargo's progress goes to stderr). With OUT_DIR, also
# copies it there as mmu-firmware-<board>.elf. Honours CARGO_TARGET_DIR and DEFMT_LOG (default:
# info, as in .cargo/config.toml). Every board builds the one binary `mmu-firmware` (one main, the
# board chosen by feature), so the ELF at the printed path is the last board built.
set -euo pipefail
cd "$(dirname "$0")/.."

board="${1:-g071}"
out_dir="${2:-}"
target=thumbv6m-none-eabi
profile=release
case "$board" in
    g071) alias=fw ;;
    g071-n20) alias=fw-n20 ;;
    pico) alias=fw-pico ;;
    bmcu) alias=fw-bmcu; target=riscv32imc-unknown-none-elf; profile=bmcu ;;
    *) echo "build-firmware: unknown board '$board' (g071, g071-n20, pico or bmcu)" >&2; exit 2 ;;
esac

# rust-toolchain.toml asks for the targets; rustup installs them on first use, but say so
# explicitly for toolchains set with RUSTUP_TOOLCHAIN (the Docker image pins one).
if command -v rustup >/dev/null 2>&1; then
    rustup target add "$target" >&2
fi

export DEFMT_LOG="${DEFMT_LOG:-info}"
# No registry paths in the image: panic locations of the dependencies name their files by
# absolute path (`/root/.cargo/registry/src/index.crates.io-<hash>/embassy-stm32-0.6.0/src/...`).
# Remapped to `embassy-stm32-0.6.0/src/...` they take less flash and say the same. The prefix
# depends on the machine, so it is set here rather than in .cargo/config.toml; `--config` adds it
# to that file's rustflags for the target (cargo joins the arrays). A plain `cargo fw` builds without it.
cargo_home="${CARGO_HOME:-$HOME/.cargo}"
remap=""
for index in "$cargo_home"/registry/src/*/ "$cargo_home"/git/checkouts/; do
    [ -d "$index" ] && remap="$remap\"--remap-path-prefix=$index=\","
done
# `cargo fw` / `cargo fw-n20` / `cargo fw-pico` / `cargo fw-bmcu` (.cargo/config.toml). --locked:
# exactly the versions in Cargo.lock.
cargo "$alias" --locked --config "target.$target.rustflags=[${remap%,}]" >&2

target_dir="${CARGO_TARGET_DIR:-target}"
case "$target_dir" in
    /*) ;;
    *) target_dir="$PWD/$target_dir" ;;
esac
elf="$target_dir/$target/$profile/mmu-firmware"
test -f "$elf" || { echo "build-firmware: $elf not found" >&2; exit 1; }

if [ -n "$out_dir" ]; then
    mkdir -p "$out_dir"
    cp "$elf" "$out_dir/mmu-firmware-$board.elf"
    echo "build-firmware: copied to $out_dir/mmu-firmware-$board.elf" >&2
fi
echo "$elf"
