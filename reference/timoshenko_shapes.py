"""Timoshenko mode shapes of clamped-clamped and cantilever beams: modal mass and the max-normalisation.

The shapes are the null vectors of the boundary matrices (`timoshenko._null_vectors`) in the bounded basis of
`timoshenko._combined`. Normalised to max |W| = 1 over the span; modal mass = int (rho A W^2 + rho I Psi^2) dx in
closed form (W and Psi are combinations of four exponentials/sinusoids: a 4x4 Gram matrix per mode). max |W| takes
O(1) work per mode (`_clamped_shapes`): below the cut-off frequency the interior sinusoid's amplitude exactly plus a
grid and Newton in the ends' windows where the hyperbolic tails matter; above it the few passes of the two-wave beat
nearest a crest. `_clamped_shapes_grid` (a grid over the whole span, O(n) per mode) is the former path, kept for
the tests and the benchmark that check the fast one against it.
"""
from __future__ import annotations

import math

import numpy as np

from impactval.reference.timoshenko import Section, _combined, _null_vectors, _phase, wave_numbers


def _gauss(L: float, panels: int, order: int = 10) -> tuple[np.ndarray, np.ndarray]:
    t, wt = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(0.0, L, panels + 1)
    h = np.diff(edges)
    x = (edges[:-1, None] + 0.5 * h[:, None] * (t[None, :] + 1.0)).ravel()
    return x, (0.5 * h[:, None] * wt[None, :]).ravel()


def _grid_mass_peak(sec: Section, om: np.ndarray, coeffs: np.ndarray, starts: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(int rho A W^2 + rho I Psi^2 dx [kg], max |W|) of the unnormalised modes, by a grid over the whole span.

    max |W|: a grid of 16 points per pi of wave phase, then Newton on W' = 0 (W'' = Psi' - q W) from the best
    grid point; the mass integral: Gauss-Legendre, 10 points per half pi of phase. O(n) work per mode."""
    rA, rI, L = sec.density * sec.area, sec.density * sec.second_moment, sec.length
    n = len(om)
    mass, peaks = np.empty(n), np.empty(n)
    ph = _phase(sec, om)
    _, _, qs = wave_numbers(sec, om)
    start = 0
    while start < n:
        end = start + 1                                # chunk: modes x grid points <= 2e5
        while end < n and (end + 1 - start) * (20 * ph[end] / math.pi + 100) <= 2e5:
            end += 1
        sl = slice(start, end)
        o, c, q = om[sl], coeffs[sl], qs[sl][:, None]
        top = float(ph[sl].max())
        xs = np.linspace(0.0, L, int(16 * top / math.pi) + 65)
        peaks[sl] = _refine_peak(sec, o, c, q, np.broadcast_to(xs, (len(o), len(xs))), xs[1] - xs[0], starts)
        xg, wg = _gauss(L, int(2 * top / math.pi) + 8)
        Wg, Pg = _combined(sec, o, xg, c)
        mass[sl] = (Wg * Wg * rA + Pg * Pg * rI) @ wg
        start = end
    return mass, peaks


def _refine_peak(sec: Section, o: np.ndarray, c: np.ndarray, q: np.ndarray, xs: np.ndarray, h,
                 starts: int = 1) -> np.ndarray:
    """max |W| per mode: from the `starts` best local maxima of |W| over the grid points xs (n, m) (spacing h,
    scalar or (n,)), 6 Newton steps on W' = 0 (W'' = Psi' - q W) each, kept within one spacing and the span.

    Several starts: a grid of 16 points per pi of phase reads a peak up to ~0.5 % low, so when W has peaks of
    nearly equal height (two waves above the cut-off) the best grid point can sit next to a lower one."""
    L = sec.length
    W = np.abs(_combined(sec, o, xs, c)[0])
    rows = np.arange(len(o))[:, None]
    if starts == 1:
        j = np.argmax(W, axis=1)[:, None]
    else:
        pad = np.pad(W, ((0, 0), (1, 1)), constant_values=-1.0)
        left, right = pad[:, :-2], pad[:, 2:]
        # rank the local maxima by the parabola through three points (error O(h^4), the point's own O(h^2))
        curv = np.maximum(2 * W - left - right, 1e-300)
        score = np.where((W >= left) & (W >= right), W + (right - left) ** 2 / (8 * curv), -1.0)
        starts = min(starts, W.shape[1])
        j = np.argpartition(-score, starts - 1, axis=1)[:, :starts]
    peak = np.max(W[rows, j], axis=1)
    h = np.reshape(np.broadcast_to(h, (len(o),)), (-1, 1))
    x0 = xs[rows, j]
    x = x0
    for _ in range(6):
        wv, _, dwv, dpv = _combined(sec, o, x, c, derivs=True)
        d2 = dpv - q * wv
        step = np.where(d2 != 0, dwv / np.where(d2 != 0, d2, 1.0), 0.0)
        x = np.clip(x - step, np.maximum(x0 - h, 0.0), np.minimum(x0 + h, L))
    return np.maximum(peak, np.max(np.abs(_combined(sec, o, x, c)[0]), axis=1))


def _clamped_shapes_grid(sec: Section, support: str, om: np.ndarray, impact_x: float) -> tuple[np.ndarray, np.ndarray]:
    """(modal_mass, phi) by grids over the whole span for every mode: O(n^2) for n modes. The reference that
    `_clamped_shapes` is tested against."""
    coeffs = _null_vectors(sec, support, om)
    mass, peak = _grid_mass_peak(sec, om, coeffs)
    phi = _combined(sec, om, np.array([impact_x]), coeffs)[0][:, 0]
    return mass / peak**2, phi / peak


# ----------------------------------------------------------------------------- shapes in O(1) per mode

def _atoms(sec: Section, om: np.ndarray, c: np.ndarray):
    """W and Psi of the modes as combinations of four atoms each: returns (kind, rates, w, p) with kind (n,)
    True where the atoms are (e^{a (x - L)}, e^{-a x}, cos k x, sin k x) (a^2 L^2 > 1) and False where they are
    (cos b x, sin b x, cos k x, sin k x), b = |a| (a^2 L^2 < -1: above the cut-off); rates (n, 2) = (a or b, k);
    w, p (n, 4) the atoms' coefficients in W and Psi."""
    a2, k2, q = wave_numbers(sec, om)
    a, k = np.sqrt(np.abs(a2)), np.sqrt(k2)
    expo = a2 * sec.length**2 > 1.0
    gk = (q - k2) / k
    safe_a = np.where(a > 0, a, 1.0)           # a = 0 only at the cut-off, a mode these atoms are not used for
    g = (a2 + q) / safe_a
    c0, c1, c2, c3 = c.T
    a = safe_a
    w = np.stack([c0, np.where(expo, c1, c1 * a2 / a), c2, c3], axis=1)
    p = np.stack([np.where(expo, g * c0, (a2 + q) * c1), np.where(expo, -g * c1, (a2 + q) * c0 / a),
                  -gk * c3, gk * c2], axis=1)
    return expo, np.stack([a, k], axis=1), w, p


