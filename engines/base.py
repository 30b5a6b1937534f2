"""The engine adapter contract (style.md, patterns 2, 4, 5).

An adapter builds the scene in one engine and steps it; the base class owns the shared work:
validation of settings, timing, metrics from the series, and the status (NaN or growing energy
-> "unstable", no force -> "no-contact"). `run_isolated` runs one job in its own process with a
timeout so a segfault or a hang becomes a status row, never a dead run.

Contract for a subclass (one module per engine, the engine imported only inside methods):
1. set `name` (registry key and pip extra), `module` (the Python module to probe),
   `contacts` (supported contact modes), `integrators` (first one is the default);
2. implement `_simulate(scene, settings) -> Simulation` (build, then step for the window);
3. optionally `version()`, `structure_frequencies(scene, settings)`.
Units are SI. delta > 0 means penetration (approach of the contact points); forces in N.
"""
from __future__ import annotations

import importlib
import importlib.util
import math
import multiprocessing as mp
import signal
import time
import traceback
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from impactval.errors import EngineError
from impactval.reference.result import Contact, ImpactResult

CONTACT_MODES = ("hertz", "native", "native-hertz")


@dataclass(frozen=True)
class EngineSettings:
    """What to run: `dt` time step [s]; `integrator` (engine's name; None = its default);
    `contact`: "hertz" (exact law injected every step), "native" (engine's own contact as a linear
    spring of the paper's k0; for Exudyn the native law is Hertz), "native-hertz" (engine knobs
    shaped toward Hertz); `segments` (links of a chain beam) and `modes` (modal bodies), None =
    sized by the reference's mode criterion or the adapter's documented default; `tail` [s] of
    simulated time after the first contact ends (re-contacts); `timeout_s` [s] for the job;
    `options`: engine-specific extras as (key, value) pairs, validated by the adapter.
    """

    dt: float = 1e-6
    integrator: str | None = None
    contact: str = "hertz"
    segments: int | None = None
    modes: int | None = None
    tail: float = 0.0
    timeout_s: float = 600.0
    options: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        if isinstance(self.dt, bool) or not isinstance(self.dt, (int, float)) or not math.isfinite(self.dt) \
                or not 0 < self.dt <= 1e-2:
            raise EngineError(f"dt must be a time step in s with 0 < dt <= 1e-2, got {self.dt!r}.")
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

    def option(self, key: str, default: Any = None) -> Any:
        return dict(self.options).get(key, default)

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["options"] = dict(self.options)
        return d


@dataclass
class Simulation:
    """What `_simulate` returns: series sampled once per step (t [s], delta [m], f [N], ball and
    contact-point displacement [m], ball velocity [m/s] toward the target, energy [J] or empty),
    wall times [s], step count, and diagnostics (e.g. structure_frequencies)."""

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


