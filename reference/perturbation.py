"""First-order perturbation solutions for a light ball (paper sec. 6-7, eq. 74-94; physics.md sec. 7).

Small parameter of mode j: s_j = (m0/m_j) phi_j0^2. Both theories give the impact quantities as the
rigid-plate values times (1 + sum_j s_j * weight(w_j)), error O(s^2), first contact only.

Linear theory (spring k0, omega0 = v0/delta_m), r_j = omega_j/omega0 (physics.md 7.1)
    delta(t) = (v0/omega0) [sin(theta) + sum_j s_j L(theta; r_j)],  theta = omega0 t
    t_m = (pi/omega0)(1 + sum s_j T(r_j)),  T(r) = L(pi; r)/pi
    delta_m = (v0/omega0)(1 + sum s_j M(r_j)),  M(r) = L(pi/2; r),  f_m = k0 delta_m
  (T from the shift of the zero of sin(theta) near pi, whose slope is -1; M from the value at the zero-order
  peak pi/2, where the slope vanishes.) L is evaluated in a form with the removable singularity at r = 1
  cancelled analytically (see `L_linear`), so it is accurate for every r > 0.

Nonlinear (Hertz) theory, scaled units (time delta_m/v0, length delta_m, force f_m), w_j = omega_j delta_m/v0
(= r_j: omega0 = v0/delta_m) (physics.md 7.2)
    d1'' + (15/8) sqrt(d0) d1 = F(t),  F = -(5/4) sum_j s_j K_j,
    K_j(t) = d0^1.5 - w_j int_0^t d0^1.5(tau) sin(w_j (t - tau)) dtau = int_0^t g'(tau) cos(w_j (t - tau)) dtau
  (the second form by parts, g = d0^1.5, g(0) = 0: bounded integrand), solved by variation of constants
    d1(t) = y2(t) int_0^t y1 F - y1(t) int_0^t y2 F,  y1 = d0', y2 = (4/5) d0 + (1/5) t d0'  (Wronskian 1).
  MH(w) = d1(c) (per unit s) = (4/5) int_0^c y1 F      (y1(c) = 0, y2(c) = 4/5)
  TH(w) = d1(2c)/(2c) = [int_0^2c y2 F - (2c/5) int_0^2c y1 F]/(2c)   (y1(2c) = -1, y2(2c) = -2c/5)

The zero-order curve d0 is exact (reference/hertz.py, scaled): with tau = min(t, 2c - t),
d0 = I^-1_{2/5,1/2}(tau/c)^(2/5) and |d0'| = sqrt(1 - d0^(5/2)) = sqrt(I^-1_{1/2,2/5}((c - tau)/c)) (the
complementary inverse keeps d0' accurate at the peak). Quadrature in phi with t = c (1 - cos phi): every
integrand (t^(1/2) behaviour at both ends included) is then analytic in phi; cumulative Simpson on a
uniform phi grid, refined for oscillatory kernels (large w).

Stiff modes (w -> inf) act as springs in series: K -> g''/w^2, so TH ~ TH_INF/w^2, MH ~ MH_INF/w^2 with
TH_INF, MH_INF from the same formulas with K = g'' (MH_INF = -5/8 exactly: energy with a series spring).
A residual static flexibility R [m/N] (all dropped modes) enters with weight rho = R k0 and these limits.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import special
from scipy.integrate import cumulative_simpson

from impactval.errors import ImpactvalError
from impactval.reference.beams import Modes
from impactval.reference.hertz import C_HERTZ, E0, plate_impact
from impactval.reference.result import Metrics
from impactval.reference.validity import perturbation_validity

#: most modes of the automatic first-order mode set (every mode up to w = W_QUADRATURE_MAX, the rest static): a light
#: ball on a slender beam (unseen fuzz scene 2513) reaches w = 2.3 at 4,096 modes (its t_m shift 33 % below its limit:
#: the cap until round 16), 4.6 at 8,192 (3 %), 9.3 at 16,384 (0.4 %, but ~0.6 ms a mode for its weights and again for
#: its curve); a result at the cap says so
PERTURBATION_MODE_CAP = 8192
#: largest scaled mode frequency computed by quadrature; above it, the 1/w^2 asymptotics TH_INF/w^2, MH_INF/w^2
#: (relative error of those weights < 1e-2 at w = 50, measured; they are themselves < 3e-4 per unit s)
W_QUADRATURE_MAX = 50.0


# ----------------------------------------------------------------------------- linear theory (7.1)

def _sin_minus_x_over_x3(y: np.ndarray) -> np.ndarray:
    """(sin y - y)/y^3, accurate for small y."""
    y = np.asarray(y, float)
    small = np.abs(y) < 0.1
    ys = np.where(small, 1.0, y)
    direct = (np.sin(ys) - ys) / ys**3
    y2 = y * y
    series = -1 / 6 + y2 / 120 - y2**2 / 5040 + y2**3 / 362880 - y2**4 / 39916800
    return np.where(small, series, direct)


def L_linear(theta, r) -> np.ndarray:
    """First-order linear-theory correction L(theta; r) per unit s (physics.md 7.1), any r > 0.

    L = [-theta cos(theta)(r^2-1) - (1+r^2) sin(theta) + 2 r sin(r theta)] / (2 (r^2-1)^2). With
    e = r - 1 the numerator is e^2 { sin(theta) [-(1+e) theta^2 sinc^2(e theta/2) - 1]
    + cos(theta) [2 (1+e) e theta^3 h(e theta) + theta] }, h(y) = (sin y - y)/y^3, and
    (r^2-1)^2 = e^2 (2+e)^2: the e^2 cancels exactly, so r = 1 needs no special case
    (L(theta; 1) = [theta cos(theta) - (1 + theta^2) sin(theta)]/8).
    """
    theta = np.asarray(theta, float)
    e = np.asarray(r, float) - 1.0
    x = 0.5 * e * theta
    sinc2 = np.sinc(x / math.pi) ** 2
    num = (np.sin(theta) * (-(1.0 + e) * theta**2 * sinc2 - 1.0)
           + np.cos(theta) * (2.0 * (1.0 + e) * e * theta**3 * _sin_minus_x_over_x3(e * theta) + theta))
    return num / (2.0 * (2.0 + e) ** 2)


def T_linear(r) -> np.ndarray:
    """Relative duration shift per unit s, T(r) = 1/(2(r^2-1)) + r sin(pi r)/(pi (r^2-1)^2); T(1) = -1/8."""
    return L_linear(math.pi, r) / math.pi


def M_linear(r) -> np.ndarray:
    """Relative peak-approach shift per unit s, M(r) = (r sin(pi r/2) - (1+r^2)/2)/(r^2-1)^2; M(1) = -(4+pi^2)/32."""
    return L_linear(0.5 * math.pi, r)


#: r -> inf limits times r^2 (a stiff mode is a spring in series): T ~ 1/(2 r^2), M ~ -1/(2 r^2)
T_LINEAR_INF, M_LINEAR_INF = 0.5, -0.5


# ----------------------------------------------------------------------------- nonlinear theory (7.2)

@dataclass(frozen=True)
class ZeroOrder:
    """The rigid-plate curve d0 on a grid uniform in phi, t = c (1 - cos phi), phi in [0, pi]."""

    phi: np.ndarray
    t: np.ndarray
    dt_dphi: np.ndarray
    d0: np.ndarray
    d0p: np.ndarray
    gp: np.ndarray        # g' = (d0^1.5)' = 1.5 sqrt(d0) d0'
    gpp_dt: np.ndarray    # g'' dt/dphi (bounded; g'' ~ t^-1/2 at the ends)
    y1: np.ndarray
    y2: np.ndarray


@lru_cache(maxsize=16)
def zero_order(n: int) -> ZeroOrder:
    """d0 and friends on n + 1 points (n even)."""
    c = C_HERTZ
    phi = np.linspace(0.0, math.pi, n + 1)
    t = c * (1.0 - np.cos(phi))
    first = phi <= 0.5 * math.pi
    ph = np.where(first, phi, math.pi - phi)          # mirror: tau = min(t, 2c - t) = c (1 - cos ph)
    x = 1.0 - np.cos(ph)                              # tau / c
    xc = np.cos(ph)                                   # (c - tau) / c
    u = special.betaincinv(0.4, 0.5, np.clip(x, 0.0, 1.0))          # d0^(5/2)
    one_minus_u = special.betaincinv(0.5, 0.4, np.clip(xc, 0.0, 1.0))
    d0 = u**0.4
    speed = np.sqrt(one_minus_u)
    d0p = np.where(first, speed, -speed)
    dt_dphi = c * np.sin(phi)
    gp = 1.5 * np.sqrt(d0) * d0p
    # g'' = 0.75 d0'^2 / sqrt(d0) - (15/8) d0^2 ; times dt/dphi, with the end limits 0.75 sqrt(2c)
    with np.errstate(divide="ignore", invalid="ignore"):
        gpp_dt = (0.75 * d0p**2 / np.sqrt(d0) - 1.875 * d0**2) * dt_dphi
    gpp_dt[0] = gpp_dt[-1] = 0.75 * math.sqrt(2.0 * c)
    y1 = d0p
    y2 = 0.8 * d0 + 0.2 * t * d0p
    return ZeroOrder(phi, t, dt_dphi, d0, d0p, gp, gpp_dt, y1, y2)


def _grid_size(w: float) -> int:
    n = int(max(2048, 40.0 * w))
    return n + (n % 2)


def _cumint(y: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """The cumulative Simpson integral of y over the zero-order grid (uniform in phi: scipy's equal-interval rule, ~10x
    less work than its unequal-interval one given the same points as x, the same integral to roundoff)."""
    return cumulative_simpson(y, dx=float(phi[1] - phi[0]), initial=0.0, axis=-1)


def hertz_d1(w: float, n: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """First-order correction d1(t) per unit s for one mode of scaled frequency `w` (w = inf: static spring,
    result per unit s/w^2). Returns (t, d1) on the zero-order grid, t in [0, 2c]."""
    if n is None:
        n = _grid_size(0.0 if math.isinf(w) else w)
    z = zero_order(n)
    if math.isinf(w):
        K_dt = z.gpp_dt                                          # K = g''
        F_dt = -1.25 * K_dt
        I1 = _cumint(z.y1 * F_dt, z.phi)
        I2 = _cumint(z.y2 * F_dt, z.phi)
        return z.t, z.y2 * I1 - z.y1 * I2
    return z.t, _d1_rows(np.array([w], float), z)[0]


def _d1_rows(w: np.ndarray, z: ZeroOrder) -> np.ndarray:
    """`hertz_d1` of finite modes `w` [k] on one zero-order grid, a row each [k, n + 1]: the same quadratures along
    the rows of one array (one cumulative Simpson call per integral for a block of modes, not per mode; with the
    equal-interval rule of `_cumint` the weights and curves of an unseen beam needing 1,109 modes took 3.3 s instead
    of 8.3 s)."""
    wt = np.outer(w, z.t)
    cw, sw = np.cos(wt), np.sin(wt)
    C = _cumint(z.gp * cw * z.dt_dphi, z.phi)
    S = _cumint(z.gp * sw * z.dt_dphi, z.phi)
    F_dt = -1.25 * (cw * C + sw * S) * z.dt_dphi
    I1 = _cumint(z.y1 * F_dt, z.phi)
    I2 = _cumint(z.y2 * F_dt, z.phi)
    return z.y2 * I1 - z.y1 * I2


#: most grid values (modes x points) of one block of `_d1_rows` (8 bytes each: 1e6 ~ 8 MB an array)
_D1_BLOCK = 1_000_000


def _d1_sum(w: np.ndarray, s: np.ndarray, n: int) -> np.ndarray:
    """sum_j s_j d1(w_j) on the zero-order grid of n + 1 points (finite w), in blocks of modes."""
    z = zero_order(n)
    out = np.zeros(n + 1)
    block = max(1, _D1_BLOCK // (n + 1))
    for i0 in range(0, len(w), block):
        out += s[i0:i0 + block] @ _d1_rows(w[i0:i0 + block], z)
    return out


def _weights_of(d1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(TH, MH) from d1 curves on the zero-order grid (rows or one curve): TH = d1(2c)/(2c), MH = d1(c) (phi = pi/2,
    the grid's middle)."""
    mid = (d1.shape[-1] - 1) // 2
    return d1[..., -1] / (2.0 * C_HERTZ), d1[..., mid]


