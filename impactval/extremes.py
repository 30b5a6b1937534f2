"""Stability and accuracy maps at the extremes (issue 14): where each engine stops being right, and
where it breaks.

A map is one scene, one or two axes and a list of engines. Each axis changes the time step or the
scene (a frozen dataclass replaced field by field, then checked like a loaded scene):

========================  =====================================================  ==================
axis                      what it sets                                           default values
========================  =====================================================  ==================
``dt``                    the time step [s]; values may be written in the base   t_m/1e4 .. t_m,
                          scene's reference contact time: ``t_m/1e4:t_m:13``   13 log-spaced
``velocity``              the approach speed v0 [m/s] (= ``ball.velocity``)      1e-3 .. 1e2, 11
``mass_ratio``            ball mass / structure mass (the ball's mass is set)    1e-3 .. 1e2, 11
``stiffness``             the elastic constants (E, nu) of the ball and the      pmma .. tungsten-
                          target material: material names, or numbers = a        carbide, then
                          synthetic E [Pa] with nu = 0.3; densities and masses   1e12, 1e13 Pa
                          are kept (a beam's bending stiffness follows E)
``frequency_ratio``       omega_1 / omega_impact, omega_impact = pi / t_plate    0.01 .. 100, 9
                          (the rigid-plate Hertz contact time): a beam's length,
                          a plate's sides, a modal target's omegas are scaled
``ball.FIELD``,           any numeric field of the scene by its TOML path        (a SPEC is needed)
``target.FIELD``          (``ball.radius``, ``target.height``, ``target.impact_at``)
========================  =====================================================  ==================

SPEC: a comma list of values and ``a:b:n`` ranges (n values log-spaced from a to b, the one range
grammar of `impactval.ranges`; material names on the stiffness axis), or nothing for the default.
The old ``LO..HI[:N]`` is refused with a one-line error naming the a:b:n form (it was linear under a
decade: read silently as a:b:n it would have changed a map's values).

Every cell's reference is solved (a cell whose reference fails is ``no-reference``, its engines are
not run); engine jobs go through `impactval.runner.execute` (result store, parallel workers,
isolation, timeouts, resumable). An explicit time step runs through `impactval.unguarded`, so the
engine steps past its predicted limit and the map shows what really happens there. Each cell gets
a `CellStatus` and the predicted limits (see `predicted_limits`).
"""
from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass
from enum import Enum
from typing import Any, Callable, Iterable, Sequence

from impactval import ranges
from impactval.errors import ImpactvalError
from impactval.scenarios.materials import BUILTIN_MATERIALS, Material

#: default relative error under which a cell is "ok" (1 %)
DEFAULT_UNDER = 0.01
#: the values of the stiffness axis by default: the built-in materials from soft to stiff, then synthetic E [Pa]
STIFFNESS_DEFAULT = ("pmma", "aluminium", "glass", "titanium", "steel", "tungsten-carbide", 1e12, 1e13)
#: Poisson's ratio of a synthetic material on the stiffness axis
SYNTHETIC_POISSON = 0.3
#: hard bounds of EngineSettings.dt [s]
DT_MAX = 1e-2
#: every cell steps this many of its reference's contact times past the first contact's end (its `tail`, unless the
#: settings give a longer one): a chain past its limit can finish the contact looking merely inaccurate and blow up
#: right after it (an unseen clamped beam, MuJoCo and PyBullet at 1.13-2.4 x dt_limit: 'inaccurate' with no tail,
#: NaN within one contact time after it; at 1.01 x within five)
TAIL_CONTACTS = 2.0


class CellStatus(str, Enum):
    """What one engine did in one cell of a map."""

    OK = "ok"                         # every error under --under
    INACCURATE = "inaccurate"         # ran, but an error is over --under
    UNSTABLE = "unstable"             # NaN, energy growth, the ball through the target, refused above the limit
    NO_CONTACT = "no-contact"         # the engine saw no contact (tunnelling: the ball passed within a step)
    CRASHED = "crashed"
    TIMEOUT = "timeout"
    SKIPPED = "skipped"               # the engine does not support this scene/settings
    NOT_INSTALLED = "not-installed"
    NO_REFERENCE = "no-reference"     # the reference could not be solved for this cell

    def __str__(self) -> str:
        return self.value


