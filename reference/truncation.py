"""The motion of modes a model leaves out, driven by a run's own force (the a-posteriori truncation estimate).

A model with n modes and the residual flexibility of the rest keeps the dropped modes' static part exactly; what it
misses is their dynamic part. For a mode x'' + omega^2 x = b f(t) at rest when the force starts (f(0) = 0), integration
by parts gives

    x(t) - b f(t) / omega^2 = -(b / omega^2) Re[ e^{i omega t} int_0^t e^{-i omega tau} f'(tau) dtau ],

which this module evaluates at a run's nodes from its force history: f' of the cubic spline through the node values (a
quadratic on each step) integrated exactly on each step (Filon's rule), so that nodes far apart for the mode's
period lose nothing to aliasing. Pure functions, SI units.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import CubicSpline

from impactval.reference.kernel import PEAK_MARGIN, crossing, peak


#: Taylor coefficients of P_k(z) = int_0^1 s^k e^{-i z s} ds in powers of (-i z), k = 0, 1, 2: 1 / (m! (k + m + 1))
_TAYLOR = np.array([[1.0 / (math.factorial(m) * (k + m + 1)) for m in range(18)] for k in range(3)])


def _moments(z: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """P_k(z) = int_0^1 s^k e^{-i z s} ds, k = 0, 1, 2, for steps of phase z = omega h (e = e^{-i z}): the closed
    forms P_0 = (1 - e)/(i z), P_k = (k P_{k-1} - e)/(i z) for z >= 1, their Taylor series below (the closed forms
    lose ~eps / z^(k+1) there)."""
    iz = 1j * z
    with np.errstate(divide="ignore", invalid="ignore"):
        p0 = (1.0 - e) / iz
        p1 = (p0 - e) / iz
        p2 = (2.0 * p1 - e) / iz
    small = z < 1.0
    if np.any(small):
        x = -iz[small]
        for k, pk in enumerate((p0, p1, p2)):
            acc = np.full(x.shape, _TAYLOR[k, -1], dtype=complex)
            for c in _TAYLOR[k, -2::-1]:
                acc = acc * x + c
            pk[small] = acc
    return p0, p1, p2


def dynamic_part(t: np.ndarray, f: np.ndarray, omega: np.ndarray, b: np.ndarray, at: np.ndarray | None = None,
                 chunk: int = 256) -> np.ndarray:
    """Sum over the modes of (response - static response) [m] under the force `f` [N] given at the nodes `t` [s]
    (f[0] = 0), at the nodes or, with `at`, at those times [s] only (within the nodes' span: they become nodes too, f'
    there from the same spline).

    omega [rad/s] and b = phi^2 / modal_mass [1/kg] per mode; the modes are taken `chunk` at a time (memory ~ chunk x
    len(t) complex numbers)."""
    t = np.asarray(t, dtype=float)
    f = np.asarray(f, dtype=float)
    spline = CubicSpline(t, f)
    if at is not None:
        grid = np.union1d(t, np.asarray(at, dtype=float))
        pick = np.searchsorted(grid, at)
    else:
        grid, pick = t, np.arange(t.shape[0])
    out = np.zeros(pick.shape[0])
    if t.shape[0] < 3 or omega.shape[0] == 0:
        return out
    # f' on each step exactly as the spline has it: f'(g + u) = f'(g) + f''(g) u + f'''(g) u^2 / 2 (the third
    # derivative of the piece to the right of g), so only its jumps at the nodes ring (amplitude ~ b jump / omega^5)
    h = np.diff(grid)
    c0 = spline(grid[:-1], 1) * h
    c1 = spline(grid[:-1], 2) * h**2
    c2 = 0.5 * spline(grid[:-1], 3) * h**3
    for lo in range(0, omega.shape[0], chunk):
        w = omega[lo:lo + chunk, None]
        E = np.exp(-1j * w * grid[None, :])                    # e^{-i omega t} at every node
        p0, p1, p2 = _moments(w * h[None, :], E[:, 1:] * np.conj(E[:, :-1]))
        steps = E[:, :-1] * (c0 * p0 + c1 * p1 + c2 * p2)     # int over each step of e^{-i omega tau} f'(tau)
        if at is None:
            acc = np.zeros(E.shape, dtype=complex)
            np.cumsum(steps, axis=1, out=acc[:, 1:])
        else:
            acc = np.stack([steps[:, :q].sum(axis=1) for q in pick], axis=1)
        out -= np.sum((b[lo:lo + chunk] / omega[lo:lo + chunk] ** 2)[:, None] * np.real(np.conj(E[:, pick]) * acc),
                      axis=0)
    return out


def metric_shifts(t: np.ndarray, f: np.ndarray, delta: np.ndarray, omega: np.ndarray, b: np.ndarray,
                  peak_share: float | None = None) -> tuple[float, float] | None:
    """First-order relative changes (|d t_m| / t_m, |d delta_m| / delta_m) of the first contact when the dropped modes
    (omega, b) move dynamically, from the run's nodes t [s], f [N], delta [m] (without the feedback of the change on the
    force): delta_m by the dynamic part at the tops of delta's humps within `peak_share` of the largest (the largest;
    each top at the maximum of the interpolant through its nodes: the dynamic part rings at the dropped modes'
    frequencies, so a node's time is not close enough), t_m by the dynamic part where the interpolant crosses zero
    over the rate delta falls there. `peak_share` defaults to kernel.PEAK_MARGIN, the humps `dense_peak` refines. None
    when the run's first contact does not end."""
    if peak_share is None:
        peak_share = PEAK_MARGIN
    ends = np.nonzero(delta[1:] <= 0.0)[0]
    if ends.shape[0] == 0:
        return None
    end = int(ends[0]) + 1
    d = delta[:end + 1]
    d_max = float(np.max(d[:end]))
    k_top = int(np.argmax(d[:end]))
    tops = [k for k in range(1, end) if k == k_top or (d[k] >= d[k - 1] and d[k] >= d[k + 1]
                                                       and d[k] >= (1.0 - peak_share) * d_max)]
    times = []
    for k in tops:
        lo, hi = max(k - 3, 0), min(k + 4, end + 1)
        times.append(peak(t[lo:hi], d[lo:hi], t[max(k - 1, 0)], t[min(k + 1, end)])[0] if hi - lo >= 4 else t[k])
    lo = max(end - 3, 0)
    t_end = crossing(t[lo:end + 1], d[lo:end + 1], t[end - 1], t[end]) if end - lo >= 3 else t[end]
    x = dynamic_part(t[:end + 1], f[:end + 1], omega, b, at=np.array(times + [t_end]))
    rel_d = float(np.max(np.abs(x[:-1]))) / d_max
    rate = (d[end - 1] - d[end]) / (t[end] - t[end - 1])
    rel_t = abs(x[-1]) / rate / (t_end - t[0]) if rate > 0.0 else np.inf
    return rel_t, rel_d
