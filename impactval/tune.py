"""Engine parameter tuning (issue 15): from a real material to each engine's contact knobs.

Two kinds of answers, both in absolute SI units a user's own model accepts:

- **closed form** where one exists. Ball on a rigid plate with Hertz alpha (paper eq. 18-37): the
  energy-equivalent spring k0(v) = 0.8 alpha sqrt(delta_m(v)) (eq. 47-49); the spring that matches
  Hertz's duration, peak force or both equally at one speed; the single spring that best matches
  Hertz's t_m and f_m over a speed range (least squares of the log ratios, closed form, below);
  conversions to MuJoCo's solref (direct and time-constant forms), PyBullet's per-body and global
  ERP/CFM routes and Exudyn's contact item; a restitution coefficient through the linear
  spring-dashpot model. All of these are pure functions.
- **numerical fit** where none exists: `fit(...)` runs scipy.optimize.least_squares over *engine runs*
  (each an isolated engine job through `impactval.runner.execute`, stored in a result store, so a
  rerun of the same fit reuses every stored job and resumes), starting from the closed form, and
  counts the engine runs it used. MuJoCo's Hertz-shaped solimp is pre-fitted on a pure model of
  MuJoCo's impedance law (`mujoco_force`, checked against MuJoCo itself in the tests).

Why a linear spring cannot match Hertz: on a rigid plate t_m * f_m = pi m v for any linear spring but
2c * (5/4) m v = 3.679 m v for Hertz, so at best both t_m and f_m are 7.6 % low at every speed
(`LINEAR_PRODUCT_RATIO`); and Hertz's t_m ~ v^-1/5 while a spring's t_m does not depend on v.

MuJoCo's contact force (measured and derived, docs/tuning.md): with a direct solref (-ks, -bs) and
impedance imp(pen) from solimp, on a contact row with inverse effective mass A (efc_diagA, exact with
the diagexact flag), no other forces: f = (ks (imp/dwidth)^2 pen + bs (imp/dwidth) v) / A. A flat solimp
(d0 = dwidth) gives the linear spring-dashpot k = ks/A, c = bs/A; the time-constant form
(tc, dr) gives k = m_eff/(tc dr)^2 and c = 2 m_eff/tc, i.e. dr is the damping ratio.

The core never imports an engine at module level; `mujoco_effective_mass` imports mujoco inside.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from impactval.errors import ImpactvalError
from impactval.reference.hertz import C_HERTZ, PlateImpact, plate_impact

#: t_m*f_m of a linear spring over that of Hertz on a rigid plate: pi / (2.5 c) (speed- and k-independent)
LINEAR_PRODUCT_RATIO = math.pi / (2.5 * C_HERTZ)
#: default speed range "a:b:n" (n speeds spaced geometrically from a to b m/s)
DEFAULT_SPEEDS = "0.1:10:5"
#: engines `impactval tune` knows
TUNE_ENGINES = ("mujoco", "pybullet", "exudyn")
#: impedance of MuJoCo's flat solimp (the adapter's native one: keeps the contact a spring on flexible targets)
MUJOCO_FLAT_IMPEDANCE = 1e-4
#: largest impedance of the Hertz-shaped solimp (the adapter's NATIVE_HERTZ_DMAX, same reason)
MUJOCO_SHAPED_DMAX = 1e-3
#: contactERP of PyBullet's global route (the adapter's default)
PYBULLET_ERP = 1e3
#: The default fixed step is sized from the engines' time-step error. Their contact integration converges at order 2:
#: a job's t_m, f_m and delta_m at N = t_H(v) / dt steps per rigid-plate Hertz contact time t_H(v) are off from their
#: dt -> 0 limit by c / N^2 (relative), c constant to 1 % over N = 100 .. 3200. Measured on `plate_steel` at 0.3, 1,
#: 3 m/s with each engine's fitted options held fixed, N = 100 .. 3200 (Richardson limit of the two finest):
#: |c| <= 2.31 (MuJoCo linear spring, f_m and delta_m at 0.3 m/s, where the spring's contact is 27 % shorter than
#: Hertz's), 1.34 (Exudyn 1.5 law, f_m), 1.31 (MuJoCo Hertz-shaped solimp, f_m), 1.97 (PyBullet ERP/CFM, f_m; two
#: terms there, not monotonic); STEP_ERROR_C bounds them all.
STEP_ERROR_C = 2.5
#: the step error the default allows on each fitted metric (relative): the last printed digit of tune.md's residual
#: table (0.001 %); a fit at the default step and one at a finer step then print the same residuals within that digit
#: (Exudyn's alpha: 2.65e-6 off at N = 553, 0.8 / N^2; 5e-8 at N = 2767)
STEP_ERROR_TARGET = 1e-5
#: steps per shortest Hertz contact time for the default fixed dt: the smallest N with STEP_ERROR_C / N^2 <=
#: STEP_ERROR_TARGET (500); `default_dt` rounds t_H / N down to 1-2-5, so the engines take 500 .. 1250 steps. It was
#: 2000 before (a fit of MuJoCo on a beam, fz2902: 36 jobs at 1e-8 s, 16.8 min; its options at 5e-8 s gave the same
#: residuals to 0.001 %)
STEPS_PER_SHORTEST_CONTACT = math.ceil(math.sqrt(STEP_ERROR_C / STEP_ERROR_TARGET) - 1e-9)


# ---------------------------------------------------------------------------- speeds and scenes

def parse_speeds(text: str | Sequence[float]) -> tuple[float, ...]:
    """Approach speeds [m/s], sorted, each once: "a:b:n" (n speeds log-spaced from a to b, the one
    range grammar of `impactval.ranges`), "v1,v2,..." or a mix; a sequence of numbers is taken as is.

    Raises ImpactvalError naming --speeds and the fix for anything else.
    """
    from impactval import ranges

    if isinstance(text, str):
        vals = ranges.parse_list(text, "--speeds", unit="m/s", example=DEFAULT_SPEEDS)
    else:
        vals = [ranges.number(v, "--speeds", unit="m/s", example=DEFAULT_SPEEDS) for v in text]
        if not vals:
            raise ImpactvalError(f"--speeds: give at least one speed (e.g. {DEFAULT_SPEEDS}).")
    return tuple(sorted(set(vals)))


def middle_speed(speeds: Sequence[float]) -> float:
    """The speed the bars single out: the middle one of an odd count, else the one nearest the geometric mean."""
    s = sorted(speeds)
    geo = math.exp(np.mean(np.log(s)))
    return min(s, key=lambda v: abs(math.log(v / geo)))


def at_speed(scene, speed: float):
    """The scene with approach speed `speed` [m/s], named "NAME[v=SPEED]"."""
    ball = dataclasses.replace(scene.ball, velocity=float(speed))
    return dataclasses.replace(scene, name=f"{scene.name}[v={speed:g}]", ball=ball)


def contact_mass(scene) -> float:
    """The mass [kg] the contact spring works against: the ball's, or the reduced mass of two balls
    (`engines.base.contact_mass`; the two-ball contact is that mass on a rigid plate)."""
    from impactval.engines.base import contact_mass as _contact_mass

    return _contact_mass(scene)


def default_dt(scene, speeds: Sequence[float], engine: str | None = None, contact: str = "native",
               integrator: str | None = None) -> float:
    """A fixed engine step [s]: the shortest rigid-plate Hertz contact time over `speeds` / STEPS_PER_SHORTEST_CONTACT
    (500: the engines' order-2 step error STEP_ERROR_C / N^2 on t_m, f_m, delta_m stays below STEP_ERROR_TARGET =
    1e-5), rounded down to a 1-2-5 value (one dt for every speed, so an emitted ERP/CFM pair stays valid); with
    `engine`, also at most DT_MARGIN x the engine model's predicted explicit stability limit at every speed (a beam
    chain's own modes: on cc_short_heavy_ball the contact alone gave 2e-7 s, above PyBullet's chain limit 1.7e-7 s, and
    every fit run was refused as unstable; the chain is sized per speed, and on fz2902 MuJoCo's limit is lowest at the
    slowest speed: 3.15e-8 s at 0.5 m/s (287 segments), 1.07e-7 s at 5 m/s)."""
    from impactval.engines.base import DT_MARGIN, EngineSettings, nice_step

    t_short = min(plate_impact(contact_mass(scene), scene.alpha, v).t_m for v in speeds)
    dt = nice_step(t_short / STEPS_PER_SHORTEST_CONTACT)
    if engine is None or scene.target.kind in ("rigid-plate", "ball"):
        return dt                       # no structure: the contact time sets the step
    from impactval.engines.base import EngineError, load_adapter

    adapter = load_adapter(engine)
    limits = []
    for v in sorted(set(speeds)):
        try:
            plan = adapter.plan(at_speed(scene, v),
                                adapter.check_settings(EngineSettings(dt=dt, contact=contact, integrator=integrator)))
        except EngineError:             # an unsupported scene: the engine run says so, as a status row
            return dt
        if math.isfinite(plan.dt_limit) and plan.dt_limit > 0:
            limits.append(plan.dt_limit)
    if limits:
        dt = min(dt, nice_step(DT_MARGIN * min(limits)))
    return dt


# ---------------------------------------------------------------------------- reference targets

@dataclass(frozen=True)
class Target:
    """The reference (Hertz) impact at one speed: `speed` [m/s], `t_m` [s], `f_m` [N], `delta_m` [m],
    `rebound_velocity` [m/s] (the elastic truth: v0 on a rigid plate, less on a flexible target; for a second ball the
    speed at which the two separate, v0: the restitution is of the relative motion, as the contact's damping is)."""

    speed: float
    t_m: float
    f_m: float
    delta_m: float
    rebound_velocity: float

    @property
    def restitution(self) -> float:
        """The reference's rebound speed over approach speed (1 on a rigid plate)."""
        return self.rebound_velocity / self.speed


def hertz_targets(scene, speeds: Sequence[float], tol: float = 1e-6) -> list[Target]:
    """Reference impacts at each speed: closed form on a rigid plate, the reference solver otherwise."""
    out = []
    for v in speeds:
        if scene.target.kind == "rigid-plate":
            p = plate_impact(scene.ball.mass, scene.alpha, v)
            out.append(Target(v, p.t_m, p.f_m, p.delta_m, v))
        else:
            import impactval

            sc = at_speed(scene, v)
            if sc.target.kind == "ball":   # the relative motion: its rebound is the two balls' separation speed
                from impactval.reference.spheres import equivalent_plate_scene

                sc = equivalent_plate_scene(sc)
            r = impactval.solve(sc, tol=tol)
            out.append(Target(v, r.t_m, r.f_m, r.delta_m, r.rebound_velocity))
    return out


# ---------------------------------------------------------------------------- closed forms: linear spring

def k0_energy(mass: float, alpha: float, speed: float) -> float:
    """Energy-equivalent spring k0 [N/m] = 0.8 alpha sqrt(delta_m) at `speed` (paper eq. 47-49): same
    delta_m as Hertz on a rigid plate, t_m +6.7 %, f_m -20 %."""
    return plate_impact(mass, alpha, speed).k0


def linear_plate(mass: float, k: float, speed: float) -> tuple[float, float, float]:
    """Linear undamped spring k [N/m] on a rigid plate: (t_m [s], f_m [N], delta_m [m]) = (pi sqrt(m/k),
    v sqrt(k m), v sqrt(m/k))."""
    return math.pi * math.sqrt(mass / k), speed * math.sqrt(k * mass), speed * math.sqrt(mass / k)


def k_matching(mass: float, t_m: float, f_m: float, speed: float) -> dict[str, float]:
    """Springs [N/m] that match a (t_m, f_m) at `speed` on a rigid plate: "t_m" (duration exact),
    "f_m" (peak force exact), "equal" (both off by the same ratio, the log-least-squares compromise)."""
    k_t = mass * (math.pi / t_m) ** 2
    k_f = (f_m / speed) ** 2 / mass
    return {"t_m": k_t, "f_m": k_f, "equal": math.sqrt(k_t * k_f)}


def linear_compromise(mass: float, targets: Sequence[Target]) -> float:
    """The single spring k [N/m] minimising sum over speeds of ln(t_lin/t_m)^2 + ln(f_lin/f_m)^2 on a
    rigid plate. With t_lin = pi sqrt(m/k), f_lin = v sqrt(k m) the residuals are linear in ln k, so
    ln k = mean over speeds of ln(k_equal(v)) (closed form)."""
    logs = [math.log(k_matching(mass, t.t_m, t.f_m, t.speed)["equal"]) for t in targets]
    return math.exp(float(np.mean(logs)))


# ---------------------------------------------------------------------------- restitution

def damping_ratio(restitution: float) -> float:
    """Damping ratio zeta of a linear spring-dashpot (Kelvin-Voigt) contact with restitution e, contact
    ending when the approach returns to zero: e = exp(-pi zeta / sqrt(1 - zeta^2)), so
    zeta = -ln e / sqrt(pi^2 + ln^2 e)."""
    if not 0 < restitution <= 1:
        raise ImpactvalError(f"restitution must be in (0, 1], got {restitution!r}.")
    le = math.log(restitution)
    return abs(le) / math.sqrt(math.pi**2 + le * le)


def restitution_of(zeta: float) -> float:
    """Inverse of `damping_ratio`: e = exp(-pi zeta / sqrt(1 - zeta^2)) for 0 <= zeta < 1."""
    return math.exp(-math.pi * zeta / math.sqrt(1 - zeta * zeta))


def damping_for(restitution: float, k: float, mass: float) -> float:
    """Dashpot c [N s/m] = 2 zeta sqrt(k m) giving restitution e with spring k [N/m] and mass m [kg]."""
    return 2.0 * damping_ratio(restitution) * math.sqrt(k * mass)


# ---------------------------------------------------------------------------- MuJoCo

def mujoco_direct_solref(k: float, c: float, m_eff: float) -> tuple[float, float]:
    """Direct solref (-k/m_eff, -c/m_eff) [1/s^2, 1/s] for spring k [N/m] and dashpot c [N s/m] on a
    contact row of effective mass m_eff [kg] (flat solimp)."""
    return -k / m_eff, -c / m_eff


def mujoco_timeconst_solref(k: float, zeta: float, m_eff: float) -> tuple[float, float]:
    """Time-constant solref (timeconst [s], dampratio) for spring k [N/m] and damping ratio zeta > 0:
    with a flat solimp MuJoCo gives k = m_eff/(tc dr)^2 and c = 2 m_eff/tc, so dr = zeta and
    tc = 1/(omega zeta), omega = sqrt(k/m_eff). zeta = 0 has no time-constant form (MuJoCo rejects
    dampratio 0 as mixed format)."""
    if not zeta > 0:
        raise ImpactvalError("the time-constant solref needs damping (dampratio > 0); use the direct form "
                             "for an elastic contact.")
    omega = math.sqrt(k / m_eff)
    return 1.0 / (omega * zeta), zeta


def mujoco_impedance(pen: np.ndarray | float, solimp: Sequence[float]) -> np.ndarray:
    """MuJoCo's impedance d(pen) in [1e-4, 0.9999] for solimp (d0, dwidth, width [m], midpoint, power):
    x = pen/width, y = x (power 1), a x^p (x <= mid, a = mid^(1-p)) or 1 - b (1-x)^p (b = (1-mid)^(1-p)),
    d = d0 + y (dwidth - d0), d = dwidth for x >= 1 (MuJoCo documentation, "Solver parameters")."""
    d0, dw, width, mid, power = (float(v) for v in solimp)
    x = np.clip(np.asarray(pen, float) / width, 0.0, 1.0)
    if power == 1:
        y = x
    else:
        lo = x ** power / mid ** (power - 1)
        hi = 1.0 - (1.0 - x) ** power / (1.0 - mid) ** (power - 1)
        y = np.where(x <= mid, lo, hi)
    return np.clip(d0 + y * (dw - d0), 1e-4, 0.9999)


def mujoco_force(pen: np.ndarray | float, solref: Sequence[float], solimp: Sequence[float], m_eff: float) -> np.ndarray:
    """Static contact force [N] of MuJoCo's pair at penetration pen [m] (ball at rest, no other forces,
    direct solref (-ks, -bs), exact diagonal): m_eff ks (d(pen)/dwidth)^2 pen; 0 for pen <= 0."""
    pen = np.asarray(pen, float)
    ks = -float(solref[0])
    d = mujoco_impedance(pen, solimp) / float(solimp[1])
    return np.where(pen > 0, m_eff * ks * d * d * pen, 0.0)


def law_plate(force: Callable[[np.ndarray], np.ndarray], mass: float, speed: float | Sequence[float],
              delta_max: float, delta_min: float | None = None, points: int = 20000):
    """Rigid-plate impact of an elastic law f(delta) (increasing, f(0) = 0), by quadrature:
    delta_m from U(delta_m) = m v^2/2, f_m = f(delta_m), t_m = 2 int_0^delta_m d delta / sqrt(v^2 - 2U/m)
    (substitution delta = delta_m (1 - s^2) removes the end singularity). The table of U spans
    [delta_min, delta_max] [m] geometrically (default delta_min = 1e-6 delta_max). Returns (t_m [s], f_m [N],
    delta_m [m]) for one speed, or arrays of them for a sequence; ~1e-6 relative at the default points."""
    lo = delta_min if delta_min is not None else 1e-6 * delta_max
    grid = np.concatenate([[0.0], np.geomspace(lo, delta_max, points)])
    f = np.asarray(force(grid), float)
    u = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(grid))])
    v = np.atleast_1d(np.asarray(speed, float))
    e = 0.5 * mass * v**2
    if u[-1] < e.max():
        raise ImpactvalError(f"law_plate: the law stores only {u[-1]:.3g} J up to {delta_max:.3g} m "
                             f"(< {e.max():.3g} J).")
    dm = np.interp(e, u, grid)
    s, w = np.polynomial.legendre.leggauss(100)
    s, w = 0.5 * (s + 1.0), 0.5 * w
    dl = dm[:, None] * (1.0 - s * s)[None, :]
    gap = np.maximum(v[:, None] ** 2 - 2.0 * np.interp(dl, grid, u) / mass, 1e-300)
    t_m = 2.0 * np.sum(w * 2.0 * dm[:, None] * s / np.sqrt(gap), axis=1)
    f_m = np.asarray(force(dm), float)
    if np.ndim(speed) == 0:
        return float(t_m[0]), float(f_m[0]), float(dm[0])
    return t_m, f_m, dm


