"""The engine adapter contract (style.md, patterns 2, 4, 5): a small base class owns the shared work.

Two levels (scipy's OdeSolver, xarray's backends):

**Stepping adapter** (subclass `SteppingAdapter`; most engines). Set the class attributes `name`
(registry key = pip extra), `module` (the Python module to probe), `contacts` (supported contact
modes), `integrators` (first = default), `Options` (a frozen dataclass of typed options, see
`engines.options`), `expected_failures` ({check name: reason}, strict xfails of the conformance
suite). Import the engine only inside methods. Then implement

- `build(scene, settings) -> model`: a live model at first touch (t = 0, ball at -v0 toward the
  target); `settings.dt` is a number here (the base resolved "auto"), `settings.options` the typed
  Options instance of this adapter;
- `step(model)`: advance one `settings.dt` with only what the physics needs (the base times this call
  alone: it is the row's stepping time, the cost axis of sweeps);
- optionally `observe(model)`: after each step, outside the timed region, compute what the sampling
  calls below report (the energy, read-backs, checks; raise `EngineDiverged` for a blow-up);
- `contact(model) -> (delta [m], force [N])`: approach of the contact points (> 0 = overlap) and
  normal force, for the state after the last step (or, with `sample_lag = 1`, at its start: an engine
  that reports a step's force with the penetration it was computed from);
- `energy(model) -> float` [J]: total mechanical energy (ball + contact potential + structure);
- optionally `kinematics(model) -> (x_ball [m], x_structure [m], v_ball [m/s])` (displacements
  into the target, ball speed toward it), `frequencies(model) -> array` [rad/s] (the structure
  model's natural frequencies), `contact_law(scene, settings)`, `plan(scene, settings)` (the predicted
  stability limit `dt_limit` [s] of the explicit model and its `model_error`, see `Plan`), and
  `retry(scene, settings, result) -> Softer | None` (a softer model after an instability, below).

**Retry with a softer model** (both levels): when a run ends `unstable` while stepping (energy growth, NaN,
the ball through the target, `EngineDiverged`; never a dt refused above the predicted limit: that is the
user's step), the base asks `retry` for a `Softer` (settings of a softer model + one line naming it) and
reruns, at most `max_retries` times. The row is the first attempt that is not unstable (else the last),
with diagnostics `retries`, `retry_models` (each `Softer.what`), `retry_first_failure` (the first
message) and a `validity` note, so the user reads that the model was softened before any number. The
conformance suite checks that a retry's model is softer (its predicted limit is not lower).

The base owns everything else: option parsing, the time step ("auto" = the largest 1-2-5 value
below both DT_MARGIN * dt_limit and t_contact / STEPS_PER_CONTACT, `contact_time`: t_plate, or a structure's
own first contact when under half of it), refusing a dt above the predicted
limit (status unstable, message with the limit and a suggested dt), the loop, ONE simulation window
(until the first contact ends, plus `settings.tail`; never beyond WINDOW_CAP rigid-plate contact
times + tail), timing (build and stepping apart), sampling once per step, divergence (NaN/inf,
energy growth beyond `energy_growth_limit`, the ball through the target: delta > ball radius, or the
smaller radius for a second ball), the
metrics (`contacts_from_series`), and the status with one message table (`MESSAGES`).

**Whole-run adapter** (subclass `EngineAdapter`; engines that integrate a run themselves: Exudyn's
solvers, batched GPU engines): implement `simulate(scene, settings) -> Simulation` with the series
sampled per step; the base does the rest the same way. Raise `EngineDiverged` for a blow-up.

`execute_job(spec, scene, settings) -> ImpactResult` runs one job in the current process and never
raises; `run_isolated` wraps it in a child process with a timeout (until the runner's executor
takes over). Third-party adapters: an entry point in the group `impactval.engines` or
"package.module:Class". Units are SI.
"""
from __future__ import annotations

import functools
import importlib
import importlib.util
import math
import multiprocessing as mp
import signal
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from impactval.engines.options import NoOptions, parse_options
from impactval.errors import EngineError
from impactval.reference.result import Contact, ImpactResult, Status

CONTACT_MODES = ("hertz", "native", "native-hertz")
#: dt = "auto": the step is at most this fraction of the predicted explicit stability limit
DT_MARGIN = 0.5
#: dt = "auto": at least this many steps per contact (`contact_time`: the rigid-plate Hertz contact time, or a
#: structure's own first contact when much shorter)
STEPS_PER_CONTACT = 200
#: a structure's first contact shorter than this fraction of the rigid-plate time sets the automatic step instead of it
SHORT_CONTACT_FRACTION = 0.5
#: simulation window cap, in rigid-plate Hertz contact times (plus the tail)
WINDOW_CAP = 200.0
#: stop stepping when the energy exceeds this multiple of its initial value (classified later)
STOP_ENERGY_FACTOR = 10.0
#: entry-point group of third-party adapters
ENTRY_POINT_GROUP = "impactval.engines"

#: one message per failure reason; formatted with the keywords named in braces
MESSAGES: dict[str, tuple[Status, str]] = {
    "not-installed": (Status.NOT_INSTALLED, "{module} is not installed: {hint}"),
    "skipped": (Status.SKIPPED, "{why}"),
    "crashed": (Status.CRASHED, "{why}"),
    "timeout": (Status.TIMEOUT, "no result after {timeout:g} s (dt = {dt})"),
    "process-died": (Status.CRASHED, "engine process died ({how}) after {elapsed:.1f} s"),
    "dt-limit": (Status.UNSTABLE, "dt = {dt:.3g} s is above the predicted explicit stability limit "
                 "dt_limit = 2/omega_max = {limit:.3g} s ({what}); refused before stepping: use dt <= {suggest:.3g} s "
                 "or dt = auto"),
    "nan": (Status.UNSTABLE, "NaN/inf after {steps} steps (t = {t:.3g} s, dt = {dt:.3g} s; predicted limit {limit})"),
    "energy": (Status.UNSTABLE, "energy grew {growth} (limit {allowed:.0%}) at dt = {dt:.3g} s (predicted limit {limit})"),
    "through": (Status.UNSTABLE, "the ball went through the target (approach {delta:.3g} m > ball radius) after "
                "{steps} steps at dt = {dt:.3g} s (predicted limit {limit})"),
    "diverged": (Status.UNSTABLE, "{why}"),
    "no-contact": (Status.NO_CONTACT, "the ball never touched the target in the simulated window"),
    "open-contact": (Status.UNSTABLE, "the first contact did not end within the window cap ({cap:.3g} s = "
                     "{factor:g} rigid-plate contact times + tail)"),
}


