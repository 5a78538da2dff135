#!/usr/bin/env bash
# Builds the firmware (release, DEFMT_LOG=info) and checks its footprint on the STM32G071RB:
# flash against the design target of 32 KiB, static RAM against 8 KiB, static RAM plus the
# worst-case stack against the 36 KiB of RAM, and that no `core::fmt` is linked.
#
#   scripts/firmware-size.sh          # build, report, fail (exit 1) above a budget
#   TOP=30 scripts/firmware-size.sh   # list more of the largest symbols
#
# flash      = .vector_table + .text + .rodata + .data (its initial values are stored in flash)
# static RAM = .data + .bss + .uninit (the 1 KiB defmt RTT buffer is in .uninit); the stack comes
#              on top, from the rest of the 36 KiB.
# stack      = scripts/stack-estimate.py, a static estimate from the disassembly.
# It also checks the firmware's memcpy, memclr and division (src/mem.rs, src/div.rs) in an emulator.
# Sizes come from `llvm-size -A` (or GNU `size -A`), the largest symbols from `llvm-nm`/`nm`.
set -euo pipefail
cd "$(dirname "$0")/.."

FLASH_BUDGET="${FLASH_BUDGET:-32768}" # the design target (docs: 32 KiB with logs and persistence on)
RAM_BUDGET="${RAM_BUDGET:-8192}"
RAM_TOTAL=36864 # the STM32G071RB's SRAM (memory.x)
TOP="${TOP:-15}"

pick() {
    for tool in "$@"; do
        if command -v "$tool" >/dev/null 2>&1; then
            echo "$tool"
            return
        fi
    done
    echo "firmware-size: none of $* found" >&2
    exit 1
}
size_tool="$(pick llvm-size size arm-none-eabi-size)"
nm_tool="$(pick llvm-nm nm arm-none-eabi-nm)"

elf="$(DEFMT_LOG=info bash scripts/build-firmware.sh | tail -n 1)"

# Section sizes, as "name size" lines.
sections="$("$size_tool" -A "$elf" | awk 'NF >= 2 && $1 ~ /^\./ { print $1, $2 }')"
section() { awk -v name="$1" '$1 == name { print $2; found = 1 } END { if (!found) print 0 }' <<<"$sections"; }

vector_table="$(section .vector_table)"
text="$(section .text)"
rodata="$(section .rodata)"
data="$(section .data)"
bss="$(section .bss)"
uninit="$(section .uninit)"
flash=$((vector_table + text + rodata + data))
ram=$((data + bss + uninit))

kib() { awk -v b="$1" 'BEGIN { printf "%.1f KiB", b / 1024 }'; }
percent() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.0f %%", 100 * a / b }'; }

echo
echo "firmware: $elf (release, DEFMT_LOG=info)"
printf '  %-14s %8s\n' .vector_table "$vector_table" .text "$text" .rodata "$rodata" .data "$data" \
    .bss "$bss" .uninit "$uninit"
printf '  flash      %6d B  (%s, %s of the %d B budget)\n' "$flash" "$(kib "$flash")" \
    "$(percent "$flash" "$FLASH_BUDGET")" "$FLASH_BUDGET"
printf '  static RAM %6d B  (%s, %s of the %d B budget)\n' "$ram" "$(kib "$ram")" \
    "$(percent "$ram" "$RAM_BUDGET")" "$RAM_BUDGET"
if [ "$flash" -le "$FLASH_BUDGET" ]; then
    printf '  flash is %d B under the %d B budget\n' "$((FLASH_BUDGET - flash))" "$FLASH_BUDGET"
fi