class EngineDiverged(Exception):
    """The simulation produced NaN or blew up; becomes status "unstable" (with `diagnostics`)."""

    def __init__(self, message: str, diagnostics: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.diagnostics = diagnostics or {}


class EngineAdapter:
    """Base class; see the module docstring for the contract."""

    name: str = ""
    module: str = ""
    contacts: tuple[str, ...] = ("hertz",)
    integrators: tuple[str, ...] = ()
    #: energy may grow by at most this fraction before a run is classed "unstable"
    energy_growth_limit: float = 0.05
    #: known gaps, by check name -> reason (become xfail in the conformance suite)
    expected_failures: dict[str, str] = {}

    # ------------------------------------------------------------------ to override
    def _simulate(self, scene, settings: EngineSettings) -> Simulation:  # pragma: no cover - abstract
        raise NotImplementedError

    def version(self) -> str:
        mod = importlib.import_module(self.module)
        return str(getattr(mod, "__version__", "unknown"))

    # ------------------------------------------------------------------ shared
    def available(self) -> bool:
        return importlib.util.find_spec(self.module) is not None

    def install_hint(self) -> str:
        return f"pip install 'impactval[{self.name}]'"

    def check_settings(self, settings: EngineSettings) -> None:
        if settings.contact not in self.contacts:
            raise EngineError(f"{self.name} does not support contact {settings.contact!r}; "
                              f"supported: {', '.join(self.contacts)}.")
        if settings.integrator is not None and self.integrators and settings.integrator not in self.integrators:
            raise EngineError(f"{self.name}: unknown integrator {settings.integrator!r}; "
                              f"known: {', '.join(self.integrators)}.")

    def run(self, scene, settings: EngineSettings) -> ImpactResult:
        """Build and step the scene in this process; failures become statuses. Never overridden."""
        if not self.available():
            return ImpactResult.failed(scene.name, self.name, "not-installed",
                                       f"{self.module} is not installed: {self.install_hint()}",
                                       settings=settings.as_dict())
        self.check_settings(settings)
        try:
            sim = self._simulate(scene, settings)
        except EngineDiverged as err:
            return ImpactResult.failed(scene.name, self.name, "unstable", str(err), settings=settings.as_dict(),
                                       version=self._safe_version(), diagnostics=getattr(err, "diagnostics", {}))
        return self.result_from(scene, settings, sim)

    def _safe_version(self) -> str:
        try:
            return self.version()
        except Exception:  # noqa: BLE001 - a version string is never worth a failed run
            return "unknown"

    def result_from(self, scene, settings: EngineSettings, sim: Simulation) -> ImpactResult:
        """Metrics, status and message from a Simulation's series."""
        common = dict(version=self._safe_version(), settings={**settings.as_dict(), **sim.settings},
                      n_steps=sim.n_steps, wall_time_build_s=sim.build_s, wall_time_step_s=sim.step_s,
                      diagnostics=sim.diagnostics, model=sim.model)
        t, d, f = (np.asarray(a, float) for a in (sim.t, sim.delta, sim.f))
        finite = np.isfinite(d) & np.isfinite(f)
        if not finite.all():
            k = int(np.argmin(finite))
            return ImpactResult.failed(scene.name, self.name, "unstable",
                                       f"NaN/inf after {k} steps (t = {t[k]:.3g} s, dt = {settings.dt:g} s)", **common)
        e = np.asarray(sim.energy, float)
        if e.size and e[0] > 0:
            growth = float(np.max(e) / e[0] - 1.0)
            if growth > self.energy_growth_limit:
                return ImpactResult.failed(scene.name, self.name, "unstable",
                                           f"energy grew {_growth_text(growth)} (limit {self.energy_growth_limit:.0%}) "
                                           f"at dt = {settings.dt:g} s", **common)
        contacts = contacts_from_series(t, d, f)
        if not contacts:
            return ImpactResult.failed(scene.name, self.name, "no-contact",
                                       "the ball never touched the target in the simulated window", **common)
        first = contacts[0]
        if not math.isfinite(first.t_end):
            return ImpactResult.failed(scene.name, self.name, "unstable",
                                       "the first contact did not end in the simulated window", **common)
        end_idx = int(np.searchsorted(t, first.t_end))
        v = np.asarray(sim.v_ball, float)
        rebound = -float(v[min(end_idx, len(v) - 1)]) if v.size else math.nan
        energy_error = float(np.max(np.abs(e / e[0] - 1.0))) if e.size and e[0] > 0 else math.nan
        return ImpactResult(scene=scene.name, source=self.name, t_m=first.t_end - first.t_start, f_m=first.f_max,
                            delta_m=first.delta_max, t=t, f=f, delta=d, x_ball=np.asarray(sim.x_ball, float),
                            x_structure=np.asarray(sim.x_structure, float), energy=e, rebound_velocity=rebound,
                            energy_error=energy_error, contacts=contacts, status="ok", **common)


def _growth_text(growth: float) -> str:
    """'by 12%' for modest growth, 'by a factor 3.4e+12' for an explosion."""
    return f"by {growth:.0%}" if growth < 10 else f"by a factor {1 + growth:.2g}"


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


def contacts_from_series(t: np.ndarray, delta: np.ndarray, f: np.ndarray) -> tuple[Contact, ...]:
    """Contact phases from per-step samples: a contact is a run of samples with f > 0; its start and
    end are where delta crosses 0 (linear interpolation), its peaks are parabola-refined."""
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
            return float(t[a] + (0.0 - da) * (t[b] - t[a]) / (db - da))

        t_start = cross(s - 1, s)
        t_end = cross(e - 1, e) if e < n else math.nan
        kf = s + int(np.argmax(f[s:e]))
        kd = s + int(np.argmax(delta[s:e]))
        out.append(Contact(t_start, t_end, _parabola_peak(t, f, kf), _parabola_peak(t, delta, kd)))
    return tuple(out)


# ---------------------------------------------------------------------------- isolation

def load_adapter(spec: str) -> EngineAdapter:
    """An adapter from a registry name ("mujoco") or an import path ("pkg.module:Class")."""
    from impactval.engines import ENGINES

    path = ENGINES.get(spec, spec)
    if ":" not in path:
        raise EngineError(f"unknown engine {spec!r}; known: {', '.join(ENGINES)}.")
    mod, cls = path.split(":", 1)
    return getattr(importlib.import_module(mod), cls)()


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
    try:
        res = load_adapter(spec).run(scene, settings)
    except EngineError as err:      # the scene/settings combination is not supported by this engine
        res = ImpactResult.failed(scene.name, spec, "skipped", str(err), settings=settings.as_dict())
    except Exception as err:  # noqa: BLE001 - every failure must become a row
        tb = traceback.format_exc(limit=4)
        res = ImpactResult.failed(scene.name, spec, "crashed", f"{type(err).__name__}: {err}",
                                  settings=settings.as_dict(), diagnostics={"traceback": tb})
    conn.send(res)
    conn.close()


def run_isolated(spec: str, scene, settings: EngineSettings) -> ImpactResult:
    """Run one engine job in its own process; a crash, hang or kill becomes a status row."""
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
        return ImpactResult.failed(scene.name, name, "timeout",
                                   f"no result after {settings.timeout_s:g} s (dt = {settings.dt:g} s)",
                                   settings=settings.as_dict())
    code = proc.exitcode
    how = (f"killed by signal {signal.Signals(-code).name}" if code is not None and code < 0
           else f"exit code {code}")
    return ImpactResult.failed(scene.name, name, "crashed", f"engine process died ({how}) after {elapsed:.1f} s",
                               settings=settings.as_dict())


__all__ = ["EngineAdapter", "EngineSettings", "Simulation", "EngineDiverged",
           "contacts_from_series", "run_isolated", "load_adapter", "CONTACT_MODES"]