#: the words of MESSAGES["dt-limit"] that tell a step refused before stepping (status "unstable", 0 steps) from a
#: stepped blow-up: the sweep's counts and the progress lines read them
REFUSED_MARKER = "refused before stepping"
assert REFUSED_MARKER in MESSAGES["dt-limit"][1]


def message(reason: str, **kw: Any) -> tuple[Status, str]:
    """(status, text) of a failure reason from the one table."""
    status, text = MESSAGES[reason]
    return status, text.format(**kw)


def _limit_text(limit: float) -> str:
    return f"{limit:.3g} s" if math.isfinite(limit) else "none (implicit)"


def _dt_text(dt: Any) -> str:
    return f"{dt:g} s" if isinstance(dt, (int, float)) else str(dt)


@dataclass(frozen=True)
class EngineSettings:
    """What to run: `dt` time step [s] or "auto" (default: the engine picks, see the module doc);
    `integrator` (engine's name; None = its default); `contact`: "hertz" (exact law injected every
    step), "native" (engine's own contact as a linear spring of the paper's k0; for Exudyn the native
    law is Hertz), "native-hertz" (engine knobs shaped toward Hertz); `segments` (links of a chain
    beam) and `modes` (modal bodies), None = sized from the scene (engines.chain.segments_for,
    reference.modechoice); `tail` [s] of simulated time after the first contact ends (re-contacts);
    `timeout_s` [s] for the job; `options`: engine-specific (key, value) pairs, parsed by the
    adapter's typed `Options`.
    """

    dt: float | str = "auto"
    integrator: str | None = None
    contact: str = "hertz"
    segments: int | None = None
    modes: int | None = None
    tail: float = 0.0
    timeout_s: float = 600.0
    options: Any = ()

    def __post_init__(self) -> None:
        if self.dt != "auto" and (isinstance(self.dt, bool) or not isinstance(self.dt, (int, float))
                                  or not math.isfinite(self.dt) or not 0 < self.dt <= 1e-2):
            raise EngineError(f"dt must be a time step in s with 0 < dt <= 1e-2, or 'auto', got {self.dt!r}.")
        if self.contact not in CONTACT_MODES:
            raise EngineError(f"contact must be one of {', '.join(CONTACT_MODES)}, got {self.contact!r}.")
        for key in ("segments", "modes"):
            v = getattr(self, key)
            if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 1):
                raise EngineError(f"{key} must be a positive whole number (or None for the default), got {v!r}.")
        if not isinstance(self.tail, (int, float)) or not math.isfinite(self.tail) or self.tail < 0:
            raise EngineError(f"tail must be a non-negative time in s, got {self.tail!r}.")
        if not isinstance(self.timeout_s, (int, float)) or not self.timeout_s > 0:
            raise EngineError(f"timeout_s must be a positive time in s, got {self.timeout_s!r}.")

    @property
    def auto_dt(self) -> bool:
        return self.dt == "auto"

    def option(self, key: str, default: Any = None) -> Any:
        """An option's value: from the typed Options instance (after parsing) or the raw pairs."""
        if isinstance(self.options, tuple):
            return dict(self.options).get(key, default)
        return getattr(self.options, key, default)

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self) if isinstance(self.options, tuple) else {**asdict(replace(self, options=())),
                                                                   "options": asdict(self.options)}
        if isinstance(self.options, tuple):
            d["options"] = dict(self.options)
        return d


@dataclass
class Plan:
    """What an adapter predicts before stepping: `dt_limit` [s] (2/omega_max of the discretised
    structure + ball + contact spring at its tangent stiffness at f_m; inf for an unconditionally
    stable scheme), `what` (one line: which model the limit is for), `model_error` (the structure
    model's own relative discretisation error, NaN if unknown), `diagnostics`, `validity` (warnings known
    before stepping, e.g. a predicted model error beyond a bar: they head the row's `validity`)."""

    dt_limit: float = math.inf
    what: str = ""
    model_error: float = math.nan
    diagnostics: dict[str, Any] = field(default_factory=dict)
    validity: tuple[str, ...] = ()


@dataclass(frozen=True)
class Softer:
    """What `EngineAdapter.retry` returns: `settings` of a softer model (parsed or raw; the base checks them
    again) and `what`, one line naming the change (e.g. "attach_ke 6e+09 -> 3e+09 N/m, N 68 -> 39")."""

    settings: EngineSettings
    what: str


@dataclass
class Simulation:
    """What `simulate` returns: series sampled once per step (t [s], delta [m], f [N], ball and
    contact-point displacement [m], ball velocity [m/s] toward the target, energy [J] or empty),
    wall times [s], step count, the model's name, diagnostics and validity warnings (into the row's); `stop` names a divergence reason
    found while stepping ("nan", "energy", "through") or is ""."""

    t: np.ndarray
    delta: np.ndarray
    f: np.ndarray
    x_ball: np.ndarray
    x_structure: np.ndarray
    v_ball: np.ndarray
    energy: np.ndarray
    build_s: float
    step_s: float
    n_steps: int
    model: str = ""
    diagnostics: dict[str, Any] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    stop: str = ""
    frequencies: np.ndarray = field(default_factory=lambda: np.zeros(0))
    contact_law: Any = None
    validity: tuple[str, ...] = ()


