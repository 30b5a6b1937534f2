"""Exact linear theory (paper sec. 6, eq. 47-69; physics.md sec. 4): Hertz replaced by a linear spring.

The contact law is f = k * delta (delta > 0), with the energy-equivalent spring of the rigid-plate
impact k0 = (4/5) alpha delta_m^(1/2) by default (eq. 47-49), so omega0 = sqrt(k0/m0) = v0/delta_m.
This is the contact model of MuJoCo- and Bullet-style soft contacts: a report splits an engine's
error into the *model-form* error (this linear law vs Hertz) and the *numerical* error (engine vs
this solution for the same k).

Method (no time stepping). Coordinates z = (x1, q_1..q_n): ball displacement and modal coordinates.
During contact the system is linear with mass M = diag(m0, m_1..m_n) and stiffness
K = k_s b b^T + diag(0, m_i omega_i^2), b = (1, -phi_10, ..., -phi_n0), so that b^T z = x1 - x2 is the
relative approach. The secular equation of this diagonal-plus-rank-one pencil (`_secular`) gives p_k^2 and
M-orthonormal vectors U; then
z(t) = U [ (U^T M z0) cos p t + (U^T M z0') sin(p t)/p ], a sum of sines for the impact data
x1(0) = q(0) = 0, x1'(0) = v0, q'(0) = 0 (eq. 63-69). The contact ends at the first root t > 0
of delta(t), bracketed on a fine grid and refined by brentq; the peak is a root of delta'(t).

Residual static flexibility R of dropped beam modes (automatic mode count only): the contact point
then moves by x2 = sum phi_i q_i + R f, so the contact spring k and R act in series. With a linear
law this is exact: f = k delta = k_s (x1 - sum phi q), k_s = k/(1 + k R), and delta = b^T z/(1 + k R).
(For Hertz the reference uses the same correction; for the linear law it is no approximation.)

After separation (window > 0) the ball flies freely and the modes vibrate freely (closed form); a
re-contact starts at the next upward zero of the gap and is solved from its state in the same way.

Memory: with distinct frequencies U is never stored. Its columns are explicit from the secular equation,
U[:, k] ~ C_k b_j / m_j / (d_j - lam_k) (a Cauchy-like matrix), so `LinearSystem` keeps O(modes) numbers (lam as
pole + offset, C, the sorted d, b/m) and forms U^T M z0 (a contact's start) and U a (its end state) a block of
columns at a time, each d_j - lam_k as (d_j - d_origin) - mu like the roots; the series needs only U's rows for x1
and phi^T q (`x1_row`, `x2_row`, made in the roots' own pass), and the first contact's start (the ball's velocity
alone) only U's row 0. Measured on tests/data/plate_thousands_of_modes.toml (`solve_linear`, automatic count up to
7,424 modes): peak RSS 280 MB instead of 928-963 MB with U stored (441 MB a copy at 7,425 modes; the imports alone
take 135 MB), the same time within this shared machine's noise (26 s vs 23 s wall; interleaved, linear_system at
7,424 modes took 5-12 s either way) and the same metrics to the last bit. On catalogue and random beams and plates
the results equal the stored-U solution's within 4e-16 (metrics) and 3e-13 (series over nine re-contacts).
Repeated frequencies are merged first (`merge_repeated_modes`: exact for the contact); only a mode of zero frequency
(the ball's own pole) still takes a dense eigh and keeps U, O(modes^2).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from scipy import linalg, optimize

from impactval.errors import ImpactvalError
from impactval.reference.beams import Modes
from impactval.reference.hertz import plate_impact
from impactval.reference.result import Contact, ImpactResult, Metrics

#: grid points per estimated contact time used to bracket roots (and to sample the series)
GRID_PER_CONTACT = 4000
#: the automatic mode count doubles until the n- and 2n-mode models agree within tol or 2n reaches this (n is kept;
#: a 7,424-mode plate takes ~16 s and ~0.3 GB, U not stored): beyond it the result says its uncertainty is above tol
LINEAR_MODE_CAP = 4096
#: give up looking for the end of a contact after this many estimated contact times
MAX_CONTACT_TIMES = 200.0


@dataclass(frozen=True)
class LinearSystem:
    """Ball + n modes with a linear contact spring, diagonalised.

    `p` [rad/s] natural frequencies in contact, `bU` = b^T U / (1 + k R) (contact approach per modal coordinate),
    `mass_diag` [kg], `omega` [rad/s] and `phi` [-] of the kept modes, `k` [N/m] the contact stiffness, `R` [m/N]
    residual flexibility; `x1_row` = U[0] (ball displacement per eigen-coordinate) and `x2_row` = phi^T U[1:] (the
    modes' displacement at the contact point per eigen-coordinate). U, the M-orthonormal eigenvectors (columns), is
    applied by `project` (U^T Y) and `expand` (U X); the `U` property forms it (O(modes^2): small systems, tests).

    Distinct frequencies (the rank-one path, `_secular`): U is not stored. Its columns are explicit,
    U[order[j], k] = w_j C_k / ((d_j - d_origin_k) - mu_k) (a Cauchy-like matrix: `d` the sorted d = (0, omega^2),
    `w` = sign(b_j) |b_j| / m_j in that order, lam_k = d_origin_k + mu_k), so the system keeps O(modes) numbers
    and `project`/`expand` form the kernel a block of columns at a time (`_BLOCK_ENTRIES`), each d_j - lam_k in
    the same full-relative-accuracy form as the roots (7,425 modes: U was 441 MB). Repeated poles left after
    `merge_repeated_modes` (a zero-frequency mode; the dense path, `linalg.eigh`): `dense` holds U, O(modes^2).
    """

    p: np.ndarray
    bU: np.ndarray
    mass_diag: np.ndarray
    omega: np.ndarray
    phi: np.ndarray
    k: float
    R: float
    x1_row: np.ndarray
    x2_row: np.ndarray
    dense: np.ndarray | None = None       # U itself (repeated frequencies only)
    order: np.ndarray | None = None       # rows of U in ascending d (None: the identity)
    d: np.ndarray | None = None           # sorted d
    origin: np.ndarray | None = None      # the pole each root is measured from (index into d)
    mu: np.ndarray | None = None          # lam - d[origin]
    C: np.ndarray | None = None           # column scales
    w: np.ndarray | None = None           # row scales sign(b) |b| / m (sorted)

    def project(self, Y: np.ndarray) -> np.ndarray:
        """U^T Y for Y [modes + 1] or [modes + 1, r] (a Y with few nonzero rows, e.g. the first contact's ball
        velocity alone, from those rows of U only: O(modes) each)."""
        if self.dense is not None:
            return self.dense.T @ Y
        Y = np.asarray(Y, float)
        nz = np.flatnonzero(Y if Y.ndim == 1 else np.any(Y != 0.0, axis=1))
        if 8 * len(nz) <= len(Y):
            return self.rows(nz).T @ Y[nz]
        Ys = (Y if self.order is None else Y[self.order]) * (self.w if Y.ndim == 1 else self.w[:, None])
        out = np.empty(Y.shape)
        for sl, inv in _cauchy_blocks(self.d, self.origin, self.mu):
            out[sl] = inv.T @ Ys
        return out * (self.C if Y.ndim == 1 else self.C[:, None])

    def expand(self, X: np.ndarray) -> np.ndarray:
        """U X for X [modes + 1] or [modes + 1, r]."""
        if self.dense is not None:
            return self.dense @ X
        X = np.asarray(X, float)
        Xc = X * (self.C if X.ndim == 1 else self.C[:, None])
        acc = np.zeros(X.shape)
        for sl, inv in _cauchy_blocks(self.d, self.origin, self.mu):
            acc += inv @ Xc[sl]
        acc *= self.w if X.ndim == 1 else self.w[:, None]
        if self.order is None:
            return acc
        out = np.empty_like(acc)
        out[self.order] = acc
        return out

    def rows(self, idx: np.ndarray) -> np.ndarray:
        """U[idx] (rows of the original coordinates), [len(idx), modes + 1]."""
        idx = np.asarray(idx, dtype=np.intp)
        if self.dense is not None:
            return self.dense[idx]
        if self.order is None:
            j = idx
        else:
            where = np.empty_like(self.order)
            where[self.order] = np.arange(len(self.order))
            j = where[idx]
        diff = (self.d[j][:, None] - self.d[self.origin][None, :]) - self.mu[None, :]
        diff[diff == 0.0] = np.finfo(float).tiny
        return self.w[j][:, None] * (self.C[None, :] / diff)

    @property
    def U(self) -> np.ndarray:
        """The eigenvectors as one (modes + 1)^2 matrix, formed on demand (small systems, tests)."""
        if self.dense is not None:
            return self.dense
        return self.expand(np.eye(len(self.p)))


def _cauchy_blocks(d: np.ndarray, origin: np.ndarray, mu: np.ndarray):
    """The kernel 1 / (d_j - lam_k) of a rank-one path's eigenvectors, a block of columns k at a time (slice, [rows,
    block]; at most `_BLOCK_ENTRIES` entries), d_j - lam_k formed as (d_j - d_origin) - mu like the roots themselves
    (full relative accuracy; an exact pole hit, impossible with beta2 > 0, kept finite as `_secular` does)."""
    n1 = len(d)
    block = max(1, int(_BLOCK_ENTRIES // max(n1, 1)))
    for c0 in range(0, n1, block):
        sl = slice(c0, min(c0 + block, n1))
        diff = (d[:, None] - d[origin[sl]][None, :]) - mu[sl][None, :]
        diff[diff == 0.0] = np.finfo(float).tiny
        np.divide(1.0, diff, out=diff)
        yield sl, diff


#: modes whose squared frequencies differ by at most this fraction are one frequency (the secular equation's poles
#: must be distinct; `merge_repeated_modes`)
REPEATED = 1e-12


def merge_repeated_modes(omega: np.ndarray, phi: np.ndarray, modal_mass: np.ndarray):
    """(omega, phi, modal_mass) with each group of modes of one frequency (squared frequencies within REPEATED) made one
    mode of that frequency with phi = 1 and 1 / modal_mass = sum phi_i^2 / m_i: the contact point's displacement
    sum phi_i q_i of the group obeys (d^2/dt^2 + omega^2) x = (sum phi_i^2 / m_i) f, one mode's equation, and the
    group's other combinations are never excited (the only force acts through the contact point, from rest), so
    the impact, its re-contacts and x2 are exactly those of the merged mode. Plates of a rational aspect ratio
    have such pairs (0.33 x 0.21 m, 11:7): their 4,096-mode linear solve took a dense eigh, O(modes^3) (45 s), not
    the secular equation's O(modes^2). Groups of one stay as they are (same arrays, same order)."""
    if len(omega) < 2:
        return omega, phi, modal_mass
    d = omega**2
    order = np.argsort(d)
    ds = d[order]
    same = np.diff(ds) <= REPEATED * ds[1:]
    if not np.any(same):
        return omega, phi, modal_mass
    starts = np.flatnonzero(np.concatenate(([True], ~same)))      # first member of each group (sorted order)
    g = (phi**2 / modal_mass)[order]
    g_sum = np.add.reduceat(g, starts)
    sizes = np.diff(np.append(starts, len(ds)))
    first = order[starts]
    new_phi = np.where(sizes > 1, 1.0, phi[first])
    new_m = np.where(sizes > 1, 1.0 / g_sum, modal_mass[first])
    return omega[first], new_phi, new_m