#: status colours of the heatmaps (reports/extremes.py) and their order in legends
STATUS_ORDER = tuple(CellStatus)


# ---------------------------------------------------------------------------- axes
@dataclass(frozen=True)
class Axis:
    """One axis of a map: `name` as given (``dt``, ``velocity``, ``target.height``), its `values`
    (numbers, or material names on the stiffness axis), `unit`, `log` (log-scaled in plots)."""

    name: str
    values: tuple
    unit: str = ""
    log: bool = True

    @property
    def numeric(self) -> bool:
        return all(isinstance(v, (int, float)) for v in self.values)

    def label(self) -> str:
        return f"{self.name} [{self.unit}]" if self.unit else self.name


_NAMED_AXES = {"dt": "s", "velocity": "m/s", "mass_ratio": "", "stiffness": "Pa", "frequency_ratio": ""}
_DEFAULT_RANGES = {"velocity": (1e-3, 1e2, 11), "mass_ratio": (1e-3, 1e2, 11), "frequency_ratio": (0.01, 100.0, 9)}
_PATH = re.compile(r"^(ball|target)\.([a-z_]+)$")
_UNITS = {"radius": "m", "velocity": "m/s", "mass": "kg", "length": "m", "width": "m", "height": "m",
          "thickness": "m", "impact_at": "", "modes": ""}


def _number(name: str, token: str, t_m: float | None) -> float:
    """A value token: a number, or on the dt axis a multiple of the contact time ("t_m/1e4", "0.5*t_m")."""
    tok = token.strip().replace(" ", "")
    if name == "dt" and "t_m" in tok:
        if t_m is None:
            raise ImpactvalError(f"--axis dt: {token!r} uses t_m, which is not known here.")
        m = re.fullmatch(r"(?:([0-9.eE+-]+)\*?)?t_m(?:/([0-9.eE+-]+))?", tok)
        if not m:
            raise ImpactvalError(f"--axis dt: cannot read {token!r}; write a time step in s or a multiple of the "
                                 f"contact time such as t_m/1e4, 0.5*t_m, t_m.")
        return float(m.group(1) or 1.0) * t_m / float(m.group(2) or 1.0)
    return float(tok)


def _refuse_old_range(name: str, spec: str) -> None:
    """LO..HI[:N] (before the one grammar): refused, naming the new form (its spacing differed: linear
    under a decade)."""
    rng, _, count = spec.partition(":")
    lo, _, hi = rng.partition("..")
    raise ImpactvalError(f"--axis {name}={spec}: LO..HI[:N] is no longer read; ranges are a:b:n (n log-spaced "
                         f"values from a to b), e.g. --axis {name}={lo.strip()}:{hi.strip()}:{count.strip() if count.strip().isdigit() else 9}, "
                         f"or give a list a,b,c.")


