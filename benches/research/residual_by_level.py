# A free run's error binned by the measured level (docs/benchmarks.md, the tanks' residual):
# the CSV that `ctsid simulate MODEL DATA --init-window 5 --score-from 5 -o SIM.csv` writes.
#   target/sklearn-venv/bin/python benches/research/residual_by_level.py SIM.csv y_V 5
import numpy as np, sys
path, out, skip = sys.argv[1], sys.argv[2], int(sys.argv[3])
d = np.genfromtxt(path, delimiter=',', names=True)
y = d[out][skip:]; e = d[out + '_sim'][skip:] - y
print('all: RMS %.4f over %d samples' % (np.sqrt(np.mean(e ** 2)), len(e)))
for lo, hi in [(-np.inf, 3), (3, 5), (5, 7), (7, 9), (9, np.inf)]:
    m = (y >= lo) & (y < hi)
    if m.any():
        print('level [%g, %g): %d samples, RMS %.2f, mean %.2f' % (lo, hi, m.sum(), np.sqrt(np.mean(e[m] ** 2)), e[m].mean()))
n = len(e)
print('last eighth: RMS %.3f' % np.sqrt(np.mean(e[7 * n // 8:] ** 2)))
