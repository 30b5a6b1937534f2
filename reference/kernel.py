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

import math

import numpy as np
from numba import njit

STATUS_OK = 0
STATUS_OUT_OF_NODES = 1
#: free flight in a window advances in jumps of at most window / SERIES_SAMPLES (the series keeps about this
#: many samples over a long window; contacts are integrated at full resolution)
SERIES_SAMPLES = 20000


#: the series of K_p for |theta| < 2 keeps the terms of its real part down to this fraction of the first one, and
#: those of its imaginary part likewise (the term that first falls below is kept too)
_SERIES_EPS = 1e-18


@njit(cache=True)
def _series_tables(p: int, ser_re: np.ndarray, ser_im: np.ndarray, inv_m: np.ndarray) -> None:
    """Horner coefficients (in theta^2) of the series K_p = sum_m (i theta)^m c_m, c_m = p!/(p+m+1)! (c_0 = 1/(p+1),
    c_m = c_(m-1)/(p+m+1)), 48 each: ser_re[k] = (-1)^k c_2k (real part), ser_im[k] = (-1)^k c_(2k+1) (imaginary part
    / theta); and inv_m[m] = 1/(p + m + 1). Once per table set; `_series_length` gives a level's lengths."""
    cm = 1.0 / (p + 1)
    for m in range(2 * ser_re.shape[0]):
        sign = 1.0 if (m // 2) % 2 == 0 else -1.0
        if m % 2 == 0:
            ser_re[m // 2] = sign * cm
        else:
            ser_im[m // 2] = sign * cm
        inv_m[m] = 1.0 / (p + m + 1)
        cm = cm / (p + m + 2)


@njit(cache=True)
def _series_length(p: int, theta_max: float, inv_m: np.ndarray, n_max: int):
    """(n_re, n_im): how many terms of `_series_tables`' ser_re, ser_im the series keeps for |theta| <= theta_max
    (<= 2): each part's terms down to _SERIES_EPS of its first at theta_max (the term that first falls below is kept
    too). The magnitudes c_m theta_max^m come by multiplications with the reciprocals inv_m (a division each cost its
    latency on ~20 terms per table level)."""
    lead_re = inv_m[0]
    lead_im = inv_m[0] / (p + 2) * theta_max
    mag = inv_m[0]                    # c_m theta_max^m
    n_re = 0
    n_im = 0
    done_re = False
    done_im = False
    m = 0
    while m < 2 * n_max - 1 and not (done_re and done_im):
        if m % 2 == 0:
            if not done_re:
                n_re += 1
                done_re = mag <= _SERIES_EPS * lead_re
        elif not done_im:
            n_im += 1
            done_im = mag <= _SERIES_EPS * lead_im
        m += 1
        mag = mag * theta_max * inv_m[m]
    return n_re, n_im


#: `moments` takes e^{i omega eta} directly (cos, sin) on every DOUBLING_RUN + 1-th level from the finest, and on the
#: coarser levels between from the next finer one by angle doubling (cos 2x = (c - s)(c + s), sin 2x = 2 s c): at most
#: DOUBLING_RUN doublings in a row, each of which about doubles the roundoff (measured on 4,160 frequencies x 12
#: levels against long-double cos/sin of the same float64 angle: direct 5.6e-17, after one doubling 2.8e-16, after
#: two 6.9e-16, after three 1.5e-15, absolute, |e^{i theta}| = 1)
DOUBLING_RUN = 2


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _series_part(theta, x, w, sr, si, ser_re, ser_im, n_re, n_im, inv_l, Kr, Ki, S, j, p, i0, i1):
    """`moments`' series branch for the modes i0..i1-1 of level j: K_p by its series (Horner in theta^2), then the
    downward recurrence K_{l-1} = (1 + i theta K_l)/l, each K_l stored (times w) as soon as it is final and its
    imaginary parts added to S[j, l]."""
    for i in range(i0, i1):
        th = theta[i]
        x[i] = min(th * th, 4.0)
    for i in range(i0, i1):
        sr[p, i] = ser_re[n_re - 1]
        si[p, i] = ser_im[n_im - 1]
    for k in range(n_re - 2, -1, -1):
        ck = ser_re[k]
        for i in range(i0, i1):
            sr[p, i] = sr[p, i] * x[i] + ck
    for k in range(n_im - 2, -1, -1):
        ck = ser_im[k]
        for i in range(i0, i1):
            si[p, i] = si[p, i] * x[i] + ck
    for i in range(i0, i1):
        si[p, i] *= min(max(theta[i], -2.0), 2.0)
    for l in range(p, 0, -1):
        il = inv_l[l]
        acc = 0.0
        for i in range(i0, i1):
            th = min(max(theta[i], -2.0), 2.0)
            a = sr[l, i]
            b = si[l, i]
            sr[l - 1, i] = (1.0 - th * b) * il
            si[l - 1, i] = (th * a) * il
            ki = w[i] * b
            Kr[j, l, i] = w[i] * a
            Ki[j, l, i] = ki
            acc += ki
        S[j, l] += acc
    acc = 0.0
    for i in range(i0, i1):
        ki = w[i] * si[0, i]
        Kr[j, 0, i] = w[i] * sr[0, i]
        Ki[j, 0, i] = ki
        acc += ki
    S[j, 0] += acc


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _upward_part(theta, w, Er, Ei, inv_t, ur, ui, Kr, Ki, S, j, p, i0, i1):
    """`moments`' upward branch for the modes i0..i1-1 of level j (every |theta| >= 2): K_0 = (sin theta + i (1 -
    cos theta)) / theta, K_l = (l K_{l-1} - 1)/(i theta), stored (times w) and their imaginary parts added to
    S[j, l]."""
    for i in range(i0, i1):
        inv_t[i] = 1.0 / theta[i]
    for i in range(i0, i1):
        ur[0, i] = Ei[j, i] * inv_t[i]
        ui[0, i] = (1.0 - Er[j, i]) * inv_t[i]
    for l in range(1, p + 1):
        for i in range(i0, i1):
            ur[l, i] = (l * ui[l - 1, i]) * inv_t[i]
            ui[l, i] = -(l * ur[l - 1, i] - 1.0) * inv_t[i]
    for l in range(p + 1):
        acc = 0.0
        for i in range(i0, i1):
            kr = w[i] * ur[l, i]
            ki = w[i] * ui[l, i]
            Kr[j, l, i] = kr
            Ki[j, l, i] = ki
            acc += ki
        S[j, l] += acc


@njit(cache=True, fastmath=True, error_model="numpy")
def moments(omega: np.ndarray, g: np.ndarray, H: float, J: int, p: int):
    """Per-step tables for step sizes eta_j = H / 2^j (real and imaginary parts apart, modes contiguous).

    Returns Er, Ei [j, i]: e^{i omega_i eta_j}; Kr, Ki [j, l, i]: g_i int_0^eta_j e^{i omega_i (eta_j - s)}
    (s/eta_j)^l ds [m/N], g_i = phi_i^2/(m_i omega_i); S[j, l] = sum_i Ki[j, l, i] [m/N].

    With theta = omega eta and K_l = int_0^1 e^{i theta (1 - s)} s^l ds (the table is g eta K_l):
    |theta| >= 2: upward recurrence K_l = (l K_{l-1} - 1)/(i theta) from K_0 = (e^{i theta} - 1)/(i theta)
    (error growth <= p!/theta^p); |theta| < 2: the series of K_p, sum_m (i theta)^m p!/(p+m+1)! (Horner in
    theta^2, `_series_tables`), then the downward recurrence K_{l-1} = (1 + i theta K_l)/l, stable there. Both
    branches run in loops the compiler vectorises. With the modes in ascending |omega| (the usual order) the modes of
    a level that take the series are a prefix: each branch then runs over its own modes only. Else both run over all
    modes of a level (arguments clamped so that the branch not taken stays finite) and each mode takes its own; a
    level whose modes all take one branch computes only that one. e^{i omega eta} comes from cos and sin on every
    DOUBLING_RUN + 1-th level from the finest and by angle doubling on the others.
    """
    n = omega.shape[0]
    Er = np.empty((J + 1, n))
    Ei = np.empty((J + 1, n))
    Kr = np.empty((J + 1, p + 1, n))
    Ki = np.empty((J + 1, p + 1, n))
    S = np.zeros((J + 1, p + 1))
    inv_l = np.empty(p + 1)
    inv_l[0] = 0.0
    for l in range(1, p + 1):
        inv_l[l] = 1.0 / l
    ser_re = np.zeros(48)
    ser_im = np.zeros(48)
    inv_m = np.empty(96)
    _series_tables(p, ser_re, ser_im, inv_m)
    theta = np.empty(n)
    x = np.empty(n)
    inv_t = np.empty(n)
    w = np.empty(n)
    sr = np.empty((p + 1, n))        # series branch, K_l
    si = np.empty((p + 1, n))
    ur = np.empty((p + 1, n))        # upward branch, K_l
    ui = np.empty((p + 1, n))
    ascending = True
    for i in range(n - 1):
        if not abs(omega[i]) <= abs(omega[i + 1]):
            ascending = False
    for j in range(J, -1, -1):       # e^{i omega eta_j}, from the finest level up
        if (J - j) % (DOUBLING_RUN + 1) == 0:
            eta = H / 2.0**j
            for i in range(n):
                th = omega[i] * eta
                Er[j, i] = np.cos(th)
                Ei[j, i] = np.sin(th)
        else:
            for i in range(n):
                c = Er[j + 1, i]
                s = Ei[j + 1, i]
                Er[j, i] = (c - s) * (c + s)
                Ei[j, i] = 2.0 * s * c
    n_small = 0                      # how many modes take the series (ascending: never fewer on a finer level)
    n_re = 1                         # the series lengths of a level that has series modes
    n_im = 1
    for j in range(J + 1):
        eta = H / 2.0**j
        t_small = 0.0                # the largest |theta| < 2 of the level: the series length
        t_min = np.inf               # the smallest and largest |theta|: which branches the level needs
        t_max = 0.0
        if not ascending:
            n_small = 0
        for i in range(n):
            theta[i] = omega[i] * eta
            w[i] = g[i] * eta
        if ascending and n > 0:      # |theta| ascends: the ends, and the series modes a prefix
            t_min = abs(theta[0])
            t_max = abs(theta[n - 1])
            while n_small < n and abs(theta[n_small]) < 2.0:
                n_small += 1
            if n_small > 0:
                t_small = abs(theta[n_small - 1])
        else:
            for i in range(n):
                a = abs(theta[i])
                if a < 2.0:
                    n_small += 1
                    if a > t_small:
                        t_small = a
                t_min = min(t_min, a)
                t_max = max(t_max, a)
        series = t_min < 2.0         # some mode takes the series branch
        upward = t_max >= 2.0        # some mode takes the upward recurrence
        if series:
            n_re, n_im = _series_length(p, t_small, inv_m, ser_re.shape[0])
        if not upward:               # a series-only level (the finer ones)
            _series_part(theta, x, w, sr, si, ser_re, ser_im, n_re, n_im, inv_l, Kr, Ki, S, j, p, 0, n)
            continue
        if not series:
            _upward_part(theta, w, Er, Ei, inv_t, ur, ui, Kr, Ki, S, j, p, 0, n)
            continue
        if ascending:                # the series modes are 0 .. n_small - 1
            _series_part(theta, x, w, sr, si, ser_re, ser_im, n_re, n_im, inv_l, Kr, Ki, S, j, p, 0, n_small)
            _upward_part(theta, w, Er, Ei, inv_t, ur, ui, Kr, Ki, S, j, p, n_small, n)
            continue
        # modes in any order: both branches over all modes, each mode takes its own
        for i in range(n):
            th = theta[i]
            x[i] = min(th * th, 4.0)
        for i in range(n):
            sr[p, i] = ser_re[n_re - 1]
            si[p, i] = ser_im[n_im - 1]
        for k in range(n_re - 2, -1, -1):
            ck = ser_re[k]
            for i in range(n):
                sr[p, i] = sr[p, i] * x[i] + ck
        for k in range(n_im - 2, -1, -1):
            ck = ser_im[k]
            for i in range(n):
                si[p, i] = si[p, i] * x[i] + ck
        for i in range(n):
            si[p, i] *= min(max(theta[i], -2.0), 2.0)
        for l in range(p, 0, -1):
            il = inv_l[l]
            for i in range(n):
                th = min(max(theta[i], -2.0), 2.0)
                sr[l - 1, i] = (1.0 - th * si[l, i]) * il     # (1 + i theta K_l) / l
                si[l - 1, i] = (th * sr[l, i]) * il
        for i in range(n):
            th = theta[i]
            inv_t[i] = 1.0 / th if abs(th) >= 2.0 else 0.5
        for i in range(n):
            ur[0, i] = Ei[j, i] * inv_t[i]
            ui[0, i] = (1.0 - Er[j, i]) * inv_t[i]
        for l in range(1, p + 1):
            for i in range(n):
                # (l K - 1)/(i theta) = -i (l K - 1)/theta
                ur[l, i] = (l * ui[l - 1, i]) * inv_t[i]
                ui[l, i] = -(l * ur[l - 1, i] - 1.0) * inv_t[i]
        for l in range(p + 1):
            acc = 0.0
            for i in range(n):
                small = abs(theta[i]) < 2.0
                kr = w[i] * (sr[l, i] if small else ur[l, i])
                ki = w[i] * (si[l, i] if small else ui[l, i])
                Kr[j, l, i] = kr
                Ki[j, l, i] = ki
                acc += ki
            S[j, l] = acc
    return Er, Ei, Kr, Ki, S


@njit(cache=True)
def _lagrange_coeffs(sig: np.ndarray, m: int, L: np.ndarray, P: np.ndarray) -> None:
    """L[k, l]: monomial coefficients (power l) of the Lagrange basis polynomial of node k of sig[0..m].

    O(m^2): L_k(s) = P(s) / ((s - sig_k) P'(sig_k)) with P(s) = prod_q (s - sig_q), by synthetic division (one
    division per node: its reciprocal scales the quotient; 26 vs 37 ns for m = 5).
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
        inv = 1.0 / dp
        b = P[m + 1]
        L[k, m] = b * inv
        for l in range(m, 0, -1):
            b = P[l] + sig[k] * b
            L[k, l - 1] = b * inv


#: slots of the stencil cache `run` keeps (direct-mapped; see `stencil_cache`)
STENCIL_SLOTS = 64


@njit(cache=True)
def stencil_cache(p: int) -> np.ndarray:
    """An empty cache of force stencils for `run` (degree p): [slot, k, l] (k, l <= p) the Lagrange coefficients
    L[k, l] of one stencil, [slot, p + 1, 0] its key (-1: empty). A stencil's nodes sit at exact multiples of the
    new step (sizes H / 2^j), so its coefficients depend only on its pattern of step levels (`_stencil_key`):
    one cache serves every run of a solve (the fine, coarse and coarsest runs repeat the same patterns at touch and
    separation, where the graded steps change size), and the key is an integer, so roundoff in the node times
    cannot defeat a lookup."""
    c = np.empty((STENCIL_SLOTS, p + 2, p + 1))
    for q in range(STENCIL_SLOTS):
        c[q, p + 1, 0] = -1.0
    return c


@njit(cache=True)
def _stencil_key(m: int, j: int, glev: np.ndarray) -> int:
    """The integer key of a stencil of m known nodes and the new one: m and the levels glev[0..m-2] (newest first) of
    the steps between the known nodes relative to the new step's level j (6 bits each: levels <= 31)."""
    key = m
    for i in range(m - 1):
        key = key * 64 + (glev[i] - j + 32)
    return key


@njit(cache=True)
def _stencil_slot(key: int) -> int:
    """The cache slot of a stencil key (multiplicative hash, direct-mapped: a slot holds the last key stored there)."""
    return ((key * 2654435761) >> 16) & (STENCIL_SLOTS - 1)


@njit(cache=True)
def _stencil_sig(sig: np.ndarray, m: int, j: int, glev: np.ndarray) -> None:
    """sig[0..m]: the stencil's node positions in units of the new step (level j): the new node at 1, the last known
    node at 0, the earlier ones back by the steps of levels glev[0], glev[1], ... (newest first). Exact: every gap
    is a power of two times the new step."""
    sig[m] = 1.0
    if m > 0:
        sig[m - 1] = 0.0
    for i in range(1, m):
        sig[m - 1 - i] = sig[m - i] - math.ldexp(1.0, j - glev[i - 1])


@njit(cache=True)
def _contact_root(D: float, B: float, alpha: float):
    """(delta, sqrt(delta)): the root delta > 0 of delta + B alpha delta^1.5 = D (D > 0) and its square root.

    With s = sqrt(delta) = sqrt(D) sigma, sigma^2 (1 + e sigma) = 1 (c = B alpha, e = c sqrt(D)). For e <= 0.01 (the
    structure-dominated contact: e ~ 1e-5 .. 2e-3 on the worked beam) sigma - 1 and sigma^2 - 1 are their series in e
    to e^9 (Lagrange inversion; radius of convergence 2/sqrt(27), the first term left out below 2e-18), evaluated by
    Estrin's scheme, so that the root costs a square root and a few multiplications (no division and no Newton loop:
    the root is on the step's dependency chain). Else Newton on s, s^2 (1 + c s) = D (no root per iteration, one
    division) from the smaller of the upper bounds sqrt(D) and (D/c)^(1/3), from which it descends monotonically
    (s^2 (1 + c s) - D is convex and increasing); the error after a step s_k is <= s_k^2 / s (the convexity bound), so
    the loop stops once the step is <= 1e-8 s, or when the steps stop shrinking (roundoff), and a last Newton step on
    delta itself removes the rounding of s^2. Both ways delta and sqrt(delta) are within ~2.2e-16 (relative) of the
    exact root (tests/test_solver_speed_invariance.py)."""
    c = B * alpha
    s = np.sqrt(D)
    e = c * s
    if e <= 0.01:
        e2 = e * e
        e4 = e2 * e2
        # sigma - 1 and sigma^2 - 1 (sigma = s / sqrt(D)) as series in e, Estrin's scheme, truncated below 2e-18;
        # the coefficients are exact dyadic fractions (-1/2, 5/8, -1, 231/128, ...; -1, 3/2, -21/8, 5, -1287/128, ...)
        t = e * ((-0.5 + 0.625 * e) + (-1.0 + 1.8046875 * e) * e2
                 + ((-3.5 + 7.1220703125 * e) + (-15.0 + 32.420257568359375 * e) * e2) * e4 + -71.5 * (e4 * e4))
        q = e * ((-1.0 + 1.5 * e) + (-2.625 + 5.0 * e) * e2
                 + ((-10.0546875 + 21.0 * e) + (-45.1064453125 + 99.0 * e) * e2) * e4 + -221.04721069335938 * (e4 * e4))
        return D + D * q, s + s * t
    elif e > 1.0:
        s2 = np.cbrt(D / c)
        if s2 < s:
            s = s2
    prev = np.inf
    for _ in range(100):
        cs = c * s
        step = (s * s * (1.0 + cs) - D) / (s * (2.0 + 3.0 * cs))
        s -= step
        if s <= 0.0:
            s = 1e-300
        if abs(step) <= 1e-8 * s or abs(step) >= 0.5 * prev:
            break
        prev = abs(step)
    d = s * s
    d += (D - d - c * d * s) / (1.0 + 1.5 * c * s)
    return d, s


@njit(cache=True)
def _solve_contact(D: float, B: float, alpha: float) -> float:
    """Root delta > 0 of delta + B alpha delta^1.5 = D (D > 0): `_contact_root`'s delta."""
    return _contact_root(D, B, alpha)[0]


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _sweep6(Er, Ei, Kr, Ki, jt, coef, yr, yi, zr, zi, ew):
    """Propagate every mode over one step, force polynomial of degree 5 (the scheme's p = 5), in one sweep the compiler
    vectorises, from the state (yr, yi) into (zr, zi): z_i = e^{i omega_i eta} y_i + sum_l K_{l,i} coef_l (tables at
    level jt: Er, Ei [level, mode] e^{i omega eta}; Kr, Ki [level, l, mode] the moments [m/N]; coef [N]: monomial
    coefficients of the force on the step). (yr, yi) stay as they were: `run` keeps the state before the first
    contact's largest node in its buffer instead of copying it, and a sweep into another buffer took 63 ns against 78
    in place for 160 modes (in a compiled loop). Returns (sum_i ew_i |z_i|^2 (twice the modal energy [J]; NaN with ew
    None: runs whose energy series nobody reads, the 2H and 4H runs of an error estimate, where numba prunes the energy
    sum at compile time), sum_i Im(e^{i omega_i eta} z_i) [m]: the free part of the next step's structure displacement
    if that step has the same size, sum_i Im z_i [m]: the structure displacement (`dense_peak`'s sub-steps; a caller
    that ignores it pays nothing, the sweep being inlined)). Inlined into `run` (a call per step cost ~8 % of a run:
    the tables' array structures passed each time)."""
    c0, c1, c2, c3, c4, c5 = coef[0], coef[1], coef[2], coef[3], coef[4], coef[5]
    emod = 0.0
    nxt = 0.0
    ysum = 0.0
    for i in range(yr.shape[0]):
        y_r = yr[i]
        y_i = yi[i]
        er = Er[jt, i]
        ei = Ei[jt, i]
        a = (er * y_r - ei * y_i + Kr[jt, 0, i] * c0 + Kr[jt, 1, i] * c1 + Kr[jt, 2, i] * c2 + Kr[jt, 3, i] * c3
             + Kr[jt, 4, i] * c4 + Kr[jt, 5, i] * c5)
        b = (er * y_i + ei * y_r + Ki[jt, 0, i] * c0 + Ki[jt, 1, i] * c1 + Ki[jt, 2, i] * c2 + Ki[jt, 3, i] * c3
             + Ki[jt, 4, i] * c4 + Ki[jt, 5, i] * c5)
        zr[i] = a
        zi[i] = b
        if ew is not None:
            emod += ew[i] * (a * a + b * b)
        nxt += er * b + ei * a
        ysum += b
    if ew is None:
        emod = np.nan
    return emod, nxt, ysum


@njit(cache=True, fastmath=True, error_model="numpy")
def _sweep(Er, Ei, Kr, Ki, jt, coef, yr, yi, ew, m):
    """`_sweep6` for any degree m (coef[0..m]), in place (y becomes the new state); returns its first two sums."""
    n = yr.shape[0]
    for i in range(n):
        a = Er[jt, i] * yr[i] - Ei[jt, i] * yi[i]
        b = Er[jt, i] * yi[i] + Ei[jt, i] * yr[i]
        yr[i] = a
        yi[i] = b
    for l in range(m + 1):
        cl = coef[l]
        for i in range(n):
            yr[i] += Kr[jt, l, i] * cl
            yi[i] += Ki[jt, l, i] * cl
    emod = 0.0
    nxt = 0.0
    for i in range(n):
        emod += ew[i] * (yr[i] * yr[i] + yi[i] * yi[i])
        nxt += Er[jt, i] * yi[i] + Ei[jt, i] * yr[i]
    return emod, nxt


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _step_sums(acc, a_known, c, S, jt, inv1, inv2, nl):
    """`run`'s sums over the force polynomial's first nl coefficients (known part a_known, new node's c): (acc +
    sum a_l S[jt, l], sum a_l inv1_l, sum a_l inv2_l, sum c_l inv1_l, sum c_l inv2_l, sum c_l S[jt, l]). Inlined, so
    that a literal nl (degree 5: 6) unrolls."""
    wu = 0.0
    wx = 0.0
    cu = 0.0
    cx = 0.0
    cs = 0.0
    for l in range(nl):
        acc += a_known[l] * S[jt, l]
        wu += a_known[l] * inv1[l]
        wx += a_known[l] * inv2[l]
        cu += c[l] * inv1[l]
        cx += c[l] * inv2[l]
        cs += c[l] * S[jt, l]
    return acc, wu, wx, cu, cx, cs


@njit(cache=True, inline="always")
def _hand_over(peak_state, ybuf, keep, pk_node):
    """`run`'s peak_state (when given and a largest node was seen): the kept state's real and imaginary parts and the
    largest node's index."""
    if peak_state is not None and keep >= 0:
        n = ybuf.shape[2]
        for i in range(n):
            peak_state[i] = ybuf[keep, 0, i]
            peak_state[n + i] = ybuf[keep, 1, i]
        peak_state[2 * n] = pk_node


@njit(cache=True, fastmath=True, error_model="numpy")
def run(ew, m0, alpha, v0, R, H, J, p, T_w, window, Er, Ei, Kr, Ki, S, max_nodes, j0=0, omega=None,
        sample_dt=0.0, energy=True, peak_state=None, stencils=None):
    """Integrate from first touch (t = 0, delta = 0, delta' = v0) to the end of the first contact,
    and on for `window` [s] after it when window > 0 (re-contacts included). Step size H/2^j uses
    table level j + j0 (so one table set serves base steps H and H/2).

    In the window, free flight (no force: ball and modes move exactly) advances in jumps of up to
    `sample_dt` [s] (0: no jumps) whenever a jump provably cannot reach a contact: the gap x1 - x2 can
    close no faster than u + sum omega_i |y_i|, and never closes once the ball moves away with
    x1 < -sum |y_i| (free modes keep |y_i|). `omega` [rad/s] is needed for the jumps.

    `energy` None leaves the modal energy out (the energy series is then NaN after the first node; nothing else
    changes): for runs whose series nobody reads. None, not False: numba prunes the branch of a None (or omitted)
    argument at compile time, while a runtime flag keeps both inlined sweeps and made every run ~1.2x slower.

    `peak_state` (float array of 2 n + 1, optional) receives the modes' state at the node BEFORE the first contact's
    largest delta node (real parts, imaginary parts, then that largest node's index), so that `dense_peak` can
    start there instead of sweeping every mode from touch again.

    `stencils` (from `stencil_cache(p)`, optional): the cache of the force stencils' Lagrange coefficients, shared by
    the runs of one solve; each run makes its own when None. The stencil is computed from its step levels (exact
    node positions in units of the step), so the coefficients do not carry the roundoff of the node times.

    Returns (status, n_nodes, t, delta, f, x1, u, energy, flags); flags[k] = 1 where a contact
    starts at node k, 2 where one has ended (first node with delta <= 0).
    Arrays: t [s], delta [m], f [N], x1 ball displacement [m], u ball velocity [m/s], energy [J].
    """
    n = ew.shape[0]
    gam = (p - 0.5) / (p + 1.0)
    # the modal state in one of three buffers: src holds the current state; a step sweeps it into another one, so the
    # state before the first contact's largest node stays in its buffer (keep) instead of being copied at every new
    # largest node (~half the first contact's steps)
    ybuf = np.zeros((3, 2, n))
    src = 0
    keep = -1
    pk_node = 0
    yr = ybuf[0, 0]
    yi = ybuf[0, 1]
    d_top = 0.0                       # the first contact's largest delta so far (for peak_state)
    first_open = True                 # the first contact has not ended yet
    ta = np.empty(max_nodes)
    da = np.empty(max_nodes)
    fa = np.empty(max_nodes)
    xa = np.empty(max_nodes)
    ua = np.empty(max_nodes)
    ea = np.empty(max_nodes)
    flags = np.zeros(max_nodes, dtype=np.int8)
    sig = np.empty(p + 1)
    Pw = np.empty(p + 2)
    glev = np.zeros(max(p, 1), dtype=np.int64)    # levels of the last accepted steps, the newest first
    # a stencil is keyed by its step levels (6 bits each, relative to the new step's): up to degree 10, 31 levels
    keyed = p <= 10 and J + 1 <= 32
    if stencils is None:
        cache = stencil_cache(p)
    else:
        cache = stencils
    a_known = np.empty(p + 1)
    c = np.empty(p + 1)
    coef = np.zeros(p + 1)            # the step's force polynomial, new node included
    free_jt = -1                      # table level at which free_acc = sum_i Im(E_i y_i) holds for the current y
    free_acc = 0.0
    inv1 = np.empty(p + 1)            # 1/(l+1): ball velocity weights
    inv2 = np.empty(p + 1)            # 1/((l+1)(l+2)): ball displacement weights
    for l in range(p + 1):
        inv1[l] = 1.0 / (l + 1)
        inv2[l] = 1.0 / ((l + 1) * (l + 2))
    cu = 0.0
    cx = 0.0

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
    thr = np.empty(J + 1)
    etas[0] = H
    for q in range(1, J + 1):                     # exact halvings: H / 2^q
        etas[q] = etas[q - 1] * 0.5
    for q in range(J + 1):
        thr[q] = T_w * 2.0 ** (-q / gam)
    inv_m0 = 1.0 / m0
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
                free_jt = -1                  # y moved
                j_prev = 0
                count += 1
                if t >= t_end * (1 - 1e-12):
                    _hand_over(peak_state, ybuf, keep, pk_node)
                    return STATUS_OK, count, ta, da, fa, xa, ua, ea, flags
                continue
        # ---------------------------------------------------------------- choose the step
        if in_contact:
            # graded step eta <= H (tau / T_w)^gam towards both ends: level j is allowed where tau >= thr[j] =
            # T_w 2^(-j / gam) (the same rule without a power per step)
            tau = t - ta[seg_start]
            if count - seg_start >= 3 and delta > 0.0:
                # predicted time to separation delta / (-delta') from the quadratic through the last three nodes
                t0, t1, t2 = ta[count - 3], ta[count - 2], ta[count - 1]
                d0, d1, d2 = da[count - 3], da[count - 2], da[count - 1]
                h1 = t1 - t0
                h2 = t2 - t1
                num = d2 * h1 * (2.0 * h2 + h1) - d1 * (h1 + h2) * (h1 + h2) + d0 * h2 * h2    # delta' h1 h2 (h1 + h2)
                if num < 0.0:
                    tau_e = delta * (h1 * h2 * (h1 + h2)) / (-num)
                    if tau_e < tau:
                        tau = tau_e
            j = 0
            while j < J and tau < thr[j]:
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
            # the stencil's Lagrange coefficients: from the cache when its pattern of step levels was seen before
            if keyed:
                key = _stencil_key(m, j, glev)
                slot = _stencil_slot(key)
                if cache[slot, p + 1, 0] != key:
                    _stencil_sig(sig, m, j, glev)
                    _lagrange_coeffs(sig, m, cache[slot], Pw)
                    cache[slot, p + 1, 0] = key
            else:
                slot = 0
                _stencil_sig(sig, m, j, glev)
                _lagrange_coeffs(sig, m, cache[slot], Pw)
                cache[slot, p + 1, 0] = -1.0
            if p == 5 and m == 5:      # the usual stencil, unrolled (straight-line code: 0.74x the scalar cost)
                f0, f1, f2, f3, f4 = fa[first], fa[first + 1], fa[first + 2], fa[first + 3], fa[first + 4]
                for l in range(6):
                    a_known[l] = (cache[slot, 0, l] * f0 + cache[slot, 1, l] * f1 + cache[slot, 2, l] * f2
                                  + cache[slot, 3, l] * f3 + cache[slot, 4, l] * f4)
                    c[l] = cache[slot, 5, l]
            else:
                for l in range(p + 1):
                    a_known[l] = 0.0
                    c[l] = 0.0
                for l in range(m + 1):
                    acc_l = 0.0
                    for k in range(m):
                        acc_l += cache[slot, k, l] * fa[first + k]
                    a_known[l] = acc_l
                    c[l] = cache[slot, m, l]
            # the structure displacement the known part of the force would give: sum_i Im(E_i y_i) plus
            # sum_l a_l S[jt, l] (S = the tables summed over modes); the first sum comes with the last accepted
            # step's sweep when the step size repeats, else from one short sweep here. The modes themselves are
            # updated once per accepted step (below), with the whole force
            if jt == free_jt:
                acc = free_acc           # from the last sweep (same step size)
            else:
                acc = 0.0
                for i in range(n):
                    acc += Er[jt, i] * yi[i] + Ei[jt, i] * yr[i]
            if p == 5:                 # a fixed trip count, unrolled (a_known and c are 0 above m)
                acc, wu, wx, cu, cx, cs = _step_sums(acc, a_known, c, S, jt, inv1, inv2, 6)
            else:
                acc, wu, wx, cu, cx, cs = _step_sums(acc, a_known, c, S, jt, inv1, inv2, m + 1)
            u_pre = u - eta * wu * inv_m0
            x1_pre = x1 + u * eta - eta * eta * wx * inv_m0
            B = eta * eta * cx * inv_m0 + cs + R
            D = x1_pre - acc
            if D <= 0.0:
                d_new = D
                f_new = 0.0
                sq_new = 0.0
            else:
                d_new, sq_new = _contact_root(D, B, alpha)
                f_new = alpha * d_new * sq_new
            if j < J and ((in_contact and d_new <= 0.0) or ((not in_contact) and d_new > 0.0)):
                j += 1          # the step crosses a contact change: retry with half the step
                continue
            break
        # ---------------------------------------------------------------- accept
        if peak_state is not None and first_open and d_new > d_top:
            d_top = d_new                # a new largest node: keep the state before its step (in its buffer)
            keep = src
            pk_node = count
        # every mode over the step in one sweep: y <- E y + sum_l K_l (a_l + c_l f_new), into a free buffer
        for l in range(p + 1):
            coef[l] = a_known[l] + c[l] * f_new if l <= m else 0.0
        dst = 0
        while dst == src or dst == keep:
            dst += 1
        zr = ybuf[dst, 0]
        zi = ybuf[dst, 1]
        if p == 5:
            if energy is not None:
                emod, free_acc, _ = _sweep6(Er, Ei, Kr, Ki, jt, coef, yr, yi, zr, zi, ew)
            else:
                emod, free_acc, _ = _sweep6(Er, Ei, Kr, Ki, jt, coef, yr, yi, zr, zi, None)
        else:
            for i in range(n):
                zr[i] = yr[i]
                zi[i] = yi[i]
            emod, free_acc = _sweep(Er, Ei, Kr, Ki, jt, coef, zr, zi, ew, m)
        src = dst
        yr = zr
        yi = zi
        free_jt = jt
        u = u_pre - eta * f_new * cu * inv_m0
        x1 = x1_pre - eta * eta * f_new * cx * inv_m0
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
            hertz = 0.4 * alpha * delta * delta * sq_new
        ea[count] = 0.5 * m0 * u * u + hertz + 0.5 * emod + 0.5 * R * f * f
        j_prev = j
        for q in range(glev.shape[0] - 1, 0, -1):
            glev[q] = glev[q - 1]
        glev[0] = j
        if in_contact and delta <= 0.0:
            in_contact = False
            first_open = False
            flags[count] = 2
            if t_end < 0.0 and window > 0.0:
                t_end = t + window
            seg_start = count
        elif (not in_contact) and delta > 0.0:
            in_contact = True
            flags[count - 1] = 1
            seg_start = count - 1
            j_prev = J
        count += 1
        if t_end > 0.0:
            if t >= t_end * (1 - 1e-12):
                _hand_over(peak_state, ybuf, keep, pk_node)
                return STATUS_OK, count, ta, da, fa, xa, ua, ea, flags
        elif not in_contact:
            _hand_over(peak_state, ybuf, keep, pk_node)
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
    sign = 1.0                       # (-1)^(l - 1)
    for l in range(1, n):
        d_lo += l * c[l] * sign
        d_hi += l * c[l]
        sign = -sign
    if d_lo > 0.0 and d_hi < 0.0:
        x = _root(c, -1.0, 1.0, True)
    else:   # no interior stationary point: the larger end
        x = -1.0 if _horner(c, -1.0)[0] > _horner(c, 1.0)[0] else 1.0
    return mid + scale * x, _horner(c, x)[0]


@njit(cache=True)
def _peak_near(ts: np.ndarray, ds: np.ndarray, k: int, lo: int, hi: int, need: int) -> float:
    """The larger of ds[k] (the largest sample) and the maximum of the interpolant through samples lo..hi-1
    between k's neighbours, when there are at least `need` samples."""
    dmax = ds[k]
    if hi - lo >= need:
        _, v = peak(ts[lo:hi], ds[lo:hi], ts[max(k - 1, lo)], ts[min(k + 1, hi - 1)])
        if v > dmax:
            dmax = v
    return dmax


@njit(cache=True)
def contacts(t: np.ndarray, d: np.ndarray, flags: np.ndarray, f: np.ndarray, R: float, first_peak=True) -> np.ndarray:
    """Contact phases from a run: rows (t_start, t_end, delta_max) [s, s, m]; t_end = NaN if the
    window ended in contact. Start: linear interpolation over the H/2^J step in which free flight
    (integrated exactly) turned into contact; end: root of the cubic through the last four nodes of the
    gap delta + R f (R [m/N]: residual flexibility, f [N]: the force), which changes sign where delta
    does but, unlike delta = gap - R alpha delta^1.5 near separation, is smooth there (interpolating
    delta itself left an error of order (smallest step)^1.5 in t_m); peak: maximum of the degree-6
    interpolant of delta around the largest node. `first_peak` False leaves the first contact's delta_max NaN (for a
    caller that takes it from `dense_peak`)."""
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
            if row == 0 and not first_peak:
                continue
            pk = s
            for q in range(s, e + 1):
                if d[q] > d[pk]:
                    pk = q
            lo = max(pk - 3, s + 1)
            hi = min(pk + 4, e)
            out[row, 2] = _peak_near(t, d, pk, lo, hi, 3)
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
                                                            Er, Ei, Kr, Ki, S, max_nodes, 0, None, 0.0, None)
    st_c, cnt_c, tc, dc, fc, xc, uc, ec, flc = run(ew, m0, alpha, v0, R, 2.0 * H, J, p, T_w, 0.0,
                                                   Er, Ei, Kr, Ki, S, max_nodes, 1, None, 0.0, None)
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



#: delta_max is refined on sub-steps of 1/2^DENSE_LEVELS of the node steps around the peak (see `dense_peak`)
DENSE_LEVELS = 3
#: node local maxima of delta within this share of the largest node's value are refined too (`dense_peak`): the
#: highest hump's top can be sampled lower than another hump's by its nodes (seen: 2e-3)
PEAK_MARGIN = 0.02


@njit(cache=True)
def _shift(c: np.ndarray, q: float, inv_q: float, out: np.ndarray) -> None:
    """out: monomial coefficients in s of c((s + q) inv_q), i.e. the step's force polynomial (in sigma on [0, 1])
    on the sub-step [q inv_q, (q + 1) inv_q] with its own variable s on [0, 1]."""
    m = c.shape[0]
    sc = 1.0
    for l in range(m):
        out[l] = c[l] * sc
        sc *= inv_q
    for k in range(m - 1):            # Taylor shift by q (repeated synthetic division)
        for l in range(m - 2, k - 1, -1):
            out[l] += q * out[l + 1]


@njit(cache=True, fastmath=True, error_model="numpy")
def dense_peak(t, d, f, x, u, end, Er, Ei, Kr, Ki, ew, j0, H, R, alpha, m0, p, peak_state=None):
    """delta_max of the first contact from the scheme's own solution between its nodes [m].

    The peak of delta was the maximum of the degree-6 interpolant of the node values. delta carries the ringing
    of every mode the contact excites (amplitude ~ s w^-3.5 for a mode, from the t^1.5 onset), which nodes a
    step omega H ~ 2-4 apart cannot interpolate: that was the largest part of the unresolved modes' error in
    delta_m (single modes: ~s w^-3.5, the old table's size). Here the modes are swept again with the run's own
    force polynomials (node 0 to the peak region: exact for them, as in the run), and on the steps around the
    largest node each step is split into 2^DENSE_LEVELS sub-steps (table level + DENSE_LEVELS, the polynomial
    re-expanded on each sub-step), on which delta = x_ball - sum Im y (less the residual spring's R f) is exact
    for the same force; the degree-6 interpolant of the sub-step values around the largest gives the peak.

    A contact with several humps of near-equal height (a heavy ball riding a ringing structure) can have its highest
    peak at a hump whose largest node is not the largest node of the contact (nodes sample a hump's top up to
    ~(omega h)^2 / 8 of the ringing low: seen 2e-3 of delta_m, 17x tol, on a random 4-mode beam whose H and 2H runs
    both took the other hump, so their difference did not show it). Every node local maximum within PEAK_MARGIN of
    the largest node is therefore refined the same way and the highest peak taken; the modes are then swept from
    touch (the run's `peak_state` holds the state next to the largest node only).

    t, d, f, x, u: the run's nodes (time [s], delta [m], force [N], ball displacement [m] and velocity [m/s]) up
    to `end` (the node ending the first contact); tables at level j + j0 for step H / 2^j and energy weights ew, as in
    `run` (the sweep is `run`'s own). With the run's `peak_state` (see `run`) and one hump, the sweep starts at the
    node before the largest one."""
    n = Er.shape[1]
    nlev = Er.shape[0]
    ybuf = np.zeros((2, 2, n))       # the modal state, swept from one buffer into the other (see `_sweep6`)
    src = 0
    yr = ybuf[0, 0]
    yi = ybuf[0, 1]
    if peak_state is not None:
        pk = int(peak_state[2 * n])
    else:
        pk = 0
        for k in range(end):
            if d[k] > d[pk]:
                pk = k
    # the steps refined: the two around the largest node and around every node local maximum near it in height
    low = d[pk] - PEAK_MARGIN * abs(d[pk])
    refine = np.zeros(end + 2, dtype=np.bool_)
    n_humps = 0
    k_hi = 0
    for k in range(1, end):
        if k == pk or (d[k] >= low and d[k] >= d[k - 1] and d[k] >= d[k + 1]):
            n_humps += 1
            refine[k] = True
            refine[min(k + 1, end)] = True
            k_hi = max(k_hi, min(k + 1, end))
    if n_humps == 0:                 # a contact of one node: its step is refined
        refine[min(pk + 1, end)] = True
        k_hi = min(pk + 1, end)
    start = 1
    if peak_state is not None and n_humps <= 1:
        for i in range(n):
            yr[i] = peak_state[i]
            yi[i] = peak_state[n + i]
        start = max(pk - 1, 0) + 1   # the modes are at node pk - 1 already
    n_ref = 0
    for k in range(start, k_hi + 1):
        if refine[k]:
            n_ref += 1
    q1 = p + 1
    ns_max = n_ref * (2 ** DENSE_LEVELS + 1) + 1
    work = np.empty(q1 * q1 + 6 * q1 + 1 + 2 * ns_max)      # one allocation for the small arrays below
    L = work[:q1 * q1].reshape((q1, q1))
    o = q1 * q1
    sig, coef, sub, inv1, inv2 = work[o:o + q1], work[o + q1:o + 2 * q1], work[o + 2 * q1:o + 3 * q1], \
        work[o + 3 * q1:o + 4 * q1], work[o + 4 * q1:o + 5 * q1]
    Pw = work[o + 5 * q1:o + 6 * q1 + 1]
    o += 6 * q1 + 1
    ts, ds = work[o:o + ns_max], work[o + ns_max:o + 2 * ns_max]
    seg = np.empty(n_ref + 1, dtype=np.int64)   # first sample of each run of refined steps, then ns
    n_seg = 0
    for l in range(q1):
        coef[l] = 0.0
        sub[l] = 0.0
        inv1[l] = 1.0 / (l + 1)
        inv2[l] = 1.0 / ((l + 1) * (l + 2))
    inv_m0 = 1.0 / m0
    ns = 0
    x1 = 0.0
    u1 = 0.0
    glev = np.zeros(max(p, 1), dtype=np.int64)     # levels of the steps ending at nodes start - 1, start - 2, ...
    for i in range(glev.shape[0]):
        q = start - 1 - i
        if q >= 1:
            glev[i] = _level(t[q] - t[q - 1], H)
    for k in range(start, k_hi + 1):
        eta = t[k] - t[k - 1]
        lev = _level(eta, H)
        first = max(k - p, 0)
        m = k - first
        _stencil_sig(sig, m, lev, glev)            # the run's own stencil (exact node positions, as in `run`)
        _lagrange_coeffs(sig, m, L, Pw)
        for q in range(glev.shape[0] - 1, 0, -1):
            glev[q] = glev[q - 1]
        glev[0] = lev
        for l in range(p + 1):
            acc = 0.0
            if l <= m:
                for q in range(m + 1):
                    acc += L[q, l] * f[first + q]
            coef[l] = acc
        jt = j0 + lev
        if not refine[k]:
            if p == 5:
                src = 1 - src
                _sweep6(Er, Ei, Kr, Ki, jt, coef, yr, yi, ybuf[src, 0], ybuf[src, 1], None)
                yr = ybuf[src, 0]
                yi = ybuf[src, 1]
            else:
                _sweep(Er, Ei, Kr, Ki, jt, coef, yr, yi, ew, p)
            continue
        if k == start or not refine[k - 1]:        # a run of refined steps starts at node k - 1
            seg[n_seg] = ns
            n_seg += 1
            ts[ns] = t[k - 1]
            ds[ns] = d[k - 1]
            ns += 1
            x1 = x[k - 1]
            u1 = u[k - 1]
        js = min(jt + DENSE_LEVELS, nlev - 1)
        nq = 2 ** (js - jt)
        es = eta / nq
        for q in range(nq):
            _shift(coef, float(q), 1.0 / nq, sub)
            if p == 5:
                src = 1 - src
                _, _, x2 = _sweep6(Er, Ei, Kr, Ki, js, sub, yr, yi, ybuf[src, 0], ybuf[src, 1], None)
                yr = ybuf[src, 0]
                yi = ybuf[src, 1]
            else:
                _sweep(Er, Ei, Kr, Ki, js, sub, yr, yi, ew, p)
                x2 = 0.0
                for i in range(n):
                    x2 += yi[i]
            wu = 0.0
            wx = 0.0
            for l in range(p + 1):
                wu += sub[l] * inv1[l]
                wx += sub[l] * inv2[l]
            x1 = x1 + u1 * es - es * es * wx * inv_m0
            u1 = u1 - es * wu * inv_m0
            gap = x1 - x2
            dv = gap
            if R > 0.0 and gap > 0.0:
                dv = _solve_contact(gap, R, alpha)
            ts[ns] = t[k - 1] + (q + 1) * es
            ds[ns] = dv
            ns += 1
    seg[n_seg] = ns
    dmax = -np.inf
    for b in range(n_seg):
        lo = seg[b]
        hi = seg[b + 1]
        best = lo
        for k in range(lo, hi):
            if ds[k] > ds[best]:
                best = k
        v = _peak_near(ts, ds, best, max(best - 3, lo), min(best + 4, hi), 4)
        if v > dmax:
            dmax = v
    return dmax


@njit(cache=True)
def _level(eta: float, H: float) -> int:
    """The level j of a step eta = H / 2^j of a run (from its node times)."""
    return int(np.round(np.log2(H / eta)))


@njit(cache=True)
def _first_end(fl: np.ndarray) -> int:
    """Index of the node ending the first contact (flag 2), 0 if none."""
    for k in range(fl.shape[0]):
        if fl[k] == 2:
            return k
    return 0


@njit(cache=True)
def solve_triple(omega, g, ew, m0, alpha, v0, R, H, J, p, T_w, max_nodes):
    """`solve_pair` with delta_max of each run's first contact from `dense_peak` (the scheme's own solution between
    nodes) instead of the interpolant of the node values: the fine (base step H), coarse (2H) and coarsest (4H)
    runs of one error estimate. Returns (status, n_nodes and series of the fine run, its contacts, the coarse
    run's, the coarsest run's); contacts rows are (t_start, t_end, delta_max)."""
    Er, Ei, Kr, Ki, S = moments(omega, g, 4.0 * H, J + 2, p)
    # the 2H and 4H runs skip the modal energy (nobody reads it)
    # each run keeps its modes' state next to its largest node, where dense_peak starts
    nm = ew.shape[0]
    pk_cc = np.zeros(2 * nm + 1)
    pk_c = np.zeros(2 * nm + 1)
    pk = np.zeros(2 * nm + 1)
    stencils = stencil_cache(p)          # the three runs repeat their stencils' step patterns
    st_cc, cnt_cc, tcc, dcc, fcc, xcc, ucc, ecc, flcc = run(ew, m0, alpha, v0, R, 4.0 * H, J, p, T_w, 0.0,
                                                            Er, Ei, Kr, Ki, S, max_nodes, 0, None, 0.0, None, pk_cc,
                                                            stencils)
    st_c, cnt_c, tc, dc, fc, xc, uc, ec, flc = run(ew, m0, alpha, v0, R, 2.0 * H, J, p, T_w, 0.0,
                                                   Er, Ei, Kr, Ki, S, max_nodes, 1, None, 0.0, None, pk_c, stencils)
    st, cnt, t, d, f, x, u, e, fl = run(ew, m0, alpha, v0, R, H, J, p, T_w, 0.0, Er, Ei, Kr, Ki, S, max_nodes, 2,
                                        peak_state=pk, stencils=stencils)
    if st != STATUS_OK or st_c != STATUS_OK or st_cc != STATUS_OK:
        z = np.zeros((0, 3))
        return STATUS_OUT_OF_NODES, 0, t, d, f, x, u, e, fl, z, z, z
    fine = _dense_contacts(t, d, f, x, u, fl, cnt, Er, Ei, Kr, Ki, ew, 2, H, R, alpha, m0, p, pk)
    coarse = _dense_contacts(tc, dc, fc, xc, uc, flc, cnt_c, Er, Ei, Kr, Ki, ew, 1, 2.0 * H, R, alpha, m0, p, pk_c)
    coarsest = _dense_contacts(tcc, dcc, fcc, xcc, ucc, flcc, cnt_cc, Er, Ei, Kr, Ki, ew, 0, 4.0 * H, R, alpha, m0, p,
                               pk_cc)
    return (STATUS_OK, cnt, t[:cnt].copy(), d[:cnt].copy(), f[:cnt].copy(), x[:cnt].copy(), u[:cnt].copy(),
            e[:cnt].copy(), fl[:cnt].copy(), fine, coarse, coarsest)


@njit(cache=True)
def _dense_contacts(t, d, f, x, u, fl, cnt, Er, Ei, Kr, Ki, ew, j0, H, R, alpha, m0, p, peak_state=None):
    """`contacts` of one run (its first cnt nodes) with the first contact's delta_max from `dense_peak`."""
    end = _first_end(fl[:cnt])
    c = contacts(t[:cnt], d[:cnt], fl[:cnt], f[:cnt], R, end <= 2)
    if end > 2:
        c[0, 2] = dense_peak(t, d, f, x, u, end, Er, Ei, Kr, Ki, ew, j0, H, R, alpha, m0, p, peak_state)
    return c

#: the observed ratio r = |x_2h - x_4h| / |x_h - x_2h| is trusted only up to r / RATIO_SAFETY: before the scheme is
#: asymptotic (r < 2^(p+1) = 64) the next halving often gains less than the last one did (random scenes: the
#: error of x_h was up to 2.2x above d1 / (r - 1) with r = 13 .. 34)
RATIO_SAFETY = 1.5
#: ratio trusted at most when x_h - x_2h and x_2h - x_4h differ in sign, i.e. the estimate is then d1 (random scenes:
#: the error of x_h was up to d1 / 5.3, e.g. a 1.6 kg ball on a 40-mode beam at tol 1e-4, errors +1.5e-7, +9.5e-7,
#: -8.3e-6 at H, 2H, 4H; without the cushion of the old unresolved-mode table up to 0.58 d1: a two-mode target at tol
#: 1e-8, 1.7x above d1 / 3, the rule before)
FLIP_RATIO = 2.0


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
def _factor(theta: float, sqrt_w: float, theta_tab: np.ndarray, c_tab: np.ndarray, r: int) -> float:
    """`unresolved_factor` with row r of a 2-D table (no row view per call): `_term` from the exact table point."""
    return _term(theta, sqrt_w, theta_tab, c_tab, r, max(np.searchsorted(theta_tab, theta), 1))[1]


@njit(cache=True, inline="always")
def _term(theta: float, sqrt_w: float, theta_tab: np.ndarray, c_tab: np.ndarray, r: int, k: int):
    """(bin, factor) of one mode at phase theta with row r of the table: the bin as `_bin` (0 below the table, k for
    theta in (theta_tab[k-1], theta_tab[k]], len(theta_tab) above) and the factor as `unresolved_factor`. The first
    table point >= theta is walked from k (1 .. len(theta_tab): the previous mode's bin, or the exact point)."""
    nt = theta_tab.shape[0]
    if theta <= theta_tab[0]:
        x = theta / theta_tab[0]
        x2 = x * x
        return 0, c_tab[r, 0] * x2 * x2 * x2
    k = _walk(theta_tab, theta, k)
    if k < nt:
        return k, c_tab[r, k]
    return k, max(c_tab[r, nt - 1], 0.25 * c_tab[r, nt - 1] * sqrt_w)


@njit(cache=True)
def unresolved_factor(theta: float, sqrt_w: float, theta_tab: np.ndarray, c_tab: np.ndarray) -> float:
    """Measured error factor C of one mode at phase theta = omega H per base step (c_tab: one row of the table):
    the value of the first table point >= theta (a step function), ~theta^6 below the table; above it the larger
    of the last value and c_tab[-1] * sqrt(w) / 4 (the error of a stiff unresolved mode falls like w^-3, not
    w^-3.5)."""
    return _factor(theta, sqrt_w, theta_tab, c_tab.reshape((1, c_tab.shape[0])), 0)


@njit(cache=True)
def _bin(theta: float, theta_tab: np.ndarray) -> int:
    """The table bin of theta: k for theta in (theta_tab[k-1], theta_tab[k]], 0 below, len(theta_tab) above."""
    if theta <= theta_tab[0]:
        return 0
    return np.searchsorted(theta_tab, theta)


@njit(cache=True)
def unresolved(s_w: np.ndarray, omega: np.ndarray, sqrt_w: np.ndarray, row: np.ndarray, H: float,
               theta_tab: np.ndarray, c_tab: np.ndarray, plain_sum=None) -> float:
    """The bound for the error of modes the base step H does not resolve, from the per-mode terms
    s_w[i] C_row[i](omega_i H, w_i) (c_tab[r]: the table of modes of coupling class r, row[i] that of mode i): the terms
    of the modes in one theta bin of the table add up (modes of about one frequency err alike: a cluster, or a
    degenerate pair, acts as one mode with their summed s), the bins' sums add in quadrature (the excess of one mode
    changes sign from bin to bin, and modes in different bins do not err in step). Measured with the whole estimate on
    random scenes (seeds 0-3999 and 8000-11999: 0 of 22,924 comparisons above; 4000-7999: 2 of 11,454, 1.69x and 1.17x,
    Richardson before its asymptotic range at tol 1e-4, the second 1.09x with the plain sum), clusters of 2-16
    near-equal modes (0 of 3,106) and single modes (0 of 4,046); the plain sum (`plain_sum` True) was 16-3000x the real
    error of beams of many modes. `plain_sum` True returns that sum (`largest_step`: the first base step, a guess
    that leaves the estimate room)."""
    if plain_sum is not None:
        total = 0.0
        for i in range(omega.shape[0]):
            total += s_w[i] * _factor(omega[i] * H, sqrt_w[i], theta_tab, c_tab, row[i])
        return total
    nt = theta_tab.shape[0]
    nb = nt + 1
    sums = np.zeros(nb)
    k = 1                            # the table point of the previous mode (`_plain_sum`'s walk)
    for i in range(omega.shape[0]):
        # `_bin` and `_factor` with one walk instead of two binary searches (the same bin and value)
        b, c = _term(omega[i] * H, sqrt_w[i], theta_tab, c_tab, row[i], k)
        if b > 0:
            k = b
        sums[b] += s_w[i] * c
    total = 0.0
    for k in range(nb):
        total += sums[k] * sums[k]
    return np.sqrt(total)


@njit(cache=True, inline="always")
def _walk(theta_tab: np.ndarray, theta: float, k: int) -> int:
    """The first table point >= theta (theta > theta_tab[0]: 1 .. len(theta_tab), as np.searchsorted), walked from the
    previous mode's point k: up while the point is below theta, down while the one before is not."""
    nt = theta_tab.shape[0]
    while k < nt and theta_tab[k] < theta:
        k += 1
    while k > 1 and theta_tab[k - 1] >= theta:
        k -= 1
    return k


@njit(cache=True)
def _plain_sum(s_w: np.ndarray, omega: np.ndarray, sqrt_w: np.ndarray, row: np.ndarray, H: float,
               theta_tab: np.ndarray, c_tab: np.ndarray) -> float:
    """`unresolved`'s plain sum (`plain_sum` True), the same terms added in the same order, with each mode's table
    point found by a walk from the previous mode's instead of a binary search: the modes come in ascending frequency
    (a walk of a point or two), and the walk is exact in any order (it steps down as well as up). `largest_step` on the
    worked beam's 160 modes: 7.5 -> 2.4 us."""
    total = 0.0
    k = 1                                   # the first point >= theta of the previous mode (1 .. nt)
    for i in range(omega.shape[0]):
        b, c = _term(omega[i] * H, sqrt_w[i], theta_tab, c_tab, row[i], k)
        if b > 0:
            k = b
        total += s_w[i] * c
    return total


@njit(cache=True)
def _step_sum(s_w, omega, sqrt_w, row, H: float, theta_tab, c_tab, binary_search=None) -> float:
    """largest_step's plain sum: `_plain_sum`'s walk, or with `binary_search` given `unresolved`'s (the same value;
    None is pruned at compile time)."""
    if binary_search is None:
        return _plain_sum(s_w, omega, sqrt_w, row, H, theta_tab, c_tab)
    return unresolved(s_w, omega, sqrt_w, row, H, theta_tab, c_tab, True)


@njit(cache=True)
def largest_step(s_w: np.ndarray, omega: np.ndarray, sqrt_w: np.ndarray, row: np.ndarray, H: float, theta_tab,
                 c_tab, target: float, binary_search=None) -> float:
    """The largest base step <= H whose plain sum of unresolved-mode terms is <= target (bisection in log H): the first
    base step of solve_auto. The plain sum (not the reported binned quadrature sum) starts where the Richardson part of
    the estimate is likely to pass too: started from the smaller quadrature sum, the first estimate failed more often
    and the retry cost a second set of runs (the 160-mode worked beam at tol 1e-6: 245 against 130 us). The sum is
    `_plain_sum` (the same value as `unresolved`'s, found faster); with `binary_search` given (any value: tests only),
    `unresolved`'s own plain sum, a binary search of the table per mode (largest_step until round 8)."""
    if _step_sum(s_w, omega, sqrt_w, row, H, theta_tab, c_tab, binary_search) <= target:
        return H
    lo = H * 0.125 if H > 1e-30 else H      # the sum at H is above target (just checked)
    while _step_sum(s_w, omega, sqrt_w, row, lo, theta_tab, c_tab, binary_search) > target and lo > 1e-30:
        lo *= 0.125
    hi = H
    for _ in range(60):
        mid = np.sqrt(lo * hi)
        if _step_sum(s_w, omega, sqrt_w, row, mid, theta_tab, c_tab, binary_search) > target:
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
#: the light-mode factor is at most 1 + LIGHT_CAP (the largest factor needed on random scenes was 1.26)
LIGHT_CAP = 0.5


#: the smallest steps' error bound may be at most this share of the rest of the estimate (else more step levels)
SMALLEST_SHARE = 0.1
#: a first contact shorter than this fraction of the time scale used so far (t_plate at first) is solved again with
#: the step rules (min_steps, smallest step, its error bound) taken from its own duration
SHORT_CONTACT = 0.9
#: at most this many levels are added before the runs for the smallest steps' bound (more after them where needed)
PRE_LEVELS = 3


@njit(cache=True)
def _estimate(omega, g, ew, m0, alpha, v0, R, H, J, p, T_w, n, node_cap, est_order):
    """`solve_triple` at base step H with J levels (more nodes allowed until it fits the first contact's budget) and
    the Richardson estimate of the fine run's relative error (the larger of t_m's and 1.5x delta_m's)."""
    cap = node_cap // 4             # the first contact: a quarter of a window's budget
    max_nodes = min(int(6 * n + 60 * J + 50), cap)
    while True:
        out = solve_triple(omega, g, ew, m0, alpha, v0, R, H, J, p, T_w, max_nodes)
        if out[0] == STATUS_OK or max_nodes >= cap:
            break
        max_nodes = min(4 * max_nodes, cap)
    if out[0] != STATUS_OK:
        return out, np.inf
    fine, coarse, coarsest = out[9], out[10], out[11]
    tm_f = fine[0, 1] - fine[0, 0]
    dm_f = fine[0, 2]
    # relative; f_m = alpha delta_m^1.5 moves 1.5x as much as delta_m
    rel_t = richardson(tm_f, coarse[0, 1] - coarse[0, 0], coarsest[0, 1] - coarsest[0, 0], est_order) / tm_f
    rel_d = richardson(dm_f, coarse[0, 2], coarsest[0, 2], est_order) / dm_f
    return out, max(rel_t, 1.5 * rel_d)


@njit(cache=True)
def solve_auto(omega, g, ew, m0, alpha, v0, R, tol, window, t_plate, delta_plate, p, grading, n0,
               est_order, theta_tab, c_tab, smallest_factor, unresolved_share=0.25,
               node_cap=4000000, series_samples=SERIES_SAMPLES, light_coupling=0.0, class_s=None, min_steps=0.0,
               smallest_c=0.0):
    """The whole time-step control in one compiled call (see solve.solve_modes for the rules).

    Returns (status, n_nodes, t, delta, f, x_ball, u_ball, energy, flags, contacts, rel_uncertainty,
    base step count n, index of the node ending the first contact, largest |E/E0 - 1|).
    """
    # weights of the unresolved-mode bound: C(omega H) s w^-3.5, s = m0 g omega, w = omega delta/v0
    nm = omega.shape[0]
    s_w = np.empty(nm)
    sqrt_w = np.empty(nm)
    omega_c = np.empty(nm)
    # the table row of each mode: its coupling class, the number of class bounds class_s below its s (row 0 without)
    row = np.zeros(nm, dtype=np.int64)
    k_t = 1.5 * alpha * np.sqrt(delta_plate)
    for i in range(nm):
        w = omega[i] * delta_plate / v0
        sq = np.sqrt(w)
        sqrt_w[i] = sq
        # w^-3.5 as 1 / (w^3 sqrt(w)) (a power call per mode cost 0.7 us of 1.3 on 160 modes; within 4e-16)
        s_w[i] = m0 * g[i] * omega[i] / (w * w * w * sq) if w > 1.0 else m0 * g[i] * omega[i]  # below: weight s
        if class_s is not None:
            for b in range(class_s.shape[0]):
                if m0 * g[i] * omega[i] > class_s[b] and row[i] < c_tab.shape[0] - 1:
                    row[i] += 1
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
    n = max(n0, min_steps)
    if nm > 0:
        n = t_plate / largest_step(s_w, omega_c, sqrt_w, row, t_plate / n, theta_tab, c_tab,
                                     unresolved_share * tol)
    t_ref = t_plate             # the contact's time scale: t_plate, or the first contact's duration once a run found it
    rel = np.inf                # shorter (SHORT_CONTACT); inf if every try was redone (never seen)
    # the try with the smallest estimate so far: returned (its estimate above tol) when a finer try would not fit the
    # node budget, e.g. a long contact at tol 1e-12, whose estimate stops at roundoff (seen: 0.3 % of random scenes)
    best_rel = np.inf
    best_n = n
    best_J = 0
    for _ in range(12):
        H = t_plate / n
        J = levels(n * t_ref / t_plate, tol, smallest_factor)
        unres = unresolved(s_w, omega_c, sqrt_w, row, H, theta_tab, c_tab)    # the modes H does not resolve (bound)
        if smallest_c > 0.0:
            # up to PRE_LEVELS more levels before the runs, so that the smallest steps' bound stays within
            # SMALLEST_SHARE of what the estimate will at least be (the unresolved-mode bound, or the a-priori error
            # at n steps): a level costs a few nodes, a second set of runs as many as the first
            floor = max(unres, tol * min(1.0, (n0 / n) ** 6))
            for _ in range(PRE_LEVELS):
                if J >= 30 or smallest_c * (H / 2.0**J / t_ref) ** 2.5 <= SMALLEST_SHARE * floor:
                    break
                J += 1
        while True:
            out, core = _estimate(omega, g, ew, m0, alpha, v0, R, H, J, p, grading * t_plate, n, node_cap, est_order)
            core += unres
            st, cnt, t, d, f, x, u, e, fl, fine, coarse, coarsest = out
            if st != STATUS_OK:
                break
            # the error of the smallest steps (touch, separation), order 2.5 in the smallest step H / 2^J: it shows in
            # the three runs' differences at ratio 5.7 only, below the ratio the Richardson estimate trusts, so it is
            # bounded apart; where it could pass SMALLEST_SHARE of the rest (a base step far shorter than tol needs),
            # the runs are made again with more levels until it cannot
            small = smallest_c * (H / 2.0**J / t_ref) ** 2.5
            if small <= SMALLEST_SHARE * core or J >= 30 or core <= 0.0 or core / tol > 1.0 - SMALLEST_SHARE:
                break
            J = min(30, J + int(np.ceil(np.log(small / (SMALLEST_SHARE * core)) / np.log(2.0**2.5))))
        if st != STATUS_OK:
            if best_rel == np.inf:
                return st, cnt, t, d, f, x, u, e, fl, fine, np.inf, n, 0, np.inf
            n, J, rel = best_n, best_J, best_rel     # the finer try did not fit: the best one so far, made again
            H = t_plate / n
            out, _ = _estimate(omega, g, ew, m0, alpha, v0, R, H, J, p, grading * t_plate, n, node_cap, est_order)
            st, cnt, t, d, f, x, u, e, fl, fine, coarse, coarsest = out
            break
        # a contact much shorter than t_plate (a ball on strongly coupled light modes, which move with it like a
        # lighter target) takes its rules from its own duration: at least min_steps base steps and the smallest step
        # from it (the smallest steps' error scales with their length relative to the contact)
        t_contact = out[9][0, 1] - out[9][0, 0]
        if 0.0 < t_contact < SHORT_CONTACT * t_ref and n < 1e6:
            t_ref = t_contact
            n = max(n, min_steps * t_plate / t_ref)
            continue
        rel = core + small
        if rel < best_rel:
            best_rel, best_n, best_J = rel, n, J
        ratio = rel / tol
        if ratio <= 1.0 or n > 1e6:
            break
        grow = 1.1 * ratio ** (1.0 / est_order)
        n *= min(max(1.25, grow), 4.0)
    if window > 0.0:
        # the window once, at the chosen step (the same tables, so the first contact is the same run's)
        Er, Ei, Kr, Ki, S = moments(omega, g, 4.0 * H, J + 2, p)
        max_nodes = int(6 * n + 60 * J + 50 + 3 * min(series_samples, 1e6) + min(2.5 * window / H, 1e6))
        pk = np.zeros(2 * ew.shape[0] + 1)      # the modes next to the first contact's largest node (dense_peak)
        while True:
            max_nodes = min(max_nodes, node_cap)
            st, cnt, t, d, f, x, u, e, fl = run(ew, m0, alpha, v0, R, H, J, p, grading * t_plate, window,
                                                Er, Ei, Kr, Ki, S, max_nodes, 2, omega, window / series_samples,
                                                peak_state=pk)
            if st == STATUS_OK or max_nodes >= node_cap:
                break
            max_nodes *= 4
        if st != STATUS_OK:
            return st, cnt, t, d, f, x, u, e, fl, fine, rel, n, 0, np.inf
        t, d, f, x, u, e, fl = t[:cnt].copy(), d[:cnt].copy(), f[:cnt].copy(), x[:cnt].copy(), u[:cnt].copy(), \
            e[:cnt].copy(), fl[:cnt].copy()
        fine = contacts(t, d, fl, f, R)
        end = _first_end(fl)
        if end > 2:         # the first contact's peak as in the estimate (the same run up to there)
            fine[0, 2] = dense_peak(t, d, f, x, u, end, Er, Ei, Kr, Ki, ew, 2, H, R, alpha, m0, p, pk)
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


@njit(cache=True)
def solve_auto_packed(*args):
    """`solve_auto` (the same arguments) with its series packed for the caller in Python: numba boxes each returned
    array apart (~0.3 us each), so the six node series plus the structure displacement come back as the rows of one
    array. Returns (status, n_nodes, series [7, n_nodes]: t [s], delta [m], f [N], x_ball [m], u_ball [m/s],
    energy [J], x_structure = x_ball - delta [m]; contacts, rel_uncertainty, base step count n, index of the node
    ending the first contact, largest |E/E0 - 1|, largest |x_structure| [m]), as `solve_auto` (the flags, which the
    caller does not need, are left out: each boxed array also costs an unpickling of its type, ~0.5 us; the largest
    displacement, for the small-deflection check, costs ~4 us in numpy after the call and nothing here)."""
    st, cnt, t, d, f, x, u, e, fl, fine, rel, n, end, drift = solve_auto(*args)
    cnt_out = min(cnt, t.shape[0])
    series = np.empty((7, cnt_out))
    w_max = 0.0
    for i in range(cnt_out):
        w = x[i] - d[i]
        series[6, i] = w
        if abs(w) > w_max:
            w_max = abs(w)
    series[0, :] = t[:cnt_out]
    series[1, :] = d[:cnt_out]
    series[2, :] = f[:cnt_out]
    series[3, :] = x[:cnt_out]
    series[4, :] = u[:cnt_out]
    series[5, :] = e[:cnt_out]
    return st, cnt, series, fine, rel, n, end, drift, w_max
