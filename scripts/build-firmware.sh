#!/usr/bin/env bash
# Builds the release firmware ELF for the reference board (NUCLEO-G071RB, thumbv6m-none-eabi).
#
# The one place the firmware build steps live: the Dockerfile RUNs this script and CI runs it, so
# the image cannot drift from what CI checks.
#
#   scripts/build-firmware.sh [OUT_DIR]
#
# Prints the path of the built ELF on stdout (cargo's progress goes to stderr). With OUT_DIR, also
# copies it there as mmu-firmware.elf. Honours CARGO_TARGET_DIR and DEFMT_LOG (default: info, as in
# .cargo/config.toml).
set -euo pipefail
cd "$(dirname "$0")/.."

out_dir="${1:-}"
target=thumbv6m-none-eabi

# rust-toolchain.toml asks for the thumb target; rustup installs it on first use, but say so
# explicitly for toolchains set with RUSTUP_TOOLCHAIN (the Docker image pins one).
if command -v rustup >/dev/null 2>&1; then
    rustup target add "$target" >&2
fi

export DEFMT_LOG="${DEFMT_LOG:-info}"
# No registry paths in the image: panic locations of the dependencies name their files by
# absolute path (`/root/.cargo/registry/src/index.crates.io-<hash>/embassy-stm32-0.6.0/src/...`).
# Remapped to `embassy-stm32-0.6.0/src/...` they take ~0.4 KiB less flash. The prefix depends on
# the machine, so it is set here rather than in .cargo/config.toml; `--config` adds it to that
# file's thumbv6m rustflags (cargo joins the arrays). A plain `cargo fw` builds without it.
cargo_home="${CARGO_HOME:-$HOME/.cargo}"
remap=""
for index in "$cargo_home"/registry/src/*/ "$cargo_home"/git/checkouts/; do
    [ -d "$index" ] && remap="$remap\"--remap-path-prefix=$index=\","
done
# `cargo fw` = build --release --target thumbv6m-none-eabi --features mcu --bin mmu-firmware
# (.cargo/config.toml). --locked: exactly the dependency versions in Cargo.lock.
cargo fw --locked --config "target.thumbv6m-none-eabi.rustflags=[${remap%,}]" >&2

target_dir="${CARGO_TARGET_DIR:-target}"
case "$target_dir" in
    /*) ;;
    *) target_dir="$PWD/$target_dir" ;;
esac
elf="$target_dir/$target/release/mmu-firmware"
test -f "$elf" || { echo "build-firmware: $elf not found" >&2; exit 1; }

if [ -n "$out_dir" ]; then
    mkdir -p "$out_dir"
    cp "$elf" "$out_dir/mmu-firmware.elf"
    echo "build-firmware: copied to $out_dir/mmu-firmware.elf" >&2
fi
echo "$elf"
