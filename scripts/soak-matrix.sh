#!/usr/bin/env bash
# The soak matrix: every hardware profile x 3 printers x 1/3/5 slots (1/3/4 on the bmcu-c) x
# seeds 1-SEEDS (x extruder geometries, when asked), CHANGES tool changes each with FAULTS faults,
# on the simulator. Prints one line
# per failing run (with the run's first notes: the change, its fault, the errors, how it ended)
# and a total line; exits non-zero when any run failed.
#   bash scripts/soak-matrix.sh [CHANGES]
#   bash scripts/soak-matrix.sh [--changes N] [--seeds N] [--faults random|power-loss|spool-ends]
#                               [--hardware LIST] [--printers LIST] [--extruders LIST]
#                               [--jobs N] [--all]
# Defaults: 100 changes, seeds 1-10, random faults, every profile, every printer, each printer's
# own extruder geometry (`--extruders sensor-first,gears-first`: both), one job, only the failing
# runs shown (--all: one line a run). LIST is comma-separated (`--hardware thesis`).
# The binary is built into $CARGO_TARGET_DIR (or ./target) with `cargo build --release`.
set -euo pipefail
cd "$(dirname "$0")/.."
changes=100 seeds=10 faults=random jobs=1 all=0
hardware_list=thesis,n20-quadrature,bmcu-c printer_list=buddy-6.5,buddy-6.4,mk3s extruder_list=own
while [ $# -gt 0 ]; do
  case $1 in
    --changes) changes=$2; shift 2 ;;
    --seeds) seeds=$2; shift 2 ;;
    --faults) faults=$2; shift 2 ;;
    --hardware) hardware_list=$2; shift 2 ;;
    --printers) printer_list=$2; shift 2 ;;
    --extruders) extruder_list=$2; shift 2 ;;
    --jobs) jobs=$2; shift 2 ;;
    --all) all=1; shift ;;
    [0-9]*) changes=$1; shift ;;
    *) echo "soak-matrix: unknown argument $1 (see the head of $0)" >&2; exit 2 ;;
  esac
done
cargo build --release -q -p mmu-host
export MMU="${CARGO_TARGET_DIR:-target}/release/mmu"
out_dir=$(mktemp -d)
trap 'rm -rf "$out_dir"' EXIT
export out_dir changes faults

# One run: its output in $out_dir/<n>.out, its exit status in $out_dir/<n>.rc.
run_one() {
  local n=$1 hardware=$2 printer=$3 extruder=$4 slots=$5 seed=$6 rc=0 geometry=()
  [ "$extruder" = own ] || geometry=(--extruder "$extruder")
  "$MMU" printer --sim --hardware "$hardware" --printer "$printer" "${geometry[@]}" --slots "$slots" \
    soak --changes "$changes" --faults "$faults" --seed "$seed" >"$out_dir/$n.out" 2>&1 || rc=$?
  echo "$rc" >"$out_dir/$n.rc"
}
export -f run_one

runs=0
for hardware in ${hardware_list//,/ }; do
  case $hardware in bmcu-c) most=4 ;; *) most=5 ;; esac
  for printer in ${printer_list//,/ }; do
    for extruder in ${extruder_list//,/ }; do
      for slots in 1 3 $most; do
        for seed in $(seq 1 "$seeds"); do
          runs=$((runs + 1))
          echo "$runs $hardware $printer $extruder $slots $seed"
        done
      done
    done
  done
done >"$out_dir/runs"
start=$SECONDS
xargs -P "$jobs" -L 1 bash -c 'run_one "$@"' _ <"$out_dir/runs"

failed=0
while read -r n hardware printer extruder slots seed; do
  rc=$(cat "$out_dir/$n.rc")
  summary=$(grep -m1 '^soak:' "$out_dir/$n.out" || head -n1 "$out_dir/$n.out")
  if [ "$rc" -ne 0 ]; then
    failed=$((failed + 1))
    echo "FAILED $hardware $printer ($extruder extruder) $slots slots seed $seed (exit $rc): $summary"
    { grep -E '^ *change [0-9]+' "$out_dir/$n.out" || true; } | head -3 | sed 's/^ */    /'
  elif [ "$all" -eq 1 ]; then
    echo "ok $hardware $printer ($extruder extruder) $slots slots seed $seed: $summary"
  fi
done <"$out_dir/runs"
echo "soak matrix: $runs runs of $changes changes ($faults faults), $failed failed, $((SECONDS - start)) s"
[ "$failed" -eq 0 ]