def parse_axis(text: str, t_m: float | None = None) -> Axis:
    """An Axis from "NAME=SPEC" (or "NAME" for the default values); `t_m` [s] is the base scene's
    reference contact time (the dt axis's default range and its "t_m" tokens). SPEC is a comma list
    of values and a:b:n ranges (`impactval.ranges`); on the stiffness axis also material names."""
    name, _, spec = str(text).partition("=")
    name, spec = name.strip(), spec.strip()
    m = _PATH.match(name)
    if name not in _NAMED_AXES and not m:
        raise ImpactvalError(f"--axis {text!r}: unknown axis {name!r}; known: {', '.join(_NAMED_AXES)}, or a scene "
                             f"field by its TOML path such as ball.velocity, target.height.")
    unit = _NAMED_AXES.get(name, _UNITS.get(m.group(2), "") if m else "")
    option = f"--axis {name}"
    if ".." in spec:
        _refuse_old_range(name, spec)
    positive_only = name in _NAMED_AXES or (m and m.group(2) != "velocity" or m and m.group(1) == "ball")
    read = dict(unit=unit, example=f"{name}=1e-3:1e2:11" if name != "dt" else "dt=t_m/1e4:t_m:13",
                convert=lambda tok: _number(name, tok, t_m))
    if name == "stiffness":
        values: list[Any] = list(STIFFNESS_DEFAULT) if not spec else []
        for tok in (spec.split(",") if spec else []):
            tok = tok.strip()
            if tok in BUILTIN_MATERIALS:
                values.append(tok)
            elif tok and not ranges.is_range(tok) and not _is_float(tok):
                raise ImpactvalError(f"--axis stiffness: {tok!r} is neither a material "
                                     f"({', '.join(BUILTIN_MATERIALS)}) nor a Young's modulus in Pa.")
            elif tok:
                values += ranges.parse_list(tok, option, **{**read, "example": "stiffness=1e9:1e13:5"})
        if not values:
            raise ImpactvalError("--axis stiffness: give at least one material or Young's modulus (e.g. "
                                 "stiffness=pmma,steel,1e12 or stiffness=1e9:1e13:5).")
        return Axis(name, tuple(values), "Pa", True)
    if not spec:
        if name == "dt":
            if t_m is None:
                raise ImpactvalError("--axis dt: the default range needs the reference contact time t_m.")
            values = ranges.log_range(t_m / 1e4, t_m, 13)
        elif name in _DEFAULT_RANGES:
            values = ranges.log_range(*_DEFAULT_RANGES[name])
        else:
            raise ImpactvalError(f"--axis {name}: give values, e.g. --axis {name}=a:b:n or --axis {name}=a,b,c.")
    else:
        values = ranges.parse_list(spec, option, positive=bool(positive_only), **read)
    if name == "dt" and max(values) > DT_MAX:
        raise ImpactvalError(f"--axis dt: time steps must be <= {DT_MAX:g} s, got {max(values):g} s.")
    log = min(values) > 0 and max(values) / min(values) >= 10
    return Axis(name, tuple(sorted(set(values))), unit, log)


