#!/usr/bin/env bash
# Each dictionary term and degree-3 monomial appended by hand to a tanks model file (a small
# coefficient: a zero one stays zero in the refit's scaling), refitted on the benchmark's training
# run and scored (docs/benchmarks.md, "The second look admits what simplify would keep"):
#   bash benches/research/tanks_terms.sh DIR/tanks.model.json
# prints per term the test record RMS, the validation NRMSE and the term's standard errors.
set -euo pipefail
cd "$(dirname "$0")/../.."
model=$1
cargo bench --bench bench_refit --no-run -q 2>/dev/null
bin=$(ls -t target/release/deps/bench_refit-* | grep -v '\.d$' | head -1)
tmp=$(mktemp -d)
for term in 'E:sqrt(abs(y_V))' 'E:y_V_d1/sqrt(abs(y_V)+0.1)' 'E:u_V/sqrt(abs(y_V)+0.1)' \
    'E:tanh(y_V_d1/0.01)' 'M:y_V=2' 'M:u_V=2' 'M:y_V=1,u_V=1' 'M:u_V=2,y_V=1' 'M:y_V_d1=2' \
    'M:u_V=1,y_V_d1=1' 'M:y_V=1,y_V_d1=1' 'M:u_V=3' 'M:u_V=2,y_V=2' 'M:y_V=3'; do
    # Exits 1 for a term the model already has.
    python3 - "$model" "$term" "$tmp/plus.json" <<'PY' || continue
import json, sys
model, term, out = sys.argv[1:4]
kind, spec = term.split(':', 1)
m = json.load(open(model))
if kind == 'E':
    t = {'expression': spec, 'coefficient': 1e-6}
else:
    t = {'exponents': {k: int(v) for k, v in (p.split('=') for p in spec.split(','))}, 'coefficient': 1e-7}
names = [t2.get('expression') or json.dumps(t2.get('exponents'), sort_keys=True) for t2 in m['outputs'][0]['terms']]
if (t.get('expression') or json.dumps(t.get('exponents'), sort_keys=True)) in names:
    sys.exit(1)
m['outputs'][0]['terms'].append(t)
m['degree'] = max(m.get('degree', 1), 4)
json.dump(m, open(out, 'w'))
PY
    echo "$term: $("$bin" tanks "$tmp/plus.json" 2>&1 | grep -E '^train tol 1e-7' | head -1)"
done
rm -rf "$tmp"