def mujoco_shape_prefit(mass: float, alpha: float, targets: Sequence[Target],
                        dmax: float = MUJOCO_SHAPED_DMAX) -> tuple[tuple[float, float], tuple[float, ...], float]:
    """Direct solref and a Hertz-shaped solimp (d0 < dwidth = dmax, width, midpoint, power) whose pure
    MuJoCo law (`mujoco_force`, m_eff = mass) best matches Hertz's t_m and f_m at every target speed on
    a rigid plate (least squares of the log ratios). Returns (solref, solimp, rms of the log residuals)."""
    from impactval.engines.mujoco_ import fit_solimp   # the adapter's fit (no engine import: mujoco loads lazily)

    dm_top = max(t.delta_m for t in targets)
    dm_low = min(t.delta_m for t in targets)
    speeds = np.array([t.speed for t in targets])
    t_ref = np.array([t.t_m for t in targets])
    f_ref = np.array([t.f_m for t in targets])

    def resid(k, solimp):
        tm, fm, _ = law_plate(lambda x: mujoco_force(x, (-k / mass, 0.0), solimp, mass), mass, speeds, 50 * dm_top,
                              1e-3 * dm_low, 1500)
        return np.concatenate([np.log(tm / t_ref), np.log(fm / f_ref)])

    k, solimp, rms = fit_solimp(resid, 0.8 * alpha * math.sqrt(dm_top), dm_top, dmax,
                                starts=([0.0, 0.3, 0.0, 0.1, 1.5], [0.3, 0.1, 0.5, 0.01, 4.0]),
                                lower=[-3.0, 0.0, -3.0, 0.001, 1.0], upper=[3.0, 0.99, 3.0, 0.98, 20.0],
                                x_scale=[1, 0.1, 1, 0.1, 1])
    return (-k / mass, 0.0), solimp, rms


