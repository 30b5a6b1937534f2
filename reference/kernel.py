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
#: free flight in a window advances in jumps of at most window / SERIES_SAMPLES (the series keeps about this
#: many samples over a long window; contacts are integrated at full resolution)
SERIES_SAMPLES = 20000


@njit(cache=True)
def _moments_one(theta: float, c: float, sn: float, p: int, out_re: np.ndarray, out_im: np.ndarray) -> None:
    """out[l] = int_0^1 e^{i theta (1 - s)} s^l ds, l = 0..p (c, sn: cos and sin of theta).

    |theta| >= 2: upward recurrence K_l = (l K_{l-1} - 1)/(i theta) from K_0 = (e^{i theta} - 1)/(i theta)
    (error growth <= p!/theta^p); |theta| < 2: the series of K_p, sum_m (i theta)^m p!/(p+m+1)!, then the
    downward recurrence K_{l-1} = (1 + i theta K_l)/l, stable there.
    """
    if abs(theta) < 2.0:
        # series for K_p
        tr, ti = 1.0 / (p + 1), 0.0
        sr, si = tr, ti
        for m in range(80):
            fac = theta / (p + m + 2)
            tr, ti = -ti * fac, tr * fac            # term *= i theta / (p + m + 2)
            sr += tr
            si += ti
            if abs(tr) + abs(ti) < 1e-18 * (abs(sr) + abs(si)):
                break
        out_re[p] = sr
        out_im[p] = si
        for l in range(p, 0, -1):
            kr, ki = out_re[l], out_im[l]
            out_re[l - 1] = (1.0 - theta * ki) / l     # (1 + i theta K_l) / l
            out_im[l - 1] = (theta * kr) / l
    else:
        # K_0 = (e^{i theta} - 1)/(i theta) = (sin theta + i (1 - cos theta)) / theta
        kr, ki = sn / theta, (1.0 - c) / theta
        out_re[0] = kr
        out_im[0] = ki
        for l in range(1, p + 1):
            # (l K - 1)/(i theta) = -i (l K - 1)/theta
            ar, ai = l * kr - 1.0, l * ki
            kr, ki = ai / theta, -ar / theta
            out_re[l] = kr
            out_im[l] = ki


@njit(cache=True, fastmath=True, error_model="numpy")
def moments(omega: np.ndarray, g: np.ndarray, H: float, J: int, p: int):
    """Per-step tables for step sizes eta_j = H / 2^j (real and imaginary parts apart, modes contiguous).

    Returns Er, Ei [j, i]: e^{i omega_i eta_j}; Kr, Ki [j, l, i]: g_i int_0^eta_j e^{i omega_i (eta_j - s)}
    (s/eta_j)^l ds [m/N], g_i = phi_i^2/(m_i omega_i); S[j, l] = sum_i Ki[j, l, i] [m/N].
    """
    n = omega.shape[0]
    Er = np.empty((J + 1, n))
    Ei = np.empty((J + 1, n))
    Kr = np.empty((J + 1, p + 1, n))
    Ki = np.empty((J + 1, p + 1, n))
    S = np.zeros((J + 1, p + 1))
    br = np.empty(p + 1)
    bi = np.empty(p + 1)
    for j in range(J + 1):
        eta = H / 2.0**j
        for i in range(n):
            theta = omega[i] * eta
            c = np.cos(theta)
            sn = np.sin(theta)
            Er[j, i] = c
            Ei[j, i] = sn
            _moments_one(theta, c, sn, p, br, bi)
            w = g[i] * eta
            for l in range(p + 1):
                Kr[j, l, i] = w * br[l]
                Ki[j, l, i] = w * bi[l]
                S[j, l] += w * bi[l]
    return Er, Ei, Kr, Ki, S