def _is_float(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


# ---------------------------------------------------------------------------- scene variants
def structure_mass(scene) -> float:
    """The structure's mass [kg] for the mass ratio: beam rho*A*L, plate rho*a*b*h, a ball's mass, a
    modal target's first modal mass; ImpactvalError for a rigid plate (infinite)."""
    t = scene.target
    if t.kind == "beam":
        return t.material.density * t.area * t.length
    if t.kind == "plate":
        return t.material.density * t.length * t.width * t.thickness
    if t.kind == "ball":
        return t.mass
    if t.kind == "modal":
        return t.modal_mass[0]
    raise ImpactvalError(f"--axis mass_ratio: a {t.kind} target has no finite mass; use a beam, plate, ball or "
                         f"modal scene (or vary ball.mass).")


def impact_omega(scene) -> float:
    """omega_impact = pi / t_plate [rad/s]: the Hertz contact on a rigid plate as a half sine."""
    from impactval.engines.base import plate_times

    return math.pi / plate_times(scene).t_m


def first_omega(scene) -> float:
    """The target's first natural frequency omega_1 [rad/s] (ImpactvalError without one)."""
    if scene.target.kind not in ("beam", "plate", "modal"):
        raise ImpactvalError(f"--axis frequency_ratio: a {scene.target.kind} target has no vibration modes; use a "
                             f"beam, plate or modal scene.")
    import impactval

    return float(min(impactval.structure_modes(scene, 1 if scene.target.kind != "modal" else None).omega))


def _material_like(value, old: Material) -> Material:
    if isinstance(value, str):
        m = BUILTIN_MATERIALS[value]
        return Material(f"{m.name}-elastic", m.young, m.poisson, old.density)
    return Material(f"E={value:.3g}", float(value), SYNTHETIC_POISSON, old.density)


def check_scene(scene, where: str) -> None:
    """The checks the TOML loader makes, for a derived scene (ImpactvalError naming the field)."""
    b, t = scene.ball, scene.target
    for obj, sect in ((b, "ball"), (t, "target")):
        for f in dataclasses.fields(obj):
            v = getattr(obj, f.name)
            if f.name in ("velocity",) and sect == "target":
                continue
            if isinstance(v, float) and not (math.isfinite(v) and v > 0):
                raise ImpactvalError(f"{where}: [{sect}] {f.name} must be a positive finite number, got {v!r}.")
    if t.kind == "beam" and not (0 < t.impact_at < 1 or (t.impact_at == 1 and t.support == "cantilever")):
        raise ImpactvalError(f"{where}: [target] impact_at must be a fraction of the length in (0, 1), got {t.impact_at!r}.")
    if getattr(t, "modes", None) is not None and (not isinstance(t.modes, int) or t.modes < 1):
        raise ImpactvalError(f"{where}: [target] modes must be a positive whole number, got {t.modes!r}.")


def vary(scene, axis: Axis, value) -> Any:
    """The scene with `axis` set to `value` (dt leaves the scene as it is); a new name says so."""
    from dataclasses import replace

    name = axis.name
    if name == "dt":
        return scene
    b, t = scene.ball, scene.target
    if name == "velocity":
        new = replace(scene, ball=replace(b, velocity=float(value)))
    elif name == "mass_ratio":
        new = replace(scene, ball=replace(b, mass=float(value) * structure_mass(scene)))
    elif name == "stiffness":
        tgt = replace(t, material=_material_like(value, t.material)) if hasattr(t, "material") else t
        new = replace(scene, ball=replace(b, material=_material_like(value, b.material)), target=tgt)
    elif name == "frequency_ratio":
        scale = float(value) * impact_omega(scene) / first_omega(scene)       # wanted omega_1 / current
        if t.kind == "beam":              # omega ~ 1/L^2 (both theories to first order)
            new = replace(scene, target=replace(t, length=t.length / math.sqrt(scale)))
        elif t.kind == "plate":
            s = 1.0 / math.sqrt(scale)
            new = replace(scene, target=replace(t, length=t.length * s, width=t.width * s))
        else:
            new = replace(scene, target=replace(t, omega=tuple(w * scale for w in t.omega)))
    else:
        sect, field = name.split(".", 1)
        obj = b if sect == "ball" else t
        names = {f.name for f in dataclasses.fields(obj) if f.init}
        old = getattr(obj, field, None) if field in names else None
        if field not in names or isinstance(old, (str, tuple, Material)):
            numeric = sorted(n for n in names if isinstance(getattr(obj, n), (int, float)) or n == "modes")
            raise ImpactvalError(f"--axis {name}: [{sect}] has no numeric field {field!r} for a {t.kind if sect == 'target' else 'ball'}; "
                                 f"numeric fields: {', '.join(numeric)}.")
        v = int(round(value)) if field == "modes" else float(value)
        obj = replace(obj, **{field: v})
        new = replace(scene, **{sect: obj})
    check_scene(new, f"{scene.name} with {name} = {value}")
    return new


def cell_name(scene, axes: Sequence[Axis], coords: Sequence) -> str:
    parts = [f"{a.name}={v:.4g}" if isinstance(v, float) else f"{a.name}={v}" for a, v in zip(axes, coords)
             if a.name != "dt"]
    return scene.name + ("[" + ",".join(parts) + "]" if parts else "")


# ---------------------------------------------------------------------------- predicted limits
@dataclass(frozen=True)
class Limits:
    """Predicted limits of one engine job [s]: `dt_limit` the adapter's explicit stability limit
    (2/omega_max of structure model + ball + contact spring at f_m; inf when implicit), `what` its
    one-line description, `dt_contact` the limit of the ball on the contact spring alone at f_m
    (2/sqrt(k_t/m_ball), k_t the law's tangent stiffness at the rigid-plate delta_m), `dt_tunnel`
    = delta_m / v0: a step over it covers the whole approach in one step (reference delta_m)."""

    dt_limit: float
    what: str
    dt_contact: float
    dt_tunnel: float


def predicted_limits(spec: str, scene, settings, ref_delta_m: float) -> Limits:
    """The limits for `spec` on `scene` with `settings` (never raises: NaN where unknown)."""
    from impactval.engines.base import load_adapter, plate_times

    from impactval.unguarded import guarded_spec

    dt_limit, what, dt_contact = math.nan, "", math.nan
    try:
        adapter = load_adapter(guarded_spec(spec))
        s = adapter.check_settings(settings)
        plan = adapter.plan(scene, s)
        dt_limit, what = float(plan.dt_limit), plan.what
        law = adapter.contact_law(scene, s)
        if law is not None:
            k = law.stiffness(plate_times(scene).delta_m)
            dt_contact = 2.0 / math.sqrt(k / scene.ball.mass)
    except Exception:  # noqa: BLE001 - a prediction we cannot make is NaN, the job still runs
        pass
    v0 = scene.ball.velocity + (getattr(scene.target, "velocity", 0.0) if scene.target.kind == "ball" else 0.0)
    dt_tunnel = ref_delta_m / v0 if ref_delta_m > 0 and v0 > 0 else math.nan
    return Limits(dt_limit, what, dt_contact, dt_tunnel)


# ---------------------------------------------------------------------------- classification
_FROM_ROW = {"ok": CellStatus.OK, "unstable": CellStatus.UNSTABLE, "no-contact": CellStatus.NO_CONTACT,
             "crashed": CellStatus.CRASHED, "timeout": CellStatus.TIMEOUT, "skipped": CellStatus.SKIPPED,
             "not-installed": CellStatus.NOT_INSTALLED, "interrupted": CellStatus.CRASHED}


def max_abs_error(row: dict) -> float:
    """The largest |signed relative error| of t_m, f_m, delta_m (NaN when none is finite)."""
    errs = [abs(float(row.get(k, math.nan))) for k in ("err_t_m", "err_f_m", "err_delta_m")]
    errs = [e for e in errs if math.isfinite(e)]
    return max(errs) if errs else math.nan


def classify(row: dict, under: float) -> CellStatus:
    """A row's cell status: the run status, and for a run that finished ok, ok or inaccurate by --under."""
    status = _FROM_ROW.get(str(row.get("status")), CellStatus.CRASHED)
    if status is CellStatus.OK:
        err = max_abs_error(row)
        return CellStatus.OK if math.isfinite(err) and err <= under else CellStatus.INACCURATE
    return status


# ---------------------------------------------------------------------------- the map
def _settings_with(base, dt):
    from dataclasses import replace

    return replace(base, dt=dt)


def run_map(scene, engines: Sequence[str], axes: Sequence[Axis], *, settings=None, under: float = DEFAULT_UNDER,
            tol: float = 1e-6, store=None, workers: int | None = None, force: bool = False, progress=None,
            unguarded: bool = True, out=None, command: str = "", reference=None) -> "pd.DataFrame":
    """Run every engine in every cell of the grid; one row per (cell, engine).

    Parameters
    ----------
    scene : Scene (the base of every cell)
    engines : engine specs ("mujoco", "pybullet", "pkg.module:Class")
    axes : one or two Axis (see `parse_axis`)
    settings : EngineSettings, optional (the dt axis replaces its dt)
    under : relative error under which a finished run is "ok" (0.01 = 1 %)
    tol : relative tolerance of the references
    store, workers, force, progress, out, command : see `impactval.runner.execute`
    unguarded : run an explicit dt past the predicted limit (impactval.unguarded) instead of refusing it
    reference : the base scene's reference at `tol`, optional (when the caller has solved it already)

    Each cell's reference is solved once, here, and handed to the runner with the jobs (never solved
    twice; a base-scene cell reuses `reference`).

    Returns a DataFrame: `engine` (as given), one column per axis, `cell_status`, `status` (the run's),
    errors (signed fractions), `max_abs_err`, `dt` [s], the predicted `dt_limit`, `dt_contact`,
    `dt_tunnel` [s], `limit_ratio` = dt / dt_limit, `tunnel_ratio` = dt / dt_tunnel, `message`,
    `job_key`, and the reference's `ref_t_m`, `ref_f_m`, `ref_delta_m`, `ref_uncertainty`.
    `df.attrs`: axes, under, scene, engines, limits_what.
    """
    import itertools

    import pandas as pd

    import impactval
    from impactval.engines.base import EngineSettings
    from impactval.jobs import Job
    from impactval.runner import execute, resolve_engine, settings_for
    from impactval.unguarded import unguarded_spec

    if not 1 <= len(axes) <= 2:
        raise ImpactvalError(f"give one or two --axis, got {len(axes)}.")
    if len({a.name for a in axes}) != len(axes):
        raise ImpactvalError("the two --axis must differ.")
    if not (isinstance(under, (int, float)) and 0 < under < 10):
        raise ImpactvalError(f"--under must be a positive fraction (0.01 = 1 %), got {under!r}.")
    specs = [resolve_engine(e) for e in engines]
    if not specs:
        raise ImpactvalError("no engine given (--engines mujoco,pybullet).")
    base = settings or EngineSettings()
    cells = []                    # (coords, scene, dt)
    for coords in itertools.product(*(a.values for a in axes)):
        sc, dt = scene, base.dt
        for a, v in zip(axes, coords):
            if a.name == "dt":
                dt = float(v)
            else:
                sc = vary(sc, a, v)
        if len(axes) and any(a.name != "dt" for a in axes):
            sc = dataclasses.replace(sc, name=cell_name(scene, axes, coords))
        cells.append((coords, sc, dt))

    refs: dict[str, Any] = {scene.name: reference} if reference is not None and reference.success else {}
    for _, sc, _ in cells:
        if sc.name not in refs:
            try:
                r = impactval.solve(sc, tol=tol)
                refs[sc.name] = r if r.success else f"reference {r.status}: {r.message}"
            except ImpactvalError as err:
                refs[sc.name] = f"reference refused: {err}"
            except Exception as err:  # noqa: BLE001 - a reference failure is that cell's status
                refs[sc.name] = f"reference failed: {type(err).__name__}: {err}"

    jobs, meta = [], []
    for coords, sc, dt in cells:
        ref = refs[sc.name]
        for label, spec in zip(engines, specs):
            st = settings_for(_settings_with(base, dt), spec)
            if not isinstance(ref, str) and math.isfinite(ref.t_m):
                st = dataclasses.replace(st, tail=max(float(st.tail), TAIL_CONTACTS * ref.t_m))
            run_spec = unguarded_spec(spec) if unguarded and dt != "auto" else spec
            lim = predicted_limits(spec, sc, st, ref.delta_m if not isinstance(ref, str) else math.nan)
            meta.append((coords, sc, label, spec, st, lim, ref))
            if not isinstance(ref, str):
                jobs.append(Job(sc, run_spec, st, tol))
    solved = {sc.name: (sc, tol, refs[sc.name]) for _, sc, _ in cells if not isinstance(refs[sc.name], str)}
    rows = execute(jobs, store=store, workers=workers, force=force, progress=progress, out=out,
                   command=command or f"extremes {scene.name}", references=solved.values(),
                   theory_gap=False) if jobs else []      # a map shows stability, not the beam-theory split
    rows_iter = iter(rows)
    out_rows = []
    for coords, sc, label, spec, st, lim, ref in meta:
        rec: dict[str, Any] = {"engine": label, **{a.name: v for a, v in zip(axes, coords)}, "scene": sc.name}
        if isinstance(ref, str):
            rec.update(cell_status=CellStatus.NO_REFERENCE.value, status="", message=ref,
                       dt=float(st.dt) if st.dt != "auto" else math.nan)
        else:
            row = next(rows_iter)
            rec.update(cell_status=classify(row, under).value, status=row["status"], message=row["message"],
                       dt=float(row["dt"]), err_t_m=row["err_t_m"], err_f_m=row["err_f_m"],
                       err_delta_m=row["err_delta_m"], max_abs_err=max_abs_error(row), n_contacts=row["n_contacts"],
                       segments=row["segments"], integrator=row["integrator"], job_key=row["job_key"],
                       ref_t_m=ref.t_m, ref_f_m=ref.f_m, ref_delta_m=ref.delta_m,
                       ref_uncertainty=ref_rel_uncertainty(ref), ref_validity="; ".join(ref.validity or ()),
                       v0=sc.ball.velocity)
            if not math.isfinite(lim.dt_limit) or lim.dt_limit <= 0:
                stored = _num(row.get("dt_limit"))
                if math.isfinite(stored):
                    lim = dataclasses.replace(lim, dt_limit=stored)
        if math.isfinite(lim.dt_limit) and "predicted limit none (implicit)" in str(rec.get("message", "")):
            # an unguarded job's plan reports no limit; the message gets the real prediction back
            rec["message"] = rec["message"].replace("predicted limit none (implicit)",
                                                    f"predicted limit {lim.dt_limit:.3g} s")
        rec.update(dt_limit=lim.dt_limit, dt_limit_what=lim.what, dt_contact=lim.dt_contact, dt_tunnel=lim.dt_tunnel)
        dt = rec.get("dt", math.nan)
        rec["limit_ratio"] = dt / lim.dt_limit if math.isfinite(lim.dt_limit) and lim.dt_limit > 0 else math.nan
        rec["tunnel_ratio"] = dt / lim.dt_tunnel if math.isfinite(lim.dt_tunnel) and lim.dt_tunnel > 0 else math.nan
        out_rows.append(rec)
    df = pd.DataFrame(out_rows)
    df.attrs.update(axes=list(axes), under=under, scene=scene.name, engines=list(engines), tol=tol)
    return df


def ref_rel_uncertainty(ref) -> float:
    """The reference's largest relative uncertainty of t_m, f_m, delta_m (NaN when it has none)."""
    u = ref.uncertainty
    if u is None:
        return math.nan
    vals = [abs(getattr(u, m)) / abs(getattr(ref, m)) for m in ("t_m", "f_m", "delta_m") if getattr(ref, m)]
    return max(vals) if vals else math.nan


def _num(x) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


# ---------------------------------------------------------------------------- reading a map
@dataclass(frozen=True)
class Onset:
    """Along a dt axis, for one engine (and one value of the other axis): the largest ok dt, the
    first dt from which every larger dt failed (unstable, no-contact, crashed, timeout), the
    predicted dt_limit and the ratio observed / predicted (NaN when there is none)."""

    engine: str
    other: Any
    largest_ok: float
    first_unstable: float
    predicted: float
    what: str
    smallest: float = math.nan

    @property
    def whole_axis(self) -> bool:
        """Broken from the smallest value on: the onset is at or below the grid, not measured."""
        return math.isfinite(self.first_unstable) and self.first_unstable == self.smallest

    @property
    def ratio(self) -> float:
        if math.isfinite(self.first_unstable) and math.isfinite(self.predicted) and self.predicted > 0:
            return self.first_unstable / self.predicted
        return math.nan


_BROKEN = {CellStatus.UNSTABLE.value, CellStatus.NO_CONTACT.value, CellStatus.CRASHED.value, CellStatus.TIMEOUT.value}


def onsets(df, axis: str = "dt") -> list[Onset]:
    """The first-unstable value along `axis` per engine (and per value of the other axis): the
    smallest value from which the rest of the axis is broken (a lone failure below a stable
    stretch is not an onset)."""
    axes = [a.name for a in df.attrs.get("axes", [])] or [axis]
    others = [a for a in axes if a != axis]
    out = []
    groups = df.groupby(["engine", *others], sort=False) if others else df.groupby(["engine"], sort=False)
    for key, g in groups:
        g = g.sort_values(axis)
        key = key if isinstance(key, tuple) else (key,)
        broken = g["cell_status"].isin(_BROKEN).to_numpy()
        first = math.nan
        for i in range(len(g)):
            if broken[i:].all():
                first = float(g[axis].iloc[i])
                break
        ok = g[g["cell_status"] == CellStatus.OK.value][axis]
        lim = g["dt_limit"].dropna()
        lim = lim[lim > 0]
        out.append(Onset(str(key[0]), key[1] if len(key) > 1 else None, float(ok.max()) if len(ok) else math.nan,
                         first, float(lim.median()) if len(lim) else math.nan,
                         str(g["dt_limit_what"].iloc[0]) if "dt_limit_what" in g else "", float(g[axis].min())))
    return out


def ok_ranges(values: Sequence[float], statuses: Sequence[str]) -> list[tuple[float, float]]:
    """Contiguous runs of "ok" cells along an axis, as (first, last) values."""
    runs, start, prev = [], None, None
    for v, s in zip(values, statuses):
        if s == CellStatus.OK.value:
            start = v if start is None else start
            prev = v
        elif start is not None:
            runs.append((start, prev))
            start = None
    if start is not None:
        runs.append((start, prev))
    return runs


# ---------------------------------------------------------------------------- predictability
@dataclass(frozen=True)
class Perturbation:
    """A small change of an input: `what` ("v0" or "impact point"), the scene, the change's size."""

    what: str
    scene: Any
    size: float


def perturbations(scene, rel_v0: float = 1e-6, point_fraction: float = 0.1, segments: int | None = None) -> list[Perturbation]:
    """Chung and Pollard (2016): v0 * (1 + rel_v0), and for a beam the impact point moved by
    `point_fraction` of a chain segment (of L/segments; L/50 when unknown)."""
    from dataclasses import replace

    out = [Perturbation("v0", replace(scene, name=scene.name + "+dv0",
                                      ball=replace(scene.ball, velocity=scene.ball.velocity * (1 + rel_v0))), rel_v0)]
    t = scene.target
    if t.kind == "beam":
        n = segments or 50
        shift = point_fraction / n                      # as a fraction of the length
        at = t.impact_at + shift if t.impact_at + shift < 1 else t.impact_at - shift
        out.append(Perturbation("impact point", replace(scene, name=scene.name + "+dx",
                                                        target=replace(t, impact_at=at)), shift))
    return out


def predictability(scene, engines: Sequence[str], dts: Iterable[float], *, settings=None, tol: float = 1e-6,
                   jump: float = 1e-3, store=None, workers: int | None = None, rel_v0: float = 1e-6,
                   point_fraction: float = 0.1, segments: int | None = None, reference=None) -> "pd.DataFrame":
    """Run each engine at each dt on the scene and its perturbations (`perturbations`); one row
    per (engine, dt, perturbation) with the engine's relative change of t_m, f_m, delta_m, the
    reference's, the contact counts, and `jumped`: a contact event gained or lost, or a metric
    whose change differs from the reference's by more than `jump` (relative), or a status change.
    `reference`: the scene's reference at `tol` when already solved; each reference is solved once
    and handed to the runner."""
    import pandas as pd

    import impactval
    from impactval.engines.base import EngineSettings
    from impactval.jobs import Job
    from impactval.runner import execute, resolve_engine, settings_for
    from impactval.unguarded import unguarded_spec

    base = settings or EngineSettings()
    specs = [resolve_engine(e) for e in engines]
    perts = perturbations(scene, rel_v0, point_fraction, segments)
    scenes = [scene, *(p.scene for p in perts)]
    refs = {s.name: reference if s is scene and reference is not None else impactval.solve(s, tol=tol) for s in scenes}
    jobs, keys = [], []
    for label, spec in zip(engines, specs):
        for dt in dts:
            st = settings_for(_settings_with(base, float(dt)), spec)
            for sc in [scene, *(p.scene for p in perts)]:
                jobs.append(Job(sc, unguarded_spec(spec), st, tol))
                keys.append((label, float(dt), sc.name))
    rows = dict(zip(keys, execute(jobs, store=store, workers=workers, command=f"predictability {scene.name}",
                                  references=[(s, tol, refs[s.name]) for s in scenes], theory_gap=False)))
    out = []
    for label in engines:
        for dt in dts:
            b = rows[(label, float(dt), scene.name)]
            for p in perts:
                r = rows[(label, float(dt), p.scene.name)]
                rec = dict(engine=label, dt=float(dt), perturbation=p.what, size=p.size, status=b["status"],
                           status_perturbed=r["status"], n_contacts=b["n_contacts"], n_contacts_perturbed=r["n_contacts"])
                reasons = []
                if b["status"] != r["status"]:
                    reasons.append(f"status {b['status']} -> {r['status']}")
                if b["status"] == "ok" and r["status"] == "ok" and b["n_contacts"] != r["n_contacts"]:
                    reasons.append(f"contacts {b['n_contacts']} -> {r['n_contacts']}")
                for m in ("t_m", "f_m", "delta_m"):
                    e0, e1 = _num(b[m]), _num(r[m])
                    ref0, ref1 = getattr(refs[scene.name], m), getattr(refs[p.scene.name], m)
                    d_eng = (e1 - e0) / abs(e0) if e0 else math.nan
                    d_ref = (ref1 - ref0) / abs(ref0)
                    rec[f"change_{m}"], rec[f"ref_change_{m}"] = d_eng, d_ref
                    if math.isfinite(d_eng) and abs(d_eng - d_ref) > jump:
                        reasons.append(f"{m} changed {100 * d_eng:+.3g} % (reference {100 * d_ref:+.3g} %)")
                rec["jumped"] = bool(reasons)
                rec["why"] = "; ".join(reasons)
                out.append(rec)
    return pd.DataFrame(out)


__all__ = ["Axis", "CellStatus", "Limits", "Onset", "parse_axis", "vary", "run_map", "classify", "onsets",
           "ok_ranges", "predicted_limits", "perturbations", "predictability", "DEFAULT_UNDER"]