def mujoco_effective_mass(scene) -> dict[str, float]:
    """The effective mass MuJoCo uses for the contact row at first touch, from the adapter's model:
    `m_eff` = 1/efc_diagA [kg] (exact diagonal, diagexact enabled) and `m_invweight` = 1/body_invweight0 of the
    ball (translational) [kg] (the ball's part of diagApprox, used without diagexact).
    Imports mujoco (only when called)."""
    import mujoco

    from impactval.engines.base import EngineSettings
    from impactval.engines.mujoco_ import _contact_diag_a, build_xml, check_scene

    check_scene(scene, "native")        # EngineError for a target MuJoCo cannot give a native contact
    xml, _ = build_xml(scene, EngineSettings(dt=1e-6, contact="native"))
    model = mujoco.MjModel.from_xml_string(xml)
    a = _contact_diag_a(mujoco, model, scene)
    inv = float(model.body_invweight0[model.body("ball").id, 0])
    return {"m_eff": 1.0 / a, "m_invweight": 1.0 / inv}


# ---------------------------------------------------------------------------- PyBullet, Exudyn

def pybullet_global(k: float, dt: float, erp: float = PYBULLET_ERP) -> tuple[float, float]:
    """PyBullet's global route for a spring k [N/m] at step dt [s]: (contactERP, globalCFM = ERP/(k dt))."""
    return erp, erp / (k * dt)