@njit(cache=True)
def _lagrange_coeffs(sig: np.ndarray, m: int, L: np.ndarray, P: np.ndarray) -> None:
    """L[k, l]: monomial coefficients (power l) of the Lagrange basis polynomial of node k of sig[0..m].

    O(m^2): L_k(s) = P(s) / ((s - sig_k) P'(sig_k)) with P(s) = prod_q (s - sig_q), by synthetic division.
    """
    for l in range(m + 2):           # P(s) coefficients, power l at index l (P: work array, len >= m + 2)
        P[l] = 0.0
    P[0] = 1.0
    for q in range(m + 1):
        for l in range(q + 1, 0, -1):
            P[l] = P[l - 1] - sig[q] * P[l]
        P[0] = -sig[q] * P[0]
    for k in range(m + 1):
        dp = 1.0
        for q in range(m + 1):
            if q != k:
                dp *= sig[k] - sig[q]
        # synthetic division of P by (s - sig_k): quotient degree m
        b = P[m + 1]
        L[k, m] = b / dp
        for l in range(m, 0, -1):
            b = P[l] + sig[k] * b
            L[k, l - 1] = b / dp


@njit(cache=True)
def _solve_contact(D: float, B: float, alpha: float) -> float:
    """Root delta > 0 of delta + B alpha delta^1.5 = D (D > 0); Newton from above (convex, monotone)."""
    d = D
    if B * alpha > 0.0:
        d2 = (D / (B * alpha)) ** (2.0 / 3.0)
        if d2 < d:
            d = d2
    prev = np.inf
    for _ in range(100):
        sq = np.sqrt(d)
        F = d + B * alpha * d * sq - D
        dF = 1.0 + 1.5 * B * alpha * sq
        step = F / dF
        d -= step
        if d <= 0.0:
            d = 1e-300
        # quadratic convergence until rounding: stop at 1 ulp or when the step stops shrinking
        if abs(step) <= 2.3e-16 * d or abs(step) >= 0.5 * prev:
            break
        prev = abs(step)
    return d