def linear_system(modes: Modes, mass: float, k: float) -> LinearSystem:
    """Build and diagonalise the ball + modes system in contact (spring `k` [N/m], ball `mass` [kg])."""
    # modes with |phi| <= 1e-8 at the impact point (nodes, e.g. even modes at mid-span, up to rounding)
    # contribute ~phi^2 <= 1e-16 relative and would put roots of the secular equation on its poles
    keep = np.abs(modes.phi) > 1e-8
    omega = np.asarray(modes.omega, float)[keep]
    phi = np.asarray(modes.phi, float)[keep]
    mm = np.asarray(modes.modal_mass, float)[keep]
    omega, phi, mm = merge_repeated_modes(omega, phi, mm)
    R = float(modes.residual_flexibility)
    ks = k / (1.0 + k * R)
    b = np.concatenate(([1.0], -phi))
    mass_diag = np.concatenate(([mass], mm))
    sq = np.sqrt(mass_diag)
    bt = b / sq                               # b in mass-scaled coordinates
    d = np.concatenate(([0.0], omega**2))
    order = np.argsort(d)
    ds = d[order]
    if len(ds) > 1 and np.any(np.diff(ds) <= REPEATED * ds[1:]):
        # repeated poles left after merge_repeated_modes (a mode of zero frequency, the ball's own): the rank-one
        # structure is degenerate; dense solver, U kept whole (O(modes^2))
        lam, V = linalg.eigh(np.diag(d) + ks * np.outer(bt, bt))
        if np.any(lam <= 0):
            raise ImpactvalError("linear theory: the contact system is not positive definite (check k and modes).")
        U = V / sq[:, None]
        return LinearSystem(np.sqrt(lam), (b @ U) / (1.0 + k * R), mass_diag, omega, phi, float(k), R,
                            U[0].copy(), phi @ U[1:], dense=U)
    # rank-one path: O(modes) numbers kept, U applied as a Cauchy-like kernel (see LinearSystem); U[:, k] =
    # (sign(bt)/sq)[order] * V[:, k] with V from the secular equation, rows unsorted by `order`
    w = (np.sign(bt) / sq)[order] * np.sqrt(bt[order] ** 2)
    e = np.zeros((len(d), 2))
    e[0, 0] = 1.0                             # x1 = z[0]
    e[1:, 1] = phi                            # x2 = phi^T z[1:]
    ident = np.array_equal(order, np.arange(len(order)))
    lam, origin, mu, C, rows = _secular_parts(ds, bt[order] ** 2, ks, e[order] * (np.sign(bt) / sq)[order][:, None])
    return LinearSystem(np.sqrt(lam), (-C / ks) / (1.0 + k * R), mass_diag, omega, phi, float(k), R,
                        rows[:, 0].copy(), rows[:, 1].copy(), order=None if ident else order, d=ds, origin=origin,
                        mu=mu, C=C, w=w)


