"""Run the reference and engine jobs over scenes; one row per (scene, engine) (style.md, pattern 5).

`run(scenes, engines, ...)` returns a pandas DataFrame. Every engine job runs in its own process
with a timeout (`impactval.engines.base.run_isolated`), so a crash, hang or explosion becomes a
status row and the run goes on. With `out`, each row is appended to `out/results.csv` as soon as
it exists (a killed run loses nothing) and `out/report.md` is written at the end.
"""
from __future__ import annotations

import csv
import importlib.util
import json
import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Iterable

import pandas as pd

from impactval.compare import curve_error, relative_errors
from impactval.engines import ENGINE_MODULES, ENGINES
from impactval.engines.base import EngineSettings, run_isolated
from impactval.errors import EngineError, ImpactvalError
from impactval.reference.result import ImpactResult

SCHEMA_VERSION = 2
#: statuses that make `impactval run` exit with 1 ("not-installed" and "skipped" only inform)
FAILED_STATUSES = ("crashed", "timeout", "unstable", "no-contact")
#: results.csv columns, in order
COLUMNS = (
    "schema_version", "run_id", "scene", "scene_hash", "engine", "version", "model", "contact", "integrator", "dt",
    "segments", "status", "message",
    "t_m", "f_m", "delta_m", "ref_t_m", "ref_f_m", "ref_delta_m",
    "err_t_m", "err_f_m", "err_delta_m", "err_curve",
    "contact_stiffness", "lin_t_m", "lin_f_m", "lin_delta_m",
    "lin_err_t_m", "lin_err_f_m", "lin_err_delta_m", "lin_err_curve",
    "rebound_velocity", "energy_error", "n_contacts", "n_steps",
    "wall_time_build_s", "wall_time_step_s", "wall_time_s",
    "structure_frequencies", "continuum_frequencies",
)


def resolve_engine(spec: str) -> str:
    """Check an engine name ("mujoco") or import path ("pkg.module:Class"); return it unchanged."""
    if not isinstance(spec, str) or not spec.strip():
        raise EngineError(f"engine names must be non-empty strings, got {spec!r}.")
    if spec in ENGINES or (":" in spec and all(spec.split(":", 1))):
        return spec
    installed = [n for n, m in ENGINE_MODULES.items() if importlib.util.find_spec(m)]
    raise EngineError(f"unknown engine {spec!r}; known: {', '.join(ENGINES)} (installed: "
                      f"{', '.join(installed) or 'none'}), or an adapter as 'package.module:Class'.")


def _unavailable(spec: str, scene, settings: EngineSettings) -> ImpactResult | None:
    """A status row for an engine that cannot run here (not installed, no adapter yet, or the
    settings are not supported), else None. Checked in this process, before spawning a job."""
    if spec in ENGINES:
        mod = ENGINE_MODULES.get(spec, spec)
        if importlib.util.find_spec(mod) is None:
            return ImpactResult.failed(scene.name, spec, "not-installed",
                                       f"{mod} is not installed: pip install 'impactval[{spec}]'",
                                       settings=settings.as_dict())
        adapter_mod = ENGINES[spec].split(":", 1)[0]
        try:
            found = importlib.util.find_spec(adapter_mod) is not None
        except ModuleNotFoundError:
            found = False
        if not found:
            return ImpactResult.failed(scene.name, spec, "skipped",
                                       f"no adapter module {adapter_mod} in this impactval version",
                                       settings=settings.as_dict())
    from impactval.engines.base import load_adapter

    try:
        load_adapter(spec).check_settings(settings)
    except EngineError as err:
        return ImpactResult.failed(scene.name, spec, "skipped", str(err), settings=settings.as_dict())
    except Exception as err:  # noqa: BLE001 - a broken adapter module is that engine's row, not the run's
        return ImpactResult.failed(scene.name, spec, "crashed", f"cannot load adapter: {type(err).__name__}: {err}",
                                   settings=settings.as_dict())
    return None


def _check_settings_somewhere(specs: list[str], settings: EngineSettings) -> None:
    """Bad input fails fast: settings that no requested (loadable) engine accepts are an error
    (e.g. a misspelt integrator); settings only some engines accept become "skipped" rows."""
    from impactval.engines.base import load_adapter

    errors = []
    for spec in specs:
        try:
            adapter = load_adapter(spec)
        except Exception:  # noqa: BLE001 - a missing or broken adapter is reported as its row
            return
        try:
            adapter.check_settings(settings_for(settings, spec))
            return
        except EngineError as err:
            errors.append(str(err))
    if errors:
        raise EngineError(errors[0] if len(errors) == 1 else "no engine accepts these settings: " + " ".join(errors))


def _linear_reference(scene, tol: float, stiffness: float):
    """The linear-theory reference for the same spring, or None when impactval.reference.linear
    is not available in this version."""
    try:
        from impactval.reference.linear import solve_linear
    except ImportError:
        return None
    return solve_linear(scene, tol=tol, stiffness=stiffness)