def _weights_one(w: float, n: int | None = None) -> tuple[float, float]:
    th, mh = _weights_of(hertz_d1(w, n)[1])
    return float(th), float(mh)


@lru_cache(maxsize=1)
def hertz_static_weights() -> tuple[float, float]:
    """(TH_INF, MH_INF): w^2 TH(w), w^2 MH(w) as w -> inf (a stiff mode = a spring in series)."""
    return _weights_one(math.inf, 8192)


#: quadrature weights (TH, MH) by scaled frequency w, at most _WEIGHTS_CACHE of them (emptied when full)
_WEIGHTS: dict[float, tuple[float, float]] = {}
_WEIGHTS_CACHE = 65536                  # >> a scene's modes (PERTURBATION_MODE_CAP), so one page's calls share them


def _hertz_weights_cached(w: float) -> tuple[float, float]:
    if w == 0.0:
        return -0.4, -0.4                    # a free mass: exact (tested against the quadrature at small w)
    if w > W_QUADRATURE_MAX:
        th, mh = hertz_static_weights()
        return th / w**2, mh / w**2
    hit = _WEIGHTS.get(w)
    if hit is None:
        hit = _weights_one(w)
        _keep(w, hit)
    return hit


def _keep(w: float, weights: tuple[float, float]) -> None:
    if len(_WEIGHTS) >= _WEIGHTS_CACHE:
        _WEIGHTS.clear()
    _WEIGHTS[w] = weights


