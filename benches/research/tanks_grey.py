# Two-tank grey box of the cascaded tanks outside ctsid (docs/benchmarks.md): x1' = -k1 sqrt(x1) + k4 u,
# x2' = k2 sqrt(x1) - k3 sqrt(x2), y = x2 + offset; "over" adds the upper tank's overflow (x1 held at
# x1max, a share of the excess flowing into the lower tank). Output-error fit (scipy, RK4 at Ts/8,
# zero-order-hold input) on the estimation record; the test record from the same initial state.
# "both" also holds the lower tank at the level the record shows as 10 V (its overflow: x2' at
# most 0 there, session 27).
#   python benches/research/tanks_grey.py plain|over|both
import numpy as np, sys
from scipy.optimize import least_squares
def load(p):
    d = np.genfromtxt(p, delimiter=',', names=True); return d['y_V'], d['u_V']
import os; D=os.path.join(os.path.dirname(os.path.abspath(__file__)),"../../../shared/data/cascaded_tanks/")
ye, ue = load(D+'cascaded_tanks_estimation.csv'); yt, ut = load(D+'cascaded_tanks_test.csv')
Ts=4.0; SUB=8; h=Ts/SUB
mode=sys.argv[1]
def rhs(x, u, p):
    k1,k2,k3,k4,x1max,off = p[:6]
    x1=max(x[0],0.0); x2=max(x[1],0.0)
    d1 = -k1*np.sqrt(x1) + k4*u
    over = 0.0
    if mode!='plain' and x1>=x1max and d1>0: over=d1; d1=0.0
    d2 = k2*np.sqrt(x1) - k3*np.sqrt(x2)
    if mode!='plain': d2 += p[6]*over
    if mode=='both' and x2>=10.0-off and d2>0: d2=0.0
    return np.array([d1,d2])
def sim(p, u, x0):
    x=np.array(x0,float); out=np.empty(len(u)); out[0]=x[1]+p[5]
    for k in range(len(u)-1):
        uu=u[k]  # zero-order hold
        for s in range(SUB):
            a=rhs(x,uu,p); b=rhs(x+h/2*a,uu,p); c=rhs(x+h/2*b,uu,p); d=rhs(x+h*c,uu,p)
            x=x+h/6*(a+2*b+2*c+d)
            if mode=='both': x[1]=min(x[1],10.0-p[5])
        out[k+1]=x[1]+p[5]
    return out
npar = 6 if mode=='plain' else 7
def res(q):
    p=q[:npar]; x0=q[npar:]
    return sim(p,ue,x0)-ye
p0=[0.05,0.05,0.05,0.03,10.0,0.0] + ([] if mode=='plain' else [0.5])
q0=np.array(p0+[5.0, ye[0]])
lo=[0,0,0,0,0.5,-5]+([] if mode=='plain' else [0])+[0,0]; hi=[5,5,5,5,100,5]+([] if mode=='plain' else [1])+[100,100]
r=least_squares(res,q0,bounds=(lo,hi),x_scale='jac',max_nfev=400)
q=r.x; p=q[:npar]
st=sim(p,ut,q[npar:])   # same initial state for both records (README)
print(mode,'est rms %.3f'%np.sqrt(np.mean(r.fun**2)),'test rms %.3f'%np.sqrt(np.mean((st-yt)[5:]**2)), np.round(q,4).tolist())