def _int_cos(z: np.ndarray, L: float) -> np.ndarray:
    """int_0^L cos(z x) dx = sin(z L)/z, stable at z = 0."""
    return L * np.sinc(z * L / math.pi)


def _int_sin(z: np.ndarray, L: float) -> np.ndarray:
    """int_0^L sin(z x) dx = (1 - cos z L)/z = 2 sin^2(z L/2)/z, stable at z = 0."""
    return L * np.sin(0.5 * z * L) * np.sinc(0.5 * z * L / math.pi)


def _trig_gram(al: np.ndarray, be: np.ndarray, L: float) -> np.ndarray:
    """(n, 2, 2): int_0^L of (cos al x, sin al x) x (cos be x, sin be x)."""
    cm, cp = _int_cos(al - be, L), _int_cos(al + be, L)
    sm, sp = _int_sin(al - be, L), _int_sin(al + be, L)
    return 0.5 * np.stack([np.stack([cm + cp, sp - sm], -1), np.stack([sp + sm, cm - cp], -1)], -2)


def _atom_gram(expo: np.ndarray, rates: np.ndarray, L: float) -> np.ndarray:
    """(n, 4, 4): int_0^L atom_i atom_j dx for the atoms of `_atoms`, in closed form with every factor bounded."""
    a, k = rates[:, 0], rates[:, 1]
    n = len(a)
    G = np.empty((n, 4, 4))
    G[:, 2:, 2:] = _trig_gram(k, k, L)
    t = ~expo
    if np.any(t):
        G[t, :2, :2] = _trig_gram(a[t], a[t], L)
        G[t, :2, 2:] = _trig_gram(a[t], k[t], L)
    if np.any(expo):
        ae, ke = a[expo], k[expo]
        same = -np.expm1(-2.0 * ae * L) / (2.0 * ae)        # int e^{2a(x-L)} = int e^{-2ax}
        cross = L * np.exp(-ae * L)                         # int e^{a(x-L)} e^{-ax}
        G[expo, 0, 0], G[expo, 1, 1], G[expo, 0, 1], G[expo, 1, 0] = same, same, cross, cross
        eikL = np.exp(1j * ke * L)
        right = (eikL - np.exp(-ae * L)) / (ae + 1j * ke)   # int e^{a(x-L)} e^{ikx}
        left = (1.0 - np.exp(-ae * L) * eikL) / (ae - 1j * ke)   # int e^{-ax} e^{ikx}
        G[expo, 0, 2], G[expo, 0, 3] = right.real, right.imag
        G[expo, 1, 2], G[expo, 1, 3] = left.real, left.imag
    G[:, 2:, :2] = np.swapaxes(G[:, :2, 2:], 1, 2)
    return G


