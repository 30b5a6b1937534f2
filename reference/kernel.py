"""Compiled step loop for the Hertz/Volterra impact equation (paper eq. 42) on a modal structure.

Scheme (cost linear in steps x modes)
-------------------------------------
Each mode i obeys q'' + omega^2 q = (phi_i/m_i) f. With y_i = (phi_i/omega_i)(q_i' + i omega_i q_i)
the structure displacement at the contact is x2 = sum_i Im y_i (+ R f for the residual static
flexibility R of dropped modes) and

    y_i(t + eta) = e^{i omega_i eta} y_i(t) + g_i * int_0^eta e^{i omega_i (eta - s)} f(t + s) ds,
    g_i = phi_i^2 / (m_i omega_i),

i.e. the sine kernel of eq. 42 separates and each mode is propagated *exactly* over a step. The
force on a step is the polynomial of degree <= p through the last p nodes and the new one
(implicit, Adams-Moulton-like); its products with e^{i omega s} are integrated in closed form
(`moments`). The ball moves exactly under the same polynomial. The unknown new force enters
linearly, so each step ends with one scalar equation delta + B alpha delta^1.5 = D (Newton).

Onset and end of contact: f grows like t^1.5 at first touch and falls like (t_end - t)^1.5 at
separation, which caps a uniform-step polynomial scheme near order 2.5. The step size is graded
towards both ends, eta <= H (tau / T_w)^gamma with gamma = (p - 1/2)/(p + 1), tau the time since
touch (or the predicted time to separation), which equidistributes the local error
eta^(p+2) tau^(1/2-p) and restores order p + 1. Steps are H / 2^j (j = 0..J) so that all
per-mode weights come from J + 1 precomputed tables; the separation (and any re-contact) is
bracketed by rejecting and halving steps down to H / 2^J.
"""
from __future__ import annotations

import numpy as np
from numba import njit

STATUS_OK = 0
STATUS_OUT_OF_NODES = 1
STATUS_NO_CONTACT = 2


@njit(cache=True)
def _moments_one(theta: float, p: int, out: np.ndarray) -> None:
    """out[l] = int_0^1 e^{i theta (1 - s)} s^l ds, l = 0..p (series for small theta)."""
    if abs(theta) < 2.0:
        for l in range(p + 1):
            term = 1.0 / (l + 1) + 0j
            total = term
            for m in range(60):
                term = term * (1j * theta) / (l + m + 2)
                total += term
                if abs(term) < 1e-18 * abs(total):
                    break
            out[l] = total
    else:
        it = 1j * theta
        k = (np.exp(it) - 1.0) / it
        out[0] = k
        for l in range(1, p + 1):
            k = (l * k - 1.0) / it
            out[l] = k


@njit(cache=True)
def moments(omega: np.ndarray, g: np.ndarray, H: float, J: int, p: int):
    """Per-step tables for step sizes eta_j = H / 2^j.

    Returns E[j, i] = e^{i omega_i eta_j}, K[j, l, i] = int_0^eta_j e^{i omega_i (eta_j - s)} (s/eta_j)^l ds
    [s], and S[j, l] = sum_i g_i Im K[j, l, i] [m/N].
    """
    n = omega.shape[0]
    E = np.empty((J + 1, n), dtype=np.complex128)
    K = np.empty((J + 1, p + 1, n), dtype=np.complex128)
    S = np.zeros((J + 1, p + 1))
    buf = np.empty(p + 1, dtype=np.complex128)
    for j in range(J + 1):
        eta = H / 2.0**j
        for i in range(n):
            theta = omega[i] * eta
            E[j, i] = np.cos(theta) + 1j * np.sin(theta)
            _moments_one(theta, p, buf)
            for l in range(p + 1):
                K[j, l, i] = eta * buf[l]
                S[j, l] += g[i] * (eta * buf[l]).imag
    return E, K, S


@njit(cache=True)
def _lagrange_coeffs(sig: np.ndarray, m: int, L: np.ndarray) -> None:
    """L[k, l]: monomial coefficients (power l) of the Lagrange basis polynomial of node k of sig[0..m]."""
    for k in range(m + 1):
        for l in range(m + 1):
            L[k, l] = 0.0
        L[k, 0] = 1.0
        deg = 0
        for q in range(m + 1):
            if q == k:
                continue
            inv = 1.0 / (sig[k] - sig[q])
            # multiply polynomial by (s - sig[q]) * inv
            for l in range(deg + 1, 0, -1):
                L[k, l] = (L[k, l - 1] - sig[q] * L[k, l]) * inv
            L[k, 0] = -sig[q] * L[k, 0] * inv
            deg += 1


