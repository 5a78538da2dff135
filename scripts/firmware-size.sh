#!/usr/bin/env bash
# Builds the firmware of each board (release, DEFMT_LOG=info) and reports its footprint against
# its chip: flash against the board's code bar (G071: 98 304 B, its 128 KiB less the 32 KiB
# store, memory.x's FLASH; Pico: 1 048 576 B; BMCU-C: 61 440 B, the rated 64 KB less its 4 KB
# store), static RAM plus the worst-case stack estimate against the chip's RAM (G071: 36 KiB;
# Pico: 264 KiB; BMCU-C: 20 KB, static RAM only: its stack is measured in the bench), and the
# largest symbols. Fails (exit 1)
# only when a board's flash is over its bar or its static RAM plus stack over its chip's RAM.
#
#   scripts/firmware-size.sh              # both boards
#   scripts/firmware-size.sh g071         # one board (g071, g071-n20, pico or bmcu)
#   TOP=30 scripts/firmware-size.sh       # list more of the largest symbols
#
# flash      = every section loaded into flash: .vector_table + .text + .rodata + .data (its
#              initial values are stored in flash), and on the Pico .boot2
# static RAM = .data + .bss + .uninit (the 1 KiB defmt RTT buffer is in .uninit)
# stack      = scripts/stack-estimate.py, a static estimate from the disassembly, with the
#              executor's task polls followed (--indirect); an over-estimate (tail calls count as
#              calls, the deepest interrupt is stacked on the deepest thread path)
set -euo pipefail
cd "$(dirname "$0")/.."

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
# stack-estimate.py disassembles with llvm-objdump: from PATH, else rustup's llvm-tools.
if [ -z "${LLVM_OBJDUMP:-}" ] && ! command -v llvm-objdump >/dev/null 2>&1; then
    rustup component add llvm-tools >&2
    LLVM_OBJDUMP="$(find "$(rustc --print sysroot)/lib/rustlib" -name llvm-objdump -type f | sed -n 1p)"
    export LLVM_OBJDUMP
fi

kib() { awk -v b="$1" 'BEGIN { printf "%.1f KiB", b / 1024 }'; }
percent() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.0f %%", 100 * a / b }'; }

