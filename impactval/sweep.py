"""Speed against accuracy: a grid of settings (dt x integrator x structure size) and its analysis.

Two halves, both plain functions:

- the grid: `parse_axis` reads the command-line syntax of one axis (log ranges ``a:b:n``, lists,
  ``auto``, per-engine values by prefix such as ``mujoco.RK4``); `build_jobs` expands scenes x
  engines x axes into `Job`s; `run_sweep` runs them and returns one row per cell;
- the analysis, pure functions over a DataFrame of rows (the columns of `impactval.runner.COLUMNS`
  plus `score`): `pareto_front`, `fit_orders` (order of convergence in dt and the dt range where it
  holds, with the reason when it differs from the integrator's nominal order), `floors` (where
  refining dt stops helping and what sets the floor, in words), `stability` (observed against
  predicted explicit stability limit), `cheapest` (cheapest setting under X %).

The score of a row is its largest |relative error| over t_m, f_m and delta_m against the reference;
the cost is its stepping wall time [s] (build excluded). Presentation lives in reports/sweep.py.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any, Iterable

import numpy as np
import pandas as pd

from impactval import ranges as _ranges
# REFUSED_MARKER: what the adapter base's message says of a cell whose dt is above the predicted explicit stability
# limit: refused before stepping (status "unstable", 0 steps), so it tells nothing about where the engine goes unstable
from impactval.engines.base import REFUSED_MARKER
from impactval.errors import ImpactvalError
from impactval.jobs import Job as _RunJob

#: the three metrics whose relative errors make a row's score
METRICS = ("t_m", "f_m", "delta_m")
#: local slopes of a power law over a fitted range stay within this much of the fitted order
ORDER_SLOPE_SPREAD = 0.3
#: an envelope (no clean range) whose local slopes stray further than this from its least-squares order has no
#: observed order at all, and its explanation says so instead of comparing it with the nominal order. One whole
#: order: the explanations place an order within 0.3 of the nominal one ("observed as nominal") or within 0.4 of
#: semi-implicit Euler's 2, and tell first- from second-order methods (Euler 1; trapezoid, generalized-alpha 2) and 2
#: from the Hertz cap near 2.5; slopes that disagree by a whole order or more cannot place the order in any of those
#: bands. (A clean range keeps them within ORDER_SLOPE_SPREAD; between the two the envelope is reported as such, with
#: its scatter.) Seen: a noisy order-1 series on a grid with two steps 2 % apart had slopes 2.3, -45.5, 1.0 around
#: 0.995 and was "observed as nominal"; PyBullet's native contact on a clamped aluminium beam, f_m from 2.5e-7 to
#: 1.6e-8 s, slopes 2.78, 2.66, -0.62 around 1.71 (its successive f_m changes change sign).
ORDER_SLOPE_SCATTER_NONE = 1.0
#: a clean range has at least this many points (4 differences: 3 points agree by chance too often)
ORDER_MIN_POINTS = 5
#: points of a fitted range lie within this factor of the fitted power law
ORDER_RESIDUAL_FACTOR = 1.15
#: refining dt "stops helping" once the score is within this fraction of the finest-dt score
FLOOR_FRACTION = 0.1
#: an error within this fraction of the engine's own |model_error| estimate is the structure floor (refining dt
#: cannot lower it), whether or not the grid shows the error level off
FLOOR_MODEL_MATCH = 0.05
#: unit roundoff of the arithmetic each engine steps in (float32 GPU-style engines, else float64)
PRECISION = {"mujoco-warp": float(np.finfo(np.float32).eps), "newton": float(np.finfo(np.float32).eps)}
_DOUBLE_EPS = float(np.finfo(np.float64).eps)

#: integration methods an adapter's integrators are declared as (`EngineAdapter.integrator_methods`):
#: method -> (nominal global order, description)
METHODS: dict[str, tuple[float, str]] = {
    "symplectic-euler": (1, "semi-implicit (symplectic) Euler"),
    "symplectic-euler-implicit-damping": (1, "semi-implicit Euler with implicit velocity-dependent forces"),
    "explicit-euler": (1, "explicit Euler"), "trapezoidal": (2, "trapezoidal rule"),
    "generalized-alpha": (2, "generalized-alpha"), "rk4": (4, "classical 4th-order Runge-Kutta"),
    "rk6": (6, "6th-order Runge-Kutta"),
}
_SYMPLECTIC_EULER = ("symplectic-euler", "symplectic-euler-implicit-damping")


@lru_cache(maxsize=None)
def _declared(engine: str) -> tuple[str, dict[str, str]]:
    """(default integrator, integrator -> method) as the engine's adapter declares them; ("", {}) when the
    adapter cannot be loaded (its module only: no engine is imported)."""
    from impactval.engines.base import adapter_class

    try:
        cls = adapter_class(engine)
    except Exception:  # noqa: BLE001 - an unknown or broken adapter just has no nominal orders
        return "", {}
    return (cls.integrators[0] if cls.integrators else ""), dict(cls.integrator_methods)


# ---------------------------------------------------------------------------- the grid
def _known_engines(engines: Iterable[str]) -> list[str]:
    from impactval.engines import ENGINES

    return list(dict.fromkeys([*ENGINES, *engines]))


#: n values from a to b (both included), log-spaced: the one range grammar (impactval.ranges)
log_range = _ranges.log_range
_DT_EXAMPLE = "1e-5:1e-8:12 or 1e-6,5e-7"


def _parse_value(text: str, kind: str, field: str) -> list[Any]:
    """One item of an axis: 'auto', a log range a:b:n (dt only) or one value."""
    if text.lower() == "auto":
        return ["auto"]
    if _ranges.is_range(text) and kind != "float":
        raise ImpactvalError(f"--{field}: ranges a:b:n are for time steps; give {field} as a list "
                             f"(e.g. 21,41,81), got {text!r}.")
    if kind == "float":
        return _ranges.parse_list(text, f"--{field}", unit="s", example=_DT_EXAMPLE)
    if kind == "int":
        try:
            v = int(text)
        except ValueError:
            raise ImpactvalError(f"--{field} takes whole numbers or auto (e.g. 21,41,81), got {text!r}.") from None
        if v < 1:
            raise ImpactvalError(f"--{field}: values must be at least 1, got {text!r}.")
        return [v]
    return [text]


def parse_axis(text: str | None, field: str, kind: str, engines: Iterable[str]) -> dict[str, list[Any]]:
    """Values of one sweep axis for each engine.

    `text` is a comma-separated list; an item may carry an engine prefix ("mujoco.RK4",
    "pybullet.1e-6:1e-7:4"); an engine with prefixed items gets only those, the others get the
    unprefixed items, and an engine with neither gets [None] (its default). `kind` is "float"
    (time steps [s]; ranges a:b:n allowed), "int" (segments, modes) or "str" (integrators);
    "auto" is kept as the string "auto". Duplicates are dropped, order kept.
    """
    engines = list(engines)
    known = _known_engines(engines)
    plain: list[Any] = []
    by_engine: dict[str, list[Any]] = {}
    for raw in [] if text is None else str(text).split(","):
        item = raw.strip()
        if not item:
            continue
        head, dot, rest = item.partition(".")
        if dot and head in known:
            if head not in engines:
                raise ImpactvalError(f"--{field}: {item!r} names engine {head!r}, which is not in --engines "
                                     f"({', '.join(engines)}).")
            by_engine.setdefault(head, []).extend(_parse_value(rest.strip(), kind, field))
        else:
            plain.extend(_parse_value(item, kind, field))
    if text is not None and not plain and not by_engine:
        raise ImpactvalError(f"--{field}: give at least one value.")
    out = {}
    for e in engines:
        vals = by_engine.get(e, plain) or [None]
        out[e] = list(dict.fromkeys(vals))
    return out


@dataclass(frozen=True)
class Job(_RunJob):
    """One cell of the grid: an `impactval.jobs.Job` (scene, engine spec, settings, reference tol)
    whose progress label names the integrator and structure size too."""

    def label(self) -> str:
        s = self.settings
        size = s.segments or s.modes
        return (f"{self.scene.name} / {self.spec} {s.integrator or 'default'}" + (f" N={size}" if size else "")
                + f" dt={_dt_text(s.dt)}")


def _dt_text(dt: Any) -> str:
    return f"{dt:g}" if isinstance(dt, (int, float)) else str(dt)


def build_jobs(scenes: Iterable, engines: Iterable[str], base, *, dt: dict[str, list] | None = None,
               integrator: dict[str, list] | None = None, segments: dict[str, list] | None = None,
               modes: dict[str, list] | None = None, tol: float = 1e-9) -> list[Job]:
    """Every (scene, engine, integrator, segments, modes, dt) combination as a Job.

    `base` is an EngineSettings; the axes are `parse_axis` results (None = the base value). "auto"
    segments or modes mean the engine sizes the structure (None); "auto" dt is passed on as is.
    `tol` is the relative tolerance of the reference the cells are compared with (part of each
    job's key). Settings an engine rejects become "skipped" rows when run, not errors here. A rigid plate has
    no structure: its segments and modes axes collapse to the default.
    """
    from impactval.engines.base import EngineSettings  # noqa: F401 - the settings type of `base`
    from impactval.runner import settings_for, unique_scenes

    engines = list(engines)
    jobs = []
    for scene in unique_scenes(scenes):
        kind = getattr(scene.target, "kind", "")
        rigid = kind in ("rigid-plate", "ball")         # no structure to size (a second ball is a free mass)
        given = kind == "modal"                         # the scene's own modes: no chain, no mode count to choose
        for eng in engines:
            ints = (integrator or {}).get(eng) or [base.integrator]
            segs = [None] if rigid or given else (segments or {}).get(eng) or [base.segments]
            mods = [None] if rigid or given else (modes or {}).get(eng) or [base.modes]
            dts = (dt or {}).get(eng) or [base.dt]
            for integ in ints:
                for seg in segs:
                    for mod in mods:
                        for step in dts:
                            s = _settings(base, step, integ, seg, mod)
                            jobs.append(Job(scene, eng, settings_for(s, eng), tol))
    return jobs


def _settings(base, dt, integrator, segments, modes):
    from impactval.errors import EngineError

    try:
        return replace(base, dt=base.dt if dt is None else dt, integrator=integrator,
                       segments=None if segments == "auto" else segments, modes=None if modes == "auto" else modes)
    except EngineError as err:
        if dt == "auto":
            raise ImpactvalError("--dt auto: this version's engines cannot pick their own step yet; "
                                 "give time steps in s.") from None
        raise ImpactvalError(f"sweep settings: {err}") from None


# ---------------------------------------------------------------------------- analysis
def as_fractions(df: pd.DataFrame) -> pd.DataFrame:
    """Rows as the analysis reads them: exported columns in % (`err_t_m_pct`, results.csv) are
    turned back into the fractions of the row API (`err_t_m`)."""
    pct = [c for c in df.columns if c.endswith("_pct") and c[:-4] not in df.columns]
    if not pct:
        return df
    d = df.copy()
    for c in pct:
        d[c[:-4]] = pd.to_numeric(d[c], errors="coerce") / 100.0
    return d.drop(columns=pct)


def largest_error(df: pd.DataFrame) -> pd.Series:
    """A row's score: the largest |relative error| of t_m, f_m, delta_m (NaN for failed rows)."""
    df = as_fractions(df)
    errs = df[[f"err_{m}" for m in METRICS]].apply(pd.to_numeric, errors="coerce").abs()
    score = errs.max(axis=1, skipna=True)
    return score.where(df["status"].astype(str) == "ok")


def with_score(df: pd.DataFrame) -> pd.DataFrame:
    """The rows with `score` (largest error), numeric `dt`, `step_time_s` (the cell's measured
    stepping time [s]), `cost_s` (its steps times the median stepping time per step of its
    configuration: scene, engine, contact, integrator, segments) and `integrator` filled with the
    engine's default where empty."""
    d = as_fractions(df).copy()
    d["score"] = largest_error(d)
    d["dt"] = pd.to_numeric(d["dt"], errors="coerce")
    integ = d["integrator"].fillna("").astype(str)
    d["integrator"] = [i or _declared(e)[0] for i, e in zip(integ, d["engine"].astype(str))]
    d["segments"] = [_size_text(v) for v in d["segments"]]
    d["step_time_s"] = pd.to_numeric(d["wall_time_step_s"], errors="coerce")
    steps = pd.to_numeric(d["n_steps"], errors="coerce")
    per_step = (d["step_time_s"] / steps).where((steps > 0) & (d["step_time_s"] > 0))
    typical = per_step.groupby([d[c] for c in SERIES]).transform("median") if len(d) else per_step
    # cost = steps x the configuration's median time per step: on a shared machine one cell's
    # timing is noisy, while the time per step of one model and integrator barely depends on dt
    d["cost_s"] = (steps * typical).where(typical.notna(), d["step_time_s"])
    return d


def _size_text(v: Any) -> str:
    """A structure size cell as text: 41, 41.0 and "41" -> "41"; empty/NaN -> ""."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    text = str(v).strip()
    if text.lower() == "nan":
        return ""
    try:
        f = float(text)
        return str(int(f)) if f.is_integer() else text
    except ValueError:
        return text


#: the columns that name one configuration except dt (a series in dt)
SERIES = ("scene", "engine", "contact", "integrator", "segments")


#: a row joins the Pareto front only when it beats every cheaper row's error by more than this
#: fraction (1 %): paying more for 0.01 % less of the same error is not a trade anyone wants shown
FRONT_GAIN = 0.01


def pareto_front(df: pd.DataFrame, gain: float = FRONT_GAIN) -> pd.DataFrame:
    """Per scene and engine, the rows worth their cost (ok rows only): cheapest first, a row is on
    the front when its largest error is below (1 - gain) times the least error of every cheaper
    row (gain = 0: the strict Pareto front). Column `on_front` marks them in a copy of all rows."""
    d = with_score(df)
    d["on_front"] = False
    for _, g in d[d["score"].notna() & d["cost_s"].notna()].groupby(["scene", "engine"], sort=False):
        best = math.inf
        for idx, r in g.sort_values(["cost_s", "score"]).iterrows():
            if r["score"] < best * (1 - gain):
                d.loc[idx, "on_front"] = True
                best = r["score"]
    return d


def cheapest(df: pd.DataFrame, unders: Iterable[float]) -> pd.DataFrame:
    """For each scene, engine and tolerance X (fraction: 0.01 = 1 %), the cheapest row (least
    `cost_s`, see `with_score`) whose largest error is below X; `found` False and the best reached (least
    error) when none is. Columns: scene, engine, under, found, integrator, dt, segments, contact,
    cost_s, step_time_s (measured), score, best_score."""
    d = with_score(df)
    out = []
    for (scene, engine), g in d.groupby(["scene", "engine"], sort=False):
        ok = g[g["score"].notna() & g["cost_s"].notna()]
        for under in unders:
            hit = ok[ok["score"] < under].sort_values(["cost_s", "score"])
            best = ok.sort_values("score").head(1)
            r = hit.iloc[0] if len(hit) else (best.iloc[0] if len(best) else None)
            out.append(dict(scene=scene, engine=engine, under=under, found=bool(len(hit)),
                            integrator=r["integrator"] if r is not None else "", dt=r["dt"] if r is not None else math.nan,
                            segments=r["segments"] if r is not None else "",
                            contact=r["contact"] if r is not None else "",
                            cost_s=r["cost_s"] if r is not None else math.nan,
                            step_time_s=r["step_time_s"] if r is not None else math.nan,
                            score=r["score"] if len(hit) else math.nan,
                            best_score=float(best["score"].iloc[0]) if len(best) else math.nan))
    return pd.DataFrame(out, columns=["scene", "engine", "under", "found", "integrator", "dt", "segments", "contact",
                                      "cost_s", "step_time_s", "score", "best_score"])


# ------------------------------------------------------------ order of convergence
@dataclass(frozen=True)
class OrderFit:
    """A power law |x(dt) - x(0)| ~ C dt^order fitted on dt in [dt_min, dt_max] (n points)."""

    order: float
    dt_min: float
    dt_max: float
    n_points: int
    log_c: float = math.nan
    #: largest factor between a point and the fitted law (1 = exact)
    scatter: float = 1.0
    #: True when the points follow the law within ORDER_RESIDUAL_FACTOR (else a least-squares envelope)
    clean: bool = True
    #: local slopes d log|x_i - x(0)| / d log dt between successive points of the range, largest dt first
    slopes: tuple[float, ...] = ()

    @property
    def slope_spread(self) -> float:
        """Largest |local slope - order| (0 with no slopes): within ORDER_SLOPE_SPREAD on a clean range."""
        return max((abs(s - self.order) for s in self.slopes), default=0.0)

    def at(self, dt: np.ndarray) -> np.ndarray:
        return np.exp(self.log_c) * np.asarray(dt, float) ** self.order


def _fit_differences(dt: np.ndarray, x: np.ndarray) -> tuple[float, float, np.ndarray, np.ndarray]:
    """Order p and log C of |x_i - x_{i+1}| = C dt_i^p (1 - (dt_{i+1}/dt_i)^p) by least squares
    (fixed point in p; on a geometric grid the correction is a constant and p is the plain slope).
    Returns p, log C, the dt_i and the error estimates |x_i - x(0)| ~ |x_i - x_{i+1}| / (1 - rho^p)."""
    diff = np.abs(np.diff(x))
    h, rho = dt[:-1], dt[1:] / dt[:-1]
    logh, logd = np.log(h), np.log(diff)
    p = np.polyfit(logh, logd, 1)[0] if len(h) >= 2 else math.nan
    for _ in range(30):
        if not math.isfinite(p) or p <= 0:
            break
        corr = np.log1p(-rho ** p)
        p_new, logc = np.polyfit(logh, logd - corr, 1)
        if abs(p_new - p) < 1e-10:
            p = p_new
            break
        p = p_new
    if not math.isfinite(p) or p <= 0:
        return p, math.nan, h, diff
    corr = np.log1p(-rho ** p)
    logc = float(np.mean(logd - corr - p * logh))
    return float(p), logc, h, diff / np.exp(corr)


def fit_order(dt: Iterable[float], x: Iterable[float], *, noise: float = 0.0) -> OrderFit | None:
    """The order of convergence in dt of a quantity x(dt) and the widest dt range where it holds.

    Uses differences of successive values (no limit value needed), so a structure or contact-law
    floor common to all steps cancels. A range holds when its points (at least 3 differences) lie
    within ORDER_RESIDUAL_FACTOR of the fitted power law (at least ORDER_MIN_POINTS), its local slopes within
    ORDER_SLOPE_SPREAD of the fit, and every difference exceeds `noise` (absolute, e.g. the
    roundoff in x's units) by 10x. When no range holds, the least-squares law over all points above
    the noise is returned with `clean` False and its `scatter`; None with fewer than 4 points.
    """
    dt = np.asarray(list(dt), float)
    x = np.asarray(list(x), float)
    keep = np.isfinite(dt) & np.isfinite(x)
    dt, x = dt[keep], x[keep]
    order = np.argsort(-dt)
    dt, x = dt[order], x[order]
    best: OrderFit | None = None
    n = len(dt)
    for i in range(n):
        for j in range(n, i + ORDER_MIN_POINTS - 1, -1):          # points i..j-1
            cand = _window_fit(dt[i:j], x[i:j], noise)
            if cand is None or cand.scatter > ORDER_RESIDUAL_FACTOR or not cand.clean:
                continue
            if best is None or math.log(cand.dt_max / cand.dt_min) > math.log(best.dt_max / best.dt_min) + 1e-9:
                best = cand
    if best is None and n >= 4:
        # no clean range: a least-squares envelope over every point above the noise, with its scatter
        above = np.concatenate([np.abs(np.diff(x)) > 10 * noise, [True]])
        k = int(np.argmin(above)) if not above.all() else n
        cand = _window_fit(dt[:k], x[:k], noise) if k >= 4 else None
        if cand is not None:
            best = replace(cand, clean=False)
    return best


def _window_fit(d: np.ndarray, v: np.ndarray, noise: float) -> OrderFit | None:
    """The fit of one window of points (dt descending), with its scatter; None when a difference
    is at the noise or the fit has no positive order."""
    if np.any(np.abs(np.diff(v)) <= 10 * noise) or np.any(np.diff(v) == 0):
        return None
    p, logc, h, e = _fit_differences(d, v)
    if not (math.isfinite(p) and p > 0 and math.isfinite(logc)):
        return None
    resid = np.abs(np.log(e) - (logc + p * np.log(h)))
    local = np.diff(np.log(e)) / np.diff(np.log(h))
    clean = bool(np.abs(local - p).max() <= ORDER_SLOPE_SPREAD)
    return OrderFit(p, float(d[-1]), float(d[0]), len(d), logc, float(np.exp(resid.max())), clean,
                    tuple(float(x) for x in local))


def _noise(g: pd.DataFrame, metric: str) -> float:
    """Absolute roundoff level of a metric in a series (differences of one model at two steps do
    not see the reference's tolerance): eps * sqrt(steps) * |value|."""
    ref = pd.to_numeric(g[f"ref_{metric}"], errors="coerce").abs().max()
    eps = max(PRECISION.get(str(g["engine"].iloc[0]), _DOUBLE_EPS), _DOUBLE_EPS)
    steps = pd.to_numeric(g["n_steps"], errors="coerce").max()
    rel = eps * math.sqrt(steps if math.isfinite(steps) and steps > 0 else 1.0)
    return float(ref * rel) if math.isfinite(ref) else 0.0


def _method(engine: str, integrator: str) -> str:
    default, methods = _declared(engine)
    return methods.get(integrator or default, "")


def _nominal(engine: str, integrator: str) -> tuple[float, str]:
    """(nominal global order, description) of the engine's integrator (its default when empty); NaN if undeclared."""
    return METHODS.get(_method(engine, integrator), (math.nan, integrator or "engine default"))


def explain_order(engine: str, integrator: str, metric: str, order: float, target_kind: str, contact: str,
                  clean: bool = True, scatter: float = 1.0, slopes: Iterable[float] = ()) -> str:
    """Why the observed order of `metric` is what it is, in words. `slopes`: the fit's local slopes (an envelope
    whose slopes stray more than ORDER_SLOPE_SCATTER_NONE from `order` has no observed order, and is told so)."""
    slopes = [float(s) for s in slopes if math.isfinite(s)]
    spread = max((abs(s - order) for s in slopes), default=0.0)
    if math.isfinite(order) and not clean and spread > ORDER_SLOPE_SCATTER_NONE:
        nominal, name = _nominal(engine, integrator)
        head = f"{name}, nominal order {nominal:g}: " if math.isfinite(nominal) else f"{name}: "
        return head + (f"no clean observed order: the local slopes between successive steps range from "
                       f"{min(slopes):.2f} to {max(slopes):.2f}, up to {spread:.3g} away from the least-squares "
                       f"{order:.2f} (a clean order keeps them within {ORDER_SLOPE_SPREAD:g}; beyond "
                       f"{ORDER_SLOPE_SCATTER_NONE:g} they cannot tell one order from the next), and the points lie up "
                       f"to {scatter:.3g}x off that law: {order:.2f} is an envelope, not an order of convergence, so "
                       f"it is not compared with the nominal order (the points scatter, change sign or sit on a "
                       f"floor, or two steps are too close to resolve a slope)")
    text = _explain_order(engine, integrator, metric, order, target_kind, contact)
    if math.isfinite(order) and not clean:
        text += (". Envelope: no sub-range follows one power law (see the scatter column); the error constant "
                 "depends on where touch and separation fall inside a step")
    return text


#: how the metrics are read from the samples (engines.base.contacts_from_series), for the explanations
READOUT = ("f_m and delta_m are read from the quartic through five samples around the peak, an O(dt^5) "
           "read-out, and t_m's end from the cubic through four samples around delta's zero crossing, O(dt^3) or "
           "better")


def _explain_order(engine: str, integrator: str, metric: str, order: float, target_kind: str, contact: str) -> str:
    nominal, name = _nominal(engine, integrator)
    if not math.isfinite(order):
        return ("no dt range with a clean power law in this grid (points scatter, change sign or sit on a floor; "
                "the read-out is not the cause: " + READOUT + ")")
    if not math.isfinite(nominal):
        return f"nominal order of {name} unknown"
    head = f"{name}, nominal order {nominal:g}: "
    if abs(order - nominal) <= 0.3:
        return head + "observed as nominal"
    if order > nominal and _method(engine, integrator) in _SYMPLECTIC_EULER and abs(order - 2) <= 0.4:
        return head + ("observed order 2 because semi-implicit Euler steps the positions exactly as Stoermer-Verlet "
                       "does (it is Verlet with the velocity sampled half a step off); t_m, f_m and delta_m are read "
                       "from positions and position-dependent forces, so they inherit Verlet's second order, while "
                       "velocities stay first order")
    if order < nominal and contact in ("hertz", "native-hertz") and order >= 1.8:
        why = ("the Hertz force f ~ delta^1.5 is not smooth at touch and separation (its second derivative is "
               "infinite there), which caps a fixed-step method near order 2.5 whatever its nominal order")
        why += f" ({READOUT}: finer than this order, so it is the integration's)"
        return head + "lower observed order because " + why
    if order < nominal and contact == "native":
        return head + ("lower observed order: the engine's native contact switches on and off between "
                       "steps (an event the integrator does not locate), which limits the order")
    return head + "the observed order differs from the nominal one for a reason this tool does not identify"


def fit_orders(df: pd.DataFrame, scene_kinds: dict[str, str] | None = None) -> pd.DataFrame:
    """Order of convergence in dt per scene, engine, contact, integrator, segments and metric.

    Columns: scene, engine, contact, integrator, segments, metric, order, dt_min, dt_max, n_points,
    log_c, scatter, slope_spread (largest |local slope - order|), clean, nominal_order, explanation. `order` is the
    least-squares envelope (`clean` False) when no dt range has a clean power law, NaN when not even that fits.
    `scene_kinds` maps scene name -> target kind (for the explanation).
    """
    d = with_score(df)
    rows = []
    for key, g in d[d["status"].astype(str) == "ok"].groupby(list(SERIES), sort=False):
        g = g.sort_values("dt", ascending=False)
        scene, engine, contact, integrator, segments = key
        for metric in METRICS:
            x = pd.to_numeric(g[metric], errors="coerce").to_numpy()
            fit = fit_order(g["dt"].to_numpy(), x, noise=_noise(g, metric)) if len(g) >= 4 else None
            order = fit.order if fit else math.nan
            kind = (scene_kinds or {}).get(scene, "")
            rows.append(dict(scene=scene, engine=engine, contact=contact, integrator=integrator, segments=segments,
                             metric=metric, order=order, dt_min=fit.dt_min if fit else math.nan,
                             dt_max=fit.dt_max if fit else math.nan, n_points=fit.n_points if fit else 0,
                             log_c=fit.log_c if fit else math.nan, scatter=fit.scatter if fit else math.nan,
                             slope_spread=fit.slope_spread if fit else math.nan, clean=bool(fit and fit.clean),
                             nominal_order=_nominal(engine, integrator)[0],
                             explanation=(explain_order(engine, integrator, metric, order, kind, contact,
                                                          clean=bool(fit and fit.clean),
                                                          scatter=fit.scatter if fit else math.nan,
                                                          slopes=fit.slopes if fit else ())
                                          if len(g) >= 4 else
                                          f"{len(g)} stable time step{'s' if len(g) != 1 else ''} in this grid: "
                                          f"an order needs at least 4 (a clean one {ORDER_MIN_POINTS})")))
    return pd.DataFrame(rows, columns=[*SERIES, "metric", "order", "dt_min", "dt_max", "n_points", "log_c", "scatter",
                                       "slope_spread", "clean", "nominal_order", "explanation"])


# ------------------------------------------------------------ floor and stability
def floors(df: pd.DataFrame, scene_kinds: dict[str, str] | None = None) -> pd.DataFrame:
    """Where refining dt stops helping, per series (scene, engine, contact, integrator, segments).

    `floor` is the score at the finest ok dt; `dt_floor` the largest dt from which every finer
    step scores within FLOOR_FRACTION of it (refining below it gains < 10 %); `reached` False when
    only the finest step gets there (still improving). `cause` says in words what sets the floor:
    structure discretisation (the engine's own `model_error`, other segment counts at the same dt,
    or by elimination on a chain), contact law (native linear contact vs Hertz: error against
    linear theory much smaller), the reference tolerance, or float precision.
    With fewer than 2 stable steps there is no trend (cause "one stable step ..."); an error within
    FLOOR_MODEL_MATCH of the engine's own |model_error| is named the structure floor even when the grid does
    not show it level off (checked before "no floor").
    """
    d = with_score(df)
    rows = []
    ok = d[d["score"].notna()]
    for key, g in ok.groupby(list(SERIES), sort=False):
        g = g.sort_values("dt", ascending=False)
        scene, engine, contact, integrator, segments = key
        scores = g["score"].to_numpy()
        floor = float(scores[-1])
        within = np.abs(scores - floor) <= FLOOR_FRACTION * floor
        k = len(scores) - 1
        while k > 0 and within[k - 1]:
            k -= 1
        reached = k < len(scores) - 1
        fine = g.iloc[-1]
        cause = _floor_cause(d, g, fine, floor, reached, (scene_kinds or {}).get(scene, ""))
        rows.append(dict(scene=scene, engine=engine, contact=contact, integrator=integrator, segments=segments,
                         floor=floor, dt_floor=float(g["dt"].iloc[k]), dt_finest=float(fine["dt"]), reached=reached,
                         cause_kind=_cause_kind(cause), cause=cause))
    return pd.DataFrame(rows, columns=[*SERIES, "floor", "dt_floor", "dt_finest", "reached", "cause_kind", "cause"])


def _cause_kind(cause: str) -> str:
    """The first cause named in a floor's text, as a short label."""
    for kind in ("no floor", "one stable step", "reference", "float precision", "structure discretisation",
                 "contact law"):
        if cause.startswith(kind) or cause.startswith("the " + kind):
            return kind
    return "not identified"


def _floor_cause(d: pd.DataFrame, g: pd.DataFrame, fine: pd.Series, floor: float, reached: bool, kind: str) -> str:
    if not reached:
        one = len(g) < 2
        at_model = _model_error_floor(fine, floor)
        if at_model:
            return at_model + ("; one stable step in this grid cannot show a trend in dt" if one else
                               "; the grid does not show the error level off yet")
        if one:
            return ("one stable step in this grid: it cannot show a trend in dt (step at least two stable dt, "
                    "below the stability limit, to find a floor)")
        return "no floor in this grid: the error still falls at the finest step (refine dt further)"
    causes = []
    ref_u = pd.to_numeric(fine.get("ref_uncertainty", math.nan), errors="coerce")
    if math.isfinite(ref_u) and floor <= 3 * ref_u:
        causes.append(f"the reference's own tolerance ({100 * ref_u:.2g} %): tighten --tol")
    eps = max(PRECISION.get(str(fine["engine"]), _DOUBLE_EPS), _DOUBLE_EPS)
    steps = pd.to_numeric(fine["n_steps"], errors="coerce")
    roundoff = 10 * eps * math.sqrt(steps if math.isfinite(steps) and steps > 0 else 1)
    if floor <= roundoff:
        bits = "float32" if eps > 1e-10 else "float64"
        causes.append(f"float precision ({bits} roundoff over {int(steps) if math.isfinite(steps) else '?'} steps "
                      f"~ {100 * roundoff:.2g} %)")
    model_err = pd.to_numeric(fine.get("model_error", math.nan), errors="coerce")
    if math.isfinite(model_err) and abs(model_err) >= 0.3 * floor:
        causes.append(f"structure discretisation: the engine's own model-error estimate is "
                      f"{100 * abs(model_err):.3g} % for N = {fine['segments'] or 'default'}")
    else:
        same_dt = d[(d["scene"] == fine["scene"]) & (d["engine"] == fine["engine"]) &
                    (d["integrator"] == fine["integrator"]) & (d["contact"] == fine["contact"]) &
                    (d["dt"] == fine["dt"]) & (d["segments"] != fine["segments"]) & d["score"].notna()]
        if len(same_dt) and (np.abs(same_dt["score"] - floor) > 0.2 * floor).any():
            alt = ", ".join(f"N = {s}: {100 * v:.3g} %" for s, v in zip(same_dt["segments"], same_dt["score"]))
            causes.append(f"structure discretisation: at the same dt other segment counts give {alt} "
                          f"(N = {fine['segments'] or 'default'}: {100 * floor:.3g} %)")
    lin = [abs(pd.to_numeric(fine.get(f"lin_err_{m}", math.nan), errors="coerce")) for m in METRICS]
    lin_score = max((v for v in lin if math.isfinite(v)), default=math.nan)
    if str(fine["contact"]) == "native" and math.isfinite(lin_score) and lin_score < 0.3 * floor:
        causes.append(f"contact law: the native contact is a linear spring; against linear theory for the same "
                      f"spring the error is {100 * lin_score:.3g} %, the rest is linear vs Hertz")
    if not causes and kind and kind != "rigid-plate" and str(fine["contact"]) == "hertz":
        causes.append(f"structure discretisation (by elimination: the contact law is exact and the reference is "
                      f"converged; N = {fine['segments'] or 'default'})")
    return "; ".join(causes) or "not identified"


def _model_error_floor(fine: pd.Series, floor: float) -> str:
    """The structure-floor text when the finest step's error is within FLOOR_MODEL_MATCH of the engine's own
    |model_error| estimate (refining dt cannot lower an error the structure sets), else ""."""
    model_err = abs(pd.to_numeric(fine.get("model_error", math.nan), errors="coerce"))
    if not (math.isfinite(model_err) and model_err > 0 and abs(floor - model_err) <= FLOOR_MODEL_MATCH * model_err):
        return ""
    return (f"structure discretisation: the error ({100 * floor:.3g} %) is the engine's own model-error estimate "
            f"({100 * model_err:.3g} % for N = {fine['segments'] or 'default'}): refining dt will not lower it")




def refused_before_stepping(df: pd.DataFrame) -> pd.Series:
    """True for the rows refused before stepping (dt above the predicted limit; never stepped): status "unstable"
    and the adapter base's refusal in the message."""
    msg = df["message"].fillna("").astype(str) if "message" in df else pd.Series("", index=df.index)
    return (df["status"].astype(str) == "unstable") & msg.str.contains(REFUSED_MARKER, regex=False)


def status_counts(df: pd.DataFrame) -> dict[str, int]:
    """How many cells ended how, each cell counted once: `cells`, `ok`, `refused` (dt above the predicted limit,
    refused before stepping: never stepped, so no blow-up was observed), `unstable_stepped` (stepped and went
    unstable), `failed` (any other failing status: crashed, timeout, no-contact, ...), `skipped` (skipped or
    engine not installed)."""
    st = df["status"].astype(str)
    refused = refused_before_stepping(df)
    skipped = st.isin(["skipped", "not-installed"])
    return dict(cells=len(df), ok=int((st == "ok").sum()), refused=int(refused.sum()),
                unstable_stepped=int(((st == "unstable") & ~refused).sum()),
                failed=int((~st.isin(["ok", "unstable"]) & ~skipped).sum()), skipped=int(skipped.sum()))


def stability(df: pd.DataFrame) -> pd.DataFrame:
    """Observed stability limit per series next to the predicted one.

    `dt_stable_max`: the largest dt that ran ok below the smallest unstable dt (stepped or refused);
    `dt_limit_observed`: the smallest dt whose cell is "unstable", stepped or refused, but only when some
    cell at or above it was stepped and went unstable (NaN otherwise: a series whose only unstable cells were
    refused before stepping observed no limit; the column keeps its name for older readers);
    `dt_unstable_stepped`: the smallest dt that was stepped and went unstable (NaN: none), the only
    observation of the real limit; `dt_refused_min`: the smallest dt refused before stepping because it
    is above the predicted limit (NaN: none; such a cell says nothing about the real limit);
    `dt_limit_predicted`: the smallest `dt_limit` the rows report (NaN when the engine predicts none);
    `n_failed`: cells not ok (refused ones included), `n_refused`: cells refused before stepping.
    """
    d = with_score(df)
    refused = refused_before_stepping(d)
    rows = []
    for key, g in d.groupby(list(SERIES), sort=False):
        st = g["status"].astype(str)
        ref = refused.loc[g.index]
        unstable = g.loc[st == "unstable", "dt"]
        lim = float(unstable.min()) if len(unstable) else math.nan
        stepped = g.loc[(st == "unstable") & ~ref, "dt"]
        refused_dt = g.loc[ref, "dt"]
        okdt = g.loc[st == "ok", "dt"]
        below = okdt[okdt < lim] if math.isfinite(lim) else okdt
        pred = pd.to_numeric(g["dt_limit"], errors="coerce") if "dt_limit" in g else pd.Series(dtype=float)
        rows.append(dict(zip(SERIES, key), dt_stable_max=float(below.max()) if len(below) else math.nan,
                         dt_limit_observed=lim if (stepped >= lim).any() else math.nan,
                         dt_unstable_stepped=float(stepped.min()) if len(stepped) else math.nan,
                         dt_refused_min=float(refused_dt.min()) if len(refused_dt) else math.nan,
                         dt_limit_predicted=float(pred.min()) if pred.notna().any() else math.nan,
                         n_failed=int((~st.isin(["ok", "skipped", "not-installed"])).sum()),
                         n_refused=int(ref.sum())))
    return pd.DataFrame(rows, columns=[*SERIES, "dt_stable_max", "dt_limit_observed", "dt_unstable_stepped",
                                       "dt_refused_min", "dt_limit_predicted", "n_failed", "n_refused"])


def orders_table(df: pd.DataFrame, scene_kinds: dict[str, str] | None = None) -> pd.DataFrame:
    """DIR/orders.csv: fitted orders (per metric) with the observed and predicted stability limits
    of their series. Columns: scene, engine, integrator, order, dt_min, dt_max, dt_limit_observed,
    dt_limit_predicted, then contact, segments, metric, nominal_order, n_points, scatter, clean,
    explanation, dt_unstable_stepped, dt_refused_min (see `stability`: dt_limit_observed is NaN unless a
    cell at or above it was stepped and went unstable; dt_unstable_stepped counts only the stepped ones),
    slope_spread (largest |local slope - order|: beyond ORDER_SLOPE_SCATTER_NONE an envelope is no observed order)."""
    o = fit_orders(df, scene_kinds)
    s = stability(df)
    m = o.merge(s, on=list(SERIES), how="left")
    cols = ["scene", "engine", "integrator", "order", "dt_min", "dt_max", "dt_limit_observed", "dt_limit_predicted",
            "contact", "segments", "metric", "nominal_order", "n_points", "scatter", "clean", "explanation",
            "dt_unstable_stepped", "dt_refused_min", "slope_spread"]
    return m[cols]


# ---------------------------------------------------------------------------- running
def _ref_uncertainty(ref) -> float:
    """Largest relative uncertainty the reference reports over t_m, f_m, delta_m."""
    u = getattr(ref, "uncertainty", None)
    if u is None:
        return math.nan
    vals = [abs(getattr(u, m) / getattr(ref, m)) for m in METRICS if getattr(ref, m)]
    return max(vals) if vals else math.nan


def _say_of(progress: Any):
    """The progress display's `note` (one line on stderr, above a live display), or None (silent)."""
    note = getattr(progress, "note", None)
    return note if callable(note) else None


def announcing_references(progress: Any = None):
    """An `impactval.runner.References` (references solved once per scene and tolerance, handed to
    `impactval.runner.execute`) that says each solve on `progress` (its `note`: one line on stderr, as the cells'
    lines): "reference NAME (tol 1e-09): solving ..." then "... solved in 14.6 s"."""
    from impactval.runner import References

    return References(say=_say_of(progress))


def reference_columns(df: pd.DataFrame, scenes: Iterable, tol: float, references: Any = None) -> pd.DataFrame:
    """The rows with `ref_tol` and `ref_uncertainty` (largest relative uncertainty the reference
    reports at `tol`; one solve per scene, reusing those `references` (an `impactval.runner.References`, e.g.
    `announcing_references`, which also says each new solve) already holds) for the floor analysis. A reference
    that cannot be solved leaves NaN."""
    from impactval.jobs import Job as _J

    refs = references if references is not None else announcing_references(None)
    d = df.copy()
    names = set(d["scene"]) if "scene" in d else set()
    unc = {}
    for s in scenes:
        if s.name in names:
            try:
                unc[s.name] = _ref_uncertainty(refs.ref(_J(s, "reference", None, tol)))
            except Exception:  # noqa: BLE001 - the floor analysis goes on without the reference's uncertainty
                unc[s.name] = math.nan
    d["ref_tol"] = tol
    d["ref_uncertainty"] = d["scene"].map(unc) if "scene" in d else math.nan
    return d


def run_sweep(jobs: list[Job], *, out=None, store=None, workers: int | None = None, scheduler: Any = None,
              force: bool = False, progress: Any = None, on_row=None, command: str = "sweep",
              keep_series: bool = False, references: Any = None) -> pd.DataFrame:
    """Run the grid through the result store and the executor (`impactval.runner.execute`): each
    cell isolated in a reusable engine worker, `workers` at a time (default: the cores) or on a
    Dask `scheduler`; every row stored as it finishes, so a killed sweep rerun with the same store
    runs only the missing cells (`force` recomputes). The store defaults to out/impactval.sqlite
    (in memory without `out`); with `out`, results.csv and frequencies.csv are regenerated from it.

    Each reference is solved once per scene (when its first computed cell finishes) and said on `progress`
    (scene, tolerance, time: `announcing_references`; or give `references`, an `impactval.runner.References`).

    Returns one row per cell (`impactval.runner.COLUMNS`, errors as signed fractions) plus
    `ref_tol` and `ref_uncertainty`. Raises `impactval.runner.RunInterrupted` on Ctrl-C/SIGTERM
    (its `rows` hold the finished cells, its `references` those solved) after writing the exports.
    """
    from pathlib import Path

    from impactval.runner import COLUMNS, RunInterrupted, execute
    from impactval.store import Store, export

    jobs = list(jobs)
    if store is None and out is not None:
        store = Path(out) / "impactval.sqlite"
    db = store if isinstance(store, Store) else Store(store)
    refs = references if references is not None else announcing_references(progress)
    try:
        rows = execute(jobs, store=db, workers=workers, scheduler=scheduler, force=force, progress=progress,
                       out=out, command=command, on_row=on_row, keep_series=keep_series, references=refs)
    except RunInterrupted as stop:
        if out is not None:
            export(db, out)
        stop.rows = pd.DataFrame(stop.rows, columns=list(COLUMNS))
        stop.references = refs
        raise
    if out is not None:
        export(db, out)
    if not isinstance(store, Store):
        db.close()
    tols = {j.tol for j in jobs}
    df = pd.DataFrame(rows, columns=list(COLUMNS))
    scenes = list({j.scene.name: j.scene for j in jobs}.values())
    return reference_columns(df, scenes, min(tols), refs) if len(df) else df
