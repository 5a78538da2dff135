#!/usr/bin/env bash
# The soak matrix of every hardware profile: 3 printers x 1/3/5 slots (1/3/4 on the bmcu-c) x
# seeds 1-10, CHANGES tool changes each (default 100) with random faults, on the simulator.
# Prints one line a run and the totals; exits non-zero when any run failed.
#   bash scripts/soak-matrix.sh [CHANGES]
set -euo pipefail
cd "$(dirname "$0")/.."
changes="${1:-100}"
cargo build --release -q -p mmu-host
mmu=./target/release/mmu
runs=0 failed=0
for hardware in thesis n20-quadrature bmcu-c; do
  case $hardware in bmcu-c) most=4 ;; *) most=5 ;; esac
  for printer in buddy-6.5 buddy-6.4 mk3s; do
    for slots in 1 3 $most; do
      for seed in 1 2 3 4 5 6 7 8 9 10; do
        runs=$((runs + 1))
        if out=$($mmu printer --sim --hardware $hardware --printer $printer --slots $slots \
            soak --changes "$changes" --faults random --seed $seed 2>&1); then
          echo "$hardware $printer $slots slots seed $seed: $(grep '^soak:' <<<"$out")"
        else
          failed=$((failed + 1))
          echo "$hardware $printer $slots slots seed $seed: FAILED"
          grep -E '^(soak|change) ' <<<"$out" | head -4
        fi
      done
    done
  done
done
echo "soak matrix: $runs runs of $changes changes, $failed failed"
[ "$failed" -eq 0 ]