def _secular(d: np.ndarray, beta2: np.ndarray, ks: float):
    """Eigenpairs of diag(d) + ks * b b^T (d ascending, distinct; beta2 = b^2 > 0) from the secular
    equation 1 + ks * sum_j beta2_j / (d_j - lam) = 0 (the paper's characteristic equation, eq. 60-62).

    Each root lies in (d_k, d_k+1) (the last above d_n); it is found by bisection in mu = lam - d_o
    measured from the nearer pole d_o, so every d_j - lam = (d_j - d_o) - mu keeps full relative
    accuracy. Eigenvectors v_j = C b_j/(d_j - lam) (for |b| components; signs restored by the caller),
    C = 1/sqrt(sum beta2/(d - lam)^2), and b.v = -C/ks exactly. A dense eigh loses absolute accuracy
    ~ eps * max(d) in the low eigenvalues, which matters with thousands of beam modes; this does not.
    Returns (lam, V with |b| instead of b, b.v): V whole, O(n^2) (tests, small systems; `linear_system` keeps
    `_secular_parts`' O(n) description instead).
    """
    lam, origin, mu, C, _ = _secular_parts(d, beta2, ks)
    V = np.empty((len(d), len(d)))
    sb = np.sqrt(beta2)
    for sl, inv in _cauchy_blocks(d, origin, mu):
        V[:, sl] = (sb[:, None] * inv) * C[sl]
    return lam, V, -C / ks


