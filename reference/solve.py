"""The reference solution of a scene: Hertz contact on a modal structure, with error estimates.

`solve(scene, tol)` returns an ImpactResult whose `uncertainty` covers
- the time step: every solution is computed at two step sizes H and 2H; the scheme's order is
  p + 1 = 6 (shown by tests/test_convergence.py), and the estimate |X_H - X_2H| / (2^4 - 1)
  assumes only order 4, so it over-estimates the real error by ~4x in the asymptotic range (the
  margin covers pre-asymptotic step sizes where the error changes sign);
- modal truncation (beams with an automatic mode count): n modes plus the residual static
  flexibility of all dropped modes (mode-acceleration correction) are compared with 2n modes;
  the difference is reported as the truncation uncertainty of the n-mode result.
"""
from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from impactval.errors import ImpactvalError
from impactval.reference import kernel
from impactval.reference.beams import Modes, beam_modes
from impactval.reference.hertz import plate_impact
from impactval.reference.result import Contact, ImpactResult, Metrics, Status, build
from impactval.reference.validity import deflection_validity, hertz_validity

#: polynomial degree of the force interpolation (order of the scheme: P_DEGREE + 1)
P_DEGREE = 5
#: grading window as a fraction of the rigid-plate contact time
GRADING_WINDOW = 0.2
#: order assumed by the error estimate (one less than the scheme's, so the estimate is conservative)
ESTIMATE_ORDER = 4
#: steps per rigid-plate contact time at which the a-priori error model is anchored, and its error
_N_ANCHOR, _ERR_ANCHOR = 20.0, 3e-6
#: the first base-step count aims at an estimate of this fraction of tol


@dataclass(frozen=True)
class Run:
    """Metrics and series of one integration at a fixed base step."""

    metrics: Metrics
    n_steps: int
    t: np.ndarray
    delta: np.ndarray
    f: np.ndarray
    x_ball: np.ndarray
    u_ball: np.ndarray
    energy: np.ndarray
    contacts: tuple[Contact, ...]
    rebound_velocity: float
    energy_error: float = math.nan


@lru_cache(maxsize=128)
def _beam_modes_cached(beam, n: int, residual: bool) -> Modes:
    return beam_modes(beam, n, residual=residual)


def structure_modes(scene, n: int | None = None, residual: bool = False) -> Modes:
    """The modal data of a scene's target (empty for a rigid plate). For a beam the first `n` modes,
    for a modal target the `n` lowest (all when n is None); `residual` adds the static flexibility
    of the rest."""
    from impactval.reference.structure import structure_modes as _modes    # the one dispatch on target kind

    return _modes(scene, n, residual)


@lru_cache(maxsize=256)
def _plate(mass: float, alpha: float, v0: float):
    """plate_impact (a frozen result) for repeated solves of one ball and contact."""
    return plate_impact(mass, alpha, v0)


