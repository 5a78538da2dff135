#!/usr/bin/env bash
# Checks that the wiring table (book/src/firmware.md) matches the pin map in src/board.rs (the single source of
# truth): every pin of the map is in the table with the same function and header, and the table
# names no pin the map does not use.
#
#   scripts/check-pinmap.sh [Markdown files...]   (default: book/src/firmware.md, README.md, README-firmware-section.md)
#
# A wiring-table row is a Markdown table row whose first cell is a pin name (`| PC6 | ...`), with
# the columns: pin | header | function | connect to.
set -euo pipefail
cd "$(dirname "$0")/.."

if [ "$#" -eq 0 ]; then
    set -- book/src/firmware.md README.md README-firmware-section.md
fi

# board.rs rows: `field: PIN, "function", "header", "wired to", safe;` -> "PIN|header|function"
map="$(sed -n -E 's/^[[:space:]]+[a-z0-9_]+:[[:space:]]+(P[A-F][0-9]+),[[:space:]]*"([^"]*)",[[:space:]]*"([^"]*)",.*$/\1|\3|\2/p' src/board.rs | sort)"
if [ -z "$map" ]; then
    echo "check-pinmap: no pin rows found in src/board.rs" >&2
    exit 1
fi

status=0
checked=0
for readme in "$@"; do
    [ -f "$readme" ] || continue
    table="$(sed -n -E 's/^\|[[:space:]]*(P[A-F][0-9]+)[[:space:]]*\|[[:space:]]*([^|]*[^|[:space:]])[[:space:]]*\|[[:space:]]*([^|]*[^|[:space:]])[[:space:]]*\|.*$/\1|\2|\3/p' "$readme" | sort)"
    [ -n "$table" ] || continue
    checked=$((checked + 1))
    if [ "$map" != "$table" ]; then
        echo "check-pinmap: the wiring table in $readme differs from src/board.rs (< board.rs, > $readme):" >&2
        diff <(echo "$map") <(echo "$table") >&2 || true
        status=1
    else
        echo "check-pinmap: $readme matches src/board.rs ($(wc -l <<<"$map") pins)"
    fi
done

if [ "$checked" -eq 0 ]; then
    echo "check-pinmap: no wiring table found in: $*" >&2
    exit 1
fi
exit "$status"