# ---------------------------------------------------------------------------- engine-run fits

@dataclass
class FitRecord:
    """What a fit did: the parameter vectors evaluated, the engine runs it started (`engine_runs`,
    stored jobs reused by a resumed fit are not counted) and the rows of the last evaluation."""

    evaluations: int = 0
    engine_runs: int = 0
    jobs_reused: int = 0
    last_rows: list[dict[str, Any]] = field(default_factory=list)
    history: list[tuple[list[float], float]] = field(default_factory=list)


class EngineObjective:
    """Residuals of engine runs against the reference at every speed, for least squares.

    `options_of(params) -> {"KEY": value}` maps a parameter vector to engine options (without the
    engine prefix); each call runs one job per speed through `impactval.runner.execute` into `store`
    (reused when stored) and returns [err_t_m, err_f_m(, err_delta_m)] per speed (signed fractions).
    A failed job gives a large residual (the fit steps back), not an exception.
    """

    def __init__(self, scene, engine: str, speeds: Sequence[float], settings, options_of: Callable[[np.ndarray], dict],
                 store, workers: int | None = None, quantities: Sequence[str] = ("t_m", "f_m"), tol: float = 1e-6,
                 keep_series: bool = False, progress: Callable[[], Any] | None = None,
                 on_evaluation: Callable[["EngineObjective", dict[str, Any], np.ndarray], None] | None = None) -> None:
        self.scene, self.engine, self.speeds = scene, engine, list(speeds)
        self.settings, self.options_of, self.store, self.workers = settings, options_of, store, workers
        # series are always kept: the final evaluation may reuse a fit job and the report plots its f(t)
        self.quantities, self.tol, self.keep_series = tuple(quantities), tol, True
        # progress: a factory of the runner's progress displays (one per evaluation: a display is closed when its
        # jobs are done); on_evaluation(objective, options, residuals) after each evaluation
        self.progress, self.on_evaluation = progress, on_evaluation
        self.record = FitRecord()
        #: "scan" while `scan` evaluates its grid, "fit" otherwise (the CLI's progress line says which)
        self.phase = "fit"

    def jobs(self, params: np.ndarray):
        from impactval.jobs import Job

        opts = tuple(sorted(self.options_of(np.asarray(params, float)).items()))
        st = dataclasses.replace(self.settings, options=opts)
        return [Job(at_speed(self.scene, v), self.engine, st, self.tol) for v in self.speeds]

    def rows(self, params: np.ndarray) -> list[dict[str, Any]]:
        from impactval.runner import REUSABLE_STATUSES, execute
        from impactval.store import Store

        jobs = self.jobs(params)
        found = self.store.find({j.key for j in jobs}, REUSABLE_STATUSES)
        rows = execute(jobs, store=self.store, workers=self.workers, keep_series=self.keep_series,
                       command="impactval tune", theory_gap=False,  # fits contact parameters: no beam-theory split
                       progress=self.progress() if self.progress is not None else None)
        if rows and all(r.get("status") == "skipped" for r in rows):     # the engine does not model this scene
            why = str(rows[0].get("message") or "the engine skipped every speed").rstrip(".")
            raise ImpactvalError(f"tune: {why}; tune needs a "
                                 f"scene the engine runs with contact native (see `impactval run`).")
        self.record.evaluations += 1
        self.record.engine_runs += len({j.key for j in jobs} - set(found))
        self.record.jobs_reused += len(set(found))
        self.record.last_rows = rows
        return rows

    def residuals_of(self, rows: list[dict[str, Any]]) -> np.ndarray:
        out = []
        for r in rows:
            for q in self.quantities:
                e = r.get(f"err_{q}")
                out.append(float(e) if r.get("status") == "ok" and e is not None and math.isfinite(float(e)) else 10.0)
        return np.array(out)

    def __call__(self, params: np.ndarray) -> np.ndarray:
        res = self.residuals_of(self.rows(params))
        self.record.history.append(([float(x) for x in params], float(np.sum(res**2))))
        if self.on_evaluation is not None:
            self.on_evaluation(self, self.options_of(np.asarray(params, float)), res)
        return res