status=0
summary=""
bars=""
report() {
    local board="$1" flash_bar ram_total vectors
    case "$board" in
        g071) flash_bar=98304; ram_total=36864; vectors=0x08000000; name="NUCLEO-G071RB (STM32G071RB, 128 KiB flash, 36 KiB RAM)" ;;
        g071-n20) flash_bar=98304; ram_total=36864; vectors=0x08000000; name="NUCLEO-G071RB, N20 encoder motors (STM32G071RB, 128 KiB flash, 36 KiB RAM)" ;;
        pico) flash_bar=1048576; ram_total=270336; vectors=0x10000100; name="Raspberry Pi Pico (RP2040, 2 MiB flash, 264 KiB RAM)" ;;
        bmcu) flash_bar=61440; ram_total=20480; vectors=""; name="BMCU-C (CH32V203C8T6, 64 KB flash rated, 4 KB of it the store; 20 KB RAM)" ;;
        *) echo "firmware-size: unknown board '$board'" >&2; exit 2 ;;
    esac
    local elf
    elf="$(DEFMT_LOG=info bash scripts/build-firmware.sh "$board" | tail -n 1)"

    local sections
    sections="$("$size_tool" -A "$elf" | awk 'NF >= 2 && $1 ~ /^\./ { print $1, $2 }')"
    section() { awk -v name="$1" '$1 == name { print $2; found = 1 } END { if (!found) print 0 }' <<<"$sections"; }
    local boot2 vector_table text rodata data bss uninit flash ram
    boot2="$(section .boot2)"
    vector_table="$(section .vector_table)"
    text="$(section .text)"
    rodata="$(section .rodata)"
    data="$(section .data)"
    bss="$(section .bss)"
    uninit="$(section .uninit)"
    flash=$((boot2 + vector_table + text + rodata + data))
    ram=$((data + bss + uninit))

    echo
    echo "=== $board: $name"
    echo "firmware: $elf (release, DEFMT_LOG=info)"
    printf '  %-14s %8s\n' .boot2 "$boot2" .vector_table "$vector_table" .text "$text" .rodata "$rodata" \
        .data "$data" .bss "$bss" .uninit "$uninit"
    printf '  flash      %6d B  (%s, %s of the %d B bar)\n' "$flash" "$(kib "$flash")" \
        "$(percent "$flash" "$flash_bar")" "$flash_bar"
    printf '  static RAM %6d B  (%s)\n' "$ram" "$(kib "$ram")"

    local stack_report stack
    if [ -n "$vectors" ]; then
        stack_report="$(python3 scripts/stack-estimate.py "$elf" --vector-table "$vectors" \
            --indirect 'Executor::run=TaskStorage')"
        echo "$stack_report" | sed 's/^/  /' | cut -c1-220
        stack="$(awk '/^worst-case stack:/ { print $3 }' <<<"$stack_report")"
    else
        # stack-estimate.py reads thumb code only: the BMCU-C's stack is measured by the
        # firmware-in-the-loop bench (its painted high-water mark), not estimated here.
        echo "  stack: not estimated for RISC-V; \`mmu fil --board bmcu\` measures its high-water mark"
        stack=0
    fi
    printf "  static RAM + stack %6d B  (%s, %s of the chip's %d B of RAM: %s)\\n" "$((ram + stack))" \
        "$(kib "$((ram + stack))")" "$(percent "$((ram + stack))" "$ram_total")" "$ram_total" \
        "$([ $((ram + stack)) -le "$ram_total" ] && echo within || echo over)"

    # The largest contributors, by crate and by symbol. `sed -n 1,Np`, not `head`: head exits
    # early and, under pipefail, sort's SIGPIPE fails the run.
    local symbols
    symbols="$("$nm_tool" --size-sort -S -C "$elf")"
    echo "  flash by crate (code and read-only data, B):"
    while read -r _ size type name; do
        case "$type" in t|T|r|R) ;; *) continue ;; esac
        crate="${name#<}"; crate="${crate#_<}"; crate="${crate%%::*}"; crate="${crate%% *}"
        case "$crate" in _*|"") crate="(runtime, compiler-builtins, linker)";; esac
        echo "$((16#$size)) $crate"
    done <<<"$symbols" | awk '{ s[$2] += $1 } END { for (c in s) printf "%8d  %s\n", s[c], c }' | sort -n -r | sed -n 1,12p
    echo "  largest flash symbols:"
    while read -r _ size type name; do
        case "$type" in t|T|r|R) printf '%8d  %.100s\n' "$((16#$size))" "$name" ;; esac
    done <<<"$symbols" | sort -n -r | sed -n "1,${TOP}p"
    echo "  largest RAM symbols:"
    while read -r _ size type name; do
        case "$type" in d|D|b|B) printf '%8d  %.100s\n' "$((16#$size))" "$name" ;; esac
    done <<<"$symbols" | sort -n -r | sed -n "1,8p"

    if [ "$flash" -gt "$flash_bar" ]; then
        echo "firmware-size: FAIL: $board flash $flash B is over the $flash_bar B bar" >&2
        status=1
    fi
    if [ "$((ram + stack))" -gt "$ram_total" ]; then
        echo "firmware-size: FAIL: $board static RAM $ram B + stack $stack B is over the $ram_total B of RAM" >&2
        status=1
    fi
    summary="$summary$(printf '\n  %-8s flash %6d B (%s), static RAM %6d B, stack (estimate) %6d B' \
        "$board" "$flash" "$(kib "$flash")" "$ram" "$stack")"
    bars="$bars${bars:+; }$board flash <= $flash_bar B, static RAM + stack <= $ram_total B"
}

boards=("$@")
[ "${#boards[@]}" -gt 0 ] || boards=(g071 pico)
for board in "${boards[@]}"; do
    report "$board"
done
echo
echo "firmware-size:$summary"
[ "$status" -eq 0 ] && echo "firmware-size: OK ($bars)"
exit "$status"
