#!/usr/bin/env bash
# Checks that the wiring tables in the docs match the boards' pin maps (the single sources of
# truth): src/board/g071/mod.rs (pins PA0..PF15, tables whose rows start `| PC6 |`) and
# src/board/pico/mod.rs (PIN_n, tables whose rows start `| GP6 |`). Every pin of a map is in a
# table with the same function and header pin, and the tables name no pin the map does not use.
#
#   scripts/check-pinmap.sh [doc files...]   (default: book/src/firmware.md, the book's wiring page)
#
# A wiring-table row is a Markdown table row whose first cell is a pin name, with the columns:
# pin | header (NUCLEO header / Pico pin) | function | connect to.
set -euo pipefail
cd "$(dirname "$0")/.."

if [ "$#" -eq 0 ]; then
    set -- book/src/firmware.md
fi

# Map rows: `field: PIN, "function", "header", "wired to", safe;` -> "PIN|header|function"
map_rows() {
    sed -n -E 's/^[[:space:]]+[a-z0-9_]+:[[:space:]]+('"$2"'),[[:space:]]*"([^"]*)",[[:space:]]*"([^"]*)",.*$/\1|\3|\2/p' "$1" \
        | sed -E 's/^PIN_([0-9]+)\|/GP\1|/' | sort
}
# Doc rows whose first cell matches the pin pattern -> "PIN|header|function"
doc_rows() {
    cat "${@:2}" 2>/dev/null | sed -n -E 's/^\|[[:space:]]*('"$1"')[[:space:]]*\|[[:space:]]*([^|]*[^|[:space:]])[[:space:]]*\|[[:space:]]*([^|]*[^|[:space:]])[[:space:]]*\|.*$/\1|\2|\3/p' | sort
}

status=0
check() {
    local board="$1" source="$2" map_pattern="$3" doc_pattern="$4"
    shift 4
    local map table
    map="$(map_rows "$source" "$map_pattern")"
    if [ -z "$map" ]; then
        echo "check-pinmap: no pin rows found in $source" >&2
        status=1
        return
    fi
    local docs=()
    for doc in "$@"; do [ -f "$doc" ] && docs+=("$doc"); done
    table="$(doc_rows "$doc_pattern" "${docs[@]}")"
    if [ -z "$table" ]; then
        echo "check-pinmap: no $board wiring table found in: $*" >&2
        status=1
    elif [ "$map" != "$table" ]; then
        echo "check-pinmap: the $board wiring table differs from $source (< map, > docs):" >&2
        diff <(echo "$map") <(echo "$table") >&2 || true
        status=1
    else
        echo "check-pinmap: the $board wiring table matches $source ($(wc -l <<<"$map") pins)"
    fi
}

check g071 src/board/g071/mod.rs 'P[A-F][0-9]+' 'P[A-F][0-9]+' "$@"
check pico src/board/pico/mod.rs 'PIN_[0-9]+' 'GP[0-9]+' "$@"
exit "$status"
