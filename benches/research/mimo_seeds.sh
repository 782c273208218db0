#!/usr/bin/env bash
# How often `ctsid demo mimo` gets the orders and terms right over seeds: many runs at once on a
# machine with more cores (each run gets RAYON_NUM_THREADS=2, as on the 2-core build machine).
#
#   benches/research/mimo_seeds.sh OUTDIR "BIN..." "SEED..." "DEGREE:NOISE..." [JOBS]
#
# e.g. benches/research/mimo_seeds.sh /tmp/seeds "target/release/ctsid" "1 2 3" "6:0.01 6:0.03" 8
# Each run's output goes to OUTDIR/<bin name>_d<D>_n<NOISE>_s<SEED>.txt; the last lines print one
# summary row per run (orders, true / extra terms, NRMSE against truth, time). Correctness only:
# runs that share a machine do not time like the 2-core machine (docs/method/identification.md).
set -euo pipefail
out=$1; bins=$2; seeds=$3; cases=$4; jobs=${5:-8}
mkdir -p "$out"
list=()
for c in $cases; do for s in $seeds; do for b in $bins; do list+=("$b $c $s"); done; done; done
run_one() {
    local b=$1 c=$2 s=$3 out=$4
    local d=${c%%:*} n=${c##*:}
    local f="$out/$(basename "$b")_d${d}_n${n}_s${s}.txt"
    RAYON_NUM_THREADS=2 "$b" demo mimo --degrees "$d" --noise "$n" --seed "$s" --quiet >"$f" 2>&1 || echo "exit $?" >>"$f"
}
export -f run_one
printf '%s\n' "${list[@]}" | xargs -P "$jobs" -I{} bash -c 'run_one {} '"$out"
for f in "$out"/*.txt; do
    row=$(grep -E '^\| [0-9]+ \| [0-9]+ \|' "$f" | head -1 | awk -F'|' '{print $5 "|" $6 "|" $7 "|" $8 "|" $10}')
    echo "$(basename "$f" .txt) |$row"
done