@njit(cache=True, fastmath=True, error_model="numpy")
def run(ew, m0, alpha, v0, R, H, J, p, T_w, window, Er, Ei, Kr, Ki, S, max_nodes, j0=0, omega=None,
        sample_dt=0.0):
    """Integrate from first touch (t = 0, delta = 0, delta' = v0) to the end of the first contact,
    and on for `window` [s] after it when window > 0 (re-contacts included). Step size H/2^j uses
    table level j + j0 (so one table set serves base steps H and H/2).

    In the window, free flight (no force: ball and modes move exactly) advances in jumps of up to
    `sample_dt` [s] (0: no jumps) whenever a jump provably cannot reach a contact: the gap x1 - x2 can
    close no faster than u + sum omega_i |y_i|, and never closes once the ball moves away with
    x1 < -sum |y_i| (free modes keep |y_i|). `omega` [rad/s] is needed for the jumps.

    Returns (status, n_nodes, t, delta, f, x1, u, energy, flags); flags[k] = 1 where a contact
    starts at node k, 2 where one has ended (first node with delta <= 0).
    Arrays: t [s], delta [m], f [N], x1 ball displacement [m], u ball velocity [m/s], energy [J].
    """
    n = ew.shape[0]
    gam = (p - 0.5) / (p + 1.0)
    yr = np.zeros(n)
    yi = np.zeros(n)
    pr = np.zeros(n)
    pi_ = np.zeros(n)
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
    Pw = np.empty(p + 2)
    a_known = np.empty(p + 1)
    c = np.empty(p + 1)
    Kcr = np.empty(n)
    Kci = np.empty(n)
    inv1 = np.empty(p + 1)            # 1/(l+1): ball velocity weights
    inv2 = np.empty(p + 1)            # 1/((l+1)(l+2)): ball displacement weights
    for l in range(p + 1):
        inv1[l] = 1.0 / (l + 1)
        inv2[l] = 1.0 / ((l + 1) * (l + 2))
    cu = 0.0
    cx = 0.0
    cs = 0.0
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
    etas = np.empty(J + 1)
    for q in range(J + 1):
        etas[q] = H / 2.0**q
    while True:
        if count >= max_nodes:
            return STATUS_OUT_OF_NODES, count, ta, da, fa, xa, ua, ea, flags
        # ---------------------------------------------------------------- free-flight jump (window only)
        if (not in_contact) and t_end > 0.0 and sample_dt > 0.0 and omega is not None:
            amp = 0.0
            vel = 0.0
            x2 = 0.0
            for i in range(n):
                a_i = np.sqrt(yr[i] * yr[i] + yi[i] * yi[i])
                amp += a_i
                vel += omega[i] * a_i
                x2 += yi[i]
            gap = x1 - x2                      # < 0 in free flight
            h_safe = 0.0
            if u <= 0.0 and x1 + amp < 0.0:
                h_safe = np.inf                # moving away and out of reach of every mode
            else:
                if u + vel <= 0.0:
                    h_safe = np.inf
                elif gap < 0.0:
                    h_safe = -gap / (u + vel)
                if u > 0.0 and x1 + amp < 0.0:
                    h_safe = max(h_safe, -(x1 + amp) / u)
            h = min(0.5 * h_safe if h_safe < np.inf else sample_dt, sample_dt, t_end - t)
            if h > 2.0 * H:
                emod = 0.0
                for i in range(n):
                    cs_ = np.cos(omega[i] * h)
                    sn_ = np.sin(omega[i] * h)
                    a = cs_ * yr[i] - sn_ * yi[i]
                    b = sn_ * yr[i] + cs_ * yi[i]
                    yr[i] = a
                    yi[i] = b
                    emod += ew[i] * (a * a + b * b)
                x2 = 0.0
                for i in range(n):
                    x2 += yi[i]
                x1 = x1 + u * h
                t = t + h
                delta = x1 - x2
                f = 0.0
                ta[count] = t
                da[count] = delta
                fa[count] = 0.0
                xa[count] = x1
                ua[count] = u
                ea[count] = 0.5 * m0 * u * u + 0.5 * emod
                seg_start = count             # the force stencil restarts here (f = 0 before)
                m_prev = -1
                j_prev = 0
                count += 1
                if t >= t_end * (1 - 1e-12):
                    return STATUS_OK, count, ta, da, fa, xa, ua, ea, flags
                continue
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
            while j < J and etas[j] > h_allow:
                j += 1
            if j < j_prev - 1:
                j = j_prev - 1          # grow at most by 2 per step
        else:
            j = 0
        if t_end > 0.0:
            while j < J and t + etas[j] > t_end * (1 + 1e-12):
                j += 1
        # ---------------------------------------------------------------- attempt (halve on crossing)
        while True:
            eta = etas[j]
            jt = j + j0
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
                _lagrange_coeffs(sig, m, L, Pw)
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
            # pass 1: propagate every mode with the known part of the force (contiguous loops)
            for i in range(n):
                er = Er[jt, i]
                ei = Ei[jt, i]
                pr[i] = er * yr[i] - ei * yi[i]
                pi_[i] = er * yi[i] + ei * yr[i]
            need_kc = Kc_j != jt
            if need_kc:
                # the new node's weights Kc = sum_l K_l c_l, in the same sweep as the known part
                for i in range(n):
                    Kcr[i] = 0.0
                    Kci[i] = 0.0
                for l in range(m + 1):
                    al = a_known[l]
                    cl = c[l]
                    for i in range(n):
                        kr = Kr[jt, l, i]
                        ki = Ki[jt, l, i]
                        pr[i] += kr * al
                        pi_[i] += ki * al
                        Kcr[i] += kr * cl
                        Kci[i] += ki * cl
                Kc_j = jt
            else:
                for l in range(m + 1):
                    al = a_known[l]
                    for i in range(n):
                        pr[i] += Kr[jt, l, i] * al
                        pi_[i] += Ki[jt, l, i] * al
            acc = 0.0
            for i in range(n):
                acc += pi_[i]
            wu = 0.0
            wx = 0.0
            for l in range(m + 1):
                wu += a_known[l] * inv1[l]
                wx += a_known[l] * inv2[l]
            if need_kc:
                # the new node's ball and structure weights change with the stencil or the step only
                cu = 0.0
                cx = 0.0
                cs = 0.0
                for l in range(m + 1):
                    cu += c[l] * inv1[l]
                    cx += c[l] * inv2[l]
                    cs += c[l] * S[jt, l]
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
        emod = 0.0
        for i in range(n):
            a = pr[i] + Kcr[i] * f_new
            b = pi_[i] + Kci[i] * f_new
            yr[i] = a
            yi[i] = b
            emod += ew[i] * (a * a + b * b)
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
def _fit(ts: np.ndarray, ds: np.ndarray, t0: float, scale: float) -> np.ndarray:
    """Monomial coefficients (in x = (t - t0)/scale) of the polynomial through the points (ts, ds)."""
    m = ts.shape[0] - 1
    sig = (ts - t0) / scale
    L = np.empty((m + 1, m + 1))
    _lagrange_coeffs(sig, m, L, np.empty(m + 2))
    c = np.zeros(m + 1)
    for k in range(m + 1):
        for l in range(m + 1):
            c[l] += L[k, l] * ds[k]
    return c