def _num(x: Any) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def scene_hash(scene) -> str:
    """Identity of what a row measured: the canonical scene (ball, target, materials) and the
    reference version; rows with different hashes are never compared (impactval.history)."""
    import hashlib

    import impactval

    canon = repr((scene.ball, scene.target, impactval.__version__))
    return hashlib.sha1(canon.encode()).hexdigest()[:12]


def make_row(run_id: str, scene, spec: str, settings: EngineSettings, res: ImpactResult, ref: ImpactResult,
             lin: ImpactResult | None) -> dict[str, Any]:
    """One results row (see COLUMNS)."""
    err = relative_errors(res, ref) if res.success else dict.fromkeys(("t_m", "f_m", "delta_m"), math.nan)
    diag = res.diagnostics or {}
    row: dict[str, Any] = dict.fromkeys(COLUMNS, math.nan)
    rs = res.settings or {}
    row.update(
        schema_version=SCHEMA_VERSION, run_id=run_id, scene=scene.name, scene_hash=scene_hash(scene),
        engine=res.source or spec,
        version=res.version, model=res.model, contact=settings.contact,
        integrator=rs.get("integrator") or settings.integrator or "", dt=settings.dt,
        # structure size: chain segments, or the mode count of a modal (FFRF) body
        segments=next((v for v in (rs.get("segments"), settings.segments, rs.get("modes"), settings.modes)
                       if v not in (None, "", 0)), ""),
        status=res.status, message=res.message,
        t_m=res.t_m, f_m=res.f_m, delta_m=res.delta_m, ref_t_m=ref.t_m, ref_f_m=ref.f_m, ref_delta_m=ref.delta_m,
        err_t_m=err["t_m"], err_f_m=err["f_m"], err_delta_m=err["delta_m"],
        err_curve=curve_error(res, ref) if res.success else math.nan,
        contact_stiffness=_num(diag.get("contact_stiffness")),
        rebound_velocity=res.rebound_velocity, energy_error=res.energy_error, n_contacts=len(res.contacts),
        n_steps=res.n_steps, wall_time_build_s=res.wall_time_build_s, wall_time_step_s=res.wall_time_step_s,
        wall_time_s=res.wall_time_s,
        structure_frequencies=json.dumps(diag["structure_frequencies"]) if "structure_frequencies" in diag else "",
        continuum_frequencies=json.dumps(diag["continuum_frequencies"]) if "continuum_frequencies" in diag else "",
    )
    if lin is not None and lin.success:
        row.update(lin_t_m=lin.t_m, lin_f_m=lin.f_m, lin_delta_m=lin.delta_m)
        if res.success:
            le = relative_errors(res, lin)
            row.update(lin_err_t_m=le["t_m"], lin_err_f_m=le["f_m"], lin_err_delta_m=le["delta_m"],
                       lin_err_curve=curve_error(res, lin))
    return row


class _CsvSink:
    """Appends rows to results.csv; an existing file with other columns is moved aside first."""

    def __init__(self, path: Path) -> None:
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.exists():
            with path.open(newline="") as fh:
                header = next(csv.reader(fh), None)
            if header != list(COLUMNS):
                path.rename(path.with_name(f"{path.stem}-old-{time.strftime('%Y%m%dT%H%M%S')}{path.suffix}"))

    def write(self, row: dict[str, Any]) -> None:
        new = not self.path.exists()
        with self.path.open("a", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=COLUMNS)
            if new:
                w.writeheader()
            w.writerow(row)
            fh.flush()


def _as_scene(s):
    import impactval

    return s if hasattr(s, "target") and hasattr(s, "ball") else impactval.load_scene(s)


def settings_for(settings: EngineSettings, spec: str) -> EngineSettings:
    """The settings one engine gets: options named "ENGINE.key" go to that engine only (as "key"),
    plain "key" options to every engine."""
    name = spec.split(":")[-1].lower() if ":" in spec else spec
    opts = []
    for key, value in settings.options:
        head, dot, rest = key.partition(".")
        if not dot:
            opts.append((key, value))
        elif head.lower() in (name, spec):
            opts.append((rest, value))
    return replace(settings, options=tuple(opts))


