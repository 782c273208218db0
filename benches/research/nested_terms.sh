#!/usr/bin/env bash
# Time of `ctsid simulate` on a model whose named term nests 30 `sin` over a product of 30
# factors (the ninth bad-input reading's 523-byte model), for each binary given, and the ratio of
# the first to each other: the cost of evaluating a named term's derivatives (docs/method/
# simulation.md, "Expression terms as one program"). Build the binary before the change with
#   git worktree add /tmp/ctsid-old 059cef0 && cargo build --release --manifest-path /tmp/ctsid-old/Cargo.toml
#
#   benches/research/nested_terms.sh OLD_BIN NEW_BIN
set -euo pipefail
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
prod=$(printf '(y+u)*%.0s' $(seq 29))'(y+u)'
expr="$(printf 'sin(%.0s' $(seq 30))${prod}$(printf ')%.0s' $(seq 30))"
cat >"$dir/model.json" <<JSON
{"format": "ctsid-model/2", "tau": 0.01, "inputs": ["u"], "outputs": [{"name": "y", "order": 1, "terms": [{"exponents": {"y": 1}, "coefficient": -2.0}, {"exponents": {"u": 1}, "coefficient": 3.0}, {"expression": "$expr", "coefficient": 0.1}]}]}
JSON
# Six runs of 300 samples: an input up to 1.5 (where (y+u)^30 is far beyond 1 and the term makes
# the model stiff, as the reading's record did) and the output of y' = -2 y + 3 u from 0.006.
awk 'BEGIN { print "run,t,u,y"; for (r = 0; r < 6; r++) { y = 0.006;
  for (k = 0; k < 300; k++) { t = k * 0.01; u = 1.5 * sin(2 * 3.14159 * (0.7 + 0.2 * r) * t);
    printf "%d,%.2f,%.6f,%.6f\n", r, t, u, y; y += 0.01 * (-2 * y + 3 * u) } } }' >"$dir/data.csv"
first=""
for bin in "$@"; do
    start=$(date +%s.%N)
    if "$bin" simulate "$dir/model.json" "$dir/data.csv" >/dev/null 2>"$dir/err"; then
        outcome="simulated"
    else
        outcome=$(head -c 160 "$dir/err")
    fi
    secs=$(echo "$(date +%s.%N) - $start" | bc)
    [ -z "$first" ] && first=$secs
    printf '%s: %.2f s (%.1fx the first) — %s\n' "$bin" "$secs" "$(echo "$first / $secs" | bc -l)" "$outcome"
done
