"""Which modes matter: size a structure model from the first-order weights (physics.md sec. 5, 7.2).

Mode j changes the relative duration by s_j TH(w_j) and the peak approach by s_j MH(w_j) (peak force
1.5 s_j MH(w_j)), to first order, with s_j = (m0/m_j) phi_j0^2 and w_j = omega_j delta_m/v0. So
- modes far *below* the impact frequency (w -> 0) do not fade: each is a free mass, weight -0.4 s_j;
  they must be kept (they come first in frequency order anyway);
- modes far *above* it fade like s_j/w_j^2 and act as springs in series: their static flexibility
  (TH -> TH_INF/w^2, MH -> MH_INF/w^2) is exactly what the residual static flexibility of the dropped modes
  restores (reference/solve.py's mode-acceleration correction). What the residual does *not* restore is
  the dynamic remainder s_j |TH(w_j) - TH_INF/w_j^2| (and the same for MH).

`required_modes(scene, tol)` keeps the first n modes (frequency order) such that the dropped modes'
summed |weights| stay below SAFETY * tol on t_m, f_m and delta_m (the f_m, delta_m sums scaled by
1 + |sum_j s_j MH_j|, a resummed estimate of how much the structure lowers them): `count` for a model with the residual
static flexibility (dynamic remainder only), `count_without_residual` for a plain n-mode model (the whole
weight of every dropped mode). Beyond w = W_QUADRATURE_MAX the remainder is bounded by REMAINDER_BOUND times
the dropped static flexibility (measured |w^2 TH - TH_INF|, |w^2 MH - MH_INF| <= 0.0034 for w >= 50).
`rigid_plate_enough` is true when the whole structure shifts every metric by less than `tol` (first order;
the shift is then small, so the second-order terms are negligible).

The verdicts are checked against exact solutions with many more modes on the whole catalogue
(tests/test_modechoice.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from impactval.errors import ImpactvalError
from impactval.reference.beams import Modes
from impactval.reference.hertz import plate_impact
from impactval.reference.perturbation import W_QUADRATURE_MAX, hertz_static_weights, mode_weights
from impactval.reference.result import Metrics

#: fraction of the tolerance the dropped modes may use (first-order estimate; margin for second order)
SAFETY = 0.25
#: bound on |w^2 TH(w) - TH_INF| and |w^2 MH(w) - MH_INF| for w >= W_QUADRATURE_MAX (measured <= 0.0034)
REMAINDER_BOUND = 0.005
#: the plain-model count extrapolated beyond the table stops here (`ModeChoice.plain_count_capped`: "at least")
PLAIN_COUNT_CAP = 100_000
#: the weights table runs up to this scaled frequency (beyond W_QUADRATURE_MAX with the 1/w^2 forms)
W_TABLE = 64 * W_QUADRATURE_MAX


@dataclass(frozen=True)
class ModeChoice:
    """The modes a scene needs for a relative tolerance `tol` on t_m, f_m, delta_m.

    `count`: first modes to keep in a model *with* the residual static flexibility of the rest;
    `count_without_residual`: the same for a plain modal (or discretised) model without it;
    `omega_max`, `omega_max_without_residual` [rad/s]: frequency of the last kept mode (0 if none), i.e. the
    band a discretised model (beam segments) must resolve;
    `rigid_plate_enough`: the whole structure changes every metric by less than `tol`;
    `structure_effect`: first-order relative shifts of t_m, f_m, delta_m by the whole structure;
    per-mode table (frequency order, modes with phi = 0 included): `omega` [rad/s], `w`, `s`, `TH`, `MH`
    (weights per unit s) and the contributions `d_t` = s TH, `d_f` = 1.5 s MH, `d_delta` = s MH;
    `rho_rest`: the static flexibility (times k0) of all modes beyond the table.
    """

    scene: str
    tol: float
    count: int
    count_without_residual: int
    omega_max: float
    omega_max_without_residual: float
    rigid_plate_enough: bool
    structure_effect: Metrics
    omega: np.ndarray
    w: np.ndarray
    s: np.ndarray
    TH: np.ndarray
    MH: np.ndarray
    rho_rest: float
    #: `count` stopped at the table's size (`required_modes`' max_modes): the scene needs at least that many
    count_capped: bool = False

    @property
    def plain_count_capped(self) -> bool:
        """True when `count_without_residual` stopped at PLAIN_COUNT_CAP: the plain model needs at least that many."""
        return self.count_without_residual >= PLAIN_COUNT_CAP

    @property
    def d_t(self) -> np.ndarray:
        return self.s * self.TH

    @property
    def d_delta(self) -> np.ndarray:
        return self.s * self.MH

    @property
    def d_f(self) -> np.ndarray:
        return 1.5 * self.s * self.MH

    def table(self, limit: int | None = None):
        """The per-mode weights as a pandas DataFrame (first `limit` rows; columns named with units)."""
        import pandas as pd

        n = len(self.omega) if limit is None else min(limit, len(self.omega))
        return pd.DataFrame({"mode": np.arange(1, n + 1), "omega_rad_s": self.omega[:n], "w": self.w[:n],
                             "s": self.s[:n], "TH": self.TH[:n], "MH": self.MH[:n], "d_t_m": self.d_t[:n],
                             "d_f_m": self.d_f[:n], "d_delta_m": self.d_delta[:n],
                             "kept": np.arange(1, n + 1) <= self.count})


def _all_modes(scene, max_modes: int = 8192) -> tuple[Modes, float]:
    """The scene's modes in frequency order up to w = W_TABLE (at least all listed ones for a
    modal target), and k0 times the static flexibility of every mode beyond them."""
    from impactval.reference.solve import structure_modes

    target = scene.target
    mass, alpha, v0 = scene.ball.mass, scene.alpha, scene.ball.velocity
    plate = plate_impact(mass, alpha, v0)
    if target.kind == "modal":
        md = structure_modes(scene)
        order = np.argsort(md.omega)
        return Modes(md.omega[order], md.modal_mass[order], md.phi[order], 0.0), 0.0
    n = 8
    while True:
        md = structure_modes(scene, n)
        if md.omega[-1] * plate.delta_m / v0 > W_TABLE or n >= max_modes:
            break
        n *= 2
    keep = max(int(np.searchsorted(md.omega * plate.delta_m / v0, W_TABLE, side="right")), 1)
    md = structure_modes(scene, keep, residual=True)
    return md, md.residual_flexibility * plate.k0


def required_modes(scene, tol: float = 1e-3, max_modes: int = 8192) -> ModeChoice:
    """The fewest modes `scene` needs for relative tolerance `tol` on t_m, f_m, delta_m (see module doc).

    Parameters
    ----------
    scene : Scene
    tol : float
        Relative tolerance (1e-8 .. 0.5).
    """
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not math.isfinite(tol) or not 1e-8 <= tol <= 0.5:
        raise ImpactvalError(f"tol must be a relative tolerance between 1e-8 and 0.5, got {tol!r}.")
    from impactval.reference.structure import contact_scene

    scene = contact_scene(scene)          # a second ball: the equivalent ball on a rigid plate
    mass, alpha, v0 = scene.ball.mass, scene.alpha, scene.ball.velocity
    if scene.target.kind == "rigid-plate":
        z = np.zeros(0)
        return ModeChoice(scene.name, tol, 0, 0, 0.0, 0.0, True, Metrics(0.0, 0.0, 0.0), z, z, z, z, z, 0.0)
    md, rho_rest = _all_modes(scene, max_modes)   # max_modes: table size (beyond: static, counts extrapolated)
    mw = mode_weights(Modes(md.omega, md.modal_mass, md.phi, 0.0), mass, alpha, v0)
    th_inf, mh_inf = hertz_static_weights()
    s, w = mw.s, mw.w
    # whole-structure first-order effect (listed modes + static weight of the rest)
    eff_t = float(np.sum(s * mw.TH)) + rho_rest * th_inf
    eff_d = float(np.sum(s * mw.MH)) + rho_rest * mh_inf
    effect = Metrics(eff_t, 1.5 * eff_d, eff_d)
    rigid = max(abs(eff_t), abs(1.5 * eff_d), abs(eff_d)) < tol
    # dropped-mode budgets: tail sums from mode n+1 on (index n), for n = 0..N
    stat = np.where(w > 0, s / np.maximum(w, 1e-300) ** 2, 0.0)
    asym = w > W_QUADRATURE_MAX                  # weights from the 1/w^2 forms: bound the remainder instead
    dyn_t = np.where(asym, REMAINDER_BOUND * stat, np.abs(s * mw.TH - th_inf * stat))
    dyn_d = np.where(asym, REMAINDER_BOUND * stat, np.abs(s * mw.MH - mh_inf * stat))
    rest_dyn = REMAINDER_BOUND * rho_rest

    def tail(x):
        return np.concatenate((np.cumsum(x[::-1])[::-1], [0.0]))

    budget = SAFETY * tol
    # The weights are relative to the rigid-plate delta_m, f_m; the tolerance is relative to the actual ones.
    # A strongly coupled structure lowers them (heavy ball on a slender beam: f_m ~ 0.2 of the plate's), so
    # the same absolute error is a larger relative one. Resummed first-order estimate of delta_plate/delta:
    # 1 + |sum s MH| (within 5 % on beam_ss_midspan, conservative by 2.5x on heavy_ball_slender_beam).
    amp = 1.0 + abs(eff_d)
    with_res = np.maximum(tail(dyn_t) + rest_dyn, 1.5 * amp * (tail(dyn_d) + rest_dyn))
    plain_t = tail(np.abs(s * mw.TH)) + rho_rest * (th_inf + REMAINDER_BOUND)
    plain_d = tail(np.abs(s * mw.MH)) + rho_rest * (abs(mh_inf) + REMAINDER_BOUND)
    plain = np.maximum(plain_t, 1.5 * amp * plain_d)
    n_all = len(w)
    count = _first_below(with_res, budget, n_all)
    count_plain = _first_below(plain, budget, n_all)
    if count_plain is None:      # the table's modes are not enough without a residual: extrapolate the 1/n^3 tail
        count_plain = _extrapolate_plain(scene, n_all, plain[-1], budget)
    capped = count is None
    if capped:
        count = n_all
    om_all = md.omega

    def omax(n):
        if n == 0:
            return 0.0
        if n <= n_all:
            return float(om_all[n - 1])
        if n_all >= max_modes:
            return math.nan          # beyond a capped table (engines asking for a count only)
        from impactval.reference.solve import structure_modes

        return float(structure_modes(scene, n).omega[-1])

    return ModeChoice(scene.name, float(tol), int(count), int(count_plain), omax(count), omax(count_plain), rigid,
                      effect, md.omega, w, s, mw.TH, mw.MH, rho_rest, capped)


def _first_below(tails: np.ndarray, budget: float, n_all: int) -> int | None:
    ok = np.flatnonzero(tails <= budget)
    return int(ok[0]) if len(ok) else None


def _extrapolate_plain(scene, n_all: int, tail_at_n_all: float, budget: float) -> int:
    """Plain-model count beyond the table: the dropped static flexibility of a beam falls like n^-3, that of a
    plate like n^-1 (modes fill the (m, n) plane: N ~ r^2, dropped sum ~ 1/r^2)."""
    power = 1.0 if scene.target.kind == "plate" else 3.0
    n = int(math.ceil(n_all * (tail_at_n_all / budget) ** (1.0 / power)))
    return min(max(n, n_all), PLAIN_COUNT_CAP)
