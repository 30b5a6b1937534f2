"""Independent Timoshenko check: Rayleigh-Ritz with Legendre polynomials (w and psi separate)."""
import numpy as np
from numpy.polynomial import legendre as leg
from scipy import linalg

def ritz(sec, support, N=40, point=None):
    L = sec.length
    EI, kGA = sec.young*sec.second_moment, sec.kappa*sec.shear_modulus*sec.area
    rA, rI = sec.density*sec.area, sec.density*sec.second_moment
    t, wt = leg.leggauss(200)
    x = 0.5*(t+1)  # xi in [0,1]
    wq = 0.5*wt
    def basis(xi):
        P = np.array([leg.legval(2*xi-1, np.eye(N)[j]) for j in range(N)])
        dP = np.array([2*leg.legval(2*xi-1, leg.legder(np.eye(N)[j])) for j in range(N)])
        return P, dP
    P, dP = basis(x)
    if support == "clamped-clamped":
        f, df = x*(1-x), 1-2*x
        W, dW = f*P, df*P + f*dP; S, dS = W, dW
    elif support == "cantilever":
        W, dW = x*P, P + x*dP; S, dS = W, dW
    else:  # simply supported: w = 0 at ends, psi free
        f, df = x*(1-x), 1-2*x
        W, dW = f*P, df*P + f*dP; S, dS = P, dP
    dW, dS = dW/L, dS/L
    J = L
    K = np.zeros((2*N, 2*N)); M = np.zeros((2*N, 2*N))
    # strain: psi' ; shear: w' - psi
    B1 = np.vstack([np.zeros_like(W), dS])
    B2 = np.vstack([dW, -S])
    K = EI*(B1*wq*J) @ B1.T + kGA*(B2*wq*J) @ B2.T
    Mw = np.vstack([W, np.zeros_like(S)]); Ms = np.vstack([np.zeros_like(W), S])
    M = rA*(Mw*wq*J) @ Mw.T + rI*(Ms*wq*J) @ Ms.T
    vals, vecs = linalg.eigh(K, M)
    out = {"omega": np.sqrt(vals)}
    if point is not None:
        Pp, _ = basis(np.array([point/L]))
        if support == "cantilever": wp = (point/L)*Pp[:,0]
        else: wp = (point/L)*(1-point/L)*Pp[:,0]
        fvec = np.concatenate([wp, np.zeros(N)])
        out["static"] = fvec @ np.linalg.solve(K, fvec)
        out["phi_at"] = vecs.T @ fvec   # mass-normalised shapes at point
        # max-normalised: sample
        xs = np.linspace(0,1,2001)
        Ps,_ = basis(xs)
        if support == "cantilever": Wf = xs*Ps
        else: Wf = xs*(1-xs)*Ps
        wshape = vecs[:N].T @ Wf
        out["maxw"] = np.max(np.abs(wshape), axis=1)
    return out