@njit(cache=True)
def _horner(c: np.ndarray, x: float):
    """(value, first derivative) of the polynomial with monomial coefficients c at x."""
    v = 0.0
    dv = 0.0
    for l in range(c.shape[0] - 1, -1, -1):
        dv = dv * x + v
        v = v * x + c[l]
    return v, dv


@njit(cache=True)
def _root(c: np.ndarray, lo: float, hi: float, deriv: bool) -> float:
    """Root in [lo, hi] of the polynomial c (deriv: of its derivative), the ends of opposite sign:
    safeguarded Newton (bisection whenever Newton leaves the bracket)."""
    if deriv:
        n = c.shape[0] - 1
        c2 = np.empty(n)
        for l in range(n):
            c2[l] = (l + 1) * c[l + 1]
        c = c2
    flo, _ = _horner(c, lo)
    x = 0.5 * (lo + hi)
    for _ in range(100):
        fx, dfx = _horner(c, x)
        if (fx > 0.0) == (flo > 0.0):
            lo, flo = x, fx
        else:
            hi = x
        xn = x - fx / dfx if dfx != 0.0 else 0.5 * (lo + hi)
        if not (lo < xn < hi):
            xn = 0.5 * (lo + hi)
        if abs(xn - x) <= 1e-15 * (abs(x) + 1.0) or hi - lo <= 1e-15:
            x = xn
            break
        x = xn
    return x


@njit(cache=True)
def crossing(ts: np.ndarray, ds: np.ndarray, lo: float, hi: float) -> float:
    """Root in [lo, hi] of the interpolant through (ts, ds), whose values at lo and hi differ in sign."""
    scale = hi - lo
    c = _fit(ts, ds, hi, scale)
    return hi + scale * _root(c, -1.0, 0.0, False)


@njit(cache=True)
def peak(ts: np.ndarray, ds: np.ndarray, lo: float, hi: float):
    """(t, value) of the maximum of the interpolant through (ts, ds) on [lo, hi]."""
    scale = 0.5 * (hi - lo)
    mid = 0.5 * (lo + hi)
    c = _fit(ts, ds, mid, scale)
    n = c.shape[0]
    d_lo = 0.0
    d_hi = 0.0
    for l in range(1, n):
        d_lo += l * c[l] * (-1.0) ** (l - 1)
        d_hi += l * c[l]
    if d_lo > 0.0 and d_hi < 0.0:
        x = _root(c, -1.0, 1.0, True)
    else:   # no interior stationary point: the larger end
        x = -1.0 if _horner(c, -1.0)[0] > _horner(c, 1.0)[0] else 1.0
    return mid + scale * x, _horner(c, x)[0]