@njit(cache=True)
def _solve_contact(D: float, B: float, alpha: float) -> float:
    """Root delta > 0 of delta + B alpha delta^1.5 = D (D > 0); Newton from above (convex, monotone)."""
    d = D
    if B * alpha > 0.0:
        d2 = (D / (B * alpha)) ** (2.0 / 3.0)
        if d2 < d:
            d = d2
    for _ in range(100):
        sq = np.sqrt(d)
        F = d + B * alpha * d * sq - D
        dF = 1.0 + 1.5 * B * alpha * sq
        step = F / dF
        d -= step
        if d <= 0.0:
            d = 1e-300
        if abs(step) <= 1e-16 * d:
            break
    return d


@njit(cache=True)
def run(omega, g, ew, m0, alpha, v0, R, H, J, p, T_w, window, E, K, S, max_nodes):
    """Integrate from first touch (t = 0, delta = 0, delta' = v0) to the end of the first contact,
    and on for `window` [s] after it when window > 0 (re-contacts included).

    Returns (status, n_nodes, t, delta, f, x1, u, energy, flags); flags[k] = 1 where a contact
    starts at node k, 2 where one has ended (first node with delta <= 0).
    Arrays: t [s], delta [m], f [N], x1 ball displacement [m], u ball velocity [m/s], energy [J].
    """
    n = omega.shape[0]
    gam = (p - 0.5) / (p + 1.0)
    y = np.zeros(n, dtype=np.complex128)
    ypre = np.zeros(n, dtype=np.complex128)
    ta = np.empty(max_nodes)
    da = np.empty(max_nodes)
    fa = np.empty(max_nodes)
    xa = np.empty(max_nodes)
    ua = np.empty(max_nodes)
    ea = np.empty(max_nodes)
    flags = np.zeros(max_nodes, dtype=np.int8)
    sig = np.empty(p + 1)
    sig_prev = np.full(p + 1, np.nan)
    L = np.empty((p + 1, p + 1))
    a_known = np.empty(p + 1)
    c = np.empty(p + 1)
    Kc = np.empty(n, dtype=np.complex128)
    Kc_j = -1
    m_prev = -1

    t = 0.0
    x1 = 0.0
    u = v0
    delta = 0.0
    f = 0.0
    ta[0] = 0.0
    da[0] = 0.0
    fa[0] = 0.0
    xa[0] = 0.0
    ua[0] = v0
    ea[0] = 0.5 * m0 * v0 * v0
    flags[0] = 1
    count = 1
    in_contact = True
    seg_start = 0
    j_prev = J
    t_end = -1.0
    while True:
        if count >= max_nodes:
            return STATUS_OUT_OF_NODES, count, ta, da, fa, xa, ua, ea, flags
        # ---------------------------------------------------------------- choose the step
        if in_contact:
            h_allow = H
            tau_s = t - ta[seg_start]
            if tau_s < T_w:
                h_allow = H * (tau_s / T_w) ** gam
            if count - seg_start >= 3 and delta > 0.0:
                # predicted time to separation from a quadratic through the last three nodes
                t0, t1, t2 = ta[count - 3], ta[count - 2], ta[count - 1]
                d0, d1, d2 = da[count - 3], da[count - 2], da[count - 1]
                dd = (d0 * (t2 - t1) / ((t0 - t1) * (t0 - t2)) + d1 * (t2 - t0) / ((t1 - t0) * (t1 - t2))
                      + d2 * (2 * t2 - t0 - t1) / ((t2 - t0) * (t2 - t1)))
                if dd < 0.0:
                    tau_e = delta / (-dd)
                    if tau_e < T_w:
                        h2 = H * (tau_e / T_w) ** gam
                        if h2 < h_allow:
                            h_allow = h2
            j = 0
            while j < J and H / 2.0**j > h_allow:
                j += 1
            if j < j_prev - 1:
                j = j_prev - 1          # grow at most by 2 per step
        else:
            j = 0
        if t_end > 0.0:
            while j < J and t + H / 2.0**j > t_end * (1 + 1e-12) :
                j += 1
        # ---------------------------------------------------------------- attempt (halve on crossing)
        while True:
            eta = H / 2.0**j
            first = count - p
            if first < seg_start:
                first = seg_start
            m = count - first
            for k in range(m):
                sig[k] = (ta[first + k] - t) / eta
            sig[m] = 1.0
            same = m == m_prev
            if same:
                for k in range(m + 1):
                    if sig[k] != sig_prev[k]:
                        same = False
                        break
            if not same:
                _lagrange_coeffs(sig, m, L)
                for k in range(m + 1):
                    sig_prev[k] = sig[k]
                m_prev = m
                Kc_j = -1
            for l in range(p + 1):
                a_known[l] = 0.0
                c[l] = 0.0
            for l in range(m + 1):
                acc_l = 0.0
                for k in range(m):
                    acc_l += L[k, l] * fa[first + k]
                a_known[l] = acc_l
                c[l] = L[m, l]
            # pass 1: propagate every mode with the known part of the force
            acc = 0.0
            for i in range(n):
                s_known = K[j, 0, i] * a_known[0]
                for l in range(1, m + 1):
                    s_known += K[j, l, i] * a_known[l]
                yp = E[j, i] * y[i] + g[i] * s_known
                ypre[i] = yp
                acc += yp.imag
            wu = 0.0
            wx = 0.0
            cu = 0.0
            cx = 0.0
            cs = 0.0
            for l in range(m + 1):
                wu += a_known[l] / (l + 1)
                wx += a_known[l] / ((l + 1) * (l + 2))
                cu += c[l] / (l + 1)
                cx += c[l] / ((l + 1) * (l + 2))
                cs += c[l] * S[j, l]
            u_pre = u - eta * wu / m0
            x1_pre = x1 + u * eta - eta * eta * wx / m0
            B = eta * eta * cx / m0 + cs + R
            D = x1_pre - acc
            if D <= 0.0:
                d_new = D
                f_new = 0.0
            else:
                d_new = _solve_contact(D, B, alpha)
                f_new = alpha * d_new * np.sqrt(d_new)
            if j < J and ((in_contact and d_new <= 0.0) or ((not in_contact) and d_new > 0.0)):
                j += 1          # the step crosses a contact change: retry with half the step
                continue
            break
        # ---------------------------------------------------------------- accept
        if Kc_j != j:
            for i in range(n):
                s = K[j, 0, i] * c[0]
                for l in range(1, m + 1):
                    s += K[j, l, i] * c[l]
                Kc[i] = g[i] * s
            Kc_j = j
        emod = 0.0
        for i in range(n):
            yi = ypre[i] + Kc[i] * f_new
            y[i] = yi
            emod += ew[i] * (yi.real * yi.real + yi.imag * yi.imag)
        u = u_pre - eta * f_new * cu / m0
        x1 = x1_pre - eta * eta * f_new * cx / m0
        t = t + eta
        delta = d_new
        f = f_new
        ta[count] = t
        da[count] = delta
        fa[count] = f
        xa[count] = x1
        ua[count] = u
        hertz = 0.0
        if delta > 0.0:
            hertz = 0.4 * alpha * delta * delta * np.sqrt(delta)
        ea[count] = 0.5 * m0 * u * u + hertz + 0.5 * emod + 0.5 * R * f * f
        j_prev = j
        if in_contact and delta <= 0.0:
            in_contact = False
            flags[count] = 2
            if t_end < 0.0 and window > 0.0:
                t_end = t + window
            seg_start = count
            m_prev = -1
        elif (not in_contact) and delta > 0.0:
            in_contact = True
            flags[count - 1] = 1
            seg_start = count - 1
            j_prev = J
            m_prev = -1
        count += 1
        if t_end > 0.0:
            if t >= t_end * (1 - 1e-12):
                return STATUS_OK, count, ta, da, fa, xa, ua, ea, flags
        elif not in_contact:
            return STATUS_OK, count, ta, da, fa, xa, ua, ea, flags


