# Output-error fit of the Silverbox (Duffing) structure outside ctsid, to see how the input
# is read between samples (docs/benchmarks.md): RK4 at half a sample, scipy least squares.
# Usage, from the repository root (benches/cpu_report.sh makes the venv):
#   target/sklearn-venv/bin/python benches/research/silverbox_input_oe.py METHOD MASK END
# METHOD: linear | cubic | natural | cr | fft | zoh; MASK: which of a0 a1 a3 b c q e p are free
# (11111100 = Duffing + y^2; 11111110 adds y^2*y'); END: last training sample (57234 = two
# multisine periods, 105712 = all). Prints the training RMS and the arrow RMS (full, no extrapolation).
import numpy as np, sys, time
from scipy.optimize import least_squares
from scipy.interpolate import CubicSpline
d = np.genfromtxt('../shared/data/silverbox/SNLS80mV.csv', delimiter=',', names=True)
u = d['u_V']; y = d['y_V']; fs = 1e7/2**14; tau = 1/fs
SUB = 2
def upsample(u, method):
    n = len(u); t = np.arange(n); tf = np.arange((n-1)*2*SUB+1)/(2*SUB)
    if method == 'linear': return np.interp(tf, t, u)
    if method == 'cubic': return CubicSpline(t, u)(tf)
    if method == 'fft':
        U = np.fft.rfft(u); m = n*2*SUB
        Uf = np.zeros(m//2+1, complex); Uf[:len(U)] = U
        return (np.fft.irfft(Uf, m)*(2*SUB))[:len(tf)]
    if method == 'cr':
        up = np.concatenate([[u[0]], u, [u[-1]]]); i = np.minimum(np.floor(tf).astype(int), n-2); x = tf - i
        p0, p1, p2, p3 = up[i], up[i+1], up[i+2], up[i+3]
        return p1 + 0.5*x*(p2-p0 + x*(2*p0-5*p1+4*p2-p3 + x*(3*(p1-p2)+p3-p0)))
    if method == 'natural': return CubicSpline(t, u, bc_type='natural')(tf)
    if method == 'zoh': return u[np.minimum(np.floor(tf+1e-9).astype(int), n-1)]
def sim(th, uf, n, filt):
    a0,a1,a3,b,c,q,e,p = [float(v) for v in th]
    a0*=1e5; a1*=10; a3*=1e5; b*=1e5; c*=1e3; q*=1e4; e*=1e4; p*=1e3
    h = tau/SUB; yv=0.0; v=0.0; w=0.0; out = [0.0]*n
    ufl = uf.tolist()
    def f(y, v, w, u):
        return v, -a0*y - a1*v - a3*y*y*y + c + q*y*y + e*y*y*v + b*(w if filt else u), (p*(u-w) if filt else 0.0)
    for k in range(n-1):
        for s in range(SUB):
            i = 2*(k*SUB+s); u0=ufl[i]; u1=ufl[i+1]; u2=ufl[i+2]
            k1=f(yv,v,w,u0); k2=f(yv+h/2*k1[0],v+h/2*k1[1],w+h/2*k1[2],u1)
            k3=f(yv+h/2*k2[0],v+h/2*k2[1],w+h/2*k2[2],u1); k4=f(yv+h*k3[0],v+h*k3[1],w+h*k3[2],u2)
            yv+=h/6*(k1[0]+2*k2[0]+2*k3[0]+k4[0]); v+=h/6*(k1[1]+2*k2[1]+2*k3[1]+k4[1]); w+=h/6*(k1[2]+2*k2[2]+2*k3[2]+k4[2])
        if abs(yv)>5: return None
        out[k+1]=yv
    return np.array(out)
method = sys.argv[1]; mask = [int(c) for c in sys.argv[2]]  # which of a0..p are free
filt = mask[7]==1
uf_all = upsample(u, method)
# train: multisine segment 40650.. use 2 periods from 40650+100*? take 40750..57200
t0, t1 = 40650, int(sys.argv[3])
ut = uf_all[2*SUB*t0: 2*SUB*(t1-1)+1]; yt = y[t0:t1]
th0 = np.array([1.84,4.18,7.3,1.94,-1.0,0.0,0.0,5.0])
free = np.array(mask, bool)
def res(pf):
    th = th0.copy(); th[free] = pf
    s = sim(th, ut, t1-t0, filt)
    if s is None: return np.full(t1-t0-300, 1.0)
    return (s-yt)[300:]
t=time.time()
r = least_squares(res, th0[free], x_scale='jac', diff_step=1e-4, max_nfev=60)
th = th0.copy(); th[free] = r.x
print(method, sys.argv[2], 'train rms mV', 1e3*np.sqrt(np.mean(r.fun**2)), 'time', time.time()-t)
n = 40575
s = sim(th, uf_all[:2*SUB*(n-1)+1], n, filt)
e = (s-y[:n])
print('  arrow full mV %.3f  no-extrap %.3f' % (1e3*np.sqrt(np.mean(e[150:40575]**2)), 1e3*np.sqrt(np.mean(e[150:32100]**2))), 'theta', np.round(th,4))