@njit(cache=True)
def contacts(t: np.ndarray, d: np.ndarray, flags: np.ndarray, f: np.ndarray, R: float) -> np.ndarray:
    """Contact phases from a run: rows (t_start, t_end, delta_max) [s, s, m]; t_end = NaN if the
    window ended in contact. Start: linear interpolation over the H/2^J step in which free flight
    (integrated exactly) turned into contact; end: root of the cubic through the last four nodes of the
    gap delta + R f (R [m/N]: residual flexibility, f [N]: the force), which changes sign where delta
    does but, unlike delta = gap - R alpha delta^1.5 near separation, is smooth there (interpolating
    delta itself left an error of order (smallest step)^1.5 in t_m); peak: maximum of the degree-6
    interpolant of delta around the largest node."""
    n = t.shape[0]
    count = 0
    for k in range(n):
        if flags[k] == 1:
            count += 1
    out = np.full((count, 3), np.nan)
    row = -1
    s = 0
    for k in range(n):
        if flags[k] == 1:
            row += 1
            s = k
            if k == 0:
                out[row, 0] = 0.0
            else:
                out[row, 0] = t[k] - d[k] * (t[k + 1] - t[k]) / (d[k + 1] - d[k])
            # find the end
            e = n - 1
            ended = False
            for q in range(k + 1, n):
                if flags[q] == 2:
                    e = q
                    ended = True
                    break
            if ended:
                lo = max(e - 3, s)
                gap = d[lo:e + 1] + R * f[lo:e + 1]
                out[row, 1] = crossing(t[lo:e + 1], gap, t[e - 1], t[e])
            pk = s
            for q in range(s, e + 1):
                if d[q] > d[pk]:
                    pk = q
            lo = max(pk - 3, s + 1)
            hi = min(pk + 4, e)
            dmax = d[pk]
            if hi - lo >= 3:
                a = max(pk - 1, lo)
                b = min(pk + 1, hi - 1)
                _, v = peak(t[lo:hi], d[lo:hi], t[a], t[b])
                if v > dmax:
                    dmax = v
            out[row, 2] = dmax
    return out


@njit(cache=True)
def solve_pair(omega, g, ew, m0, alpha, v0, R, H, J, p, T_w, window, max_nodes):
    """The fine (base step H), coarse (2H) and coarsest (4H) runs that make one error estimate, in one call.

    The tables for steps 4H/2^k, k = 0..J+2, serve all three (coarsest: k = 0..J, coarse: 1..J+1, fine:
    2..J+2), so the smallest step scales with H and its error shows in the differences. Returns (status,
    n_nodes and series of the fine run, its contacts, the coarse run's contacts, the coarsest run's);
    contacts rows are (t_start, t_end, delta_max).
    """
    Er, Ei, Kr, Ki, S = moments(omega, g, 4.0 * H, J + 2, p)
    st_cc, cnt_cc, tcc, dcc, fcc, xcc, ucc, ecc, flcc = run(ew, m0, alpha, v0, R, 4.0 * H, J, p, T_w, 0.0,
                                                            Er, Ei, Kr, Ki, S, max_nodes, 0)
    st_c, cnt_c, tc, dc, fc, xc, uc, ec, flc = run(ew, m0, alpha, v0, R, 2.0 * H, J, p, T_w, 0.0,
                                                   Er, Ei, Kr, Ki, S, max_nodes, 1)
    st, cnt, t, d, f, x, u, e, fl = run(ew, m0, alpha, v0, R, H, J, p, T_w, window,
                                        Er, Ei, Kr, Ki, S, max_nodes, 2, omega, window / SERIES_SAMPLES)
    if st != STATUS_OK or st_c != STATUS_OK or st_cc != STATUS_OK:
        z = np.zeros((0, 3))
        return STATUS_OUT_OF_NODES, 0, t, d, f, x, u, e, fl, z, z, z
    fine = contacts(t[:cnt], d[:cnt], fl[:cnt], f[:cnt], R)
    coarse = contacts(tc[:cnt_c], dc[:cnt_c], flc[:cnt_c], fc[:cnt_c], R)
    coarsest = contacts(tcc[:cnt_cc], dcc[:cnt_cc], flcc[:cnt_cc], fcc[:cnt_cc], R)
    return (STATUS_OK, cnt, t[:cnt].copy(), d[:cnt].copy(), f[:cnt].copy(), x[:cnt].copy(), u[:cnt].copy(),
            e[:cnt].copy(), fl[:cnt].copy(), fine, coarse, coarsest)