# The largest contributors: symbols by size, flash (code, read-only data) and RAM separately.
# `sed -n 1,Np`, not `head`: head exits early and, under pipefail, sort's SIGPIPE fails the run
# (exit 141) once the symbol list outgrows the pipe buffer.
symbols="$("$nm_tool" --size-sort -S -C "$elf")"
top() {
    awk -v types="$1" '
        NF >= 4 && index(types, $3) {
            name = $4; for (i = 5; i <= NF; i++) name = name " " $i
            if (length(name) > 100) name = substr(name, 1, 97) "..."
            printf "%8d  %s\n", ("0x" $2) + 0, name
        }' <<<"$symbols" | sort -n -r | sed -n "1,${TOP}p"
}
hex_awk_ok="$(awk 'BEGIN { print ("0x10" + 0) }')"
if [ "$hex_awk_ok" != 16 ]; then
    # mawk and busybox awk do not read hex: convert with printf instead.
    top() {
        while read -r _ size type name; do
            case "$1" in *"$type"*) printf '%8d  %.100s\n' "$((16#$size))" "$name" ;; esac
        done <<<"$symbols" | sort -n -r | sed -n "1,${TOP}p"
    }
fi
# The worst-case stack, a static estimate from the disassembly (scripts/stack-estimate.py): the
# deepest call chain from reset, plus the deepest interrupt and the NMI/HardFault on top. It must fit the RAM that
# static RAM leaves.
echo
# It disassembles with llvm-objdump: from PATH, else from rustup's llvm-tools component.
if [ -z "${LLVM_OBJDUMP:-}" ] && ! command -v llvm-objdump >/dev/null 2>&1; then
    rustup component add llvm-tools >&2
    LLVM_OBJDUMP="$(find "$(rustc --print sysroot)/lib/rustlib" -name llvm-objdump -type f | sed -n 1p)"
    export LLVM_OBJDUMP
fi
stack_report="$(python3 scripts/stack-estimate.py "$elf")"
echo "$stack_report"
stack="$(awk '/^worst-case stack:/ { print $3 }' <<<"$stack_report")"

echo
echo "largest flash symbols (code and read-only data):"
top tTrR
echo
echo "largest RAM symbols (.data, .bss):"
top dDbB

status=0
# The firmware's own memcpy, memclr (src/mem.rs) and division (src/div.rs), checked as linked in
# the Unicorn emulator: every length and alignment, edge and random operands
# (scripts/check-runtime-routines.py; PyPI `unicorn`, as the step-cost benchmark uses).
if ! python3 -c 'import unicorn' 2>/dev/null; then
    python3 -m pip install --quiet 'unicorn==2.1.4' >&2
fi
echo
if ! python3 scripts/check-runtime-routines.py "$elf"; then
    echo "firmware-size: FAIL: the firmware's run-time routines (src/mem.rs, src/div.rs) are wrong" >&2
    status=1
fi
# The panic handler keeps `core::fmt` out (src/main.rs, `panic`): any of its symbols means a
# formatting path came back (about 1.7 KiB).
fmt_symbols="$(grep -c 'core::fmt::' <<<"$symbols" || true)"
if [ "$fmt_symbols" -gt 0 ]; then
    grep 'core::fmt::' <<<"$symbols" | sed -n 1,5p >&2
    echo "firmware-size: FAIL: core::fmt is linked ($fmt_symbols symbols): see src/main.rs, panic" >&2
    status=1
fi
if [ "$flash" -gt "$FLASH_BUDGET" ]; then
    echo "firmware-size: FAIL: flash $flash B is over the $FLASH_BUDGET B budget" >&2
    status=1
fi
if [ "$((ram + stack))" -gt "$RAM_TOTAL" ]; then
    echo "firmware-size: FAIL: static RAM $ram B + worst-case stack $stack B is over the $RAM_TOTAL B of RAM" >&2
    status=1
fi
if [ "$ram" -gt "$RAM_BUDGET" ]; then
    echo "firmware-size: FAIL: static RAM $ram B is over the $RAM_BUDGET B budget" >&2
    status=1
fi
[ "$status" -eq 0 ] && echo && echo "firmware-size: OK (flash $flash B <= $FLASH_BUDGET B, static RAM $ram B <= $RAM_BUDGET B, stack $stack B)"
exit "$status"