#: a fit stops once STALL_EVALS evaluations in a row (finite-difference steps included) have not lowered the best
#: sum of squared errors by more than STALL_REL of it: engine runs are costly, and where the contact law cannot match
#: the reference (a linear spring on a light, flexible beam, where the first contact can split into several) the
#: objective is noisy at the 1e-3 level and least_squares' own tolerances (xtol 1e-8, ftol 1e-10) never stop it
#: (an unseen cantilever, 127 x 4.4 x 1.65 mm titanium under a 3.7 mm WC ball: all 30 evaluations, 152 engine jobs,
#: 44 min, its largest error 116-117 % from the 10th on; with this rule 17 evaluations, the same residuals within 0.3 %
#: points; 1e-3 instead of 1e-2 stopped at 23). A smooth fit (a rigid plate) converges before the rule applies.
STALL_EVALS, STALL_REL = 4, 1e-2


class _Stalled(Exception):
    """Raised inside least_squares' objective to end a fit that no longer improves."""


def fit(objective: EngineObjective, x0: Sequence[float], bounds=(-np.inf, np.inf), diff_step: float = 1e-3,
        max_nfev: int = 30):
    """scipy.optimize.least_squares over engine runs from x0 (the closed-form start), stopped early when it stalls
    (STALL_EVALS, STALL_REL). Deterministic, so a rerun asks the store for the same jobs and resumes. Returns the
    OptimizeResult (on a stall: x the best point evaluated, status 0, message saying so)."""
    from scipy import optimize

    best = {"cost": math.inf, "x": np.asarray(x0, float), "since": 0}

    def residuals(x: np.ndarray) -> np.ndarray:
        res = objective(x)
        cost = float(np.sum(res**2))
        if cost < best["cost"] * (1.0 - STALL_REL):
            best["since"] = 0
        else:
            best["since"] += 1
        if cost < best["cost"]:
            best["cost"], best["x"] = cost, np.array(x, float)
        if best["since"] >= STALL_EVALS:
            raise _Stalled
        return res

    try:
        return optimize.least_squares(residuals, np.asarray(x0, float), bounds=bounds, diff_step=diff_step,
                                      xtol=1e-8, ftol=1e-10, max_nfev=max_nfev)
    except _Stalled:
        return optimize.OptimizeResult(x=best["x"], cost=0.5 * best["cost"], status=0, success=False,
                                       message=f"stopped: {STALL_EVALS} evaluations without lowering the squared "
                                               f"error by {STALL_REL:g} of it")


#: on a flexible target (beam, plate, modal) the closed-form start is the rigid plate's and only a guess: the fit first
#: scans the stiffness over these factors [decades] around it (and the engine's default spring), then starts least
#: squares from the best point. An unseen cantilever (127 x 4.4 x 1.65 mm titanium, a 3.7 mm WC ball, 0.1-10 m/s):
#: from the rigid plate's compromise k = 2.6e6 N/m least squares ended at 2.3e6 (t_m, f_m within 117 %), worse than
#: the engine's default 2.4e7 (within 42 %) that it never tried: the first contact splits near-grazing at some springs,
#: so t_m jumps and the local fit stops in a pocket.
SCAN_DECADES = (-1.0, -0.5, 0.0, 0.5, 1.0)


def scan_points(x_start: float, extra: Sequence[float] = ()) -> list[float]:
    """The log-stiffness points [ln(k / k_start-scale)] a flexible target's fit scans before least squares:
    x_start + SCAN_DECADES ln 10, plus `extra` (the engine's default spring), sorted, each once."""
    pts = [x_start + d * math.log(10.0) for d in SCAN_DECADES] + [float(x) for x in extra if math.isfinite(x)]
    return sorted(set(round(x, 12) for x in pts))