#: the observed ratio r = |x_2h - x_4h| / |x_h - x_2h| is trusted only up to r / RATIO_SAFETY: before the scheme is
#: asymptotic (r < 2^(p+1) = 64) the next halving often gains less than the last one did (random scenes: the
#: error of x_h was up to 2.2x above d1 / (r - 1) with r = 13 .. 34)
RATIO_SAFETY = 1.5
#: ratio trusted at most when x_h - x_2h and x_2h - x_4h differ in sign (random scenes: the error of x_h was then up
#: to d1 / 5.3, e.g. a 1.6 kg ball on a 40-mode beam at tol 1e-4, errors +1.5e-7, +9.5e-7, -8.3e-6 at H, 2H, 4H)
FLIP_RATIO = 4.0


@njit(cache=True)
def richardson(x_h: float, x_2h: float, x_4h: float, est_order: float) -> float:
    """Error estimate of x_h from three step sizes H, 2H, 4H: |x_h - x_2h| / (r' - 1) with the observed ratio
    r = |x_2h - x_4h| / |x_h - x_2h| capped at 2^est_order (the assumed order: conservative once the
    scheme is asymptotic) and divided by RATIO_SAFETY, r' = max(min(r, 2^est_order) / RATIO_SAFETY, 1.5); before
    convergence shows (r < 2), the larger of the two differences. A ratio above 2^(p+2) (p + 1 = 6 the scheme's
    order) means x_h and x_2h agree by accident: then d2 / 2^(p + 1), x_2h's error carried down one halving at
    the scheme's order. When the two differences change sign the ratio is trusted to FLIP_RATIO at most."""
    d1 = abs(x_h - x_2h)
    d2 = abs(x_2h - x_4h)
    if d1 == 0.0 or d2 > 128.0 * d1:
        return max(d1, d2 / 64.0)
    r = d2 / d1
    if r < 2.0:
        return max(d1, d2)
    trusted = max(min(r, 2.0**est_order) / RATIO_SAFETY, 1.5)
    if (x_h - x_2h) * (x_2h - x_4h) < 0.0:
        trusted = min(trusted, FLIP_RATIO)     # the differences change sign: not asymptotic yet
    return d1 / (trusted - 1.0)


@njit(cache=True)
def unresolved_factor(theta: float, sqrt_w: float, theta_tab: np.ndarray, c_tab: np.ndarray) -> float:
    """Measured error factor C of one mode at phase theta = omega H per base step: the value of the first
    table point >= theta (a step function), ~theta^6 below the table; above it the larger of the last
    value and c_tab[-1] * sqrt(w) / 4 (the error of a stiff unresolved mode falls like w^-3, not w^-3.5)."""
    k = 0
    nt = theta_tab.shape[0]
    if theta <= theta_tab[0]:
        x = theta / theta_tab[0]
        x2 = x * x
        return c_tab[0] * x2 * x2 * x2
    while k < nt and theta_tab[k] < theta:
        k += 1
    if k < nt:
        return c_tab[k]
    return max(c_tab[nt - 1], 0.25 * c_tab[nt - 1] * sqrt_w)