def _secular_parts(d: np.ndarray, beta2: np.ndarray, ks: float, Y: np.ndarray | None = None):
    """`_secular`'s eigenpairs as O(n) numbers: (lam, origin, mu, C, V^T Y) with lam = d[origin] + mu and
    V[j, k] = C_k sqrt(beta2_j) / ((d_j - d[origin_k]) - mu_k); V^T Y (Y [n, r], None for none) made from the same
    blocks of the kernel as C (no second pass)."""
    n1 = len(d)
    hi_gap = np.append(np.diff(d), ks * float(np.sum(beta2)))    # last root in (d_n, d_n + ks |b|^2]
    out_lam = np.empty(n1)
    out_origin = np.empty(n1, dtype=np.intp)
    out_mu = np.empty(n1)
    out_C = np.empty(n1)
    sb = np.sqrt(beta2)
    proj = None if Y is None else np.empty((n1, Y.shape[1]))
    chunk = max(1, int(_BLOCK_ENTRIES // n1))     # roots a block: a few [n1, chunk] arrays at a time
    for c0 in range(0, n1, chunk):
        ks_ = np.arange(c0, min(c0 + chunk, n1))
        gap = hi_gap[ks_]
        last = ks_ == n1 - 1

        def g(origin_idx, mu):
            diff = (d[:, None] - d[origin_idx][None, :]) - mu[None, :]
            return 1.0 + ks * np.sum(beta2[:, None] / diff, axis=0), diff

        # which half: left pole (origin k, mu in (0, gap/2]) or right pole (origin k+1, mu in [-gap/2, 0))
        mid_val, _ = g(ks_, 0.5 * gap)
        left = (mid_val >= 0) | last
        origin = np.where(left, ks_, np.minimum(ks_ + 1, n1 - 1))
        lo = np.where(left, 0.0, -0.5 * gap)
        hi = np.where(left, np.where(last, gap, 0.5 * gap), 0.0)
        mu = _secular_roots(d, beta2, ks, origin, np.where(left, hi, lo), lo, hi)
        _, diff = g(origin, mu)
        # guard against an exact hit of a pole (cannot happen with beta2 > 0, but keep finite)
        diff = np.where(diff == 0.0, np.finfo(float).tiny, diff)
        Vc = sb[:, None] / diff
        C = 1.0 / np.sqrt(np.sum(Vc**2, axis=0))
        if proj is not None:
            proj[ks_] = (Y.T @ Vc).T * C[:, None]
        out_C[ks_] = C
        out_origin[ks_] = origin
        out_mu[ks_] = mu
        out_lam[ks_] = d[origin] + mu
    if np.any(out_lam <= 0):
        raise ImpactvalError("linear theory: the contact system is not positive definite (check k and modes).")
    return out_lam, out_origin, out_mu, out_C, proj


#: most Newton-or-bisection iterations per secular root (bisection alone needs ~52 from a half gap to roundoff, up to
#: ~100 for a root that hugs its pole)
_SECULAR_ITERATIONS = 200


def _secular_roots(d, beta2, ks, origin, mu, lo, hi):
    """The roots mu = lam - d[origin] in (lo, hi) (one per column; zero excluded) of the secular function
    f(mu) = 1 + ks sum_j beta2_j / ((d_j - d_origin) - mu), increasing between its poles: safeguarded Newton on
    h = mu f (the nearer pole's term made smooth: a root that hugs its pole, where f ~ -ks beta2_o / mu, converges
    as fast as any other), the bracket kept by the sign of f, a bisection wherever Newton would leave it; each root
    iterates until its step is at roundoff (median 6, at most 58 iterations a root on a 7,425-mode plate, against
    52-100 bisections: a 2,049-mode plate's eigenpairs in 0.50 s instead of 2.55 s)."""
    mu, lo, hi = mu.copy(), lo.copy(), hi.copy()
    act = np.arange(len(mu))
    rel = d[:, None] - d[origin][None, :]
    for _ in range(_SECULAR_ITERATIONS):
        m = mu[act]
        diff = rel[:, act] - m[None, :]
        r = beta2[:, None] / diff
        f = 1.0 + ks * np.sum(r, axis=0)
        fp = ks * np.sum(r / diff, axis=0)
        pos = f > 0.0
        lo_a = np.where(pos, lo[act], m)
        hi_a = np.where(pos, m, hi[act])
        with np.errstate(divide="ignore", invalid="ignore"):
            new = m - m * f / (f + m * fp)
        inside = np.isfinite(new) & (new > lo_a) & (new < hi_a)
        new = np.where(inside, new, 0.5 * (lo_a + hi_a))
        tight = hi_a - lo_a <= 4e-16 * np.maximum(np.abs(lo_a), np.abs(hi_a)) + 1e-300
        done = (f == 0.0) | (np.abs(new - m) <= 2e-16 * np.abs(m)) | tight
        mu[act] = np.where(f == 0.0, m, new)
        lo[act] = lo_a
        hi[act] = hi_a
        act = act[~done]
        if act.size == 0:
            break
    return mu


@dataclass(frozen=True)
class _Phase:
    """delta(t0 + tau) = sum_k A_k cos(p_k tau) + B_k sin(p_k tau) during a contact starting at t0."""

    t0: float
    A: np.ndarray
    B: np.ndarray
    c: np.ndarray      # modal coordinates U^T M z0
    s: np.ndarray      # U^T M z0' / p

    def delta(self, p: np.ndarray, tau) -> np.ndarray:
        return _sines(p, tau, self.A, self.B)

    def ddelta(self, p: np.ndarray, tau) -> np.ndarray:
        return _sines(p, tau, self.B * p, -self.A * p)


def _sines(p: np.ndarray, tau, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """sum_k a_k cos(p_k tau) + b_k sin(p_k tau) at each tau, in blocks of samples (bounded memory); a, b [modes] or
    [modes, r] (r sums at once)."""
    tau = np.atleast_1d(np.asarray(tau, float))
    out = np.empty((len(tau),) + np.shape(a)[1:])
    block = max(1, int(_BLOCK_ENTRIES // max(len(p), 1)))
    for i0 in range(0, len(tau), block):
        P = np.outer(tau[i0:i0 + block], p)
        out[i0:i0 + block] = np.cos(P) @ a + np.sin(P) @ b
    return out


def _phase(sysm: LinearSystem, t0: float, z0: np.ndarray, zd0: np.ndarray) -> _Phase:
    cs = sysm.project(np.column_stack((sysm.mass_diag * z0, sysm.mass_diag * zd0)))
    c, s = cs[:, 0].copy(), cs[:, 1] / sysm.p
    return _Phase(t0, sysm.bU * c, sysm.bU * s, c, s)


def _state(sysm: LinearSystem, ph: _Phase, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """z, z' at t0 + tau in a contact phase."""
    cp, sp = np.cos(sysm.p * tau), np.sin(sysm.p * tau)
    zz = sysm.expand(np.column_stack((ph.c * cp + ph.s * sp, sysm.p * (ph.s * cp - ph.c * sp))))
    return zz[:, 0].copy(), zz[:, 1].copy()


def _sines_grid(p: np.ndarray, t0: float, h: float, count: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """`_sines` on the uniform grid t_j = t0 + j h (j = 0 .. count - 1), for coefficient vectors a, b [modes] or
    matrices [modes, r] (r sums at once: result [count, r]): Re((a - i b) e^{i p t}) with e^{i p (t_b + j h)} =
    e^{i p t_b} e^{i p j h}, the offsets' table e^{i p j h} made once for a block of samples and each block one
    complex matrix-vector product. Every entry is a product of two correctly rounded exponentials (no recurrence, no
    error growth: within a few ulp of the phases, like cos(p t) itself, whose argument p t rounds alike), and no
    cos/sin of large arguments per sample (30x faster on a 4,097-mode plate)."""
    c = np.asarray(a, float) - 1j * np.asarray(b, float)
    out = np.empty((count,) + c.shape[1:])
    if count == 0:
        return out
    block = max(1, min(count, int(_BLOCK_ENTRIES // max(len(p), 1))))
    offsets = np.exp(1j * np.outer(h * np.arange(block), p))
    for i0 in range(0, count, block):
        z0 = np.exp(1j * (p * (t0 + i0 * h)))
        k = min(block, count - i0)
        out[i0:i0 + k] = (offsets[:k] @ (c * (z0 if c.ndim == 1 else z0[:, None]))).real
    return out


def _track(sysm: LinearSystem, ph: _Phase, end: float, m: int, extra: float):
    """The series of a contact phase: tau = m + 1 equal steps over [0, end] and the sample `extra` (the peak) in
    order, and there the ball displacement x1 [m], the modes' displacement at the contact point x2 = sum phi_i q_i
    [m] and the ball velocity u [m/s]: the eigen-coordinates a = c cos(p tau) + s sin(p tau) projected on the rows
    of U that give x1 and x2 (`sysm.x1_row`, `sysm.x2_row`), O(modes) a sample instead of the whole state
    (O(modes^2): a plate's series, 11,000 samples a contact, took 38 s of its solve over mode counts up to 7,425
    and 2 GB an array)."""
    r1, r2 = sysm.x1_row, sysm.x2_row
    pc, ps = sysm.p * ph.c, sysm.p * ph.s
    a = np.column_stack((r1 * ph.c, r2 * ph.c, r1 * ps))
    b = np.column_stack((r1 * ph.s, r2 * ph.s, -r1 * pc))
    tau = np.linspace(0.0, end, m + 1)
    vals = _sines_grid(sysm.p, 0.0, end / m, m + 1, a, b)
    if not np.any(tau == extra):
        at = np.searchsorted(tau, extra)
        tau = np.insert(tau, at, extra)
        vals = np.insert(vals, at, _sines(sysm.p, extra, a, b), axis=0)
    return tau, vals[:, 0], vals[:, 1], vals[:, 2]


#: most entries (samples x modes) of one block of cos/sin tables or of `_sines_grid`'s complex offsets (8 and 16 bytes
#: each: 2e6 ~ 16-32 MB a table)
_BLOCK_ENTRIES = 2e6


def _first_root(fun, grid_fun, h: float, tau_max: float, start: float = 0.0, sign: int = -1):
    """First tau in (start, tau_max] where fun changes sign (from + to - for sign=-1): `grid_fun(t0, h, count)`, fun
    on the uniform grid t0 + j h (`_sines_grid`), finds the first sign change, brentq on fun itself the root.

    Returns (tau_root or None, grid taus, grid values up to the root)."""
    taus, vals = [], []
    lo = start
    chunk = 4000
    while lo < tau_max:
        grid = lo + h * np.arange(1, chunk + 1)
        v = grid_fun(lo + h, h, chunk)
        bad = np.flatnonzero(v * sign > 0) if sign < 0 else np.flatnonzero(v > 0)
        if len(bad):
            i = int(bad[0])
            taus.append(grid[:i]); vals.append(v[:i])
            a, b = _bracket(fun, grid[i - 1] if i > 0 else lo, grid[i], h, sign)
            root = optimize.brentq(lambda x: float(fun(x)[0]), a, b, xtol=1e-15 * b, rtol=1e-15, maxiter=200)
            return root, np.concatenate(taus), np.concatenate(vals)
        taus.append(grid); vals.append(v)
        lo = grid[-1]
    return None, np.concatenate(taus), np.concatenate(vals)


def _bracket(fun, a: float, b: float, h: float, sign: int, tries: int = 4) -> tuple[float, float]:
    """A bracket of fun's sign change (to negative for sign=-1, to positive for sign=+1) near the grid's [a, b],
    checked with fun itself: the grid's sum (`_sines_grid`) and the direct one round differently, so a crossing
    within roundoff of a grid point (a rigid plate's contact ends exactly on one: its grid is t_est/4000) may show in
    one and not the other; the bracket then moves by a grid step (at most `tries` times) until fun agrees."""
    def after(x: float) -> bool:
        return x < 0.0 if sign < 0 else x > 0.0

    fa, fb = float(fun(a)[0]), float(fun(b)[0])
    for _ in range(tries):
        if fa * fb <= 0.0:
            break
        if after(fa):               # fun crossed before a: step back
            a, b, fb = a - h, a, fa
            fa = float(fun(a)[0])
        else:                       # fun crosses after b: step on
            a, b, fa = b, b + h, fb
            fb = float(fun(b)[0])
    return a, b


def _contact_phase(sysm: LinearSystem, ph: _Phase, h: float, tau_max: float):
    """End time (tau) of a contact phase, peak (tau, delta), and its grid."""
    end, taus, vals = _first_root(lambda x: ph.delta(sysm.p, x),
                                  lambda t0, hh, k: _sines_grid(sysm.p, t0, hh, k, ph.A, ph.B), h, tau_max)
    if end is None:
        raise ImpactvalError(f"linear theory: the contact did not end within {tau_max:.3g} s.")
    taus = np.concatenate(([0.0], taus, [end]))
    vals = np.concatenate(([0.0 if ph.A.size == 0 else float(ph.delta(sysm.p, 0.0)[0])], vals, [0.0]))
    i = int(np.argmax(vals))
    a, b = taus[max(i - 1, 0)], taus[min(i + 1, len(taus) - 1)]
    dfun = lambda x: float(ph.ddelta(sysm.p, x)[0])  # noqa: E731
    if dfun(a) > 0 > dfun(b):
        tp = optimize.brentq(dfun, a, b, xtol=1e-15 * b, rtol=1e-15, maxiter=200)
    else:
        tp = taus[i]
    # the grid's largest value (a bracket only) evaluated as the peak is, so the two compare alike
    dp = max(float(ph.delta(sysm.p, tp)[0]), float(ph.delta(sysm.p, taus[i])[0]))
    return end, tp, dp, taus


@dataclass(frozen=True)
class LinearRun:
    """The exact linear solution over the first contact (and a window): metrics, contacts, series."""

    metrics: Metrics
    contacts: tuple[Contact, ...]
    t: np.ndarray
    delta: np.ndarray
    f: np.ndarray
    x_ball: np.ndarray
    x_structure: np.ndarray
    energy: np.ndarray
    rebound_velocity: float
    root_uncertainty: float


def solve_linear_modes(modes: Modes, mass: float, k: float, v0: float, window: float = 0.0,
                       n_series: int = 2000) -> LinearRun:
    """Exact impact of a ball (`mass` [kg], `v0` [m/s]) on `modes` with contact spring `k` [N/m].

    `window` [s]: follow free flight and re-contacts this long after the first contact ends.
    `n_series`: approximate number of series points per contact.
    """
    sysm = linear_system(modes, mass, k)
    n = len(sysm.omega)
    omega_c = math.sqrt(k / mass)
    t_est = math.pi / omega_c
    h = t_est / GRID_PER_CONTACT
    z = np.zeros(n + 1)
    zd = np.zeros(n + 1)
    zd[0] = v0
    t_now = 0.0
    contacts: list[Contact] = []
    series = []           # (t, x1, x2 = sum phi q, u, energy, in_contact) per phase
    rebound = math.nan
    t_stop = math.inf
    while True:
        ph = _phase(sysm, t_now, z, zd)
        end, tp, dp, _ = _contact_phase(sysm, ph, h, MAX_CONTACT_TIMES * t_est)
        contacts.append(Contact(t_now, t_now + end, k * dp, dp))
        m = max(int(n_series * end / t_est), 50)
        tau, x1s, x2s, us = _track(sysm, ph, end, m, tp)
        # the exact solution keeps its energy: the phase's total in its own eigen-coordinates (a_k = c_k cos + s_k
        # sin: kinetic + potential = p_k^2 (c_k^2 + s_k^2) / 2); what energy_error measures is its change between
        # phases (the flights' totals are in the modes' own coordinates), i.e. U's M-orthonormality
        e_phase = 0.5 * float(np.sum(sysm.p**2 * (ph.c**2 + ph.s**2)))
        series.append((t_now + tau, x1s, x2s, us, np.full(len(tau), e_phase), np.ones(len(tau), bool)))
        t_now += end
        if len(contacts) == 1:
            # the ball's velocity from row 0 of U (O(modes)); the whole state (`_state`) only if the solution goes on
            cp, sp = np.cos(sysm.p * end), np.sin(sysm.p * end)
            rebound = -float(sysm.x1_row @ (sysm.p * (ph.s * cp - ph.c * sp)))
            t_stop = t_now + window
        if t_now >= t_stop:
            break
        z, zd = _state(sysm, ph, end)
        # free flight: x1 = x1_0 + u tau; q_i = q_i0 cos(w tau) + qd_i0 sin(w tau)/w
        x10, u, q0, qd0 = z[0], zd[0], z[1:], zd[1:]
        w = sysm.omega

        cq, sq = sysm.phi * q0, sysm.phi * qd0 / w       # x2 = sum phi q = sum cq cos(w tau) + sq sin(w tau)

        def gap(tau, x10=x10, u=u, cq=cq, sq=sq):
            tau = np.atleast_1d(np.asarray(tau, float))
            return x10 + u * tau - _sines(w, tau, cq, sq)

        def gap_grid(t0, hh, k, x10=x10, u=u, cq=cq, sq=sq):
            return x10 + u * (t0 + hh * np.arange(k)) - _sines_grid(w, t0, hh, k, cq, sq)

        start, _, _ = _first_root(gap, gap_grid, h, t_stop - t_now, start=0.0, sign=+1)
        span = (start if start is not None else t_stop - t_now)
        m = max(int(n_series * span / t_est), 50)
        x = np.linspace(0.0, span, m + 1)[1:]
        mm = sysm.mass_diag[1:]
        e_flight = 0.5 * mass * u * u + 0.5 * float(np.sum(mm * (qd0**2 + (w * q0) ** 2)))
        series.append((t_now + x, x10 + u * x, _sines_grid(w, span / m, span / m, m, cq, sq), np.full(len(x), u),
                       np.full(len(x), e_flight), np.zeros(len(x), bool)))
        if start is None:
            break
        t_now += start
        cw, sw = np.cos(w * start), np.sin(w * start)
        z = np.concatenate(([x10 + u * start], q0 * cw + qd0 * sw / w))
        zd = np.concatenate(([u], -q0 * w * sw + qd0 * cw))
    t, x1, x2, _, energy, inside = (np.concatenate([s[i] for s in series]) for i in range(6))
    gap_ = x1 - x2
    delta = np.where(inside, gap_ / (1.0 + k * sysm.R), gap_)
    f = np.where(inside, k * np.maximum(delta, 0.0), 0.0)
    first = contacts[0]
    ft = first.t_end
    return LinearRun(Metrics(first.t_end - first.t_start, first.f_max, first.delta_max), tuple(contacts), t,
                     delta, f, x1, x2 + sysm.R * f, energy, float(rebound), 1e-14 * ft)


def _check(tol, window, modes, stiffness):
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not math.isfinite(tol) or not 1e-12 <= tol <= 0.1:
        raise ImpactvalError(f"tol must be a relative tolerance between 1e-12 and 0.1, got {tol!r}.")
    if not (isinstance(window, (int, float)) and math.isfinite(window) and window >= 0):
        raise ImpactvalError(f"window must be a non-negative time in s, got {window!r}.")
    if modes is not None and (isinstance(modes, bool) or not isinstance(modes, int) or modes < 1):
        raise ImpactvalError(f"modes must be a positive whole number, got {modes!r}.")
    if stiffness is not None and (isinstance(stiffness, bool) or not isinstance(stiffness, (int, float))
                                  or not math.isfinite(stiffness) or stiffness <= 0):
        raise ImpactvalError(f"stiffness must be a positive contact stiffness in N/m (or None for k0), "
                             f"got {stiffness!r}.")


def solve_linear(scene, tol: float = 1e-6, modes: int | None = None, stiffness: float | None = None,
                 window: float = 0.0) -> ImpactResult:
    """Exact linear-contact impact of `scene` (model "linear").

    Parameters
    ----------
    scene : Scene
        From :func:`impactval.load_scene`.
    tol : float
        Relative tolerance for modal truncation (automatic beam mode count only; the solution of a
        given mode set is exact up to root finding, ~1e-14 relative).
    modes : int, optional
        Beam mode count (as in :func:`impactval.solve`): explicit = exactly n modes, no residual;
        None with no count in the scene = automatic (n modes + residual static flexibility,
        doubled until twice the n-vs-2n difference is <= `tol`; that is the reported uncertainty).
    stiffness : float, optional
        Contact spring k [N/m]; default k0 = (4/5) alpha delta_m^(1/2) of the rigid-plate impact.
    window : float
        Time [s] to follow after the first contact ends (free flight, re-contacts).

    The result's `f_m` is k * delta_m (spring force) and `settings["k"]` the stiffness used.
    """
    from impactval.reference.solve import initial_mode_count, structure_modes

    from impactval.reference.structure import contact_scene

    _check(tol, window, modes, stiffness)
    t0 = time.perf_counter()
    scene = contact_scene(scene)          # a second ball: the equivalent ball on a rigid plate
    ball = scene.ball
    mass, alpha, v0 = ball.mass, scene.alpha, ball.velocity
    plate = plate_impact(mass, alpha, v0)
    k = float(stiffness) if stiffness is not None else plate.k0
    target = scene.target
    fixed = modes if modes is not None else getattr(target, "modes", None)
    model = "linear-rigid" if target.kind == "rigid-plate" else "linear-modal"
    trunc = Metrics(0.0, 0.0, 0.0)
    if target.kind in ("beam", "plate") and fixed is None:
        n = initial_mode_count(scene)
        prev = None
        while True:
            run = solve_linear_modes(structure_modes(scene, n, residual=True), mass, k, v0, window)
            if prev is not None:
                a, b = prev[0].metrics, run.metrics
                # x2 the n-vs-2n difference: covers an error falling like 1/n (measured on beam_ss_midspan:
                # the 192-mode error is 1.2x the 192-vs-384 difference)
                trunc = Metrics(2 * abs(a.t_m - b.t_m), 2 * abs(a.f_m - b.f_m), 2 * abs(a.delta_m - b.delta_m))
                rel = max(trunc.t_m / a.t_m, trunc.f_m / a.f_m, trunc.delta_m / a.delta_m)
                if rel <= tol or n >= LINEAR_MODE_CAP:
                    run, n = prev
                    break
            prev = (run, n)
            n *= 2
        n_modes = n
        model += "+static"
    else:
        md = structure_modes(scene, fixed)
        run = solve_linear_modes(md, mass, k, v0, window)
        n_modes = md.n
    m = run.metrics
    if target.kind == "rigid-plate":
        # closed form delta = (v0/omega0) sin(omega0 t): t_m = pi/omega0, delta_m = v0/omega0
        omega0 = math.sqrt(k / mass)
        m = Metrics(math.pi / omega0, k * v0 / omega0, v0 / omega0)
    ru = run.root_uncertainty
    unc = Metrics(trunc.t_m + ru, trunc.f_m + 1e-14 * m.f_m, trunc.delta_m + 1e-14 * m.delta_m)
    rel = max(unc.t_m / m.t_m, unc.f_m / m.f_m, unc.delta_m / m.delta_m)
    validity = ()
    if rel > tol * (1 + 1e-9):          # the doubling stopped at its cap (plates converge like 1/n)
        # the count kept is n, measured against the 2n-mode solve (2n >= LINEAR_MODE_CAP: no finer pair is made)
        validity = (f"uncertainty {rel:.2g} (relative) is above tol {tol:g}: the automatic mode count stopped at "
                    f"{n_modes} modes, measured against {2 * n_modes} (the doubling stops once the count reaches "
                    f"{LINEAR_MODE_CAP}: the cost grows like modes^2); give a looser tol",)
    return ImpactResult(
        scene=scene.name, source="reference", model=model, t_m=m.t_m, f_m=m.f_m, delta_m=m.delta_m,
        uncertainty=unc, modes=n_modes, t=run.t, f=run.f, delta=run.delta, x_ball=run.x_ball,
        x_structure=run.x_structure, energy=run.energy, rebound_velocity=run.rebound_velocity,
        energy_error=float(np.max(np.abs(run.energy / run.energy[0] - 1.0))),
        contacts=run.contacts if target.kind != "rigid-plate" else (Contact(0.0, m.t_m, m.f_m, m.delta_m),),
        settings={"tol": tol, "window": window, "k": k, "model": "linear"}, n_steps=len(run.t) - 1,
        wall_time_step_s=time.perf_counter() - t0, validity=validity,
    )