#: a scan whose best point is its lowest or highest goes on by SCAN_DECADES' step that way, at most this many more
#: points, while the error keeps falling (the cantilever above: best at the top of the grid, 41 %)
SCAN_EXTEND = 4


def scan(objective: EngineObjective, x_start: float, extra: Sequence[float] = (), prefix: str = "") -> list[dict]:
    """Evaluate `objective` at `scan_points(x_start, extra)`, then, while the best is an end point, one step further
    that way (at most SCAN_EXTEND); one dict per point in the order run: {"options" (keys with `prefix`), "sum_sq",
    "largest" (|error|, a fraction)}. The points join the objective's record (`best_evaluated`)."""
    out, seen = [], {}

    def at(x: float) -> None:
        res = objective(np.array([x]))
        seen[x] = float(np.sum(res**2))
        out.append({"options": {prefix + k: v for k, v in objective.options_of(np.array([x])).items()},
                    "sum_sq": seen[x], "largest": float(np.max(np.abs(res)))})

    objective.phase = "scan"
    try:
        for x in scan_points(x_start, extra):
            at(x)
        step = (SCAN_DECADES[1] - SCAN_DECADES[0]) * math.log(10.0)
        for _ in range(SCAN_EXTEND):
            best = min(seen, key=seen.get)
            if best == max(seen):
                at(best + step)
            elif best == min(seen):
                at(best - step)
            else:
                break
    finally:
        objective.phase = "fit"
    return out


def best_evaluated(record: FitRecord) -> tuple[np.ndarray, float]:
    """The point with the least sum of squared errors among every evaluation of a fit (scan, least-squares steps
    and finite-difference steps alike: each was a real set of engine runs) and that sum."""
    x, cost = min(record.history, key=lambda h: h[1])
    return np.asarray(x, float), cost


# ---------------------------------------------------------------------------- the tune driver

@dataclass
class Tuned:
    """The outcome of `tune`: what goes into DIR/tuned.json and the report."""

    engine: str
    scene: str
    contact: str
    dt: float
    speeds: list[float]
    options: dict[str, Any]
    residuals: list[dict[str, float]]
    engine_runs: int
    parameters: dict[str, Any]
    closed_form: dict[str, Any]
    notes: list[str]
    before_options: dict[str, Any]
    before_residuals: list[dict[str, float]]
    targets: list[Target]
    rows: list[dict[str, Any]] = field(default_factory=list)
    before_rows: list[dict[str, Any]] = field(default_factory=list)
    evaluations: int = 0
    jobs_reused: int = 0
    #: the stiffness scan of a flexible target before least squares: [{"options", "sum_sq", "largest"}] (errors as
    #: signed fractions; empty for a rigid plate or ball, whose closed-form start is the fit's)
    scan: list[dict[str, Any]] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        return {"engine": self.engine, "scene": self.scene, "contact": self.contact, "dt": self.dt,
                "speeds": self.speeds, "options": self.options, "residuals": self.residuals,
                "engine_runs": self.engine_runs, "evaluations": self.evaluations, "jobs_reused": self.jobs_reused,
                "parameters": self.parameters, "closed_form": self.closed_form, "notes": self.notes,
                "before": {"options": self.before_options, "residuals": self.before_residuals}, "scan": self.scan,
                "reference": [dataclasses.asdict(t) | {"restitution": t.restitution} for t in self.targets]}


def _residual_rows(rows: list[dict[str, Any]], speeds: Sequence[float]) -> list[dict[str, float]]:
    out = []
    for v, r in zip(speeds, rows):
        ok = r.get("status") == "ok"
        out.append({"speed": float(v), "status": r.get("status"),
                    "t_m": float(r["t_m"]) if ok else math.nan, "f_m": float(r["f_m"]) if ok else math.nan,
                    "delta_m": float(r["delta_m"]) if ok else math.nan,
                    "err_t_m": float(r["err_t_m"]) if ok else math.nan,
                    "err_f_m": float(r["err_f_m"]) if ok else math.nan,
                    "err_delta_m": float(r["err_delta_m"]) if ok else math.nan,
                    "job_key": r.get("job_key", "")})
    return out


def _check_engine_runs(engine: str, scene, speeds: Sequence[float], integrator: str | None) -> None:
    """Refuse, before any reference is solved, a scene the engine's plan refuses with contact native (a Kirchhoff
    plate; PyBullet or MuJoCo on a modal target): the engine's own reason, one line. (A scene every job skips
    anyway is refused after the first evaluation, `EngineObjective`.)"""
    from impactval.engines.base import EngineError, EngineSettings, load_adapter

    adapter = load_adapter(engine)
    try:
        adapter.plan(at_speed(scene, max(speeds)),
                     adapter.check_settings(EngineSettings(dt=1e-7, contact="native", integrator=integrator)))
    except EngineError as exc:
        raise ImpactvalError(f"tune: {str(exc).rstrip('.')}; tune needs a scene the engine runs with contact "
                             f"native (see `impactval run`).") from None


def _fmt(x: float) -> str:
    return f"{x:.10g}"


