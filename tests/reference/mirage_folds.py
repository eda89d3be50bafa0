#!/usr/bin/env python3
# Independent reference for tests/integration/end_to_end.rs (check 3): pure-Python (no numpy),
# written separately from the Rust code. Usage: mirage_folds.py ATM h0_m D_m alpha_lo_deg alpha_hi_deg step_deg [ds_m]
# with ATM in inferior|superior|fata; prints h(D; alpha) samples and the golden-refined extrema.
# n - 1 (dry Ciddor 1996, 550 nm, 450 ppm) was also used for kappa(0) of data/novaya_zemlya.toml:
#   n = mk([], ramp=(0.0, 100.0, 0.1185)); -n(0)[1]/n(0)[0]*R = 1.00194
# Model: RK4 in arc length, polar coordinates; tanh step layers over -6.5 K/km from 0 C, 1013.25 hPa;
# hydrostatic P (Simpson, g = 9.80665, R_d = 287.05); Ciddor density with compressibility Z;
# dn/dh by central difference (1 mm).
import math, sys
R=6371000.0; g=9.80665; Rd=287.05
lam=0.55; s2=1/lam**2
nas=(5792105/(238.0185-s2)+167917/(57.362-s2))*1e-8
naxs=nas*(1+0.534e-6*(450-450))
Ma=0.0289635+1.2011e-8*(450-400); Rg=8.314510
def Z(p,T):
    t=T-273.15
    return 1-(p/T)*(1.58123e-6-2.9331e-8*t+1.1043e-10*t*t)+(p/T)**2*1.83e-11
def rho(p,T): return p*Ma/(Z(p,T)*Rg*T)
rho_axs=rho(101325.0,288.15)
def mk(layers, T0=273.15, lapse=-0.0065, ramp=None):
    def T(h):
        t=T0+lapse*h
        for (c,L,dT) in layers:
            t+=dT*0.5*(math.tanh((h-c)/(L/4))-math.tanh((0-c)/(L/4)))
        if ramp:
            a,b,gr=ramp; t+=gr*(min(max(h,a),b)-a)
        return t
    dz=0.02; N=int(600/dz); lnp=[math.log(101325.0)]
    for i in range(N):
        a=T(i*dz); b=T((i+1)*dz); m=T((i+0.5)*dz)
        lnp.append(lnp[-1]-g/Rd*(1/a+4/m+1/b)/6*dz)
    def nm1(h):
        i=min(int(h/dz),N-1); f=h/dz-i
        # quadratic-free: linear in ln p is fine at 2 cm spacing
        p=math.exp(lnp[i]*(1-f)+lnp[i+1]*f); t=T(h)
        return rho(p,t)/rho_axs*naxs
    def n(h):
        h=max(h,0.0); e=1e-3
        if h<e: d=(nm1(h+e)-nm1(h))/e
        else: d=(nm1(h+e)-nm1(h-e))/(2*e)
        return 1+nm1(h), d
    return n
def trace(n,h0,alpha,D,ds=1.0):
    r=R+h0; th=0.0; psi=alpha; px=0.0; ph=h0
    def f(r,psi):
        nn,dn=n(r-R); c=math.cos(psi)
        return math.sin(psi), c/r, c*(1/r+dn/nn)
    while True:
        k1=f(r,psi); k2=f(r+ds/2*k1[0],psi+ds/2*k1[2]); k3=f(r+ds/2*k2[0],psi+ds/2*k2[2]); k4=f(r+ds*k3[0],psi+ds*k3[2])
        r+=ds/6*(k1[0]+2*k2[0]+2*k3[0]+k4[0]); th+=ds/6*(k1[1]+2*k2[1]+2*k3[1]+k4[1]); psi+=ds/6*(k1[2]+2*k2[2]+2*k3[2]+k4[2])
        x=R*th; h=r-R
        if h<0: return float('nan')
        if x>=D: return ph+(h-ph)*(D-px)/(x-px)
        px,ph=x,h
def golden(fn,a,c,mx):
    s=-1 if mx else 1; r=(5**0.5-1)/2
    x1=c-r*(c-a); x2=a+r*(c-a); f1=s*fn(x1); f2=s*fn(x2)
    while c-a>2e-6:
        if f1<f2: c=x2; x2=x1; f2=f1; x1=c-r*(c-a); f1=s*fn(x1)
        else: a=x1; x1=x2; f1=f2; x2=a+r*(c-a); f2=s*fn(x2)
    return (x1,s*f1) if f1<f2 else (x2,s*f2)
ATM={"inferior":[(7.5,15.0,-5.0)],"superior":[(100.0,15.0,10.0)],"fata":[(80.0,15.0,5.0),(120.0,15.0,15.0)]}
if __name__=="__main__":
    name=sys.argv[1]; h0=float(sys.argv[2]); D=float(sys.argv[3]); lo=float(sys.argv[4]); hi=float(sys.argv[5]); step=float(sys.argv[6])
    ds=float(sys.argv[7]) if len(sys.argv)>7 else 1.0
    n=mk(ATM[name])
    m=int(round((hi-lo)/step))+1
    al=[lo+step*i for i in range(m)]
    hs=[trace(n,h0,math.radians(a),D,ds) for a in al]
    print(f"# {name} h0 {h0} D {D}: samples", " ".join(f"{a:.3f}:{h:.2f}" for a,h in zip(al,hs)))
    for i in range(1,m-1):
        p,q,r_=hs[i-1],hs[i],hs[i+1]
        if all(map(math.isfinite,(p,q,r_))) and (q-p)*(r_-q)<0:
            mx=q>p
            a,h=golden(lambda x: trace(n,h0,math.radians(x),D,ds),al[i-1],al[i+1],mx)
            print(f"{name} h0 {h0} D {D}: {'max' if mx else 'min'} at {a:.4f} deg, h {h:.3f} m")
    sys.stdout.flush()