@njit(cache=True)
def unresolved(s_w: np.ndarray, omega: np.ndarray, sqrt_w: np.ndarray, H: float, theta_tab: np.ndarray,
               c_tab: np.ndarray) -> float:
    """sum_i s_w[i] C(omega_i H, w_i): the bound for the error of modes the base step H does not resolve."""
    total = 0.0
    for i in range(omega.shape[0]):
        total += s_w[i] * unresolved_factor(omega[i] * H, sqrt_w[i], theta_tab, c_tab)
    return total


@njit(cache=True)
def largest_step(s_w: np.ndarray, omega: np.ndarray, sqrt_w: np.ndarray, H: float, theta_tab, c_tab,
                 target: float) -> float:
    """The largest base step <= H whose unresolved-mode bound is <= target (bisection in log H)."""
    if unresolved(s_w, omega, sqrt_w, H, theta_tab, c_tab) <= target:
        return H
    lo = H
    while unresolved(s_w, omega, sqrt_w, lo, theta_tab, c_tab) > target and lo > 1e-30:
        lo *= 0.125
    hi = H
    for _ in range(60):
        mid = np.sqrt(lo * hi)
        if unresolved(s_w, omega, sqrt_w, mid, theta_tab, c_tab) > target:
            hi = mid
        else:
            lo = mid
        if hi / lo < 1.0 + 1e-3:
            break
    return lo


@njit(cache=True)
def levels(n_steps: float, tol: float, smallest_factor: float) -> int:
    """Step-size levels J: the smallest step H/2^J is ~(smallest_factor tol)^0.4 t_plate. The first
    step's force is only approximated (error ~ (step / t_plate)^2.5), so it is made small enough not
    to matter."""
    smallest = (smallest_factor * tol) ** 0.4
    J = int(np.ceil(np.log2(1.0 / (smallest * n_steps))))
    return min(max(J, 3), 30)


#: modes below this w = omega delta_plate / v0 count as light modes that change the contact's time scale
LIGHT_W = 3.0
#: the light-mode factor is at most 1 + LIGHT_CAP (the largest excess measured on random scenes was 1.22x)
LIGHT_CAP = 0.5