#: a tail e^{-a x} counts where it exceeds this fraction of the sinusoid's amplitude (below roundoff elsewhere)
TAIL_NEGLIGIBLE = 1e-18
#: candidate passes per sign searched for max |W| above the cut-off (3 suffice; one spare for near ties)
PASSES = 4
#: grid points per pi of wave phase in the windows and passes searched for max |W| (then Newton from several
#: starts ranked by a parabola through three points)
WINDOW_PER_PI = 16


def _window_peaks(sec: Section, om, c, q, lo: np.ndarray, hi: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """max |W| over the union of intervals [lo, hi] (n, J) per mode: WINDOW_PER_PI grid points per pi of phase at `rate`
    [1/m] (n,) over the widest interval, then Newton; modes in chunks of <= 2e5 grid points."""
    n, J = lo.shape
    width = np.max(hi - lo, axis=1)
    m_need = np.ceil(WINDOW_PER_PI * rate * width / math.pi).astype(int) + 17
    out = np.empty(n)
    order = np.argsort(m_need, kind="stable")
    start = 0
    while start < n:
        m = int(m_need[order[min(start + 63, n - 1)]])
        end = start + max(1, min(64, int(2e5 // (J * m))))
        idx = order[start:end]
        m = int(m_need[idx].max())
        t = np.linspace(0.0, 1.0, m)
        xs = (lo[idx, :, None] + (hi - lo)[idx, :, None] * t).reshape(len(idx), J * m)
        h = np.max(hi[idx] - lo[idx], axis=1) / (m - 1)
        out[idx] = _refine_peak(sec, om[idx], c[idx], q[idx, None], xs, h, max(3 * J, 16))
        start = end
    return out


def _pass_windows(k1, k2, p1, p2, L: float, block: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (n, 2 PASSES): for W = R1 cos(k1 x - p1) + R2 cos(k2 x - p2) (k1 <= k2), the PASSES passes
    |k1 x - p1 - s - 2 pi j| <= pi (s = 0 for max W, pi for min W) whose centres x_j have the other wave's phase
    k2 x_j - p2 - s closest to 0 (mod 2 pi), cut to [0, L]. In turns that phase is alpha j + beta (alpha = k2/k1),
    and the passes with the smallest |alpha j + beta mod 1| are found in O(sqrt(passes)) per mode (`_nearest_turns`)."""
    n = len(k1)
    lo, hi = np.empty((n, 2 * PASSES)), np.empty((n, 2 * PASSES))
    alpha = k2 / k1
    for col, shift in ((0, 0.0), (PASSES, math.pi)):
        # passes whose centre is within half a pass of the span: j_first .. j_first + count - 1
        first = np.ceil((-math.pi - p1 - shift) / (2 * math.pi))
        count = (np.floor(((L * k1 + math.pi) - p1 - shift) / (2 * math.pi)) - first + 1).astype(int)
        beta = (alpha * (p1 + shift + 2 * math.pi * first) - p2 - shift) / (2 * math.pi)
        order = np.argsort(count, kind="stable")              # blocks of similar pass counts
        for b in range(0, n, block):
            sl = order[b:b + block]
            best = _nearest_turns(alpha[sl], beta[sl], count[sl], PASSES)
            xb = (p1[sl, None] + shift + 2 * math.pi * (first[sl, None] + best)) / k1[sl, None]
            half = math.pi / k1[sl, None]
            lo[sl, col:col + PASSES] = np.clip(xb - half, 0.0, L)
            hi[sl, col:col + PASSES] = np.clip(xb + half, 0.0, L)
    return lo, hi


def _turn_distance(alpha, beta, t):
    """|alpha t + beta| to the nearest whole number (alpha, beta (n, 1), t (n, m))."""
    v = alpha * t + beta
    return np.abs(v - np.round(v))


def _nearest_turns(alpha: np.ndarray, beta: np.ndarray, count: np.ndarray, k: int) -> np.ndarray:
    """(n, k): the k indices t in [0, count) with the smallest distance of alpha t + beta to a whole number,
    by baby steps s < B and giant steps t = s + B g (B ~ sqrt(count)): for each giant step the k nearest are among
    the k baby steps on either side of where frac(alpha s) meets -frac(alpha B g + beta) in sorted order; the last,
    partial giant step is read whole. O(sqrt(count)) per mode instead of O(count)."""
    a, b = alpha[:, None], beta[:, None]
    B = max(int(math.ceil(math.sqrt(int(count.max())))), 2 * k)
    s = np.arange(B)
    baby = a * s - np.floor(a * s)                            # frac(alpha s) in [0, 1)
    sort = np.argsort(baby, axis=1)
    baby_sorted = np.take_along_axis(baby, sort, axis=1)
    full = count // B                                         # whole giant steps per mode
    g = np.arange(int(full.max()) + 1)
    target = -(a * (B * g) + b)
    target -= np.floor(target)                                # frac(alpha s) closest to this is best
    shelf = 2.0 * np.arange(len(alpha))[:, None]               # one sorted array for all modes: row r in [2r, 2r + 1)
    pos = np.searchsorted((baby_sorted + shelf).ravel(), (target + shelf).ravel()).reshape(target.shape)
    pos -= B * np.arange(len(alpha))[:, None]
    off = np.arange(-k, k)
    cand_pos = (pos[:, :, None] + off) % B                    # (n, G, 2k), circular
    rows = np.arange(len(alpha))[:, None, None]
    cand = sort[rows, cand_pos] + B * g[None, :, None]        # indices t
    cand = cand.reshape(len(alpha), -1)
    valid = g[None, :, None].repeat(2 * k, axis=2).reshape(1, -1) < full[:, None]
    last = B * full[:, None] + s                              # the partial giant step, read whole
    cand = np.concatenate([np.where(valid, cand, 0), last], axis=1)
    ok = np.concatenate([valid, last < count[:, None]], axis=1)
    d = np.where(ok, _turn_distance(a, b, cand), np.inf)
    pick = np.argpartition(d, k - 1, axis=1)[:, :k]
    return np.take_along_axis(cand, pick, axis=1)


def _clamped_shapes(sec: Section, support: str, om: np.ndarray, impact_x: float) -> tuple[np.ndarray, np.ndarray]:
    """(modal_mass, phi) of the modes at frequencies `om`, O(1) work per mode for all but a bounded number.

    Modal mass: W and Psi are combinations of four atoms (`_atoms`), so int rho A W^2 + rho I Psi^2 dx =
    rho A w^T G w + rho I p^T G p with the atoms' Gram matrix G in closed form (`_atom_gram`); modes with
    |a| L <= 1 (next to the cut-off) use Gauss-Legendre (`_grid_mass_peak`).

    max |W|:
    - below the cut-off (a L > 1): W = c2 cos k x + c3 sin k x plus tails c1 e^{-a x}, c0 e^{a (x - L)}; where
      both tails are below TAIL_NEGLIGIBLE of R = hypot(c2, c3), |W| reaches R once per half wavelength, exactly;
      the end windows (tails not negligible, plus one wavelength) are searched by a grid + Newton;
    - above it (b L > 1): W = R1 cos(k1 x - p1) + R2 cos(k2 x - p2), k1 <= k2; the span is tiled by passes
      |k1 x - p1 - 2 pi j| <= pi (for max W; shifted by pi for min W); in each, the largest value is a function
      of the other wave's phase offset nu_j = k2 x_j - p2 (mod 2 pi) at the pass centre alone (the same line on
      the torus, shifted), decreasing in |nu_j| for k1 <= k2 (a pass cut by an end is lower still), so only the
      PASSES passes of smallest |nu_j| per sign, and the two ends, are searched (grid + Newton from several
      starts). Choosing them takes O(sqrt(passes)) multiply-and-rounds per mode (`_nearest_turns`);
    - low modes, tail windows covering the span, |a| L <= 1 or fewer than 8 passes: the whole-span grid with 16
      Newton starts (a bounded number of modes).
    The whole-span grid with one start (`_clamped_shapes_grid`, the previous method) reads max |W| up to 1e-3 low
    above the cut-off, where two waves give many peaks of nearly equal height.
    """
    coeffs = _null_vectors(sec, support, om)
    mass, peak = _fast_mass_peak(sec, om, coeffs)
    phi = _combined(sec, om, np.array([impact_x]), coeffs)[0][:, 0]
    return mass / peak**2, phi / peak


def _fast_mass_peak(sec: Section, om: np.ndarray, coeffs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`_grid_mass_peak` in O(1) work per mode for all but a bounded number of modes (see `_clamped_shapes`)."""
    rA, rI, L = sec.density * sec.area, sec.density * sec.second_moment, sec.length
    n = len(om)
    a2, k2, qs = wave_numbers(sec, om)
    expo, rates, w, p = _atoms(sec, om, coeffs)
    closed = np.abs(a2) * L * L > 1.0
    mass, peak = np.full(n, np.nan), np.full(n, np.nan)
    if np.any(closed):
        G = _atom_gram(expo[closed], rates[closed], L)
        wc, pc = w[closed], p[closed]
        mass[closed] = (rA * np.einsum("ni,nij,nj->n", wc, G, wc) + rI * np.einsum("ni,nij,nj->n", pc, G, pc))
    full = ~closed
    # below the cut-off: tails and interior sinusoid
    a, k = rates[:, 0], rates[:, 1]
    R = np.hypot(coeffs[:, 2], coeffs[:, 3])
    with np.errstate(divide="ignore"):
        left = np.log(np.abs(coeffs[:, 1]) / (TAIL_NEGLIGIBLE * R)) / a
        right = np.log(np.abs(coeffs[:, 0]) / (TAIL_NEGLIGIBLE * R)) / a
    wave = 2 * math.pi / k
    xl = np.clip(left, 0.0, L) + wave
    xr = L - np.clip(right, 0.0, L) - wave
    tails = expo & (xr - xl > 0.5 * wave)
    full |= expo & ~tails
    if np.any(tails):
        i = np.flatnonzero(tails)
        lo = np.stack([np.zeros(len(i)), xr[i]], axis=1)
        hi = np.stack([np.minimum(xl[i], L), np.full(len(i), L)], axis=1)
        peak[i] = np.maximum(R[i], _window_peaks(sec, om[i], coeffs[i], qs[i], lo, hi, k[i]))
    # above the cut-off: two sinusoids
    osc = closed & ~expo
    if np.any(osc):
        z1 = coeffs[:, 0] + 1j * w[:, 1]             # W = Re(z1 e^{-i b x} + z2 e^{-i k x})
        z2 = coeffs[:, 2] + 1j * coeffs[:, 3]
        swap = a > k                                  # carrier 1: the smaller wave number
        k1, k2w = np.where(swap, k, a), np.where(swap, a, k)
        p1, p2 = np.angle(np.where(swap, z2, z1)), np.angle(np.where(swap, z1, z2))
        passes = k1 * L / (2 * math.pi)
        ok = osc & (passes >= 8)
        full |= osc & ~ok
        i = np.flatnonzero(ok)
        if len(i):
            lo, hi = _pass_windows(k1[i], k2w[i], p1[i], p2[i], L)
            peak[i] = _window_peaks(sec, om[i], coeffs[i], qs[i], lo, hi, k1[i] + k2w[i])
            ends = np.abs(_combined(sec, om[i], np.array([0.0, L]), coeffs[i])[0]).max(axis=1)
            peak[i] = np.maximum(peak[i], ends)
    if np.any(full):
        i = np.flatnonzero(full)
        m_grid, p_grid = _grid_mass_peak(sec, om[i], coeffs[i], starts=16)
        peak[i] = p_grid
        mass[i] = np.where(closed[i], mass[i], m_grid)
    return mass, peak
