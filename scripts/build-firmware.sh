#!/usr/bin/env bash
# Builds the release firmware ELF of one board (thumbv6m-none-eabi).
#
# The one place the firmware build steps live: the Dockerfile RUNs this script and CI runs it, so
# the image cannot drift from what CI checks.
#
#   scripts/build-firmware.sh [g071|g071-n20|pico] [OUT_DIR]     (default: g071, the NUCLEO-G071RB;
#                                                             g071-n20: the same board, N20 encoder motors)
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
case "$board" in
    g071) alias=fw ;;
    g071-n20) alias=fw-n20 ;;
    pico) alias=fw-pico ;;
    *) echo "build-firmware: unknown board '$board' (g071, g071-n20 or pico)" >&2; exit 2 ;;
esac

# rust-toolchain.toml asks for the thumb target; rustup installs it on first use, but say so
# explicitly for toolchains set with RUSTUP_TOOLCHAIN (the Docker image pins one).
if command -v rustup >/dev/null 2>&1; then
    rustup target add "$target" >&2
fi

export DEFMT_LOG="${DEFMT_LOG:-info}"
# No registry paths in the image: panic locations of the dependencies name their files by
# absolute path (`/root/.cargo/registry/src/index.crates.io-<hash>/embassy-stm32-0.6.0/src/...`).
# Remapped to `embassy-stm32-0.6.0/src/...` they take less flash and say the same. The prefix
# depends on the machine, so it is set here rather than in .cargo/config.toml; `--config` adds it
# to that file's thumbv6m rustflags (cargo joins the arrays). A plain `cargo fw` builds without it.
cargo_home="${CARGO_HOME:-$HOME/.cargo}"
remap=""
for index in "$cargo_home"/registry/src/*/ "$cargo_home"/git/checkouts/; do
    [ -d "$index" ] && remap="$remap\"--remap-path-prefix=$index=\","
done
# `cargo fw` / `cargo fw-n20` / `cargo fw-pico` (.cargo/config.toml). --locked: exactly the versions in Cargo.lock.
cargo "$alias" --locked --config "target.thumbv6m-none-eabi.rustflags=[${remap%,}]" >&2

target_dir="${CARGO_TARGET_DIR:-target}"
case "$target_dir" in
    /*) ;;
    *) target_dir="$PWD/$target_dir" ;;
esac
elf="$target_dir/$target/release/mmu-firmware"
test -f "$elf" || { echo "build-firmware: $elf not found" >&2; exit 1; }

if [ -n "$out_dir" ]; then
    mkdir -p "$out_dir"
    cp "$elf" "$out_dir/mmu-firmware-$board.elf"
    echo "build-firmware: copied to $out_dir/mmu-firmware-$board.elf" >&2
fi
echo "$elf"