@njit(cache=True)
def solve_auto(omega, g, ew, m0, alpha, v0, R, tol, window, t_plate, delta_plate, p, grading, n0,
               est_order, theta_tab, c_tab, smallest_factor, unresolved_share=0.25,
               node_cap=4000000, series_samples=SERIES_SAMPLES, light_coupling=0.0):
    """The whole time-step control in one compiled call (see solve.solve_modes for the rules).

    Returns (status, n_nodes, t, delta, f, x_ball, u_ball, energy, flags, contacts, rel_uncertainty,
    base step count n, index of the node ending the first contact, largest |E/E0 - 1|).
    """
    # weights of the unresolved-mode bound: C(omega H) s w^-3.5, s = m0 g omega, w = omega delta/v0
    nm = omega.shape[0]
    s_w = np.empty(nm)
    sqrt_w = np.empty(nm)
    omega_c = np.empty(nm)
    k_t = 1.5 * alpha * np.sqrt(delta_plate)
    for i in range(nm):
        w = omega[i] * delta_plate / v0
        s_w[i] = m0 * g[i] * omega[i] * max(w, 1.0) ** -3.5     # a mode below the impact frequency: weight s
        sqrt_w[i] = np.sqrt(w)
        # the frequency a mode rings at while the contact spring (tangent stiffness at the rigid-plate peak)
        # holds it: a light mode (large s) is stiffened far above omega and needs shorter steps
        omega_c[i] = np.sqrt(omega[i] * omega[i] + k_t * (g[i] * omega[i]))
    # strongly coupled light modes (w < LIGHT_W, large s) sharpen the contact force beyond the rigid-plate
    # scaling the table was measured on: every unresolved-mode weight grows by 1 + light_coupling sum(s)
    s_light = 0.0
    for i in range(nm):
        if omega[i] * delta_plate / v0 < LIGHT_W:
            s_light += m0 * g[i] * omega[i]
    for i in range(nm):
        s_w[i] *= 1.0 + min(light_coupling * s_light, LIGHT_CAP)
    n = n0
    if nm > 0:
        n = t_plate / largest_step(s_w, omega_c, sqrt_w, t_plate / n, theta_tab, c_tab, unresolved_share * tol)
    for _ in range(12):
        H = t_plate / n
        J = levels(n, tol, smallest_factor)
        cap = node_cap // 4             # the first contact: a quarter of a window's budget
        max_nodes = min(int(6 * n + 60 * J + 50), cap)
        while True:
            out = solve_pair(omega, g, ew, m0, alpha, v0, R, H, J, p, grading * t_plate, 0.0, max_nodes)
            if out[0] == STATUS_OK or max_nodes >= cap:
                break
            max_nodes = min(4 * max_nodes, cap)
        st, cnt, t, d, f, x, u, e, fl, fine, coarse, coarsest = out
        if st != STATUS_OK:
            return st, cnt, t, d, f, x, u, e, fl, fine, np.inf, n, 0, np.inf
        tm_f = fine[0, 1] - fine[0, 0]
        tm_c = coarse[0, 1] - coarse[0, 0]
        tm_cc = coarsest[0, 1] - coarsest[0, 0]
        dm_f = fine[0, 2]
        # relative; f_m = alpha delta_m^1.5 moves 1.5x as much as delta_m
        rel_t = richardson(tm_f, tm_c, tm_cc, est_order) / tm_f
        rel_d = richardson(dm_f, coarse[0, 2], coarsest[0, 2], est_order) / dm_f
        rel = max(rel_t, 1.5 * rel_d)
        rel += unresolved(s_w, omega_c, sqrt_w, H, theta_tab, c_tab)
        ratio = rel / tol
        if ratio <= 1.0 or n > 1e6:
            break
        grow = 1.1 * ratio ** (1.0 / est_order)
        n *= min(max(1.25, grow), 4.0)
    if window > 0.0:
        # the window once, at the chosen step (the same tables, so the first contact is the same run's)
        Er, Ei, Kr, Ki, S = moments(omega, g, 4.0 * H, J + 2, p)
        max_nodes = int(6 * n + 60 * J + 50 + 3 * min(series_samples, 1e6) + min(2.5 * window / H, 1e6))
        while True:
            max_nodes = min(max_nodes, node_cap)
            st, cnt, t, d, f, x, u, e, fl = run(ew, m0, alpha, v0, R, H, J, p, grading * t_plate, window,
                                                Er, Ei, Kr, Ki, S, max_nodes, 2, omega, window / series_samples)
            if st == STATUS_OK or max_nodes >= node_cap:
                break
            max_nodes *= 4
        if st != STATUS_OK:
            return st, cnt, t, d, f, x, u, e, fl, fine, rel, n, 0, np.inf
        t, d, f, x, u, e, fl = t[:cnt].copy(), d[:cnt].copy(), f[:cnt].copy(), x[:cnt].copy(), u[:cnt].copy(), \
            e[:cnt].copy(), fl[:cnt].copy()
        fine = contacts(t, d, fl, f, R)
    # the first contact's end node (ball velocity there = rebound) and the largest energy drift
    end = 0
    for k in range(cnt):
        if fl[k] == 2:
            end = k
            break
    drift = 0.0
    for k in range(cnt):
        dev = abs(e[k] / e[0] - 1.0)
        if dev > drift:
            drift = dev
    return st, cnt, t, d, f, x, u, e, fl, fine, rel, n, end, drift