@njit(cache=True)
def _interp(ts: np.ndarray, ds: np.ndarray, x: float) -> float:
    """Value at x of the polynomial through the points (ts, ds) (Lagrange form)."""
    total = 0.0
    for k in range(ts.shape[0]):
        w = ds[k]
        for l in range(ts.shape[0]):
            if l != k:
                w *= (x - ts[l]) / (ts[k] - ts[l])
        total += w
    return total


@njit(cache=True)
def crossing(ts: np.ndarray, ds: np.ndarray, lo: float, hi: float) -> float:
    """Root in [lo, hi] of the interpolant through (ts, ds), whose values at lo and hi differ in sign."""
    flo = _interp(ts, ds, lo)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        fm = _interp(ts, ds, mid)
        if (fm > 0.0) == (flo > 0.0):
            lo, flo = mid, fm
        else:
            hi = mid
        if hi - lo <= 1e-16 * abs(hi) + 1e-300:
            break
    return 0.5 * (lo + hi)


@njit(cache=True)
def peak(ts: np.ndarray, ds: np.ndarray, lo: float, hi: float):
    """(x, value) of the maximum of the interpolant through (ts, ds) on [lo, hi] (golden section)."""
    gr = 0.6180339887498949
    a, b = lo, hi
    c = b - gr * (b - a)
    d = a + gr * (b - a)
    fc = _interp(ts, ds, c)
    fd = _interp(ts, ds, d)
    for _ in range(200):
        if fc > fd:
            b, d, fd = d, c, fc
            c = b - gr * (b - a)
            fc = _interp(ts, ds, c)
        else:
            a, c, fc = c, d, fd
            d = a + gr * (b - a)
            fd = _interp(ts, ds, d)
        if b - a <= 1e-15 * (abs(a) + abs(b)) + 1e-300:
            break
    x = 0.5 * (a + b)
    return x, _interp(ts, ds, x)