def tune(engine: str, scene, speeds: Sequence[float], contact: str = "native", dt: float | None = None,
         store=None, workers: int | None = None, tol: float = 1e-6, start: float | None = None,
         max_nfev: int = 30, integrator: str | None = None, timeout_s: float = 600.0,
         progress: Callable[[], Any] | None = None, on_evaluation: Callable[..., None] | None = None) -> Tuned:
    """Fit `engine`'s native contact parameters so its impacts on `scene` match the reference at `speeds`.

    Parameters
    ----------
    engine : "mujoco", "pybullet" or "exudyn"
    scene : Scene (a rigid plate gives closed-form targets; other targets use the reference solver)
    speeds : approach speeds [m/s]
    contact : "native" (a linear spring: MuJoCo flat solimp, PyBullet global ERP/CFM, Exudyn exponent 1)
        or "native-hertz" (MuJoCo: Hertz-shaped solimp; Exudyn: exponent 1.5, alpha fitted; PyBullet has
        no pasteable Hertz law and refuses)
    dt : engine step [s] (default `default_dt`: the same for every speed)
    store : Store, SQLite path or URL (the fit's engine runs; a rerun resumes from it)
    start : starting stiffness for the fit [N/m or N/m^1.5] (default: the closed form)
    max_nfev : most least-squares evaluations (each one engine job per speed)
    progress : factory of a runner progress display (`impactval.progress.make_progress`), one per evaluation
    on_evaluation : called as on_evaluation(objective, options, residuals) after each fit evaluation (residuals:
        signed fractions, the quantities per speed); the CLI prints a line per evaluation from it

    Returns a `Tuned` (options usable as `--option KEY=VALUE` with `impactval run --contact native`).
    """
    from impactval.engines.base import EngineSettings
    from impactval.store import Store

    if engine not in TUNE_ENGINES:
        raise ImpactvalError(f"tune: unknown engine {engine!r}; known: {', '.join(TUNE_ENGINES)}.")
    if contact not in ("native", "native-hertz"):
        raise ImpactvalError(f"tune: --contact must be native or native-hertz, got {contact!r}.")
    import importlib.util

    if importlib.util.find_spec(engine) is None:
        raise ImpactvalError(f"tune: {engine} is not installed: pip install 'impactval[{engine}]'.")
    if engine == "pybullet" and contact == "native-hertz":
        raise ImpactvalError("tune: pybullet has no pasteable Hertz law (its native-hertz mode updates the CFM every "
                             "step from the penetration); use --contact native.")
    if scene.target.kind == "ball" and scene.target.velocity != 0.0:
        raise ImpactvalError(f"tune: target.velocity is {scene.target.velocity:g} m/s: --speeds are the first ball's "
                             f"approach speeds onto a second ball at rest; set target.velocity = 0 and give the "
                             f"relative speeds (v1 + v2) in --speeds (the contact depends on those only).")
    speeds = [float(v) for v in speeds]
    _check_engine_runs(engine, scene, speeds, integrator)
    dt = float(dt) if dt is not None else default_dt(scene, speeds, engine, contact, integrator)
    targets = hertz_targets(scene, speeds, tol)
    mass, alpha = contact_mass(scene), scene.alpha
    v_mid = middle_speed(speeds)
    k_comp = linear_compromise(mass, targets)
    closed: dict[str, Any] = {
        "k_compromise": k_comp,
        "k_by_speed": [{"speed": t.speed, "k0_energy": k0_energy(mass, alpha, t.speed),
                        **{f"k_{n}": v for n, v in k_matching(mass, t.t_m, t.f_m, t.speed).items()}}
                       for t in targets],
        "alpha": alpha, "mass": mass, "e_star": scene.e_star,
        "linear_product_ratio": LINEAR_PRODUCT_RATIO,
    }
    notes: list[str] = []
    db = store if isinstance(store, Store) else Store(store)
    own = not isinstance(store, Store)
    settings = EngineSettings(dt=dt, contact="native", integrator=integrator, timeout_s=timeout_s)
    prefix = engine + "."
    params: dict[str, Any] = {}
    try:
        if engine == "mujoco":
            masses = mujoco_effective_mass(scene)
            m_eff = masses["m_eff"]
            params.update(m_eff=m_eff, m_invweight=masses["m_invweight"])
            closed["m_eff"] = m_eff
            if contact == "native":
                d = MUJOCO_FLAT_IMPEDANCE
                solimp = (d, d, 0.001, 0.5, 2.0)
                x_start = math.log((start or k_comp) / k_comp)

                def options_of(p):
                    k = k_comp * math.exp(p[0])
                    return {"solref": f"{_fmt(-k / m_eff)},0", "solimp": ",".join(_fmt(x) for x in solimp)}
                before = {"solref": f"{_fmt(-k0_energy(mass, alpha, v_mid) / m_eff)},0",
                          "solimp": ",".join(_fmt(x) for x in solimp)}
                x_before = math.log(k0_energy(mass, alpha, v_mid) / k_comp)
            else:
                solref0, solimp0, rms = mujoco_shape_prefit(m_eff, alpha, targets)
                closed.update(prefit_solref=solref0, prefit_solimp=solimp0, prefit_rms_log=rms)
                x_start = math.log(start / (-solref0[0] * m_eff)) if start else 0.0

                def options_of(p):
                    ks = -solref0[0] * math.exp(p[0])
                    return {"solref": f"{_fmt(-ks)},0", "solimp": ",".join(_fmt(x) for x in solimp0)}
                d = MUJOCO_FLAT_IMPEDANCE
                before = {"solref": f"{_fmt(-k0_energy(mass, alpha, v_mid) / m_eff)},0",
                          "solimp": ",".join(_fmt(x) for x in (d, d, 0.001, 0.5, 2.0))}
                x_before = math.nan          # a flat law: not a point of the shaped law's scale
            quantities = ("t_m", "f_m")
        elif engine == "pybullet":
            x_start = math.log((start or k_comp) / k_comp)

            def options_of(p):
                erp, cfm = pybullet_global(k_comp * math.exp(p[0]), dt)
                return {"erp": erp, "cfm": float(_fmt(cfm))}
            erp, cfm = pybullet_global(k0_energy(mass, alpha, v_mid), dt)
            before = {"erp": erp, "cfm": float(_fmt(cfm))}
            x_before = math.log(k0_energy(mass, alpha, v_mid) / k_comp)
            quantities = ("t_m", "f_m")
        else:
            exponent = 1.0 if contact == "native" else 1.5
            if contact == "native":
                k_ref = k_comp
            else:
                # start independent of alpha's formula: the linear compromise turned into a 1.5-law that gives
                # the same force at that spring's own peak approach at the middle speed
                _, _, dl = linear_plate(mass, k_comp, v_mid)
                k_ref = k_comp / math.sqrt(dl)
            x_start = math.log((start or k_ref) / k_ref)

            def options_of(p):
                return {"contact_stiffness": float(_fmt(k_ref * math.exp(p[0]))), "contact_exponent": exponent,
                        "contact_damping": 0.0}
            # before: the adapter's linear k0 of the middle speed, or for the 1.5 law the fit's own start
            before = {"contact_stiffness": float(_fmt(k0_energy(mass, alpha, v_mid))), "contact_exponent": 1.0,
                      "contact_damping": 0.0} if contact == "native" else options_of(np.array([x_start]))
            x_before = math.log(k0_energy(mass, alpha, v_mid) / k_ref) if contact == "native" else math.nan
            quantities = ("t_m", "f_m", "delta_m") if contact == "native-hertz" else ("t_m", "f_m")
        objective = EngineObjective(scene, engine, speeds, settings, options_of, db, workers, quantities, tol,
                                    progress=progress, on_evaluation=on_evaluation)
        x0 = x_start
        scanned: list[dict[str, Any]] = []
        if scene.target.kind not in ("rigid-plate", "ball") and start is None:
            scanned = scan(objective, x_start, [x_before], prefix)
            x0 = float(best_evaluated(objective.record)[0][0])
        sol = fit(objective, [x0], diff_step=1e-4 if contact == "native-hertz" else 1e-3, max_nfev=max_nfev)
        # the best point evaluated (least squares' last point is not always it: a stall, a noisy objective)
        x_best = best_evaluated(objective.record)[0] if objective.record.history else sol.x
        best = objective.options_of(x_best)
        final = EngineObjective(scene, engine, speeds, settings, lambda p: best, db, workers, quantities, tol,
                                keep_series=True, progress=progress)
        rows = final.rows(np.zeros(1))
        before_rows: list[dict[str, Any]] = []
        if before:
            prev = EngineObjective(scene, engine, speeds, settings, lambda p: before, db, workers, quantities, tol,
                                   keep_series=True, progress=progress)
            before_rows = prev.rows(np.zeros(1))
            objective.record.engine_runs += prev.record.engine_runs
        objective.record.engine_runs += final.record.engine_runs
    finally:
        if own:
            db.close()
    if engine == "mujoco":
        ks = -float(best["solref"].split(",")[0])
        params.update(solref=best["solref"], solimp=best["solimp"], stiffness_per_mass=ks)
        if contact == "native":
            params["k"] = ks * params["m_eff"]
        else:
            params["k_scale"] = ks * params["m_eff"]
    elif engine == "pybullet":
        params.update(k=best["erp"] / (best["cfm"] * dt), erp=best["erp"], cfm=best["cfm"])
    else:
        params.update(contact_stiffness=best["contact_stiffness"], contact_exponent=best["contact_exponent"])
        if contact == "native-hertz":
            params["alpha_fit_rel_error"] = best["contact_stiffness"] / alpha - 1.0
    if contact == "native" or engine == "pybullet":
        notes.append(f"A linear spring cannot match Hertz at every speed: on a rigid plate t_m*f_m is "
                     f"{LINEAR_PRODUCT_RATIO:.4f} of Hertz's for any k, so at best t_m and f_m are both "
                     f"{100 * (math.sqrt(LINEAR_PRODUCT_RATIO) - 1):.1f} % off, and a spring's t_m does not vary with "
                     f"speed (Hertz: v^-1/5). k_by_speed gives the speed-dependent springs.")
    if engine == "pybullet":
        notes.append(f"globalCFM = ERP/(k dt) holds for dt = {dt:g} s only: recompute it for another step.")
    if before_rows:
        after_sq, before_sq = (float(np.sum(objective.residuals_of(r) ** 2)) for r in (rows, before_rows))
        if before_sq < after_sq:
            notes.append(f"The engine's default options (Before) match the reference better than the fitted ones "
                         f"(sum of squared errors over {', '.join(quantities)}: {before_sq:.4g} against "
                         f"{after_sq:.4g}): the fit did not find the better point; keep the default, or give --start.")
    opts = {prefix + k: v for k, v in best.items()}
    return Tuned(engine=engine, scene=scene.name, contact=contact, dt=dt, speeds=speeds, options=opts,
                 residuals=_residual_rows(rows, speeds), engine_runs=objective.record.engine_runs,
                 parameters=params, closed_form=closed, notes=notes,
                 before_options={prefix + k: v for k, v in before.items()},
                 before_residuals=_residual_rows(before_rows, speeds) if before_rows else [],
                 targets=targets, rows=rows, before_rows=before_rows,
                 evaluations=objective.record.evaluations, jobs_reused=objective.record.jobs_reused, scan=scanned)


def option_args(options: dict[str, Any]) -> list[str]:
    """The options as `--option KEY=VALUE` command-line arguments."""
    out = []
    for k, v in options.items():
        out += ["--option", f"{k}={v}"]
    return out


def write(tuned: Tuned, out: str | Path) -> Path:
    """DIR/tuned.json (see `Tuned.as_json`); returns its path."""
    import json

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "tuned.json"

    def clean(x):
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(v) for v in x]
        return x
    path.write_text(json.dumps(clean(tuned.as_json()), indent=2) + "\n")
    return path


__all__ = ["parse_speeds", "at_speed", "hertz_targets", "k0_energy", "linear_plate", "k_matching",
           "linear_compromise", "damping_ratio", "restitution_of", "damping_for", "mujoco_direct_solref",
           "mujoco_timeconst_solref", "mujoco_impedance", "mujoco_force", "law_plate", "mujoco_shape_prefit",
           "mujoco_effective_mass", "pybullet_global", "EngineObjective", "fit", "scan", "scan_points",
           "best_evaluated", "tune", "Tuned", "write", "option_args", "Target", "LINEAR_PRODUCT_RATIO"]
