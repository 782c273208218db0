# Output-error fit of the EMPS physics outside ctsid (docs/benchmarks.md): q'' = -a q' + b F
# - c tanh(q'/W) + d (+ e |q'| + f q), trained on DATA_EMPS, scored on the pulses record.
#   target/sklearn-venv/bin/python benches/research/emps_oe.py MASK [W]
# MASK: which of a b c d e f are free (111100 = the published physics).
import numpy as np, sys
from scipy.optimize import least_squares
from scipy.interpolate import CubicSpline
def load(p):
    d = np.genfromtxt(p, delimiter=',', names=True); return d['q_m'], d['force_N']
qt, Ft = load('../shared/data/emps/EMPS_train_DATA_EMPS.csv')
qv, Fv = load('../shared/data/emps/EMPS_test_DATA_EMPS_PULSES.csv')
h = 1e-3; W = float(sys.argv[2]) if len(sys.argv)>2 else 1e-3
names = ['a','b','c','d','e','f']  # q''= -a*10 q' + b*1e-2 F - c*0.1 sgn(q') + d*0.1 + e*0.1*|q'|... 
def sim(th, F, q0, v0, mask):
    a,b,c,d,e,f = [float(x) for x in th]
    a*=1; b*=1e-2; c*=0.1; d*=0.01; e*=1; f*=1
    Fl = F.tolist(); n = len(Fl); q=q0; v=v0; out=[0.0]*n; out[0]=q
    tanh = np.tanh
    import math
    def acc(q, v, u):
        s = math.tanh(v/W)
        return -a*v + b*u - c*s + d + e*abs(v) + f*q
    for k in range(n-1):
        u0 = Fl[k]; u1 = Fl[k+1]; um = 0.5*(u0+u1)
        k1q=v; k1v=acc(q,v,u0)
        k2q=v+h/2*k1v; k2v=acc(q+h/2*k1q, v+h/2*k1v, um)
        k3q=v+h/2*k2v; k3v=acc(q+h/2*k2q, v+h/2*k2v, um)
        k4q=v+h*k3v; k4v=acc(q+h*k3q, v+h*k3v, u1)
        q += h/6*(k1q+2*k2q+2*k3q+k4q); v += h/6*(k1v+2*k2v+2*k3v+k4v)
        out[k+1]=q
    return np.array(out)
mask = np.array([int(c) for c in sys.argv[1]], bool)
th0 = np.array([203.5/95.1, 1/95.1*100, 20.39/95.1*10, -3.16/95.1*100*-1, 0.0, 0.0])
def res(p):
    th = th0.copy(); th[mask] = p
    return sim(th, Ft, qt[0], 0.0, mask) - qt
r = least_squares(res, th0[mask], x_scale='jac', diff_step=1e-5, max_nfev=100)
th = th0.copy(); th[mask] = r.x
v0 = (qv[20]-qv[0])/0.02
s = sim(th, Fv, qv[0], (qv[2]-qv[0])/(2*h), mask)
print(sys.argv[1], 'W', W, 'train rms mm %.3f' % (1e3*np.sqrt(np.mean(r.fun**2))), 'test rms mm %.3f' % (1e3*np.sqrt(np.mean((s-qv)[20:]**2))), 'theta', np.round(th,4))
d = np.genfromtxt('../shared/data/emps/EMPS_test_DATA_EMPS_PULSES.csv', delimiter=',', names=True)
for sgn in [1, -1]:
    s2 = sim(th, Fv + sgn*d['pulses_N'], qv[0], (qv[2]-qv[0])/(2*h), mask)
    print('  with pulses x%d: test rms mm %.3f' % (sgn, 1e3*np.sqrt(np.mean((s2-qv)[20:]**2))), 'pulse rms N %.2f, force rms %.2f' % (np.sqrt(np.mean(d['pulses_N']**2)), np.sqrt(np.mean(Fv**2))))
