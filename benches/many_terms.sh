#!/usr/bin/env bash
# The adversarial pass's "model too big to simulate" case: 3 outputs of order 2, every monomial
# of degree 2 to 7 in the 6 states and 2 inputs (10,659 terms, small coefficients), simulated on
# 1,000 samples with its initial-state fit. Prints the wall-clock time of `ctsid simulate`.
# Run from the repository root: bash benches/many_terms.sh
set -euo pipefail
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
cargo build --release --quiet
python3 - "$dir" <<'PY'
import itertools, json, math, sys
d = sys.argv[1]
v = ["y0", "y0_d1", "y1", "y1_d1", "y2", "y2_d1", "u1", "u2"]
monos = []
for deg in range(2, 8):
    for combo in itertools.combinations_with_replacement(range(len(v)), deg):
        e = {}
        for c in combo:
            e[v[c]] = e.get(v[c], 0) + 1
        monos.append(e)
outs = []
for i in range(3):
    y = f"y{i}"
    terms = [{"exponents": {y: 1}, "coefficient": -1.0},
             {"exponents": {f"{y}_d1": 1}, "coefficient": -2.0},
             {"exponents": {"u1": 1}, "coefficient": 1.0}]
    terms += [{"exponents": e, "coefficient": 1e-5 if j % 2 == 0 else -1e-5}
              for j, e in enumerate(monos[:3550])]
    outs.append({"name": y, "order": 2, "terms": terms})
json.dump({"format": "ctsid-model/2", "inputs": ["u1", "u2"], "outputs": outs},
          open(f"{d}/big.json", "w"))
with open(f"{d}/big.csv", "w") as f:
    f.write("t,y0,y1,y2,u1,u2\n")
    for k in range(1000):
        t = k * 0.01
        f.write(f"{t},0,0,0,{math.sin(1.3*t)+0.3*math.sin(7*t)},{0.5*math.cos(2.1*t)}\n")
print(sum(len(o["terms"]) for o in outs), "terms")
PY
start=$(date +%s.%N)
./target/release/ctsid simulate "$dir/big.json" "$dir/big.csv" --time-column t > /dev/null
end=$(date +%s.%N)
echo "simulate: $(echo "$end - $start" | bc) s"