def hertz_weights(w) -> tuple[np.ndarray, np.ndarray]:
    """TH(w), MH(w) per unit s (physics.md 7.2) for scaled mode frequencies `w` (array-like, >= 0)."""
    w = np.atleast_1d(np.asarray(w, float))
    if np.any(~np.isfinite(w)) or np.any(w < 0):
        raise ImpactvalError(f"scaled mode frequencies must be finite and >= 0, got {w!r}.")
    fresh = _weights_together(w)
    out = np.array([fresh.get(x) or _hertz_weights_cached(x) for x in map(float, w)]).reshape(-1, 2)
    return out[:, 0], out[:, 1]


def _weights_together(w: np.ndarray) -> dict[float, tuple[float, float]]:
    """The quadrature weights of the modes of `w` not cached yet, computed together (`_d1_rows`: blocks of modes
    sharing their grid size; the same arithmetic as `_weights_one`, row by row) and cached."""
    todo = sorted({float(x) for x in w if 0.0 < x <= W_QUADRATURE_MAX} - _WEIGHTS.keys())
    fresh: dict[float, tuple[float, float]] = {}
    by_size: dict[int, list[float]] = {}
    for x in todo:
        by_size.setdefault(_grid_size(x), []).append(x)
    for n, ws in by_size.items():
        z = zero_order(n)
        block = max(1, _D1_BLOCK // (n + 1))
        for i0 in range(0, len(ws), block):
            part = ws[i0:i0 + block]
            for x, th, mh in zip(part, *_weights_of(_d1_rows(np.array(part), z))):
                fresh[x] = (float(th), float(mh))
                _keep(x, fresh[x])
    return fresh


# ----------------------------------------------------------------------------- scenes

@dataclass(frozen=True)
class ModeWeights:
    """Per-mode first-order data of a scene: `omega` [rad/s], `w` = omega delta_m/v0 (= r), `s` = (m0/m) phi^2,
    weights per unit s: TH, MH (Hertz), T, M (linear); plus the residual flexibility's weight `rho` = R k0."""

    omega: np.ndarray
    w: np.ndarray
    s: np.ndarray
    TH: np.ndarray
    MH: np.ndarray
    T: np.ndarray
    M: np.ndarray
    rho: float


def mode_weights(modes: Modes, mass: float, alpha: float, v0: float) -> ModeWeights:
    """First-order weights of each mode of `modes` for a ball (`mass` [kg], `v0` [m/s]) and Hertz `alpha`."""
    plate = plate_impact(mass, alpha, v0)
    omega = np.asarray(modes.omega, float)
    w = omega * plate.delta_m / v0
    s = mass / np.asarray(modes.modal_mass, float) * np.asarray(modes.phi, float) ** 2
    TH, MH = hertz_weights(w)
    return ModeWeights(omega, w, s, TH, MH, T_linear(w), M_linear(w), float(modes.residual_flexibility) * plate.k0)


@dataclass(frozen=True)
class PerturbationResult:
    """First-order metrics of a scene: `metrics` (t_m [s], f_m [N], delta_m [m]), the model
    ("linear", "hertz" or "hertz-sine"), the relative shifts (sum of s_j * weight) and the weights used.
    `validity`: warnings when the shifts leave the first-order range (reference/validity.py); the metrics
    are NaN when a shift reaches -100 % (no first-order answer)."""

    model: str
    metrics: Metrics
    shift_t: float
    shift_delta: float
    weights: ModeWeights
    validity: tuple[str, ...] = ()


def _scene_modes(scene, modes: int | None) -> Modes:
    from impactval.reference.solve import structure_modes

    target = scene.target
    fixed = modes if modes is not None else getattr(target, "modes", None)
    if target.kind in ("beam", "plate") and fixed is None:
        # automatic: every mode up to w = W_QUADRATURE_MAX, the rest as a residual static flexibility
        plate = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
        n = 8
        while True:
            md = structure_modes(scene, n)
            if md.omega[-1] * plate.delta_m / scene.ball.velocity > W_QUADRATURE_MAX or n >= PERTURBATION_MODE_CAP:
                break
            n *= 2
        keep = int(np.searchsorted(md.omega * plate.delta_m / scene.ball.velocity, W_QUADRATURE_MAX))
        return structure_modes(scene, max(keep, 1), residual=True)
    return structure_modes(scene, fixed)


def perturbation(scene, model: str = "hertz", modes: int | None = None) -> PerturbationResult:
    """First-order (light-ball) impact of `scene`.

    Parameters
    ----------
    scene : Scene
    model : {"hertz", "hertz-sine", "linear"}
        "hertz": exact zero-order Hertz curve and TH, MH by quadrature; "hertz-sine": the paper's sine
        approximation d0 ~ sin(e0 t) (TH -> T(w/e0), MH -> M(w/e0)); "linear": the linear contact k0.
    modes : int, optional
        Beam mode count (as in impactval.solve); None = automatic (all modes up to w = 50, plus the residual
        static flexibility of the rest with the w -> inf weights).
    """
    if model not in ("hertz", "hertz-sine", "linear"):
        raise ImpactvalError(f"perturbation model must be 'hertz', 'hertz-sine' or 'linear', got {model!r}.")
    if modes is not None and (isinstance(modes, bool) or not isinstance(modes, int) or modes < 1):
        raise ImpactvalError(f"modes must be a positive whole number, got {modes!r}.")
    from impactval.reference.structure import contact_scene

    scene = contact_scene(scene)          # a second ball: the equivalent ball on a rigid plate
    ball = scene.ball
    mass, alpha, v0 = ball.mass, scene.alpha, ball.velocity
    plate = plate_impact(mass, alpha, v0)
    md = _scene_modes(scene, modes)
    mw = mode_weights(md, mass, alpha, v0)
    if model == "hertz":
        th_inf, mh_inf = hertz_static_weights()
        st = float(np.sum(mw.s * mw.TH)) + mw.rho * th_inf
        sd = float(np.sum(mw.s * mw.MH)) + mw.rho * mh_inf
        m = Metrics(plate.t_m * (1 + st), plate.f_m * (1 + 1.5 * sd), plate.delta_m * (1 + sd))
    elif model == "hertz-sine":
        r = mw.w / E0
        st = float(np.sum(mw.s * T_linear(r))) + mw.rho * T_LINEAR_INF * E0**2
        sd = float(np.sum(mw.s * M_linear(r))) + mw.rho * M_LINEAR_INF * E0**2
        m = Metrics(plate.t_m * (1 + st), plate.f_m * (1 + 1.5 * sd), plate.delta_m * (1 + sd))
    else:
        st = float(np.sum(mw.s * mw.T)) + mw.rho * T_LINEAR_INF
        sd = float(np.sum(mw.s * mw.M)) + mw.rho * M_LINEAR_INF
        t0, d0 = math.pi * plate.delta_m / v0, plate.delta_m
        m = Metrics(t0 * (1 + st), plate.k0 * d0 * (1 + sd), d0 * (1 + sd))
    validity, usable = perturbation_validity(st, sd)
    if md.residual_flexibility > 0 and md.n >= PERTURBATION_MODE_CAP and mw.w[-1] < W_QUADRATURE_MAX:
        validity += (f"first-order weights: the automatic mode set stopped at its cap ({md.n} modes, w up to "
                     f"{mw.w[-1]:.3g} of {W_QUADRATURE_MAX:g}): the modes above are taken as static springs, their "
                     f"dynamic part left out (give modes=N for a fixed set)",)
    if not usable:
        m = Metrics(math.nan, math.nan, math.nan)
    return PerturbationResult(model, m, st, sd, mw, validity)


def perturbation_curve(scene, model: str = "hertz", modes: int | None = None, n: int = 801):
    """First-order approach curve: (t [s], delta [m], f [N]) over the zero-order contact [0, t_0]
    (t_0 = the rigid-plate duration of the model; first order, so the end is not shifted)."""
    from impactval.reference.structure import contact_scene

    res = perturbation(scene, model, modes)
    scene = contact_scene(scene)
    ball = scene.ball
    mass, alpha, v0 = ball.mass, scene.alpha, ball.velocity
    plate = plate_impact(mass, alpha, v0)
    mw = res.weights
    if model == "linear":
        theta = np.linspace(0.0, math.pi, n)
        d = np.sin(theta) + _linear_sum(theta, mw.w, mw.s)
        d = d + mw.rho * _static_linear_curve(theta)
        t = theta * plate.delta_m / v0
        delta = plate.delta_m * d
        return t, delta, plate.k0 * np.maximum(delta, 0.0)
    if model == "hertz-sine":
        ts = np.linspace(0.0, 2 * C_HERTZ, n)
        d = np.sin(E0 * ts) + _linear_sum(E0 * ts, mw.w / E0, mw.s)
        d = d + mw.rho * E0**2 * _static_linear_curve(E0 * ts)
    else:
        nz = _grid_size(float(np.max(mw.w[mw.w <= W_QUADRATURE_MAX], initial=0.0)))
        z = zero_order(nz)
        # the modes by quadrature (their curves summed block by block), the stiff ones and the residual as one
        # static curve with their summed weights s/w^2 (it was made again for every stiff mode)
        quad = (mw.s != 0) & (mw.w <= W_QUADRATURE_MAX)
        stiff = (mw.s != 0) & (mw.w > W_QUADRATURE_MAX)
        d = z.d0 + _d1_sum(mw.w[quad], mw.s[quad], nz)
        d = d + (float(np.sum(mw.s[stiff] / mw.w[stiff] ** 2)) + mw.rho) * hertz_d1(math.inf, nz)[1]
        ts = z.t
        idx = np.linspace(0, len(ts) - 1, n).round().astype(int)
        ts, d = ts[idx], d[idx]
    t = ts * plate.delta_m / v0
    delta = plate.delta_m * d
    return t, delta, alpha * np.maximum(delta, 0.0) ** 1.5


def _linear_sum(theta: np.ndarray, r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """sum_j s_j L(theta; r_j) at every theta, blocks of modes at once (L broadcasts; one call per mode took ~0.2 ms)."""
    out = np.zeros(len(theta))
    block = max(1, _D1_BLOCK // max(len(theta), 1))
    for i0 in range(0, len(r), block):
        out += s[i0:i0 + block] @ L_linear(theta[None, :], r[i0:i0 + block, None])
    return out


def _static_linear_curve(theta: np.ndarray) -> np.ndarray:
    """lim r^2 L(theta; r) as r -> inf: -(sin(theta) + theta cos(theta))/2 (a spring in series)."""
    return -0.5 * (np.sin(theta) + theta * np.cos(theta))
