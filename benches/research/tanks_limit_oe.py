# The cascaded tanks' lower-tank overflow outside ctsid (docs/benchmarks.md, "The lower tank's
# overflow"): an output-error fit of y'' = c0 + c1 y + c2 y' + c3 u (scipy, RK4 at a quarter
# sample, zero-order-hold input) on the first half of the estimation record (or the whole of it),
# the initial state of the test record fitted on its first 5 samples; what the 10 V the record
# holds is read as:
#   plain       nothing (a free level)
#   sensor      the simulated output clipped at 10 V, held samples out of the fit
#   state       the level held at 10 V with its velocity at most 0 (an overflow)
#   state_excl  the same, held samples out of the fit
#   target/sklearn-venv/bin/python benches/research/tanks_limit_oe.py MODE 512|1024
import numpy as np, sys, math, os
from scipy.optimize import least_squares
D = os.path.join(os.path.dirname(os.path.abspath(__file__)), "../../../shared/data/cascaded_tanks/")
def load(p):
    d = np.genfromtxt(D + p, delimiter=',', names=True); return d['y_V'], d['u_V']
ye, ue = load('cascaded_tanks_estimation.csv')
yt, ut = load('cascaded_tanks_test.csv')
Ts = 4.0; SUB = 4; h = Ts / SUB; YMAX = 10.0
mode = sys.argv[1]; ntrain = int(sys.argv[2])
clamp = mode in ('state', 'state_excl')
excl = mode in ('sensor', 'state_excl')
def sim(th, u, y0, v0):
    n = len(u); y = y0; v = v0; out = np.empty(n); out[0] = y; c0, c1, c2, c3 = th
    f = lambda y, v, uu: c0 + c1 * y + c2 * v + c3 * uu
    for k in range(n - 1):
        uu = u[k]
        for s in range(SUB):
            k1y = v; k1v = f(y, v, uu); k2y = v + h / 2 * k1v; k2v = f(y + h / 2 * k1y, v + h / 2 * k1v, uu)
            k3y = v + h / 2 * k2v; k3v = f(y + h / 2 * k2y, v + h / 2 * k2v, uu); k4y = v + h * k3v; k4v = f(y + h * k3y, v + h * k3v, uu)
            y += h / 6 * (k1y + 2 * k2y + 2 * k3y + k4y); v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
            if clamp and y > YMAX: y = YMAX; v = min(v, 0.0)
            if abs(y) > 100 or not math.isfinite(y): out[k + 1:] = 100; return out
        out[k + 1] = y
    return out
Y = ye[:ntrain]; U = ue[:ntrain]; w = np.ones(ntrain)
if excl: w[Y >= YMAX - 1e-9] = 0.0
def res(p):
    s = sim(p[:4], U, p[4], p[5])
    if mode == 'sensor': s = np.minimum(s, YMAX)
    return (s - Y) * w
r = least_squares(res, np.array([0, -1e-4, -1e-2, 3e-4, Y[0], 0.0]), x_scale='jac', diff_step=1e-6, max_nfev=400)
th = r.x[:4]
def from_5(u, y):
    q = least_squares(lambda q: sim(th, u[:5], q[0], q[1]) - y[:5], [y[0], (y[4] - y[0]) / 16], diff_step=1e-6).x
    return sim(th, u, q[0], q[1])
out = lambda s: np.minimum(s, YMAX) if mode == 'sensor' else s
val = '-'
if ntrain < len(ye):
    val = '%.3f' % np.sqrt(np.mean((out(from_5(ue[ntrain:], ye[ntrain:])) - ye[ntrain:]) ** 2))
st = out(from_5(ut, yt))
print(mode, ntrain, 'validation RMS', val, 'test RMS %.3f' % np.sqrt(np.mean((st - yt)[5:] ** 2)), np.round(th, 6).tolist())
