"""scikit-learn's `lars_path` on the problem `cpu_report` writes (run by benches/cpu_report.sh).

Reads DIR/problem.json (sizes), DIR/z.f64 (samples x variables, row-major), DIR/exps.u8
(candidates x variables, the basis's exponents in basis order) and DIR/y.f64; builds every
non-constant candidate column, centred and scaled to unit norm as ctsid's path standardises
them, centres y, and times `lars_path(X, y, method="lar", max_iter=STEPS)` REPS times.
Prints one line: `seconds t1 t2 ...` and one line `order j1 j2 ...` (basis indices in the order
they entered, for the caller to compare with ctsid's). Building X is not timed.
"""

import json
import sys
import time

import numpy as np
from sklearn.linear_model import lars_path


def main():
    d = sys.argv[1]
    reps = int(sys.argv[2])
    meta = json.load(open(f"{d}/problem.json"))
    n, nz, nc, steps = meta["samples"], meta["vars"], meta["candidates"], meta["steps"]
    z = np.fromfile(f"{d}/z.f64", dtype=np.float64).reshape(n, nz)
    e = np.fromfile(f"{d}/exps.u8", dtype=np.uint8).reshape(nc, nz)
    y = np.fromfile(f"{d}/y.f64", dtype=np.float64)
    # Column 0 is the constant monomial: ctsid never offers it to the path.
    ids = np.arange(1, nc)
    x = np.empty((n, ids.size), order="F")
    for start in range(0, ids.size, 256):
        chunk = ids[start : start + 256]
        block = np.ones((n, chunk.size))
        for k in range(nz):
            p = e[chunk, k].astype(np.int64)
            if p.any():
                block *= z[:, k : k + 1] ** p[None, :]
        block -= block.mean(axis=0)
        block /= np.linalg.norm(block, axis=0)
        x[:, start : start + chunk.size] = block
    yc = y - y.mean()
    times = []
    active = None
    for _ in range(reps):
        t = time.perf_counter()
        _, active, _ = lars_path(x, yc, method="lar", max_iter=steps)
        times.append(time.perf_counter() - t)
    print("seconds " + " ".join(f"{t:.4f}" for t in times))
    print("order " + " ".join(str(int(ids[j])) for j in active))


if __name__ == "__main__":
    main()