class EngineDiverged(Exception):
    """The simulation produced NaN or blew up; becomes status "unstable" (with `diagnostics`)."""

    def __init__(self, message: str, diagnostics: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.diagnostics = diagnostics or {}


def nice_step(dt: float) -> float:
    """The largest 1-2-5 x 10^k value <= dt (readable steps in rows)."""
    e = math.floor(math.log10(dt))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0**e <= dt * (1 + 1e-12):
            return m * 10.0**e
    return 10.0 ** (e - 1) * 5.0


#: an engine model's first FREQ_GAP_MODES frequencies may differ from the scene theory's by this fraction before a row
#: note (Exudyn's solid beam) and the report's error split name the gap as a cause: a discretised chain follows
#: Timoshenko's first modes within ~0.4 % (fz3002, PyBullet), and a 1 % frequency shift moves f_m by ~0.2-0.25 %
#: (fz3002: 3.6-5.0 % stiffer, +0.76 % in f_m), a quarter of the default mode_tol: above it the gap is a cause worth
#: naming, below it is noise
FREQ_GAP, FREQ_GAP_MODES = 1e-2, 4


def modes_not_applied(scene, settings: EngineSettings, engine: str, structure: str = "chain") -> tuple[int | None, str]:
    """For an engine that models every mode of a modal target (one oscillator per mode) and a beam as a `structure`
    sized by its segments (MuJoCo, PyBullet): (the mode count it models: the modal target's all, else None; a row note
    when `settings.modes` (--modes) asked for something it does not apply, else ""). The row's N then says what was
    built (a `--modes 2` on a 3-mode target was shown as N = 2 for the 3-mode model)."""
    target = scene.target
    kind = getattr(target, "kind", "")
    n_model = len(target.omega) if kind == "modal" else None
    asked = settings.modes
    if asked is None:
        return n_model, ""
    if kind == "modal":
        if asked == n_model:
            return n_model, ""
        return n_model, (f"--modes {asked} does not apply to {engine}'s modal target: it builds one oscillator per mode "
                         f"of the scene (all {n_model}), the model the reference solves")
    what = {"beam": f"beam, a {structure} sized by --segments", "plate": "plate", "rigid-plate": "rigid plate",
            "ball": "second ball"}.get(kind, f"{kind} target")
    return n_model, f"--modes {asked} does not apply to {engine}'s {what}: ignored"


def add_validity(diagnostics: dict, note: str) -> None:
    """Append `note` to `diagnostics["validity"]` (a string or a list; the runner shows them with the row)."""
    if not note:
        return
    v = diagnostics.get("validity")
    diagnostics["validity"] = ([v] if isinstance(v, str) and v else list(v or ())) + [note]


def plate_times(scene):
    """The rigid-plate Hertz impact of the scene's contact (closed form): for a second ball (target kind
    "ball") the equivalent ball on a plate (reduced mass m1 m2/(m1 + m2), approach speed v1 + v2, same
    alpha; reference/spheres.py), so t_m, delta_m and k0 are those of the two-ball contact."""
    from impactval.reference.hertz import plate_impact

    sc = contact_scene(scene)
    return plate_impact(sc.ball.mass, sc.alpha, sc.ball.velocity)


def contact_time(scene) -> float:
    """Duration [s] the automatic step is sized on: the rigid-plate contact time, or for a structure (beam, modal,
    plate target) the continuum reference's first contact when it is shorter than SHORT_CONTACT_FRACTION of it (a
    heavy ball on a flexible beam: a 35 mm WC ball on an aluminium beam touched for 113 us against t_plate 400 us,
    and Exudyn's implicit step t_plate / 200 = 2 us gave 57 steps and a 0.18 % time-step error against a model
    error of 0.0004 %). The reference solve is the one the adapters' model errors use (cached per process); if it is
    refused, t_plate."""
    t_plate = plate_times(scene).t_m
    if getattr(scene.target, "kind", "") not in ("beam", "modal", "plate"):
        return t_plate
    from impactval.engines.chain import continuum_metrics
    from impactval.errors import ImpactvalError

    try:
        t_first = continuum_metrics(scene)[0]
    except ImpactvalError:
        return t_plate
    return t_first if 0.0 < t_first < SHORT_CONTACT_FRACTION * t_plate else t_plate


def contact_scene(scene):
    """The scene as the reference's contact model sees it (`reference.structure.contact_scene`): a second
    ball becomes the equivalent ball (mass m*, speed v1 + v2) on a rigid plate; other scenes unchanged."""
    if scene.target.kind != "ball":
        return scene
    from impactval.reference.structure import contact_scene as equivalent

    return equivalent(scene)


def contact_mass(scene) -> float:
    """The mass [kg] the contact spring acts on for a rigid target: the ball's, or the reduced mass
    m1 m2/(m1 + m2) of two free balls (their relative motion)."""
    return contact_scene(scene).ball.mass


def through_depth(scene) -> float:
    """Approach [m] beyond which the ball has gone through the target: the ball's radius, or the smaller of
    the two radii for a second ball."""
    r = scene.ball.radius
    return min(r, scene.target.radius) if scene.target.kind == "ball" else r


class EngineAdapter:
    """Base class of every adapter; the module docstring is the contract."""

    name: str = ""
    module: str = ""
    contacts: tuple[str, ...] = ("hertz",)
    integrators: tuple[str, ...] = ()
    #: integrator -> method (a key of impactval.sweep.METHODS: nominal order and name), for the sweep's order check
    integrator_methods: dict[str, str] = {}
    Options: type = NoOptions
    #: energy may grow by at most this fraction before a run is classed "unstable"
    energy_growth_limit: float = 0.05
    #: known gaps, by check name -> reason (become strict xfails in the conformance suite)
    expected_failures: dict[str, str] = {}
    #: most reruns with a softer model per job (`retry`)
    max_retries: int = 3

    # ------------------------------------------------------------------ to override
    def simulate(self, scene, settings: EngineSettings) -> Simulation:  # pragma: no cover - abstract
        raise NotImplementedError

    def plan(self, scene, settings: EngineSettings) -> Plan:
        """Predicted stability limit and model error (default: ball on the contact spring, rigid target)."""
        law = self.contact_law(scene, settings)
        if law is None or not self.explicit(settings):
            return Plan()
        p = plate_times(scene)
        k = law.stiffness(p.delta_m)
        return Plan(2.0 / math.sqrt(k / contact_mass(scene)), "ball on the contact spring's tangent stiffness at f_m")

    def retry(self, scene, settings: EngineSettings, result: ImpactResult) -> Softer | None:
        """After `settings` (parsed) gave `result`, `unstable` while stepping: a softer model to rerun with, or
        None to keep the row (default: never retry). A softer model's predicted limit (`plan().dt_limit`) must
        not be lower (the conformance suite checks it); keep a user's explicit choice (return None)."""
        return None

    def explicit(self, settings: EngineSettings) -> bool:
        """True when the integrator has a stability limit (default: yes)."""
        return True

    def contact_law(self, scene, settings: EngineSettings):
        """The normal contact law this run uses (`reference.hertz.ContactLaw`), None if not a pure power law."""
        from impactval.reference.hertz import ContactLaw

        if settings.contact == "hertz":
            return ContactLaw.hertz(scene.alpha)
        if settings.contact == "native":
            return ContactLaw.linear(plate_times(scene).k0)
        return ContactLaw.hertz(scene.alpha)

    def version(self) -> str:
        mod = importlib.import_module(self.module)
        return str(getattr(mod, "__version__", "unknown"))

    def structure_frequencies(self, scene, settings: EngineSettings) -> np.ndarray:
        """Natural frequencies [rad/s] of the engine's structure model (empty for a rigid target)."""
        return np.zeros(0)

    # ------------------------------------------------------------------ shared
    def available(self) -> bool:
        return importlib.util.find_spec(self.module) is not None

    def install_hint(self) -> str:
        return f"pip install 'impactval[{self.name}]'"

    def parse(self, settings: EngineSettings) -> EngineSettings:
        """The settings with `options` parsed into this adapter's typed Options (EngineError if bad)."""
        if not isinstance(settings.options, tuple):
            return settings
        return replace(settings, options=parse_options(self.Options, settings.options, self.name))

    #: smallest `segments` a chain beam of this adapter accepts (1: no chain, any count)
    min_segments: int = 1

    def check_settings(self, settings: EngineSettings) -> EngineSettings:
        """Validate settings for this adapter (EngineError naming the field and what is allowed)."""
        if settings.contact not in self.contacts:
            raise EngineError(f"{self.name} does not support contact {settings.contact!r}; "
                              f"supported: {', '.join(self.contacts)}.")
        if settings.integrator is not None and self.integrators and settings.integrator not in self.integrators:
            raise EngineError(f"{self.name}: unknown integrator {settings.integrator!r}; "
                              f"known: {', '.join(self.integrators)}.")
        if settings.segments is not None and settings.segments < self.min_segments:
            raise EngineError(f"segments must be at least {self.min_segments} for a Hencky chain, "
                              f"got {settings.segments}.")
        return self.parse(settings)

    def resolve_dt(self, scene, settings: EngineSettings, plan: Plan) -> float:
        """The step: settings.dt, or for "auto" the largest 1-2-5 value <= DT_MARGIN * dt_limit and
        <= t_contact / STEPS_PER_CONTACT (`contact_time`: t_plate, or the structure's own first contact when it is
        much shorter)."""
        if not settings.auto_dt:
            return float(settings.dt)
        cap = contact_time(scene) / STEPS_PER_CONTACT
        if math.isfinite(plan.dt_limit):
            cap = min(cap, DT_MARGIN * plan.dt_limit)
        return nice_step(cap)

    def run(self, scene, settings: EngineSettings) -> ImpactResult:
        """Plan, build and step the scene in this process; failures become statuses; an instability while
        stepping is rerun with the adapter's softer model (`retry`, module doc). Never overridden."""
        if not self.available():
            status, text = message("not-installed", module=self.module, hint=self.install_hint())
            return ImpactResult.failed(scene.name, self.name, status, text, settings=settings.as_dict())
        settings = self.check_settings(settings)
        result, stepped_unstable = self._attempt(scene, settings)
        first, models = result, []
        while stepped_unstable and len(models) < self.max_retries:
            softer = self.retry(scene, settings, result)
            if softer is None:
                break
            settings = self.check_settings(softer.settings)
            models.append(softer.what)
            result, stepped_unstable = self._attempt(scene, settings)
        if not models:
            return result
        me = f"{100 * result.model_error:.2g} %" if math.isfinite(result.model_error) else "unknown"
        note = (f"{self.name}: unstable with its default model ({first.message}); retried {len(models)}x with a "
                f"softer model ({'; '.join(models)}): {result.status.value}, model_error {me}")
        diag = {**result.diagnostics, "retries": len(models), "retry_models": models,
                "retry_first_failure": first.message}
        return replace(result, diagnostics=diag, validity=(*result.validity, note))

    def _attempt(self, scene, settings: EngineSettings) -> tuple[ImpactResult, bool]:
        """One plan-build-step of parsed settings: (row, True when it went unstable while stepping)."""
        plan = self.plan(scene, settings)
        dt = self.resolve_dt(scene, settings, plan)
        law = self.contact_law(scene, settings)
        common = dict(version=self._safe_version(), dt=dt, dt_limit=plan.dt_limit, model_error=plan.model_error,
                      contact_law=law, validity=tuple(plan.validity))
        if math.isfinite(plan.dt_limit) and dt > plan.dt_limit:
            status, text = message("dt-limit", dt=dt, limit=plan.dt_limit, what=plan.what,
                                   suggest=nice_step(DT_MARGIN * plan.dt_limit))
            return ImpactResult.failed(scene.name, self.name, status, text, settings=settings.as_dict(),
                                       diagnostics=dict(plan.diagnostics), **common), False
        settings = replace(settings, dt=dt)
        try:
            sim = self.simulate(scene, settings)
        except EngineDiverged as err:
            why = str(err)
            if math.isfinite(plan.dt_limit) and "limit" not in why:
                why += f" (predicted stability limit {plan.dt_limit:.3g} s)"
            status, text = message("diverged", why=why)
            return ImpactResult.failed(scene.name, self.name, status, text, settings=settings.as_dict(),
                                       diagnostics={**plan.diagnostics, **err.diagnostics}, **common), True
        sim.diagnostics = {**plan.diagnostics, **sim.diagnostics}
        if sim.frequencies.size and "structure_frequencies" not in sim.diagnostics:
            sim.diagnostics["structure_frequencies"] = [float(x) for x in sim.frequencies]
        result = self.result_from(scene, settings, sim, plan, sim.contact_law or law)
        return result, result.status == Status.UNSTABLE

    def _safe_version(self) -> str:
        try:
            return self.version()
        except Exception:  # noqa: BLE001 - a version string is never worth a failed run
            return "unknown"

    def result_from(self, scene, settings: EngineSettings, sim: Simulation, plan: Plan | None = None,
                    law=None) -> ImpactResult:
        """Metrics, status and message from a Simulation's series."""
        plan = plan or Plan()
        dt = float(settings.dt)
        lim = _limit_text(plan.dt_limit)
        common = dict(version=self._safe_version(), settings={**settings.as_dict(), **sim.settings},
                      n_steps=sim.n_steps, wall_time_build_s=sim.build_s, wall_time_step_s=sim.step_s,
                      diagnostics=sim.diagnostics, model=sim.model, dt=dt, dt_limit=plan.dt_limit,
                      model_error=plan.model_error, contact_law=law, validity=(*plan.validity, *sim.validity))

        def failed(reason: str, more: str = "", **kw: Any) -> ImpactResult:
            status, text = message(reason, **kw)
            return ImpactResult.failed(scene.name, self.name, status, text + more, **common)

        t, d, f = (np.asarray(a, float) for a in (sim.t, sim.delta, sim.f))
        finite = np.isfinite(d) & np.isfinite(f)
        if sim.stop == "nan" or not finite.all():
            k = int(np.argmin(finite)) if not finite.all() else len(t) - 1
            return failed("nan", _under_resolved(scene, dt, plan.dt_limit), steps=k, t=float(t[k]) if len(t) else math.nan,
                          dt=dt, limit=lim)
        e = np.asarray(sim.energy, float)
        if e.size and e[0] > 0:
            # by magnitude: a chain blowing up past its limit can drive an engine's total energy far below zero (an
            # unseen clamped beam, MuJoCo at 1.01x its limit: 1.006 E0 through the tail, then -2.4 and -10.7 E0 in
            # two steps), which a check of the largest value alone passed as "ok"
            growth = float(np.max(np.abs(e)) / e[0] - 1.0)
            if sim.stop == "energy" or growth > self.energy_growth_limit or not np.all(np.isfinite(e)):
                negative = (f"; the total energy went negative ({float(np.min(e)) / e[0]:.3g} x its initial value)"
                            if np.isfinite(e).all() and np.min(e) < 0 else "")
                return failed("energy", _energy_onset(t, d, f, e, self.energy_growth_limit) + negative
                              + _under_resolved(scene, dt, plan.dt_limit),
                              growth=_growth_text(growth), allowed=self.energy_growth_limit, dt=dt, limit=lim)
        if sim.stop == "through":
            return failed("through", _under_resolved(scene, dt, plan.dt_limit), delta=float(np.max(d)),
                          steps=sim.n_steps, dt=dt, limit=lim)
        contacts = contacts_from_series(t, d, f)
        if not contacts:
            return failed("no-contact")
        first = contacts[0]
        if not math.isfinite(first.t_end):
            cap = WINDOW_CAP * plate_times(scene).t_m + settings.tail
            return failed("open-contact", cap=cap, factor=WINDOW_CAP)
        end_idx = int(np.searchsorted(t, first.t_end))
        v = np.asarray(sim.v_ball, float)
        rebound = -float(v[min(end_idx, len(v) - 1)]) if v.size and np.isfinite(v).any() else math.nan
        faster = _faster_than_it_came(scene, rebound)
        if faster:
            common["validity"] = (*common["validity"], faster)
        energy_error = float(np.max(np.abs(e / e[0] - 1.0))) if e.size and e[0] > 0 else math.nan
        return ImpactResult(scene=scene.name, source=self.name, t_m=first.t_end - first.t_start, f_m=first.f_max,
                            delta_m=first.delta_max, t=t, f=f, delta=d, x_ball=np.asarray(sim.x_ball, float),
                            x_structure=np.asarray(sim.x_structure, float), energy=e, rebound_velocity=rebound,
                            energy_error=energy_error, contacts=contacts, status=Status.OK, **common)


class SteppingAdapter(EngineAdapter):
    """An adapter that steps: implement build/step/contact/energy (module docstring); the base loops."""

    #: 1 when contact/energy/kinematics after step k describe the state at the start of that step (an engine
    #: that reports a step's force with the penetration it was computed from, e.g. Bullet); 0 = after it
    sample_lag: int = 0

    def build(self, scene, settings: EngineSettings) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError

    def stepper(self, model: Any) -> Callable[[], None]:
        """A zero-argument callable that advances `model` by one step: what the base loop times. Default:
        `step` bound to the model; an adapter may return its engine's own step call (one Python frame
        less per step: benchmarks/bench_sweep_overhead.py counts it). Must do exactly what `step` does."""
        return functools.partial(self.step, model)

    def step(self, model: Any) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def contact(self, model: Any) -> tuple[float, float]:  # pragma: no cover - abstract
        raise NotImplementedError

    def energy(self, model: Any) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def observe(self, model: Any) -> None:
        """After each step, outside the timed stepping region: prepare what contact/energy/kinematics report
        (bookkeeping that is not physics, so the stepping time stays the engine's own cost). Default: nothing."""

    def kinematics(self, model: Any) -> tuple[float, float, float]:
        """(x_ball [m], x_structure [m], v_ball [m/s]); NaN when the adapter does not say."""
        return math.nan, math.nan, math.nan

    def frequencies(self, model: Any) -> np.ndarray:
        return np.zeros(0)

    def describe(self, model: Any) -> str:
        """The model's name for rows (e.g. "hencky-chain-81")."""
        return ""

    def close(self, model: Any) -> None:
        """Release the model's resources (called once, also after a failure)."""

    def structure_frequencies(self, scene, settings: EngineSettings) -> np.ndarray:
        settings = self.check_settings(settings)
        if settings.auto_dt:
            settings = replace(settings, dt=self.resolve_dt(scene, settings, self.plan(scene, settings)))
        model = self.build(scene, settings)
        try:
            return np.asarray(self.frequencies(model), float)
        finally:
            self.close(model)

    def simulate(self, scene, settings: EngineSettings) -> Simulation:
        """The loop: sample, step, sample ... until the first contact ends plus the tail (one rule)."""
        dt = float(settings.dt)
        plate = plate_times(scene)
        t_cap = WINDOW_CAP * plate.t_m + settings.tail
        n_max = int(math.ceil(t_cap / dt))
        through = through_depth(scene)
        t0 = time.perf_counter()
        model = self.build(scene, settings)
        try:
            build_s = time.perf_counter() - t0
            freqs = np.asarray(self.frequencies(model), float)
            # per-step work kept small (benchmarks/bench_sweep_overhead.py counts it): locals instead of
            # attribute and global lookups, one tuple per step, the sample time rebuilt from k afterwards
            cols: list[tuple[float, ...]] = []
            append = cols.append
            step, contact, energy, kin, observe = self.stepper(model), self.contact, self.energy, self.kinematics, self.observe
            clock, isfinite = time.perf_counter, math.isfinite
            lag = self.sample_lag

            step_s, k = 0.0, 0
            if lag:                # the first step's report describes the initial state
                ts = clock()
                step()
                step_s += clock() - ts
                k = 1
            k_first = k
            observe(model)          # not timed: the stepping time is the engine's step alone
            d, f = contact(model)
            e0 = energy(model)
            append((d, f, *kin(model), e0))
            e_stop = STOP_ENERGY_FACTOR * e0
            touched, ended, stop = False, False, ""
            while k < n_max:
                ts = clock()
                step()
                step_s += clock() - ts
                k += 1
                observe(model)
                d, f = contact(model)
                e = energy(model)
                append((d, f, *kin(model), e))
                if not (isfinite(d) and isfinite(f) and isfinite(e)):
                    stop = "nan"
                    break
                if e > e_stop:
                    stop = "energy"
                    break
                if d > through:
                    stop = "through"
                    break
                if f > 0:
                    touched = True
                elif touched and d <= 0 and not ended:
                    ended = True
                    n_max = min(n_max, k + int(math.ceil(settings.tail / dt)))
            arr = np.asarray(cols, float).reshape(-1, 6)
            t = (np.arange(k_first, k_first + len(arr)) - lag) * dt
            sim = Simulation(t=t, delta=arr[:, 0], f=arr[:, 1], x_ball=arr[:, 2], x_structure=arr[:, 3],
                             v_ball=arr[:, 4], energy=arr[:, 5], build_s=build_s, step_s=step_s, n_steps=k,
                             model=self.describe(model), stop=stop, frequencies=freqs)
        finally:
            self.close(model)
        sim.diagnostics = dict(getattr(model, "diagnostics", {}) or {})     # close() may add to them
        return sim


#: a ball that leaves a target at rest faster than this fraction above its approach speed gets a note: an elastic
#: contact cannot give it more than it brought (the reference's rebound is below v0), so the step created energy
REBOUND_SLACK = 1e-3


def _faster_than_it_came(scene, rebound: float) -> str:
    """"" or a validity note when the ball rebounds from a target at rest faster than it came (v0 (1 + REBOUND_SLACK)):
    energy the time step created (an unseen clamped beam, MuJoCo at 1.7 x its limit: 7.15 m/s out of 7.07 m/s in,
    the row otherwise only 'inaccurate')."""
    v0 = float(getattr(scene.ball, "velocity", math.nan))
    at_rest = float(getattr(scene.target, "velocity", 0.0) or 0.0) == 0.0
    if not (at_rest and math.isfinite(rebound) and math.isfinite(v0) and v0 > 0) or rebound <= v0 * (1 + REBOUND_SLACK):
        return ""
    return (f"the ball left faster than it came (rebound {rebound:.4g} m/s > approach {v0:.4g} m/s, "
            f"+{100 * (rebound / v0 - 1):.2g} %): an elastic contact cannot give that; the time step created energy "
            f"(try a smaller dt)")


#: a failed row whose step resolves the contact with fewer steps than this says so: the stability limit (2/omega_max
#: of the model) does not bound that error (two 1-13 mm balls at 9.2 m/s, dt 1e-5 s below the predicted limit 1.46e-5
#: s: a 29.5 us contact in 3 steps, energy +12.7 %, "unstable" with no word of why)
FEW_STEPS_PER_CONTACT = 20.0


def _under_resolved(scene, dt: float, limit: float) -> str:
    """"" or, for a failed row, a sentence when dt resolves the contact (`contact_time`) in fewer than
    FEW_STEPS_PER_CONTACT steps, with the step dt = auto would take (STEPS_PER_CONTACT steps, below DT_MARGIN of the
    predicted limit)."""
    try:
        t_contact = contact_time(scene)
    except Exception:  # noqa: BLE001 - a hint is never worth a failed classification
        return ""
    if not (math.isfinite(t_contact) and t_contact > 0 and dt > 0) or t_contact / dt >= FEW_STEPS_PER_CONTACT:
        return ""
    suggest = t_contact / STEPS_PER_CONTACT
    if math.isfinite(limit):
        suggest = min(suggest, DT_MARGIN * limit)
    below = " below the predicted stability limit," if math.isfinite(limit) and dt <= limit else ""
    return (f"; at dt = {dt:.3g} s{below} the contact (~{t_contact:.3g} s) spans only {t_contact / dt:.2g} steps: the "
            f"step under-resolves the contact, which the stability limit does not bound; use dt <= "
            f"{nice_step(suggest):.3g} s or dt = auto")


def _energy_onset(t: np.ndarray, delta: np.ndarray, f: np.ndarray, energy: np.ndarray, allowed: float) -> str:
    """For a failed energy check: "" when the energy first passed the limit during the first contact (or never
    finitely), else where it did, after that contact had ended: the growth is in the window after it (--tail), so
    a shorter tail keeps the first contact's row (MuJoCo Warp's float32 chain grows from ~3 ms after touch on the
    worked beam)."""
    over = ~(np.abs(energy) / energy[0] - 1.0 <= allowed)   # non-finite counts as over; by magnitude (result_from)
    if not over.any():
        return ""
    k = int(np.argmax(over))
    contacts = contacts_from_series(t[:k], delta[:k], f[:k])
    if not contacts or not math.isfinite(contacts[0].t_end) or contacts[0].t_end >= t[k]:
        return ""
    first = contacts[0]
    return (f"; first past the limit at t = {t[k]:.3g} s, after the first contact ({first.t_start:.3g} .. "
            f"{first.t_end:.3g} s) had ended: the growth is in the window after it (--tail), a shorter tail keeps "
            f"the contact's row")


def _growth_text(growth: float) -> str:
    """'by 12.3%' for modest growth (3 digits: 5.04 % is not 'by 5% (limit 5%)'), 'by a factor 3.4e+12' for an
    explosion."""
    return f"by {100 * growth:.3g}%" if growth < 10 else f"by a factor {1 + growth:.2g}"


def _parabola_peak(t: np.ndarray, y: np.ndarray, k: int) -> float:
    """Peak value of the parabola through samples k-1, k, k+1 (the sampled max otherwise)."""
    if k <= 0 or k >= len(y) - 1:
        return float(y[k])
    t0, t1, t2 = t[k - 1] - t[k], 0.0, t[k + 1] - t[k]
    y0, y1, y2 = y[k - 1], y[k], y[k + 1]
    denom = (t0 - t1) * (t0 - t2) * (t1 - t2)
    a = (t2 * (y1 - y0) + t1 * (y0 - y2) + t0 * (y2 - y1)) / denom
    b = (t2 * t2 * (y0 - y1) + t1 * t1 * (y2 - y0) + t0 * t0 * (y1 - y2)) / denom
    if a >= 0:
        return float(y1)
    x = -b / (2 * a)
    if not t0 <= x <= t2:
        return float(y1)
    c = y1 - a * t1 * t1 - b * t1
    return float(max(y1, a * x * x + b * x + c))


#: samples of the polynomial a peak is read from (degree PEAK_POINTS - 1): its read-out error is
#: O(dt^PEAK_POINTS), beyond the order of every integrator the adapters use (RK4: 4); a parabola's
#: O(dt^3) error, whose constant oscillates with where the peak falls between samples, swamped the
#: O(dt^2.5) differences of RK4 runs on beams and made their fitted orders scatter
PEAK_POINTS = 5


def _peak(t: np.ndarray, y: np.ndarray, k: int, lo: int, hi: int) -> float:
    """Peak value near sample k (the largest sample of y[lo:hi]) read from the interpolating polynomial
    through PEAK_POINTS samples of [lo, hi) around k (one contact's samples: the force's kink at touch
    and separation stays outside): its largest critical value within one sample of k. Falls back to
    the parabola through k-1, k, k+1 when the contact has fewer samples, the polynomial has no maximum
    there, or it moves the parabola's peak by more than the samples' own curvature (an unresolved peak)."""
    par = _parabola_peak(t, y, k)
    if hi - lo < PEAK_POINTS or k <= lo or k >= hi - 1:
        return par
    a = min(max(k - PEAK_POINTS // 2, lo), hi - PEAK_POINTS)
    tt, yy = t[a:a + PEAK_POINTS], y[a:a + PEAK_POINTS]
    h = 0.5 * (t[k + 1] - t[k - 1])
    if not (h > 0 and np.all(np.isfinite(yy))):
        return par
    x = (tt - t[k]) / h                                  # O(1) abscissae: a well-conditioned Vandermonde
    coef = np.linalg.solve(np.vander(x), yy - y[k])
    poly = np.poly1d(coef)
    x_lo, x_hi = (t[k - 1] - t[k]) / h, (t[k + 1] - t[k]) / h
    crit = [r.real for r in poly.deriv().roots if abs(r.imag) <= 1e-9 * max(1.0, abs(r)) and x_lo <= r.real <= x_hi]
    crit = [r for r in crit if poly.deriv(2)(r) < 0]
    if not crit:
        return par
    peak = float(y[k] + max(poly(r) for r in crit))
    curvature = y[k] - min(y[k - 1], y[k + 1])
    if not (peak >= y[k] and abs(peak - par) <= curvature):
        return par
    return peak


def _zero_crossing(t: np.ndarray, y: np.ndarray, a: int, linear: float) -> float:
    """Where y crosses 0 between samples a and a+1, from the cubic through four samples around them
    (two each side where the series has them): read-out error O(dt^4) where y is smooth, O(dt^3) across
    a jump of its third derivative (a contact force that vanishes at delta = 0: Hertz or a linear
    spring), instead of the O(dt^2) of the straight line (`linear`, kept when the samples do not bracket
    a sign change, the series is too short or the cubic has no root between them)."""
    n = len(y)
    if n < 4 or not (y[a] > 0 >= y[a + 1] or y[a] <= 0 < y[a + 1]):
        return linear
    lo = min(max(a - 1, 0), n - 4)
    h = t[a + 1] - t[a]
    yy = y[lo:lo + 4]
    if not (h > 0 and np.all(np.isfinite(yy))):
        return linear
    x = (t[lo:lo + 4] - t[a]) / h
    roots = np.poly1d(np.linalg.solve(np.vander(x), yy)).roots
    inside = [r.real for r in roots if abs(r.imag) <= 1e-9 and 0.0 <= r.real <= 1.0]
    if not inside:
        return linear
    x_lin = (linear - t[a]) / h
    return float(t[a] + h * min(inside, key=lambda r: abs(r - x_lin)))


def contacts_from_series(t: np.ndarray, delta: np.ndarray, f: np.ndarray) -> tuple[Contact, ...]:
    """Contact phases from per-step samples: a contact is a run of samples with f > 0; its start and
    end are where delta crosses 0 (the cubic through four samples around the crossing, `_zero_crossing`),
    its peaks are read from the quartic through
    the five samples of the contact around the largest one (`_peak`, error O(dt^5))."""
    on = f > 0
    out = []
    i, n = 0, len(t)
    while i < n:
        if not on[i]:
            i += 1
            continue
        s = i
        while i < n and on[i]:
            i += 1
        e = i                                   # first sample after the contact (or n)

        def cross(a: int, b: int) -> float:
            if a < 0:
                return float(t[b])
            if b >= n:
                return math.nan
            da, db = delta[a], delta[b]
            if da == db:
                return float(t[b])
            return _zero_crossing(t, delta, a, float(t[a] + (0.0 - da) * (t[b] - t[a]) / (db - da)))

        t_start = cross(s - 1, s)
        t_end = cross(e - 1, e) if e < n else math.nan
        kf = s + int(np.argmax(f[s:e]))
        kd = s + int(np.argmax(delta[s:e]))
        out.append(Contact(t_start, t_end, _peak(t, f, kf, s, e), _peak(t, delta, kd, s, e)))
    return tuple(out)


# ---------------------------------------------------------------------------- loading and jobs

def _entry_points() -> dict[str, Any]:
    try:
        from importlib.metadata import entry_points

        return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}
    except Exception:  # noqa: BLE001 - broken metadata means no third-party engines
        return {}


def adapter_class(spec: str) -> type:
    """The adapter class of a registry name ("mujoco"), an entry point of the group
    `impactval.engines`, or an import path "package.module:Class"; EngineError otherwise."""
    from impactval.engines import ENGINES

    if not isinstance(spec, str) or not spec.strip():
        raise EngineError(f"engine names must be non-empty strings, got {spec!r}.")
    if spec in ENGINES:
        path = ENGINES[spec]
    elif spec in (eps := _entry_points()):
        try:
            cls = eps[spec].load()
        except Exception as err:  # noqa: BLE001 - a broken plug-in is bad input, not a crash of the run
            raise EngineError(f"engine {spec!r} (entry point {eps[spec].value}) cannot be loaded: "
                              f"{type(err).__name__}: {err}") from None
        return _checked(spec, cls)
    elif ":" in spec and all(spec.split(":", 1)):
        path = spec
    else:
        known = ", ".join([*ENGINES, *_entry_points()])
        raise EngineError(f"unknown engine {spec!r}; known: {known}, or an adapter as 'package.module:Class'.")
    mod, _, cls_name = path.partition(":")
    try:
        module = importlib.import_module(mod)
    except Exception as err:  # noqa: BLE001
        raise EngineError(f"engine {spec!r}: cannot import module {mod!r}: {type(err).__name__}: {err}") from None
    cls = getattr(module, cls_name, None)
    if cls is None:
        raise EngineError(f"engine {spec!r}: module {mod!r} has no {cls_name!r}.")
    return _checked(spec, cls)


def _checked(spec: str, cls: Any) -> type:
    if not (isinstance(cls, type) and issubclass(cls, EngineAdapter)):
        raise EngineError(f"engine {spec!r} is not an impactval EngineAdapter subclass (got {cls!r}).")
    return cls


def load_adapter(spec: str) -> EngineAdapter:
    """An adapter instance from a registry name, entry point or "pkg.module:Class" (see adapter_class)."""
    return adapter_class(spec)()


def execute_job(spec: str, scene, settings: EngineSettings) -> ImpactResult:
    """Run one engine job in this process; never raises (every failure is a status row):
    unknown/unsupported -> skipped, missing engine -> not-installed, exceptions -> crashed."""
    name = spec.split(":")[-1] if ":" in spec else spec
    try:
        adapter = load_adapter(spec)
    except EngineError as err:
        return ImpactResult.failed(scene.name, name, Status.SKIPPED, str(err), settings=_settings_dict(settings))
    except Exception as err:  # noqa: BLE001
        return ImpactResult.failed(scene.name, name, Status.CRASHED, f"cannot load adapter: {type(err).__name__}: {err}",
                                   settings=_settings_dict(settings))
    try:
        return adapter.run(scene, settings)
    except EngineError as err:      # the scene/settings combination is not supported by this engine
        return ImpactResult.failed(scene.name, adapter.name or name, Status.SKIPPED, str(err),
                                   settings=_settings_dict(settings))
    except Exception as err:  # noqa: BLE001 - every failure must become a row
        tb = traceback.format_exc(limit=6)
        return ImpactResult.failed(scene.name, adapter.name or name, Status.CRASHED, f"{type(err).__name__}: {err}",
                                   settings=_settings_dict(settings), diagnostics={"traceback": tb})


def _settings_dict(settings) -> dict[str, Any]:
    try:
        return settings.as_dict()
    except Exception:  # noqa: BLE001
        return {}


def _quiet_stdout() -> None:
    """Engines print banners from C (pybullet's build time, on stderr): keep the parent's table clean.
    Failures still reach the parent: exceptions as rows, a dying process by its exit code."""
    try:
        import os
        import sys

        sys.stdout.flush()
        sys.stderr.flush()
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        os.close(devnull)
    except OSError:  # pragma: no cover - only cosmetic
        pass


def _child(spec: str, scene, settings: EngineSettings, conn) -> None:
    _quiet_stdout()
    conn.send(execute_job(spec, scene, settings))
    conn.close()


def run_isolated(spec: str, scene, settings: EngineSettings) -> ImpactResult:
    """`execute_job` in its own process with settings.timeout_s; a crash, hang or kill becomes a status
    row. (A thin wrapper until the runner's executor owns isolation.)"""
    name = spec.split(":")[-1] if ":" in spec else spec
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(spec, scene, settings, child), daemon=True)
    t0 = time.perf_counter()
    proc.start()
    child.close()
    result = None
    try:
        if parent.poll(settings.timeout_s):
            try:
                result = parent.recv()
            except EOFError:
                result = None
    finally:
        if result is None and proc.is_alive():
            proc.kill()
        proc.join(5)
    if result is not None:
        return result
    elapsed = time.perf_counter() - t0
    if elapsed >= settings.timeout_s:
        status, text = message("timeout", timeout=settings.timeout_s, dt=_dt_text(settings.dt))
    else:
        code = proc.exitcode
        how = (f"killed by signal {signal.Signals(-code).name}" if code is not None and code < 0
               else f"exit code {code}")
        status, text = message("process-died", how=how, elapsed=elapsed)
    return ImpactResult.failed(scene.name, name, status, text, settings=settings.as_dict())


__all__ = ["EngineAdapter", "SteppingAdapter", "EngineSettings", "Simulation", "Plan", "Softer", "EngineDiverged",
           "contacts_from_series", "execute_job", "plate_times", "contact_scene", "contact_mass", "through_depth", "run_isolated", "load_adapter", "adapter_class", "CONTACT_MODES",
           "MESSAGES", "message", "DT_MARGIN", "STEPS_PER_CONTACT", "WINDOW_CAP", "nice_step", "contact_time"]