def _select(modes: Modes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    key = id(modes)
    hit = _SELECT_CACHE.get(key)
    if hit is not None and hit[0] is modes:
        return hit[1]
    out = _select_uncached(modes)
    if len(_SELECT_CACHE) > 64:
        _SELECT_CACHE.clear()
    _SELECT_CACHE[key] = (modes, out)
    return out


_SELECT_CACHE: dict = {}


def _select_uncached(modes: Modes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arrays for the kernel: omega, g = phi^2/(m omega), energy weight omega/g; modes with
    phi = 0 at the impact point are never excited and are dropped."""
    keep = np.abs(modes.phi) > 1e-12
    omega = np.ascontiguousarray(modes.omega[keep], dtype=float)
    g = np.ascontiguousarray(modes.phi[keep] ** 2 / (modes.modal_mass[keep] * omega))
    return omega, g, omega / g


def integrate(modes: Modes, mass: float, alpha: float, v0: float, n_steps: float,
              window: float = 0.0, J: int | None = None, tol: float = 1e-6) -> Run:
    """One integration with base step H = t_plate / n_steps (t_plate: rigid-plate duration).

    `window` [s]: keep integrating this long after the first contact ends (re-contacts).
    `J` sets the smallest step H / 2^J used at touch and separation (default: from `tol`, see
    `levels`).
    """
    plate = plate_impact(mass, alpha, v0)
    H = plate.t_m / n_steps
    if J is None:
        J = levels(n_steps, tol)
    omega, g, ew = _select(modes)
    Er, Ei, Kr, Ki, S = kernel.moments(omega, g, H, J, P_DEGREE)
    max_nodes = int(6 * n_steps + 60 * J + 50 + (2.5 * window / H if window > 0 else 0))
    for _ in range(8):
        status, cnt, t, d, f, x, u, e, flags = kernel.run(
            ew, mass, alpha, v0, modes.residual_flexibility, H, J, P_DEGREE,
            GRADING_WINDOW * plate.t_m, window, Er, Ei, Kr, Ki, S, max_nodes)
        if status == kernel.STATUS_OK:
            break
        max_nodes *= 4
    else:  # pragma: no cover - would need a pathological scene
        raise ImpactvalError(f"reference solver did not finish the contact within {max_nodes} steps")
    t, d, f, x, u, e, flags = t[:cnt], d[:cnt], f[:cnt], x[:cnt], u[:cnt], e[:cnt], flags[:cnt]
    table = kernel.contacts(t, d, flags, f, modes.residual_flexibility)
    return _make_run(alpha, t, d, f, x, u, e, table, int(np.argmax(flags == 2)),
                     float(np.max(np.abs(e / e[0] - 1.0))))


def _make_run(alpha, t, d, f, x, u, e, table, end: int, drift: float) -> Run:
    """A Run from the kernel's series and contact table (rows t_start, t_end, delta_max)."""
    contacts = tuple([Contact(a, b, alpha * c**1.5, c) for a, b, c in table.tolist()])
    first = contacts[0]
    return build(Run, {"metrics": Metrics(first.t_end - first.t_start, first.f_max, first.delta_max),
                       "n_steps": len(t) - 1, "t": t, "delta": d, "f": f, "x_ball": x, "u_ball": u, "energy": e,
                       "contacts": contacts, "rebound_velocity": -float(u[end]), "energy_error": drift})


#: the smallest step H/2^J is ~(SMALLEST_STEP_FACTOR tol)^0.4 t_plate. The first step's force is approximated
#: with an error ~(smallest step / t_plate)^2.5 ~ SMALLEST_STEP_FACTOR tol that converges at order 2.5 only (ratio 5.7
#: per halving, below the ratio the Richardson estimate trusts): at 1e-3 it showed on random scenes (a plate with
#: residual flexibility at tol 1e-4: errors 1.5e-7, 1.0e-6, 2.0e-5 at H, 2H, 4H, 1.7x above the estimate; 2.4x on
#: another); at 1e-5 it is negligible, for ~2 more levels (+4 % nodes on 1,500 random scenes).
SMALLEST_STEP_FACTOR = 1e-5
#: that error, relative, is taken as at most SMALLEST_STEP_C (eta_min / t_ref)^2.5 (eta_min = H/2^J, the fine run's
#: smallest step; t_ref = t_plate, or the first contact's duration where shorter), added to the uncertainty (round 9):
#: the three runs share J, so it falls by 2^2.5 = 5.7 per halving of H, below the ratio the Richardson estimate trusts
#: (up to 16 / 1.5), and where the base step is far shorter than tol
#: needs (n set by the unresolved modes) it is the larger part of the real error: held-out seed 6832 (a 120-mode plate
#: at tol 1e-4, n = 512, J = 3) erred 5.7e-8 against an estimate of 3.4e-8, 98 % of it this error (the runs at H, 2H,
#: 4H fit a H^6 + b H^2.5 with b/a = 55). Measured as |X(J) - X(J + 6)| at the chosen H on seeds 0-1999 of the tests'
#: generator at tol 1e-4/1e-6/1e-8 (6,000 solves; `python benchmarks/bound_honesty.py 0 2000 --smallest`): where it
#: converges at order 2.5 (872 solves, X(J) - X(J+6) = 4-8x X(J+1) - X(J+6)) the constant was at most 536 (beams;
#: plates 195, modal targets 277, median 7); 3x that, as for the unresolved-mode table. With eta_min relative to a
#: shorter contact's own duration (kernel.SHORT_CONTACT) it is at most 170 / 185 / 277 there, 311 on seeds 4000-7999,
#: and 141 on 8000-11999 but for one soft beam (seed 9717, contact 2.35 t_plate: 7570, the error 3 % of its estimate):
#: the constant is not a bound on every scene; the share below gives the margin, and the honesty counts check it.
#: With J from tol the term is at most 1.6 % of tol; where it would pass kernel.SMALLEST_SHARE of the rest of the
#: estimate, the runs are made again with more levels (added alone it loosened random scenes' median reported/real
#: from 6.9 to 9.8).
SMALLEST_STEP_C = 1600.0
#: the window refusal keeps the time resolution rule it was set with (1e-3 of a smallest step at 1e-3 tol)
_WINDOW_STEP_FACTOR = 1e-3


def levels(n_steps: float, tol: float) -> int:
    """Step-size levels J for a base step t_plate / n_steps (see kernel.levels)."""
    return kernel.levels(float(n_steps), float(tol), SMALLEST_STEP_FACTOR)


#: Error of one mode the base step H does not resolve that the Richardson estimate misses, relative on t_m,
#: f_m, delta_m: <= C(omega_c H) s w^-3.5 (s = (m0/m) phi^2, w = omega delta_m/v0, omega_c the mode's frequency held by
#: the contact's tangent stiffness). Measured by benchmarks/unresolved_table.py with the metrics solve_auto computes
#: (delta_max from the scheme's own solution between nodes, kernel.dense_peak): the largest excess (error - Richardson
#: estimate - the plate's own error) / (s w^-3.5) of a single mode (s = 0.01 .. 30 at 17 values, w = 3 .. 1000 at 27,
#: base steps t_plate/10 .. t_plate/1000 at 400, tol 1e-5 and 1e-8: 266,220 runs) per theta bin; C is 3x the largest
#: excess of the bin and its two neighbours, a running maximum up to theta = 3.5. Above 3.5, row 0 follows the
#: measurements: its excess peaks where one base step holds a whole period of the mode (theta near 2 pi: up to 1.24;
#: near 4 pi: 1.44; all three runs of the estimate then alias the mode alike) and is <= 0.06 between, floored at the
#: bins of (3.5, 5.5]. One row per coupling class (UNRESOLVED_CLASSES): s <= 1, and s above (strongly coupled modes,
#: whose error at omega_c H >= 2.7 is up to ~20 s w^-3.5; a running maximum throughout). A third class (s <= 0.2,
#: up to 40x below s <= 1 at theta ~1) was tried with the plain sum: 17 of 25 scenes within 10x against 15, but its
#: smaller first steps made the step control retry more often (the worked beam, tols 1e-4 .. 1e-8: 15-30 % slower).
#: A step function (the value of the first point >= theta), ~theta^6 below the table, above it
#: max(C[-1], C[-1] sqrt(w)/4) (a stiff mode's raw error falls like w^-3, not w^-3.5). The table before (a running
#: maximum of each bin alone, 16 w and 9 s values, 160 steps) was 50x below a mode off its grid (s 1, w 15 at theta
#: 1.14) and 5x below one just past a bin edge (s 0.85, w 50 at theta 1.800): single-mode solves reported up to 1.87x
#: less than their real error (4 of 2,542 off-grid comparisons); with this table 0 of 4,046 (14 couplings x 16
#: frequencies off the grid x 22 tolerances, worst 0.52 of the bound). Checked by tests/test_convergence.py
#: (test_unresolved_mode_error_table on the grid, test_uncertainty_bounds_single_modes_off_the_table_grid* off it).
UNRESOLVED_THETA = np.array([0.35, 0.5, 0.6, 0.7, 0.8, 1, 1.2, 1.5, 1.65, 1.8, 2, 2.2, 2.45, 2.7, 3, 3.25, 3.5,
                             3.75, 4, 4.25, 4.5, 4.75, 5, 5.25, 5.5, 5.75, 6, 6.25, 6.5, 6.75, 7, 7.25, 7.5, 7.75,
                             8, 8.5, 9, 10, 11, 12, 13, 14, 15, 16, 18, 20])
UNRESOLVED_C = np.array([
    [3.00e-06, 3.00e-06, 1.42e-05, 3.61e-05, 2.26e-04, 3.72e-03, 3.72e-03, 4.09e-03, 4.09e-03, 1.73e-02,
     2.99e-02, 2.99e-02, 4.20e-02, 5.61e-02, 5.61e-02, 6.04e-02, 7.89e-02, 1.46e-01, 1.46e-01, 1.46e-01,
     1.46e-01, 1.46e-01, 1.46e-01, 1.46e-01, 1.75e-01, 4.94e-01, 3.43e+00, 3.73e+00, 3.73e+00, 3.73e+00,
     3.53e-01, 1.70e-01, 1.46e-01, 1.46e-01, 1.46e-01, 1.46e-01, 1.46e-01, 1.46e-01, 1.46e-01, 4.31e+00,
     4.31e+00, 4.31e+00, 1.46e-01, 1.46e-01, 1.46e-01, 1.46e-01],
    [3.00e-06, 3.00e-06, 1.84e-04, 1.84e-04, 2.06e-02, 2.21e-02, 9.03e-02, 9.03e-02, 3.77e-01, 3.77e-01,
     4.53e-01, 4.53e-01, 3.09e+00, 1.41e+01, 1.53e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01,
     7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01,
     7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01,
     7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01, 7.01e+01]])
#: the coupling classes of the table's rows: row k holds the modes with
#: UNRESOLVED_CLASSES[k-1] < s <= UNRESOLVED_CLASSES[k]
UNRESOLVED_CLASSES = np.array([1.0])
#: the base step is at most t_plate / MIN_STEPS: the coarsest of the three runs (4H) then has >= 8 steps per rigid-plate
#: time. Coarser, the errors at H, 2H, 4H were not monotone (random plates at tol 1e-4, n = 16-25: 1.2-3.1x above the
#: Richardson estimate, once the old unresolved-mode table no longer added its cushion)
#: (round 9) Counted per contact where a run finds the first contact shorter than 0.9 t_plate (kernel.SHORT_CONTACT):
#: then the smallest step and its error bound are relative to the contact too (held-out seed 7263, a 7-mode target
#: with couplings up to 27 whose contact lasts 0.82 t_plate, erred 1.15x above its estimate at tol 1e-4)
MIN_STEPS = 32.0

#: share of tol the unresolved-mode bound may take when the first base step is chosen (its error falls
#: like H^3 in aggregate, the Richardson part like H^6: a large share means fewer steps)
UNRESOLVED_SHARE = 0.5
LIGHT_COUPLING = 0.1


def _rel(u: Metrics, m: Metrics) -> float:
    return max(u.t_m / m.t_m, u.f_m / m.f_m, u.delta_m / m.delta_m)


def solve_modes(modes: Modes, mass: float, alpha: float, v0: float, tol: float = 1e-6,
                window: float = 0.0, series_samples: float = kernel.SERIES_SAMPLES) -> tuple[Run, Metrics]:
    """Solve to a relative time-step error estimate <= tol on t_m, f_m, delta_m.

    Returns the finer run and its (absolute) time-step uncertainty: the Richardson estimate of the
    fine/coarse pair (order ESTIMATE_ORDER assumed) plus the bound for modes the base step does not
    resolve; the base step shrinks until their sum is <= tol (the loop runs in kernel.solve_auto).
    In a window, free flight jumps ahead by up to window / series_samples [s] where no contact can occur
    (kernel.run): the series keeps ~series_samples nodes plus every contact's, in bounded memory.
    """
    t, d, f, x, u, e, table, rel, end, drift, _ = _solve_series(modes, mass, alpha, v0, tol, window, series_samples)
    run = _make_run(alpha, t, d, f, x, u, e, table, end, drift)
    m = run.metrics
    return run, Metrics(rel * m.t_m, rel * m.f_m, rel * m.delta_m)


def _solve_series(modes: Modes, mass: float, alpha: float, v0: float, tol: float, window: float,
                  series_samples: float = kernel.SERIES_SAMPLES):
    """solve_modes' kernel call and refusals: (t, delta, f, x_ball, u_ball, energy series, contact table rows
    (t_start, t_end, delta_max), relative uncertainty, index of the node ending the first contact, largest
    |E/E0 - 1|, x_structure = x_ball - delta series). The series are rows (views) of one array."""
    series, fine, rel, end, drift, _ = _run_kernel(_kernel_args(modes, mass, alpha, v0, tol, window, series_samples))
    t, d, f, x, u, e, xs = series
    return t, d, f, x, u, e, fine, rel, end, drift, xs


def _kernel_args(modes: Modes, mass: float, alpha: float, v0: float, tol: float, window: float,
                 series_samples: float = kernel.SERIES_SAMPLES) -> tuple:
    """kernel.solve_auto_packed's arguments for `modes` hit by a ball (mass [kg], Hertz alpha [N/m^1.5], v0 [m/s])
    at relative tolerance `tol`, `window` [s] after the first contact (refused up front when too long)."""
    plate = _plate(mass, alpha, v0)
    omega, g, ew = _select(modes)
    # estimate ~ 4x the real error (ESTIMATE_ORDER): aim the first try at an estimate of tol / 2;
    # the base step is then shortened until modes it does not resolve stay within UNRESOLVED_SHARE tol (kernel)
    n0 = max(8.0, _N_ANCHOR * (8.0 * _ERR_ANCHOR / tol) ** (1.0 / (P_DEGREE + 1)))
    if window > 0.0:
        check_window(window, plate.t_m, tol)
    return (omega, g, ew, mass, alpha, v0, modes.residual_flexibility, tol, window, plate.t_m, plate.delta_m,
            P_DEGREE, GRADING_WINDOW, n0, ESTIMATE_ORDER, UNRESOLVED_THETA, UNRESOLVED_C, SMALLEST_STEP_FACTOR,
            UNRESOLVED_SHARE, node_cap(len(omega)), float(series_samples), LIGHT_COUPLING, UNRESOLVED_CLASSES,
            MIN_STEPS, SMALLEST_STEP_C)


def _run_kernel(args: tuple):
    """The kernel call on `_kernel_args`' arguments and its refusals: (series [7, nodes]: t, delta, f, x_ball, u_ball,
    energy, x_structure; contact table rows (t_start, t_end, delta_max); relative uncertainty; index of the node
    ending the first contact; largest |E/E0 - 1|; largest |x_structure| [m])."""
    st, cnt, series, fine, rel, n, end, drift, w_max = kernel.solve_auto_packed(*args)
    if st != kernel.STATUS_OK:
        omega, mass, window, t_plate = args[0], args[3], args[8], args[9]
        t = series[0]
        if window > 0.0 and cnt > 0 and t[cnt - 1] > 0.0:
            _refuse_window(window, float(t[cnt - 1]), int(cnt), len(omega))
        cap = node_cap(len(omega)) // 4
        if node_cap(len(omega)) < NODE_CAP:     # the budget is set by the work, steps x modes
            why = (f"with {len(omega)} modes (a budget of {MODE_STEP_CAP:.0e} mode-steps, to bound the time): the "
                   f"tolerance is too tight for this many modes, or the contact lasts far longer than the rigid-plate "
                   f"contact time {t_plate:.3g} s; use a looser tol, a lighter ball or a stiffer target")
        else:
            why = (f"(it lasts far longer than the rigid-plate contact time {t_plate:.3g} s): the structure is far "
                   f"softer than the contact (ball mass {mass:.3g} kg); refused to stay within memory: use a lighter "
                   f"ball, a stiffer target or a looser tol")
        raise ImpactvalError(f"the first contact needs more than {cap} steps {why}")
    return series, fine, rel, end, drift, w_max


#: most nodes a windowed run may store (7 arrays, 49 bytes a node: 4e6 nodes ~ 200 MB), and most mode-steps
#: (work ~ nodes x modes; 4e9 ~ 10-30 s on one core)
NODE_CAP, MODE_STEP_CAP = 4_000_000, 4e9
#: bytes and (measured, one core) seconds per node and mode, for the estimate in a refusal
_BYTES_PER_NODE, _S_PER_MODE_STEP = 49.0, 3e-9


def node_cap(n_modes: int) -> int:
    """The node budget of a windowed run with `n_modes` modes (memory and time bounded)."""
    return int(max(100_000, min(NODE_CAP, MODE_STEP_CAP / max(n_modes, 1))))


def check_window(window: float, t_plate: float, tol: float) -> None:
    """Refuse up front a window whose end time double precision cannot resolve at the contact's smallest
    step (~(SMALLEST_STEP_FACTOR tol)^0.4 t_plate): node times there would be off by more than 1e-3 step."""
    smallest = (_WINDOW_STEP_FACTOR * tol) ** 0.4 * t_plate
    limit = 1e-3 * smallest / np.finfo(float).eps
    if window > limit:
        raise ImpactvalError(
            f"window {window:g} s is too long for this scene: at its end double-precision time resolves only "
            f"{window * np.finfo(float).eps:.1g} s, coarser than the contact needs ({1e-3 * smallest:.1g} s); "
            f"use a window of at most {limit:.3g} s (--window).")


def _refuse_window(window: float, t_reached: float, nodes: int, n_modes: int) -> None:
    """The windowed run hit its node budget: refuse with the estimate for the whole window."""
    est = nodes * (window / t_reached)
    fits = min(t_reached, window)
    raise ImpactvalError(
        f"window {window:g} s needs about {est:.2g} steps (~{est * _BYTES_PER_NODE / 1e9:.2g} GB, "
        f"~{est * max(n_modes, 1) * _S_PER_MODE_STEP:.2g} s): the ball stays within reach of the structure; "
        f"the budget of {nodes} steps covered {t_reached:.3g} s; use a window of at most {0.9 * fits:.3g} s "
        f"(--window).")


def _check_tol(tol: float) -> float:
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not math.isfinite(tol) or not 1e-12 <= tol <= 0.1:
        raise ImpactvalError(f"tol must be a relative tolerance between 1e-12 and 0.1, got {tol!r}.")
    return float(tol)


def solve(scene, tol: float = 1e-6, window: float = 0.0, modes: int | None = None,
          static_correction: bool = True) -> ImpactResult:
    """Reference impact of `scene` with relative uncertainty <= `tol` on t_m, f_m, delta_m.

    Parameters
    ----------
    scene : Scene
        From :func:`impactval.load_scene`.
    tol : float
        Relative tolerance (1e-12 .. 0.1) for the time step and, with an automatic mode count, for
        modal truncation (their sum <= tol).
    window : float
        Time [s] to keep integrating after the first contact ends (re-contacts).
    modes : int, optional
        Beam or plate mode count; overrides the scene's `modes`. An explicit count defines the model
        (exactly n modes, no residual: the paper's modal model), and the uncertainty covers only that
        model's time step, not its distance to the continuum (no warning is made here, to keep this call's
        cost: `impactval run` and `impactval reference` add one, reference/explicit_modes.py); None with
        no count in the scene chooses it automatically.
    static_correction : bool
        With an automatic mode count only, add the residual static flexibility of the dropped modes; with
        an explicit count (`modes=` or the scene's) it is not used (the n-mode model has no residual).
    """
    if not (hasattr(scene, "ball") and hasattr(scene, "target")):
        hint = f" (call impactval.solve(impactval.load_scene({scene!r})))" if isinstance(scene, str) else ""
        raise ImpactvalError(f"solve() needs a Scene from impactval.load_scene(), got {type(scene).__name__} "
                             f"{scene!r:.60}{hint}.")
    # the common argument types pass at a glance; anything else gets the full checks and their messages
    if not (tol.__class__ is float and 1e-12 <= tol <= 0.1):
        tol = _check_tol(tol)
    if not (window.__class__ is float and 0.0 <= window < math.inf):
        if isinstance(window, bool) or not (isinstance(window, (int, float)) and math.isfinite(window) and window >= 0):
            raise ImpactvalError(f"window must be a non-negative time in s, got {window!r}.")
        window = float(window)          # an int (0) would compile the kernel anew and key the plans apart
    if modes is not None and not (modes.__class__ is int and modes >= 1):
        if isinstance(modes, bool) or not isinstance(modes, int) or modes < 1:
            raise ImpactvalError(f"modes must be a positive whole number, got {modes!r}.")
    target = scene.target
    if target.kind == "ball":     # two free spheres: the relative motion is a ball on a rigid plate
        from impactval.reference.spheres import equivalent_plate_scene, two_sphere_result

        return two_sphere_result(scene, solve(equivalent_plate_scene(scene), tol, window))
    t0 = time.perf_counter()
    ball = scene.ball
    mass, alpha, v0 = ball.mass, scene.alpha, ball.velocity
    fixed = modes if modes is not None else getattr(target, "modes", None)
    model = "hertz-rigid" if target.kind == "rigid-plate" else "hertz-modal"
    if target.kind in ("beam", "plate") and fixed is None:
        try:
            run, unc, n_modes, trunc = _solve_auto_modes(scene, tol, window, static_correction)
        except ImpactvalError as exc:
            hint = _plate_travel_hint(scene) if target.kind == "plate" else ""
            if not hint:
                raise
            raise ImpactvalError(f"{exc}. {hint}") from None
        unc = Metrics(unc.t_m + trunc.t_m, unc.f_m + trunc.f_m, unc.delta_m + trunc.delta_m)
        model += "+static" if static_correction else ""
        m = run.metrics
        t_m, f_m, delta_m = m.t_m, m.f_m, m.delta_m
        t, f, delta, x_ball, energy = run.t, run.f, run.delta, run.x_ball, run.energy
        x_structure = x_ball - delta
        w_max = float(np.max(np.abs(x_structure)))
        contacts, rebound, drift, n_steps = run.contacts, run.rebound_velocity, run.energy_error, run.n_steps
    else:       # solve_modes without its Run (the same numbers, fewer objects per call)
        plan = _PLANS.get((id(scene), tol, window, fixed))
        if plan is None or plan[0] is not scene:
            plan = _plan(scene, tol, window, fixed)
        series, table, rel, end, drift, w_max = _run_kernel(plan[2])
        t, delta, f, x_ball, u, energy, x_structure = series
        n_modes = plan[1]
        contacts = tuple([Contact(a, b, alpha * c**1.5, c) for a, b, c in table.tolist()])
        first = contacts[0]
        t_m, f_m, delta_m = first.t_end - first.t_start, first.f_max, first.delta_max
        unc = Metrics(rel * t_m, rel * f_m, rel * delta_m)
        rebound, n_steps = -float(u[end]), len(t) - 1
    if not (math.isfinite(t_m) and math.isfinite(f_m) and math.isfinite(delta_m) and math.isfinite(unc.t_m)
            and math.isfinite(unc.f_m) and math.isfinite(unc.delta_m) and math.isfinite(rebound)) \
            or min(t_m, f_m, delta_m) <= 0.0:
        raise ImpactvalError(f"scene {scene.name!r}: the reference solver got a non-finite or non-positive answer "
                             f"(t_m={t_m!r}, f_m={f_m!r}, delta_m={delta_m!r}): an input is outside the range "
                             f"double precision can carry (check the ball's and target's sizes, masses and "
                             f"frequencies).")
    validity = hertz_validity(scene, f_m, delta_m)
    validity += deflection_validity(target, w_max, t_m)
    rel = max(unc.t_m / t_m, unc.f_m / f_m, unc.delta_m / delta_m)     # _rel(unc, metrics) without a Metrics
    if rel > tol * (1 + 1e-9):
        validity += (f"uncertainty {rel:.2g} (relative) is above tol {tol:g}: the mode count or step "
                     f"reached its limit",)
    return build(ImpactResult, {
        "scene": scene.name, "source": "reference", "model": model, "t_m": t_m, "f_m": f_m, "delta_m": delta_m,
        "validity": validity, "uncertainty": unc, "modes": n_modes, "t": t, "f": f, "delta": delta,
        "x_ball": x_ball, "x_structure": x_structure, "energy": energy, "rebound_velocity": rebound,
        "energy_error": drift, "contacts": contacts, "status": Status.OK, "message": "", "version": "",
        "settings": {"tol": tol, "window": window, "p": P_DEGREE}, "n_steps": n_steps, "wall_time_build_s": 0.0,
        "wall_time_step_s": time.perf_counter() - t0, "diagnostics": {}, "dt": math.nan, "dt_limit": math.nan,
        "model_error": math.nan, "contact_law": None})       # every field: build() takes the dict as it is


def _plate_travel_hint(scene) -> str:
    """For a refused plate scene: "" or one sentence when Zener's infinite plate (a dashpot c = 8 sqrt(D rho h) under
    the ball) says the load point travels more than the plate's thickness, m0 v0 / c (the ball's momentum, all of it
    passed on when lambda is large), i.e. far outside Kirchhoff's small-deflection theory."""
    from impactval.reference.plates import infinite_plate_damping, zener_lambda

    plate, m0, v0 = scene.target, scene.ball.mass, scene.ball.velocity
    travel = m0 * v0 / infinite_plate_damping(plate)
    if travel <= plate.thickness:
        return ""
    return (f"Zener's infinite plate (lambda = {zener_lambda(scene):.3g}) puts the load point's travel near m v0 / "
            f"(8 sqrt(D rho h)) = {travel:.3g} m, {travel / plate.thickness:.3g} x the plate's thickness: far outside "
            f"Kirchhoff's small-deflection theory; a thicker plate, or a lighter or slower ball, is within it")


def _plan(scene, tol: float, window: float, fixed: int | None) -> tuple:
    """(scene, mode count, kernel arguments) of a solve with a fixed mode count: what solve() derives from the scene
    and its arguments before the kernel call. Kept per scene object and arguments when the scene is immutable all
    the way down (repeated solves of one scene skip the mode, plate and argument look-ups: ~5 us of a ~100 us call
    on the worked beam); the plan holds the scene, so its id cannot be reused while cached."""
    from impactval.scenarios.scene import _all_frozen

    md = _target_modes(scene, fixed)
    ball = scene.ball
    plan = (scene, md.n, _kernel_args(md, ball.mass, scene.alpha, ball.velocity, tol, window))
    if _all_frozen(scene):
        if len(_PLANS) > 64:
            _PLANS.clear()
        _PLANS[(id(scene), tol, window, fixed)] = plan
    return plan


_PLANS: dict = {}


def _target_modes(scene, n: int | None) -> Modes:
    """structure_modes(scene, n) with a front cache per target object: the structure cache keys on the target's
    value, whose hash walks every field of the target and its material on each call (~1.5 us); this one checks
    identity. A target is kept only when it is a frozen dataclass with a frozen material and hashable (nothing
    in it can change); the cache holds the target, so its id cannot be reused while cached."""
    target = scene.target
    key = (id(target), n)
    hit = _MODES_BY_TARGET.get(key)
    if hit is not None and hit[0] is target:
        return hit[1]
    md = structure_modes(scene, n)
    if _immutable(target):
        if len(_MODES_BY_TARGET) > 64:
            _MODES_BY_TARGET.clear()
        _MODES_BY_TARGET[key] = (target, md)
    return md


_MODES_BY_TARGET: dict = {}


def _immutable(target) -> bool:
    parts = (target, getattr(target, "material", None))
    if not all(dataclasses.is_dataclass(p) and type(p).__dataclass_params__.frozen for p in parts):
        return False
    try:
        hash(target)
    except TypeError:
        return False
    return True


#: with the residual static flexibility of the dropped modes (mode-acceleration correction), what an n-mode beam or
#: plate model leaves out is the dropped modes' motion beyond their static part. A mode k hit by the Hertz onset
#: (F ~ t^1.5, a force spectrum falling like omega^-2.5) rings with amplitude ~1.7 s_k w_k^-3.5 delta_m (s_k = m0
#: phi_k^2 / m_k, w_k = omega_k delta_m / v0, rigid-plate delta_m), i.e. its static compliance c_k times
#: (v0/delta_m)^1.5 omega_k^-1.5 relative to the contact's compliance delta_m^2 / (m0 v0^2); summed over the dropped
#: modes, a priori at most F_n = R_n m0 v0^2 / delta_m^2 * w_{n+1}^-1.5 (R_n: their static flexibility, exact).
#: Each mode's effect on the metrics has its own sign (seed 5168: modes 7-12 moved f_m by +2.2, -0.9, -2.1, +0.4,
#: -0.3e-4 and nearly cancelled, while mode 13 alone moved it 4.6e-5), so one difference X_n - X_2n can vanish
#: while the tail does not: the observed ratio over three counts then over-promises (main until round 7: 4 of 749
#: random beams above, 1.19-1.92x). The truncation error of the 2n-mode model is taken as F_2n times the scene's
#: sensitivity c, the larger of the last TRUNCATION_BLOCKS differences each divided by the a-priori size of its block
#: of modes ((|X_a - X_b| + u_a + u_b) / (F_a - F_b)), times TRUNCATION_COHERENCE (the tail may add up more
#: coherently than the blocks seen), and at least TRUNCATION_PER_MODE (a coherent tail on an insensitive contact:
#: measured per mode ~5 s w^-3.5 on f_m, and F_n is up to ~2x the sum over the modes). The count is accepted only
#: once the first dropped mode is quasi-static, w_{n+1} >= TRUNCATION_QUASI_STATIC[kind] (below it the w^-1.5 law does
#: not hold: a Timoshenko beam's error stayed at 1e-4 over 32-128 modes, w_{n+1} 0.7-2.4, then fell 20x). Calibrated
#: on random beams seeds 5000-5399 (`python benchmarks/auto_mode_honesty.py`; docs/reference.md). Plates (round 7,
#: the same constants): random plates of the tests' generator, seeds 9000-9059, tol 1e-4 and 1e-6, 0 of 111 solves
#: above (the observed-ratio rule before: 12 of 115, up to 40x: a block of modes on a nodal line of the impact point
#: changed nothing, seed 9055 from 2 to 4 modes, and the ratio trusted it); held out 9100-9145: 0 of 83. Plates take no
#: quasi-static gate: their modes are dense (omega_n ~ n), so a light fast ball's contact would need w_{n+1} >= 5 only
#: past 32768 modes (refused: seeds 9028, 9029), and without it none was above.
TRUNCATION_COHERENCE, TRUNCATION_PER_MODE, TRUNCATION_BLOCKS = 3.0, 2.0, 2
TRUNCATION_QUASI_STATIC = {"euler-bernoulli": 5.0, "timoshenko": 5.0, "plate": 0.0}
#: models without the residual (static_correction=False) keep the ratio rule: the error falls per doubling by a ratio
#: trusted only to 1/TRUNCATION_SAFETY of the ratio observed over the last three counts, at most TRUNCATION_PLAIN and
#: at least TRUNCATION_FLOOR (also with two counts only). (Until round 7 it served the residual models too, with caps
#: per theory measured per doubling: Euler-Bernoulli beams 18-323x from 16 modes on, Kirchhoff plates 4.6-9.5x from
#: 128-256 modes on, Timoshenko beams 2.9-17x; irregular below.)
TRUNCATION_PLAIN, TRUNCATION_SAFETY, TRUNCATION_FLOOR = 2.0, 1.5, 1.5
#: the a-posteriori truncation estimate (round 10, `reference/truncation.py`): the modes n+1 .. TRUNCATION_SWEPT n - 1
#: the n-mode model leaves out (on Euler-Bernoulli beams the 2n modes the rule above computes anyway) are driven by its
#: run's own force; their dynamic part at the peak and at the end of the contact, times TRUNCATION_APOSTERIORI, plus the
#: rule's bound for the rest (F from mode TRUNCATION_SWEPT n on), is reported where it is smaller than the rule's, but
#: never below TRUNCATION_TIGHTEST of it (the dynamic part at one instant can vanish by its phase). Calibrated on the 19
#: catalogue and tests' beams with an automatic count at tol 1e-6: the real truncation error (the n-mode model and 8x /
#: 32x the modes, both at tol 1e-11) was 0.45-1.63x the first-order shift of delta_m and 0.47-2.03x that of t_m, modes
#: n+1 .. 8n swept (the change's feedback on the force is left out); the rule above was 4-34x the real error. Skipped
#: above TRUNCATION_SWEPT_MAX swept mode-nodes.
TRUNCATION_APOSTERIORI, TRUNCATION_TIGHTEST, TRUNCATION_SWEPT_MAX = 4.0, 0.1, 2e7
#: per structure theory (the rest's bound F falls per doubling ~64x on Euler-Bernoulli beams, ~6x on plates and
#: Timoshenko beams, whose frequencies grow ~n: there the swept modes go on to 4n; heavy_wc_slender_timoshenko reports
#: 8.6x its real error so, 10.1x with 2n)
TRUNCATION_SWEPT = {"euler-bernoulli": 2, "timoshenko": 4, "plate": 4}
#: ... and only for contacts up to this many rigid-plate times: the first-order shift leaves out the change's feedback
#: on the ball's motion, which grows with the contact's length (calibrated on contacts of 0.90-2.24 t_plate; a 7.2 kg
#: ball at 0.07 m/s on a glass beam, contact 6.7 t_plate, erred 5.7x the shift of delta_m and 23x that of t_m: 1.07x
#: above the estimate, random beam seed 5379; the rule alone bounds it)
TRUNCATION_SWEPT_CONTACT = 2.5
#: share of tol given to each mode-count run's time step. The time step's estimate (Richardson, ratio trusted to 16 / 1.5)
#: is ~8x its real error once the runs are asymptotic, the a-posteriori truncation estimate 2-9x its own: the smaller
#: the step's share, the more the reported total is the truncation's. At 1/3, with the dense peak's fewer steps, the
#: stubby steel beam (tests/unseen) was 41x its real error, at 1/6 10.5x, at 1/32 6.1x (round 11; 1.3-2.1x the nodes).
#: Not smaller: where the truncation error is tiny and of the other sign, the real total shrinks faster than the
#: estimate (light_ball_heavy_beam: 6.0x at 1/6, 9.6x at 1/32, 26x at 1/96)
STEP_SHARE = 1.0 / 32.0
#: ... but no step tolerance below STEP_TOL_FLOOR is asked for unless tol / 6 is: near roundoff each halving of the
#: estimate costs ever more nodes (the worked beam at tol 1e-12: 22,114 nodes at tol / 6, 81,165 at tol / 32)
STEP_TOL_FLOOR = 1e-12


def step_tolerance(tol: float) -> float:
    """The time-step tolerance of each mode-count run of a solve at `tol` (relative): STEP_SHARE tol, at least the
    smaller of tol / 6 and STEP_TOL_FLOOR."""
    return max(STEP_SHARE * tol, min(tol / 6.0, STEP_TOL_FLOOR))


def _dynamic_tail(scene, md: Modes, n: int, mass: float, v0: float, delta_plate: float) -> tuple[float, float]:
    """(F_n, w_{n+1}): the a-priori size of the dropped modes' motion beyond static (relative to the metrics) and the
    first dropped mode's omega delta_m / v0, for the n-mode model `md` (with its residual flexibility). The 2n modes
    are the next count's model (residual included), so the structure cache hands them to the next doubling."""
    above = structure_modes(scene, 2 * n, residual=True).omega
    w_next = float(np.sort(above)[n]) * delta_plate / v0
    return md.residual_flexibility * mass * (v0 / delta_plate) ** 2 * w_next ** -1.5, w_next


def _swept_truncation(scene, run, n: int, mass: float, v0: float, delta_plate: float, coherence: float,
                      kind: str = "euler-bernoulli") -> float | None:
    """The a-posteriori truncation estimate of the n-mode model (with its residual) whose first-contact run is `run`:
    TRUNCATION_APOSTERIORI x the first-order relative shift of the metrics (f_m counts 1.5x delta_m) by the dynamic part
    of the modes n+1 .. TRUNCATION_SWEPT n - 1 under the run's force, plus F of the modes from TRUNCATION_SWEPT n on
    times max(TRUNCATION_PER_MODE, TRUNCATION_COHERENCE coherence), as the rule does for all dropped modes. None when it
    cannot be made (too many modes, or the contact does not end in the run)."""
    from impactval.reference.truncation import metric_shifts

    count = TRUNCATION_SWEPT.get(kind, 4) * n
    if (count - n) * len(run.t) > TRUNCATION_SWEPT_MAX:
        return None
    try:
        big = structure_modes(scene, count, residual=True)
    except ImpactvalError:
        return None
    order = np.argsort(big.omega, kind="stable")
    omega, b = big.omega[order], big.phi[order] ** 2 / big.modal_mass[order]
    swept = slice(n, count - 1)
    keep = b[swept] > 0.0
    shifts = metric_shifts(run.t, run.f, run.delta, omega[swept][keep], b[swept][keep])
    if shifts is None:
        return None
    rest = big.residual_flexibility + b[count - 1] / omega[count - 1] ** 2      # the modes from the count-th on
    w_rest = omega[count - 1] * delta_plate / v0
    f_rest = rest * mass * (v0 / delta_plate) ** 2 * w_rest ** -1.5
    rel_t, rel_d = shifts
    return TRUNCATION_APOSTERIORI * max(rel_t, 1.5 * rel_d) + \
        f_rest * max(TRUNCATION_PER_MODE, TRUNCATION_COHERENCE * coherence)


def _solve_auto_modes(scene, tol: float, window: float, residual: bool):
    """Double the mode count until the 2n-mode model's time-step uncertainty plus its truncation uncertainty is
    <= tol; returns (run, time-step uncertainty, mode count, truncation uncertainty) of the 2n-mode model.

    Beams and plates with the residual: truncation = F_2n max(TRUNCATION_PER_MODE, TRUNCATION_COHERENCE c), c the
    larger of the last two (|X_a - X_b| + u_a + u_b) / (F_a - F_b) (u: the runs' time-step uncertainties, which may
    hide in the difference; F: the a-priori size of the dropped modes' dynamic part, see the constants), accepted once
    the first dropped mode is quasi-static (beams). Models without the residual: with the error falling per doubling
    by a ratio r, e_2n <= (|X_n - X_2n| + u_n + u_2n) / (r - 1), r the ratio observed over the last three counts
    (|X_n/2 - X_n| / |X_n - X_2n|) divided by TRUNCATION_SAFETY, at most TRUNCATION_PLAIN and at least
    TRUNCATION_FLOOR (also with two counts only). The largest relative value over t_m, f_m, delta_m
    is used for all three (one metric's difference may vanish by accident). With the residual, the count accepted, the
    a-posteriori estimate `_swept_truncation` is reported where it is smaller (never below TRUNCATION_TIGHTEST of the
    rule's)."""
    ball = scene.ball
    mass, alpha, v0 = ball.mass, scene.alpha, ball.velocity
    target = scene.target
    kind = "plate" if target.kind == "plate" else getattr(target, "theory", "euler-bernoulli")
    gate = TRUNCATION_QUASI_STATIC.get(kind, 5.0)
    delta_plate = _plate(mass, alpha, v0).delta_m
    n = max(2, initial_mode_count(scene) // 2)      # a cheap half count first: its ratio lets the next pair stop
    prev, d_prev, f_prev, sens = None, None, None, []
    while True:
        md = structure_modes(scene, n, residual=residual)
        run, unc = solve_modes(md, mass, alpha, v0, step_tolerance(tol))
        f_now, w_next = _dynamic_tail(scene, md, n, mass, v0, delta_plate) if residual else (0.0, 0.0)
        if prev is not None:
            p_run, p_unc = prev
            a, b = p_run.metrics, run.metrics
            d_now = max(abs(a.t_m - b.t_m) / b.t_m, abs(a.f_m - b.f_m) / b.f_m, abs(a.delta_m - b.delta_m) / b.delta_m)
            if residual:        # the dropped modes' dynamic part; without the residual, the ratio rule
                shrink = f_prev - f_now
                sens.append((d_now + _rel(p_unc, b) + _rel(unc, b)) / shrink if shrink > 0.0 else math.inf)
                ready = len(sens) >= TRUNCATION_BLOCKS and w_next >= gate
                rel = f_now * max(TRUNCATION_PER_MODE, TRUNCATION_COHERENCE * max(sens[-TRUNCATION_BLOCKS:])) \
                    if ready or n >= 20000 else math.inf
            else:
                r = TRUNCATION_FLOOR
                if d_prev is not None:
                    r = max(TRUNCATION_FLOOR, min(TRUNCATION_PLAIN, d_prev / d_now / TRUNCATION_SAFETY if d_now > 0.0
                                                  else TRUNCATION_PLAIN))
                rel = (d_now + _rel(p_unc, b) + _rel(unc, b)) / (r - 1.0)
            if rel + _rel(unc, b) <= tol or n >= 20000:
                long_contact = b.t_m > TRUNCATION_SWEPT_CONTACT * _plate(mass, alpha, v0).t_m
                if residual and math.isfinite(rel) and not long_contact:
                    swept = _swept_truncation(scene, run, n, mass, v0, delta_plate, max(sens[-TRUNCATION_BLOCKS:]),
                                              kind)
                    if swept is not None:
                        rel = min(rel, max(swept, TRUNCATION_TIGHTEST * rel))
                trunc = Metrics(rel * b.t_m, rel * b.f_m, rel * b.delta_m)
                if window > 0.0:       # the same 2n-mode run again, on through the window
                    run, _ = solve_modes(md, mass, alpha, v0, step_tolerance(tol), window)
                return run, unc, n, trunc
            d_prev = d_now
        prev, f_prev = (run, unc), f_now
        n *= 2


def initial_mode_count(scene) -> int:
    """First guess of the beam mode count: the modes up to ~8x the rigid-plate impact frequency."""
    plate = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
    md = structure_modes(scene, 64)
    below = int(np.sum(md.omega < 8.0 * plate.omega_m))
    return max(4, below)