def run(scenes: Iterable, engines: Iterable[str] | str = ("mujoco",), settings: EngineSettings | None = None, *,
        dt: float | list[float] | None = None, contact: str | None = None, integrator: str | None = None,
        segments: int | None = None, timeout_s: float | None = None, tol: float = 1e-6,
        out: str | Path | None = None, on_row: Callable[[dict[str, Any]], None] | None = None,
        baseline: str | Path | None = None, threshold: float = 0.2) -> pd.DataFrame:
    """Run the reference and every engine on every scene; one row per (scene, engine).

    Parameters
    ----------
    scenes : iterable of Scene, catalogue names or TOML paths
    engines : engine names ("mujoco", ...) or adapters as "package.module:Class" (or one
        comma-separated string)
    settings : EngineSettings, optional
        Base settings; `dt` [s], `contact`, `integrator`, `segments`, `timeout_s` [s] override it.
        `dt` may be a list: every job then runs once per time step (a speed/accuracy sweep), and the
        report gets a table and a plot of wall time against error.
    tol : float
        Relative tolerance of the reference solutions (Hertz and, for native contact, linear).
    out : directory, optional
        Append each row to `out/results.csv` as soon as it exists; write `out/report.md` at the end.
    on_row : callable, optional
        Called with each row dict as soon as it exists (e.g. to print progress).
    baseline : path, optional
        results.csv of an earlier run: the report gets a section with marks (see
        `impactval.history`) and the DataFrame's `attrs["baseline"]` holds the comparison.
    threshold : float
        Relative change of a row's score that counts as worse or better (0.2 = 20 %).

    Returns a DataFrame with the columns of `COLUMNS`; errors are signed relative differences
    (engine - reference) / reference; `err_curve` is the whole-curve error (see
    `impactval.compare.curve_error`); `lin_*` compare a native (linear) contact with the
    linear-theory reference for the same spring (NaN for other contact modes).
    """
    if isinstance(engines, str):
        engines = [e.strip() for e in engines.split(",") if e.strip()]
    specs = [resolve_engine(e) for e in engines]
    if not specs:
        raise EngineError("no engine given; known: " + ", ".join(ENGINES) + ".")
    base = settings or EngineSettings()
    # several time steps = a speed/accuracy sweep: every job runs once per dt
    dts = [float(x) for x in dt] if isinstance(dt, (list, tuple)) else [dt] if dt is not None else [base.dt]
    if not dts:
        raise EngineError("dt: give at least one time step.")
    over = {k: v for k, v in dict(contact=contact, integrator=integrator, segments=segments,
                                  timeout_s=timeout_s).items() if v is not None}
    variants = [replace(base, dt=step, **over) for step in dts]
    settings = variants[0]
    _check_settings_somewhere(specs, settings)
    per_engine = {(spec, v.dt): settings_for(v, spec) for spec in specs for v in variants}
    if not (isinstance(threshold, (int, float)) and math.isfinite(threshold) and threshold > 0):
        raise ImpactvalError(f"threshold must be a positive fraction (0.2 = 20 %), got {threshold!r}.")
    old = None
    if baseline is not None:      # read before this run appends to what may be the same file
        from impactval.history import load_results

        old = load_results(baseline, SCHEMA_VERSION)
    scene_objs = [_as_scene(s) for s in scenes]
    if not scene_objs:
        raise ImpactvalError("no scene given; see `impactval scenes`.")
    sink = _CsvSink(Path(out) / "results.csv") if out is not None else None
    run_id = time.strftime("%Y%m%dT%H%M%S")
    import impactval

    rows = []
    for scene in scene_objs:
        ref = impactval.solve(scene, tol=tol)
        lin_cache: dict[float, ImpactResult | None] = {}
        for spec, step in ((sp, v.dt) for v in variants for sp in specs):
            eng = per_engine[(spec, step)]
            res = _unavailable(spec, scene, eng) or run_isolated(spec, scene, eng)
            lin = None
            if settings.contact == "native" and res.success:
                k = _num((res.diagnostics or {}).get("contact_stiffness"))
                if math.isfinite(k) and k > 0:
                    if k not in lin_cache:
                        lin_cache[k] = _linear_reference(scene, tol, k)
                    lin = lin_cache[k]
            row = make_row(run_id, scene, spec, eng, res, ref, lin)
            if sink is not None:
                sink.write(row)
            if on_row is not None:
                on_row(row)
            rows.append(row)
    df = pd.DataFrame(rows, columns=list(COLUMNS))
    cmp = None
    if old is not None:
        from impactval import history

        cmp = history.compare(df, old, threshold)
        df.attrs["baseline"] = cmp
        df.attrs["baseline_rows"] = old
    report = markdown_report(df, settings, cmp=cmp, baseline=None if baseline is None else f"`{baseline}`",
                             checks=threshold)
    if len(variants) > 1:
        from impactval.reports.sweep import speed_accuracy_plot, speed_accuracy_table

        report += speed_accuracy_table(df)
        if out is not None:
            png = speed_accuracy_plot(df, Path(out) / "speed_accuracy.png")
            if png is not None:
                report += f"\n![wall time vs error]({png.name})\n"
    if out is not None:
        (Path(out) / "report.md").write_text(report)
    return df


def any_failed(df: pd.DataFrame) -> bool:
    """True when a row has a failing status (see FAILED_STATUSES)."""
    return bool(df["status"].isin(FAILED_STATUSES).any())


# presentation lives in reports/ (data flows one way); re-exported for existing callers
from impactval.reports.run_report import markdown_report, table_rows, text_table  # noqa: E402,F401
