#!/usr/bin/env bash
# Checks that the wiring tables in the docs match the boards' pin maps (the single sources of
# truth): src/board/g071/mod.rs (pins PA0..PF15, tables whose rows start `| PC6 |`; its first
# `pin_map!` is the `g071` build's, its second the `g071-n20` build's) and src/board/pico/mod.rs
# (PIN_n, tables whose rows start `| GP6 |`). Every pin of a map is in a table with the same
# function and header pin, and the tables name no pin the map does not use.
#
#   scripts/check-pinmap.sh [doc files...]   (default: book/src/firmware.md, the book's wiring page)
#
# A wiring-table row is a Markdown table row whose first cell is a pin name, with the columns:
# pin | header (NUCLEO header / Pico pin) | function | connect to. A table of a variant build is
# marked by a line `<!-- pin map: g071-n20 -->` before it (up to the next blank line after its
# rows); unmarked tables are the boards' main builds.
set -euo pipefail
cd "$(dirname "$0")/.."

if [ "$#" -eq 0 ]; then
    set -- book/src/firmware.md
fi

# Map rows of the file's `$3`-th `pin_map!` (1: the first):
# `field: PIN, "function", "header", "wired to", safe;` -> "PIN|header|function"
map_rows() {
    awk -v want="$3" '/^[[:space:]]*pin_map! \{/ { block++ } block == want' "$1" \
        | sed -n -E 's/^[[:space:]]+[a-z0-9_]+:[[:space:]]+('"$2"'),[[:space:]]*"([^"]*)",[[:space:]]*"([^"]*)",.*$/\1|\3|\2/p' \
        | sed -E 's/^PIN_([0-9]+)\|/GP\1|/' | sort
}
# Doc rows of the tables marked `<!-- pin map: $2 -->` (an empty $2: the unmarked tables) whose
# first cell matches the pin pattern -> "PIN|header|function"
doc_rows() {
    cat "${@:3}" 2>/dev/null \
        | awk -v want="$2" '
            /^<!-- pin map: [a-z0-9-]+ -->/ { label = $4; rows = 0; next }
            /^\|/ { rows = 1; if (label == want) print; next }
            /^[[:space:]]*$/ { if (rows) { label = ""; rows = 0 } }' \
        | sed -n -E 's/^\|[[:space:]]*('"$1"')[[:space:]]*\|[[:space:]]*([^|]*[^|[:space:]])[[:space:]]*\|[[:space:]]*([^|]*[^|[:space:]])[[:space:]]*\|.*$/\1|\2|\3/p' | sort
}

status=0
check() {
    local board="$1" source="$2" block="$3" label="$4" map_pattern="$5" doc_pattern="$6"
    shift 6
    local map table
    map="$(map_rows "$source" "$map_pattern" "$block")"
    if [ -z "$map" ]; then
        echo "check-pinmap: no pin rows found in $source" >&2
        status=1
        return
    fi
    local docs=()
    for doc in "$@"; do [ -f "$doc" ] && docs+=("$doc"); done
    table="$(doc_rows "$doc_pattern" "$label" "${docs[@]}")"
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

check g071 src/board/g071/mod.rs 1 '' 'P[A-F][0-9]+' 'P[A-F][0-9]+' "$@"
check g071-n20 src/board/g071/mod.rs 2 g071-n20 'P[A-F][0-9]+' 'P[A-F][0-9]+' "$@"
check pico src/board/pico/mod.rs 1 '' 'PIN_[0-9]+' 'GP[0-9]+' "$@"
exit "$status"
