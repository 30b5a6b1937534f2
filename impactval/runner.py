"""Run the reference and engine jobs over scenes; one row per (scene, engine, settings) (style.md,
pattern 5; issue 12).

`run(scenes, engines, ...)` returns a pandas DataFrame; `execute(jobs, ...)` is the lower level
that sweeps and tuning call with their own job lists. Every engine job runs isolated with its
timeout in a reusable worker process (`impactval.executor`), locally (`workers`, default: the
cores) or on a Dask cluster (`scheduler`). Every row goes into the result store
(`impactval.store`) in its own transaction as soon as it exists; a rerun reuses stored jobs with
the same key (`force=True` recomputes). With `out`, results.csv / results.parquet /
frequencies.csv are regenerated from the store and report.md is written at the end, also when the
run is interrupted (Ctrl-C, SIGTERM: `RunInterrupted`).
"""
from __future__ import annotations

import importlib.util
import json
import math
import signal
import sys
import threading
import time
import uuid
from concurrent.futures import FIRST_COMPLETED, wait
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import pandas as pd

from impactval.compare import (METRICS, NO_REFERENCE, contact_cut, curve_error, error_split, relative_errors,
                               structure_errors, vs_mujoco_c)
from impactval.engines import ENGINE_MODULES, ENGINES
from impactval.engines.base import EngineSettings
from impactval.errors import EngineError, ImpactvalError
from impactval.jobs import Job, engine_version, reference_version
from impactval.reference.result import FAILED, ImpactResult, Status
from impactval.store import COLUMN_TYPES, SCHEMA_VERSION, RunStatus, Store

#: statuses that make `impactval run` exit with 1 ("not-installed" and "skipped" only inform)
FAILED_STATUSES = tuple(sorted(s.value for s in FAILED))
#: stored rows with these statuses are reused by a rerun; crashed and timeout rows are retried
REUSABLE_STATUSES = ("ok", "no-contact", "unstable", "skipped", "not-installed")
#: row columns, in order (units and meaning: docs/results.md)
COLUMNS = tuple(COLUMN_TYPES)


class RunInterrupted(Exception):
    """A run stopped by SIGINT (Ctrl-C) or SIGTERM. `rows`: the jobs that finished (a DataFrame for
    `run`, a list of row dicts for `execute`); `signum`; exit code 128 + signum (130, 143)."""

    def __init__(self, signum: int, rows: Any, run_id: str, total: int) -> None:
        self.signum, self.rows, self.run_id, self.total = signum, rows, run_id, total
        super().__init__(f"run {run_id} interrupted by {signal.Signals(signum).name}: "
                         f"{len(rows)} of {total} jobs finished and stored")

    @property
    def exit_code(self) -> int:
        return 128 + self.signum


class _Stop(BaseException):
    def __init__(self, signum: int) -> None:
        self.signum = signum


def resolve_engine(spec: str) -> str:
    """Check an engine name ("mujoco"), entry point (group impactval.engines) or import path
    ("pkg.module:Class", which must name an EngineAdapter subclass); return it unchanged."""
    if not isinstance(spec, str) or not spec.strip():
        raise EngineError(f"engine names must be non-empty strings, got {spec!r}.")
    if spec in ENGINES:
        return spec
    from impactval.engines.base import _entry_points, adapter_class

    if ":" in spec or spec in _entry_points():
        adapter_class(spec)          # EngineError (exit 2) when it is not an adapter class
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
    """Identity of the scene a row measured: the canonical scene (ball, target, materials) and impactval's version
    (not the reference solver's: `impactval.history` compares rows whose hashes agree when their stored reference
    values agree too, so a solver whose code changed but whose values did not keeps a night comparable); rows with
    different hashes are never compared."""
    import hashlib

    import impactval

    canon = repr((scene.ball, scene.target, impactval.__version__))
    return hashlib.sha1(canon.encode()).hexdigest()[:12]


#: Timoshenko frequencies put next to an engine's structure frequencies (at most this many modes)
N_TIMOSHENKO_FREQUENCIES = 20


@dataclass(frozen=True)
class TheoryGap:
    """The structure-theory question of a beam scene: `other` ("timoshenko" for an Euler-Bernoulli
    scene and vice versa), `gap` (the reference solved with the other theory relative to the scene's
    reference, per metric, signed fractions; NaN if that solve failed) and `timoshenko_frequencies`
    (the Timoshenko beam's lowest frequencies [rad/s], both spectra in frequency order)."""

    other: str
    gap: dict[str, float]
    timoshenko_frequencies: tuple[float, ...] = field(default=())


def _structure_size(scene, rs: Mapping[str, Any], settings: EngineSettings, diag: Mapping[str, Any],
                    ok: bool = True) -> str:
    """The run table's N: chain segments, fe-beam elements or the modes of a modal body, as the engine used them
    (its result settings, then what was asked, then a refused row's plan); none for a target without a structure
    to size (a rigid plate, a second ball: `--segments 35` showed N = 35 there) and, for a modal target, only the
    modes an engine reports (the scene's own)."""
    kind = getattr(scene.target, "kind", "")
    if kind in ("rigid-plate", "ball"):
        return ""
    if kind == "modal" and not ok:      # a failed row's settings are only what was asked (--modes 2 on 3 modes)
        return ""
    order = (rs.get("modes"),) if kind == "modal" else (rs.get("segments"), rs.get("modes"), settings.segments,
                                                        settings.modes, diag.get("segments"))
    return str(next((v for v in order if v not in (None, "", 0)), ""))


def make_row(run_id: str, scene, spec: str, settings: EngineSettings, res: ImpactResult, ref: ImpactResult,
             lin: ImpactResult | None, job_key: str = "", theory: TheoryGap | None = None,
             reference_gap: Mapping[str, Mapping[str, float]] | None = None) -> dict[str, Any]:
    """One results row (see COLUMNS; errors are signed fractions (engine - reference) / reference).

    The error is split per metric into `structure_err_*` (the engine's structure model vs the scene's
    continuum, from the adapter's `model_error_*` diagnostics, measured under the row's contact law: the
    adapter's `model_error_law`) and `numerics_err_*` = err - structure (Hertz laws), lin_err - structure (a
    linear law whose structure part is measured under that spring, against the linear theory; else NaN); `theory_gap_*` (from `theory`, beam scenes) is the other beam theory's reference
    relative to this one; `vs_mujoco_c_*` is MuJoCo Warp against MuJoCo C on the identical model.

    `reference_gap` (a beam or plate scene with an explicit `modes = n`, from `References.reference_gap`): per contact
    law ("hertz", "linear"), the n-mode reference's departure from the structure's continuum, signed fractions. The
    adapters size and error-estimate their structures against the continuum (engines/chain.py `continuum_metrics`),
    the row's error is against the n-mode reference: the structure error becomes the engine's structure against the
    scene's reference model, (1 + adapter's) / (1 + gap) - 1, so structure + numerics = error holds, and a row note says
    how much of it is the reference's truncation (reference/explicit_modes.py)."""
    err = relative_errors(res, ref) if res.success else dict.fromkeys(METRICS, math.nan)   # NaN without a reference
    diag = res.diagnostics or {}
    row: dict[str, Any] = dict.fromkeys(COLUMNS, math.nan)
    rs = res.settings or {}
    law = res.contact_law
    dt = _num(res.dt) if math.isfinite(_num(res.dt)) else _num(settings.dt)
    steps_per_s = res.n_steps / res.wall_time_step_s if res.n_steps and res.wall_time_step_s > 0 else math.nan
    row.update(
        schema_version=SCHEMA_VERSION, job_key=job_key, run_id=run_id, scene=scene.name,
        scene_hash=scene_hash(scene), engine=res.source or spec,
        version=res.version, model=res.model, contact=settings.contact,
        integrator=rs.get("integrator") or settings.integrator or diag.get("integrator") or "", dt=dt,
        # structure size: chain segments, or the mode count of a modal (FFRF) body; a row refused before
        # stepping has the planned size in its diagnostics (so it joins its series: sweep's stability table)
        segments=_structure_size(scene, rs, settings, diag, res.success),
        status=str(res.status), message=res.message,
        t_m=res.t_m, f_m=res.f_m, delta_m=res.delta_m, ref_t_m=ref.t_m, ref_f_m=ref.f_m, ref_delta_m=ref.delta_m,
        err_t_m=err["t_m"], err_f_m=err["f_m"], err_delta_m=err["delta_m"],
        err_curve=curve_error(res, ref) if res.success and ref.success else math.nan,
        contact_law=getattr(law, "kind", "") or "",
        contact_stiffness=_contact_stiffness(res),
        rebound_velocity=res.rebound_velocity, energy_error=res.energy_error, dt_limit=_num(res.dt_limit),
        model_error=_num(res.model_error), n_contacts=len(res.contacts),
        n_steps=int(res.n_steps), steps_per_s=steps_per_s, wall_time_build_s=res.wall_time_build_s,
        wall_time_step_s=res.wall_time_step_s, wall_time_s=res.wall_time_s,
        structure_frequencies=json.dumps(diag["structure_frequencies"]) if "structure_frequencies" in diag else "",
        continuum_frequencies=json.dumps(diag["continuum_frequencies"]) if "continuum_frequencies" in diag else "",
    )
    structure = structure_errors(diag)
    gap_note = ""
    if reference_gap:
        gap = reference_gap.get(str(diag.get("model_error_law", "hertz")))
        if gap:
            structure = {m: (1.0 + structure[m]) / (1.0 + gap[m]) - 1.0 if math.isfinite(structure[m]) else structure[m]
                         for m in METRICS}
        gap_note = str(reference_gap.get("note", "") or "")
    hertz = law.kind == "hertz" if law is not None else settings.contact == "hertz"
    lin_err = dict.fromkeys(METRICS, math.nan)
    if lin is not None and lin.success and res.success:
        lin_err = relative_errors(res, lin)
    if not hertz and diag.get("model_error_law") == "linear":
        # a linear law whose structure part is measured under the same spring: the split against the linear theory
        numerics = error_split(lin_err, structure, True)
    else:
        numerics = error_split(err, structure, hertz)
    vs_c = vs_mujoco_c(diag)
    for m in METRICS:
        row.update({f"structure_err_{m}": structure[m], f"numerics_err_{m}": numerics[m],
                    f"vs_mujoco_c_{m}": vs_c[m]})
        if theory is not None:
            row[f"theory_gap_{m}"] = theory.gap[m]
    row["beam_theory"] = getattr(scene.target, "theory", "") if scene.target.kind == "beam" else ""
    if theory is not None and theory.timoshenko_frequencies and row["structure_frequencies"]:
        n = len(json.loads(row["continuum_frequencies"] or row["structure_frequencies"]))
        row["timoshenko_frequencies"] = json.dumps(list(theory.timoshenko_frequencies[:n]))
    else:
        row["timoshenko_frequencies"] = ""
    if lin is not None and lin.success:
        row.update(lin_t_m=lin.t_m, lin_f_m=lin.f_m, lin_delta_m=lin.delta_m)
        if res.success:
            row.update(lin_err_t_m=lin_err["t_m"], lin_err_f_m=lin_err["f_m"], lin_err_delta_m=lin_err["delta_m"],
                       lin_err_curve=curve_error(res, lin))
    if res.success:
        notes = row_notes(res, err if hertz else lin_err, structure, hertz or any(map(math.isfinite, lin_err.values())),
                          against="the Hertz reference" if hertz else "the linear theory",
                          reference_validity=tuple(ref.validity or ()) if ref.success else ())
        # a differently cut contact against the Hertz reference (err_*) and, on a linear-law row, against the linear
        # theory for its spring (lin_err_*; an unseen cantilever: 20 of 220 tune jobs split where that theory's
        # force only dips to 0.06 % of f_m, lin t_m -29 %, and the row blamed the time step)
        vs_lin = not hertz and lin is not None and lin.success and any(map(math.isfinite, lin_err.values()))
        cuts = [contact_cut(res, ref) if ref.success else "", contact_cut(res, lin, "the linear theory") if vs_lin
                else ""]
        # before an "error against ... beyond" note: a smaller --dt does not move a cut
        at = next((i for i, n in enumerate(notes) if n.startswith("error against")), len(notes))
        notes[at:at] = [c for c in cuts if c]
        if not ref.success:
            notes.insert(0, f"{NO_REFERENCE}: {ref.message}")
        elif gap_note:
            notes.insert(0, gap_note)
        if notes:
            row["message"] = "; ".join(notes)
    return row


#: an error this much larger than the model's own estimate (fraction of the reference) needs a note
UNEXPLAINED_ERROR = 5e-3


def row_notes(res: ImpactResult, err: dict[str, float], structure: dict[str, float], check: bool,
              against: str = "the Hertz reference", reference_validity: tuple[str, ...] = ()) -> list[str]:
    """Validity notes of a row with a result (its `message`, shown with the row): the result's `validity`, the
    adapter's `diagnostics["validity"]` (a string or a list), and, when `check`, every metric whose error `err`
    (against the Hertz reference, or the linear theory for a linear law) exceeds the model's own estimate
    (`structure_err`, else `model_error`) by more than UNEXPLAINED_ERROR: such an error is not the structure
    model's, so it is the time step, the integrator or the engine (never silent), or, where the reference's own
    `reference_validity` says the structure deflects beyond its linear theory, that theory (named first)."""
    notes = [str(v) for v in (res.validity or ())]
    extra = (res.diagnostics or {}).get("validity")
    notes += [extra] if isinstance(extra, str) else [str(v) for v in (extra or ())]
    if check:
        me = _num(res.model_error)
        worst = []
        # structure_err is comparable sign for sign when measured under the law the error is taken against: the
        # adapter says which (`model_error_law`, "linear" for a chain's linear theory under the native spring k);
        # an estimate measured with Hertz on a linear-law row only bounds the magnitude
        law = str((res.diagnostics or {}).get("model_error_law", "hertz"))
        signed = law == ("hertz" if against == "the Hertz reference" else "linear")
        for m in METRICS:
            if math.isfinite(structure[m]):
                excess = abs(err[m] - structure[m]) if signed else abs(err[m]) - abs(structure[m])
            else:
                excess = abs(err[m]) - (abs(me) if math.isfinite(me) else 0.0)
            if math.isfinite(excess) and excess > UNEXPLAINED_ERROR:
                worst.append(f"{m} {100 * err[m]:+.2f} %")
        if worst:
            spring = " under this spring" if signed and against != "the Hertz reference" else ""
            est = (f"its model's own estimate{spring}" if any(math.isfinite(v) for v in structure.values())
                   else f"its model error {100 * me:.2f} %" if math.isfinite(me) else "a model error of 0 (none reported)")
            cause = (f"the time step (dt = {_num(res.dt):.3g} s), the integrator or the engine; try a smaller --dt"
                     if signed else
                     f"the structure model under this spring (its estimate is measured with Hertz contact: a coarse "
                     f"or capped model can be further off under a linear spring, see a sizing note), the time step "
                     f"(dt = {_num(res.dt):.3g} s), the integrator or the engine; try more segments or a smaller --dt")
            bent = [str(v) for v in reference_validity if str(v).startswith("small deflection")]
            if bent:
                cause = (f"the reference's linear structure theory (engines whose structures are geometrically "
                         f"nonlinear differ from it; the reference says: {bent[0]}), or {cause}")
            notes.append(f"error against {against} beyond {est} by more than {100 * UNEXPLAINED_ERROR:g} % "
                         f"({', '.join(worst)}): {cause}")
    return list(dict.fromkeys(n for n in notes if n))


def _contact_stiffness(res: ImpactResult) -> float:
    """k [N/m] of a linear contact law: from `contact_law` (kind "linear"), else the adapter's
    diagnostics; NaN for a Hertz law."""
    law = res.contact_law
    if law is not None and getattr(law, "kind", "") == "linear":
        return _num(getattr(law, "coefficient", math.nan))
    if law is not None:
        return math.nan
    return _num((res.diagnostics or {}).get("contact_stiffness"))


def _as_scene(s):
    import impactval

    return impactval.load_scene(s)      # names and paths are loaded, Scene objects checked (issue 18)


def settings_for(settings: EngineSettings, spec: str) -> EngineSettings:
    """The settings one engine gets (engines.options.options_for): "ENGINE.key" options go to that
    engine only (as "key"), plain "key" options to every engine."""
    from impactval.engines.options import options_for

    return options_for(settings, spec)


# ---------------------------------------------------------------------------- execution
class References:
    """Reference (and linear-theory) solutions, computed once per scene, tolerance and spring."""

    def __init__(self, known: Iterable[tuple[Any, float, ImpactResult]] = (),
                 say: Callable[[str], None] | None = None) -> None:
        from impactval.jobs import canonical_scene

        self._ref: dict[tuple, ImpactResult] = {(canonical_scene(sc), tol): r for sc, tol, r in known}
        self._lin: dict[tuple, ImpactResult | None] = {}
        self._theory: dict[tuple, TheoryGap | None] = {}
        #: scenes with an explicit `modes = n`: the continuum reference (or None when refused) and the linear one
        self._cont: dict[tuple, ImpactResult | None] = {}
        self._lin_cont: dict[tuple, ImpactResult | None] = {}
        #: say(line): told of each new solve ("reference NAME (tol 1e-09): solving ...", then "... solved in 14.6 s"):
        #: at tol 1e-9 one solve can take 10-15 s, during which no row waiting for it can be written
        self.say = say

    def _timed(self, what: str, solve: Callable[[], Any]) -> Any:
        """solve(), said before and after (with its time) when `say` is set."""
        if self.say is None:
            return solve()
        import time

        from impactval.progress import _fmt_s

        self.say(f"{what}: solving ...")
        t0 = time.monotonic()
        res = solve()
        ok = getattr(res, "success", True)
        why = "" if ok else f": {str(getattr(res, 'message', ''))[:160]}"
        self.say(f"{what}: {'solved' if ok else 'failed'} in {_fmt_s(time.monotonic() - t0)}{why}")
        return res

    def theory(self, job: Job) -> TheoryGap | None:
        """The scene's theory gap (beam scenes; None otherwise), computed once per scene and tolerance."""
        from impactval.jobs import canonical_scene

        if getattr(job.scene.target, "kind", "") != "beam":
            return None
        key = (canonical_scene(job.scene), job.tol)
        if key not in self._theory:
            ref = self.ref(job)                 # said on its own first
            theory = getattr(job.scene.target, "theory", "euler-bernoulli")
            other = "timoshenko" if theory == "euler-bernoulli" else "euler-bernoulli"
            scene, base = job.scene, ref
            cont = self.continuum(job)
            if cont is not None:        # an explicit mode count: the theory's effect on the beam the engines model
                from impactval.reference.explicit_modes import continuum_scene

                scene, base = continuum_scene(job.scene), cont
            self._theory[key] = self._timed(f"reference {job.scene.name}, {other} theory for the beam-theory gap (tol "
                                            f"{max(job.tol, THEORY_GAP_TOL):g})",
                                            lambda: theory_gap(scene, base, job.tol))
        return self._theory[key]

    def ref(self, job: Job) -> ImpactResult:
        from impactval.jobs import canonical_scene

        key = (canonical_scene(job.scene), job.tol)
        if key not in self._ref:
            import impactval

            def solve() -> ImpactResult:
                try:
                    return impactval.solve(job.scene, tol=job.tol)
                except ImpactvalError as exc:   # refused (e.g. over its node budget): the rows stand, uncompared
                    return ImpactResult.failed(job.scene.name, "reference", "crashed", str(exc))
            ref = self._timed(f"reference {job.scene.name} (tol {job.tol:g})", solve)
            self._ref[key] = self._explicit_modes(job, key, ref)
        return self._ref[key]

    def _explicit_modes(self, job: Job, key: tuple, ref: ImpactResult) -> ImpactResult:
        """A scene with an explicit `modes = n` (beam, plate): its continuum solved once (`continuum`), and `ref`
        with a validity warning when the n-mode model is far from it (reference/explicit_modes.py); else `ref`."""
        from impactval.reference.explicit_modes import continuum_tol, explicit_count, truncation_check, with_warning

        if explicit_count(job.scene) is None or not ref.success or key in self._cont:
            return ref
        cont, warning = self._timed(
            f"reference {job.scene.name} without its modes = {explicit_count(job.scene)}, the continuum the engines "
            f"model (tol {continuum_tol(job.tol):g})", lambda: truncation_check(job.scene, ref, job.tol))
        self._cont[key] = cont
        return with_warning(ref, warning)

    def continuum(self, job: Job) -> ImpactResult | None:
        """For a scene with an explicit mode count, its continuum reference (None when refused); None otherwise."""
        from impactval.jobs import canonical_scene

        key = (canonical_scene(job.scene), job.tol)
        ref = self.ref(job)
        if key not in self._cont:       # a reference handed in already solved (`known`): checked here, once
            self._ref[key] = self._explicit_modes(job, key, ref)
        return self._cont.get(key)

    def reference_gap(self, job: Job, res: ImpactResult | None = None) -> dict[str, Any] | None:
        """For a scene with an explicit mode count: {"hertz": the n-mode reference's departure from the continuum per
        metric, "linear": the same for the linear theory of the row's spring (a linear-law row), "note": the row note
        when it is significant}; None for other scenes (see make_row)."""
        from impactval.jobs import canonical_scene
        from impactval.reference.explicit_modes import (continuum_scene, explicit_count, significant,
                                                        truncation_gap)

        cont = self.continuum(job)
        if cont is None:
            return None
        ref = self.ref(job)
        out: dict[str, Any] = {"hertz": truncation_gap(ref, cont)}
        n = explicit_count(job.scene)
        if significant(ref, cont, job.tol):
            g = out["hertz"]
            out["note"] = (f"the reference is the scene's {n}-mode model (modes = {n}), {', '.join(f'{m} {100 * g[m]:+.3g} %' for m in METRICS)} "
                           f"from the {job.scene.target.kind}'s continuum that this engine models: that is in this "
                           f"row's structure error; remove `modes` from the scene to compare with the "
                           f"{job.scene.target.kind}")
        lin = self.lin(job, res) if res is not None else None
        if lin is not None and lin.success:
            k = _contact_stiffness(res)
            key = (canonical_scene(job.scene), job.tol, k)
            if key not in self._lin_cont:
                def solve_lin() -> ImpactResult | None:
                    try:
                        return _linear_reference(continuum_scene(job.scene), job.tol, k)
                    except ImpactvalError:
                        return None
                self._lin_cont[key] = self._timed(f"linear-theory reference {job.scene.name} without its modes = {n} "
                                                  f"(tol {job.tol:g})", solve_lin)
            lc = self._lin_cont[key]
            if lc is not None and lc.success:
                out["linear"] = truncation_gap(lin, lc)
        return out

    def solved(self, scene, tol: float) -> ImpactResult | None:
        """The reference of `scene` at `tol` if it was solved (or refused: a failed result holding the refusal),
        else None."""
        from impactval.jobs import canonical_scene

        return self._ref.get((canonical_scene(scene), tol))

    def by_name(self, scenes: Iterable[Any], tol: float) -> dict[str, ImpactResult]:
        """`solved` for each of `scenes` at `tol`, by scene name (those solved or refused only): what a report takes."""
        return {s.name: r for s in scenes if (r := self.solved(s, tol)) is not None}

    def lin(self, job: Job, res: ImpactResult) -> ImpactResult | None:
        """The linear-theory reference for a linear contact law (a native contact), else None."""
        from impactval.jobs import canonical_scene

        if not res.success:
            return None
        law = res.contact_law
        linear = getattr(law, "kind", "") == "linear" if law is not None else job.settings.contact == "native"
        k = _contact_stiffness(res)
        if not (linear and math.isfinite(k) and k > 0):
            return None
        key = (canonical_scene(job.scene), job.tol, k)
        if key not in self._lin:
            self._lin[key] = self._timed(f"linear-theory reference {job.scene.name} (tol {job.tol:g})",
                                         lambda: _linear_reference(job.scene, job.tol, k))
        return self._lin[key]


#: loosest tolerance the other theory's reference is solved to: the gap is a percent-level quantity, and a
#: sweep's tol 1e-9 made a clamped Timoshenko solve take ~8 min before any engine job ran. (At 1e-6 a slender
#: Timoshenko cantilever once ran past 1024 modes for > 10 min and returned t_m +14914 %: that was the reference's
#: Timoshenko root search losing the first mode at 4096 modes, fixed in reference/timoshenko.py; 1e-6 now takes
#: 14 s there, 1e-5 3 s with t_m +0.59 %, f_m -1.11 %, explicit 256/512 modes: f_m -0.91/-0.99 %.)
THEORY_GAP_TOL = 1e-5


def theory_gap(scene, ref: ImpactResult, tol: float) -> TheoryGap:
    """How much the beam theory alone moves this scene's answer: the reference solved with the other
    theory (Timoshenko for an Euler-Bernoulli scene, and vice versa; Cowper's shear coefficient)
    relative to `ref` (solved to max(tol, THEORY_GAP_TOL)), plus the Timoshenko frequencies. A failed solve
    gives NaN, never a failed run."""
    import impactval
    from impactval.reference.structure import structure_modes

    theory = getattr(scene.target, "theory", "euler-bernoulli")
    other = "timoshenko" if theory == "euler-bernoulli" else "euler-bernoulli"
    other_scene = replace(scene, target=replace(scene.target, theory=other))
    try:
        gap = relative_errors(impactval.solve(other_scene, tol=max(tol, THEORY_GAP_TOL)), ref)
    except Exception:  # noqa: BLE001 - the gap is context for the report; the engine rows stand without it
        gap = dict.fromkeys(METRICS, math.nan)
    tim = scene if theory == "timoshenko" else other_scene
    try:
        freqs = tuple(float(w) for w in structure_modes(tim, N_TIMOSHENKO_FREQUENCIES).omega)
    except Exception:  # noqa: BLE001 - as above
        freqs = ()
    return TheoryGap(other, gap, freqs)


def _notify_start(callback, key: str, fn, *args, on_end=None):
    """Run fn(*args) in this pool thread, telling `callback` when it starts and `on_end` when it ends (the job's
    own time: the main thread may still be busy with an earlier row's reference solve)."""
    callback(key)
    try:
        return fn(*args)
    finally:
        if on_end is not None:
            on_end(key)


class _Signals:
    """While active (main thread only): SIGINT and SIGTERM raise _Stop(signum) in the main thread."""

    def __enter__(self):
        self.old = {}
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self.old[sig] = signal.signal(sig, self._raise)
        return self

    @staticmethod
    def _raise(signum, _frame):
        raise _Stop(signum)

    def __exit__(self, *exc):
        for sig, handler in self.old.items():
            signal.signal(sig, handler)
        return False


#: the progress kinds `run` and `execute` take by name (`impactval.progress.make_progress`)
PROGRESS_KINDS = ("auto", "plain", "rich", "none")


def _progress(progress: Any):
    """`execute`'s progress argument as a progress object or None: a kind by name (PROGRESS_KINDS), True ("auto"),
    None or False (silent), or an object with start/done/close (returned as is); anything else a one-line
    ImpactvalError (a string such as "auto", as the README writes it, reached `progress.start` and raised
    AttributeError)."""
    from impactval.progress import make_progress

    if progress is None or progress is False:
        return None
    if progress is True:
        return make_progress("auto")
    if isinstance(progress, str):
        if progress not in PROGRESS_KINDS:
            raise ImpactvalError(f"progress must be one of {', '.join(map(repr, PROGRESS_KINDS))}, True, False, None "
                                 f"or a progress object, got {progress!r}.")
        return make_progress(progress)
    if not all(callable(getattr(progress, name, None)) for name in ("start", "started", "done", "close")):
        raise ImpactvalError(f"progress must be one of {', '.join(map(repr, PROGRESS_KINDS))}, True, False, None or an "
                             f"object with start, started, done and close methods (impactval.progress), got "
                             f"{type(progress).__name__}.")
    return progress


def execute(jobs: Iterable[Job], *, store: Store | str | Path | None = None, workers: int | None = None,
            scheduler: Any = None, force: bool = False, progress: Any = None, out: str | Path | None = None,
            command: str = "", tag: str | None = None, keep_series: bool = False,
            on_row: Callable[[dict[str, Any]], None] | None = None, run_id: str | None = None,
            references: Iterable[tuple[Any, float, ImpactResult]] | References = (),
            theory_gap: bool = True) -> list[dict[str, Any]]:
    """Run engine jobs (reusing stored ones) and return one row per job, in the jobs' order.

    Parameters
    ----------
    jobs : iterable of `impactval.jobs.Job` (scene, engine spec, EngineSettings, reference tol)
    store : Store, path of an SQLite file, a database URL, or None (an in-memory store)
    workers : int, optional
        Engine jobs running at once on this machine (default: the cores); ignored with `scheduler`.
    scheduler : Dask scheduler address ("tcp://host:8786"), Client or LocalCluster, optional
    force : bool
        Recompute jobs already in the store (the new rows replace the stored ones).
    progress : "auto" (a live display on a terminal, lines otherwise), "plain", "rich", True ("auto"), None, False or
        "none" (silent), or an object with start/started/done/close and optionally tick (see `impactval.progress`)
    out : directory, optional; recorded with the run (exports select runs by it)
    command, tag : recorded with the run
    keep_series : bool
        Also store each engine job's time series (compressed; `Store.load_series(job_key)`).
    on_row : callable, optional
        Called with each row dict as soon as it is stored.
    run_id : str, optional
        The run's id (default: a new UUID4).
    references : iterable of (scene, tol, reference ImpactResult), or a `References`, optional
        References the caller has solved already (not solved again for jobs of that scene and tol); a
        `References` given is filled with those this call solves (`run` hands them on to its report).
    theory_gap : bool
        For beam scenes, also solve the reference with the other beam theory once per scene
        (`theory_gap_*`, `timoshenko_frequencies`; ~0.01 s for a simply supported beam, 3-17 s for a
        clamped one as the velocity and the modes needed grow). False leaves those columns empty, e.g.
        for maps over many beam cells whose report does not show them.

    Rows are dicts with the keys of `COLUMNS` (errors as signed fractions). Stored rows with a
    status in `REUSABLE_STATUSES` are reused (crashed and timeout rows are retried). Raises
    `RunInterrupted` (holding the finished rows) on SIGINT/SIGTERM, after killing the engine
    workers and recording the run as interrupted.
    """
    from impactval import executor as ex
    from impactval.store import pack_series

    progress = _progress(progress)
    jobs = list(jobs)
    own_store = not isinstance(store, Store)
    db = Store(store) if own_store else store
    keys = [j.key for j in jobs]
    run_id = run_id or str(uuid.uuid4())
    engines = {j.spec: engine_version(j.spec) for j in jobs}
    db.begin_run(run_id, command, out, engines, reference_version(), tag=tag, n_jobs=len(jobs))
    found = {} if force else db.find(set(keys), REUSABLE_STATUSES)
    rows: dict[str, dict[str, Any]] = {}
    position = {k: i for i, k in reversed(list(enumerate(keys)))}
    for k in found:
        rows[k] = db.put(found[k], run_id=run_id, position=position[k], reused=True)
    n_reused = len(rows)
    todo: dict[str, Job] = {}
    for j, k in zip(jobs, keys):
        if k not in rows and k not in todo:
            todo[k] = j
    if progress is not None:
        progress.start(len(set(keys)), n_reused)
    refs = references if isinstance(references, References) else References(references)

    def finish(k: str, res: ImpactResult, seconds: float) -> None:
        job = todo[k]
        row = make_row(run_id, job.scene, job.spec, job.settings, res, refs.ref(job), refs.lin(job, res), k,
                       theory=refs.theory(job) if theory_gap else None, reference_gap=refs.reference_gap(job, res))
        meta = dict(engine_version=engines[job.spec], adapter_version=_adapter_version(job.spec),
                    reference_version=reference_version(), tol=float(job.tol),
                    settings=json.dumps(job.settings.as_dict(), sort_keys=True, default=repr),
                    diagnostics=json.dumps(res.diagnostics or {}, sort_keys=True, default=repr),
                    validity=json.dumps(list(res.validity or ())))
        stored = db.put(row, run_id=run_id, position=position[k], reused=False, force=force, meta=meta,
                        series=pack_series(res) if keep_series and res.success else None, contacts=res.contacts)
        rows[k] = stored
        if progress is not None:
            progress.done(job.label(), stored, seconds)
            for warning in (res.validity or ()) if hasattr(progress, "note") else ():   # the engine's caveats first
                progress.note(f"  note: {warning}")
        if on_row is not None:
            on_row(stored)

    client = pool = None
    futures: dict[Any, str] = {}
    status = RunStatus.FAILED
    try:
        with _Signals():
            # rows that need no engine process: not installed, unsupported settings
            remote = {}
            for k, job in todo.items():
                res = _unavailable(job.spec, job.scene, job.settings)
                if res is not None:
                    finish(k, res, 0.0)
                else:
                    remote[k] = job
            if remote:
                if scheduler is not None:
                    pool, client = ex.dask_executor(scheduler)
                else:
                    pool = ex.local_executor(workers)
                t_start: dict[str, float] = {}

                t_end: dict[str, float] = {}

                def started(k: str) -> None:
                    t_start[k] = time.monotonic()
                    if progress is not None:
                        progress.started(todo[k].label())

                def ended(k: str) -> None:
                    t_end[k] = time.monotonic()
                    if progress is not None and hasattr(progress, "stopped"):
                        progress.stopped(todo[k].label())

                # grouped by engine: a worker thread keeps serving the engine it has loaded
                for k, job in sorted(remote.items(), key=lambda kv: kv[1].spec):
                    if scheduler is None:       # a local thread can say when the job starts
                        fut = pool.submit(_notify_start, started, k, ex.run_job, job.spec, job.scene, job.settings,
                                          on_end=ended)
                    else:
                        started(k)
                        fut = pool.submit(ex.run_job, job.spec, job.scene, job.settings)
                    futures[fut] = k
                pending = set(futures)
                while pending:
                    done, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
                    if progress is not None and hasattr(progress, "tick"):
                        progress.tick()
                    for fut in done:
                        k = futures[fut]
                        try:
                            res = fut.result()
                        except Exception as err:  # noqa: BLE001 - a lost Dask worker is that job's row
                            job = todo[k]
                            res = ImpactResult.failed(job.scene.name, job.spec, Status.CRASHED,
                                                      f"executor lost the job: {type(err).__name__}: {err}",
                                                      settings=job.settings.as_dict())
                        now = time.monotonic()
                        finish(k, res, t_end.get(k, now) - t_start.get(k, now))
            status = RunStatus.FINISHED
    except (_Stop, KeyboardInterrupt) as stop:
        signum = getattr(stop, "signum", signal.SIGINT)
        status = RunStatus.INTERRUPTED
        if pool is not None:
            for fut in list(futures):
                fut.cancel()                    # queued jobs; on Dask also the ones running remotely
            _shutdown(pool)
        ex.kill_workers()
        done_rows = [rows[k] for k in dict.fromkeys(keys) if k in rows]
        raise RunInterrupted(int(signum), done_rows, run_id, len(set(keys))) from None
    finally:
        if pool is not None:
            _shutdown(pool)
        if scheduler is None or client is not None:
            ex.kill_workers()
        if client is not None:
            client.close()
        n_failed = sum(1 for r in rows.values() if r["status"] in FAILED_STATUSES)
        db.end_run(run_id, status, n_reused, n_failed)
        if progress is not None:
            progress.close()
        if own_store:
            db.close()
    return [rows[k] for k in keys]


def _shutdown(pool) -> None:
    """Stop an executor without waiting, dropping queued jobs (Dask's executor has no cancel_futures)."""
    try:
        pool.shutdown(wait=False, cancel_futures=True)
    except TypeError:
        pool.shutdown(wait=False)


def _adapter_version(spec: str) -> str:
    from impactval.jobs import adapter_version

    return adapter_version(spec)


def unique_scenes(scenes: Iterable) -> list:
    """The scenes once each; two different scenes with one name are refused (rows, reports and baselines key on
    the name: two glass-beam files both named ss_glass_wc_fast ran as indistinguishable rows)."""
    out: dict[str, Any] = {}
    for scene in scenes:
        seen = out.get(scene.name)
        if seen is None:
            out[scene.name] = scene
        elif scene_hash(seen) != scene_hash(scene):
            where = [str(getattr(s, "source", "") or "(built in Python)") for s in (seen, scene)]
            raise ImpactvalError(f"two different scenes are named {scene.name!r} ({where[0]}; {where[1]}): rows and "
                                 f"reports key on the name; give one of them its own `name = \"...\"`.")
    return list(out.values())


def build_jobs(scenes: Iterable, specs: list[str], variants: list[EngineSettings], tol: float) -> list[Job]:
    """Scene-major job list: for each scene (once; unique_scenes), each settings variant, each engine."""
    return [Job(scene, spec, settings_for(v, spec), tol) for scene in unique_scenes(scenes) for v in variants
            for spec in specs]


def run(scenes: Iterable, engines: Iterable[str] | str = ("mujoco",), settings: EngineSettings | None = None, *,
        dt: float | list[float] | None = None, contact: str | None = None, integrator: str | None = None,
        segments: int | None = None, timeout_s: float | None = None, tol: float = 1e-6,
        out: str | Path | None = None, on_row: Callable[[dict[str, Any]], None] | None = None,
        baseline: str | Path | None = None, threshold: float = 0.2, store: Store | str | Path | None = None,
        workers: int | None = None, scheduler: Any = None, force: bool = False, progress: Any = None,
        tag: str | None = None, keep_series: bool = False, command: str | None = None) -> pd.DataFrame:
    """Run the reference and every engine on every scene; one row per (scene, engine, time step).

    Parameters
    ----------
    scenes : iterable of Scene, catalogue names or TOML paths (empty with `tag`: the catalogue
        scenes carrying `tag`)
    engines : engine names ("mujoco", ...) or adapters as "package.module:Class" (or one
        comma-separated string)
    settings : EngineSettings, optional
        Base settings; `dt` [s], `contact`, `integrator`, `segments`, `timeout_s` [s] override it.
        `dt` may be a list: every job then runs once per time step (a speed/accuracy sweep), and the
        report gets a table and a plot of wall time against error.
    tol : float
        Relative tolerance of the reference solutions (Hertz and, for native contact, linear).
    out : directory, optional
        The store defaults to `out/impactval.sqlite`; at the end (also after an interrupt)
        results.csv, frequencies.csv, results.parquet (with pyarrow) are regenerated from the store
        and report.md covers this run's rows.
    on_row : callable, optional
        Called with each row dict as soon as it is stored.
    baseline : path, optional
        results.csv of an earlier run: the report gets a section with marks (see
        `impactval.history`) and the DataFrame's `attrs["baseline"]` holds the comparison.
    threshold : float
        Relative change of a row's score that counts as worse or better (0.2 = 20 %).
    store, workers, scheduler, force, progress, keep_series : see `execute`
    tag : str, optional
        Select catalogue scenes by tag (added to `scenes`); recorded with the run.

    Returns a DataFrame with the columns of `COLUMNS`; errors are signed relative differences
    (engine - reference) / reference; `err_curve` is the whole-curve error (see
    `impactval.compare.curve_error`); `lin_*` compare a linear contact law with the
    linear-theory reference for the same spring (NaN for other contact laws).
    `df.attrs`: run_id, n_reused, store (URL). Raises `RunInterrupted` (with `.rows` a DataFrame
    of the finished jobs) after writing the exports and the report of what finished.
    """
    if isinstance(engines, str):
        engines = [e.strip() for e in engines.split(",") if e.strip()]
    if not isinstance(engines, Iterable):
        raise EngineError(f"engines must be engine names (a list or a comma-separated string), got {engines!r}.")
    # each engine once (`--engines mujoco,mujoco` ran every job twice and counted both in the summary)
    specs = list(dict.fromkeys(resolve_engine(e) for e in engines))
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
    from impactval.engines.options import check_prefixes

    check_prefixes(settings.options, specs)       # "bullet.x": no such engine in this run -> exit 2
    _check_settings_somewhere(specs, settings)
    if not (isinstance(threshold, (int, float)) and math.isfinite(threshold) and threshold > 0):
        raise ImpactvalError(f"threshold must be a positive fraction (0.2 = 20 %), got {threshold!r}.")
    old = None
    if baseline is not None:      # read before this run rewrites what may be the same file
        from impactval.history import load_results

        old = load_results(baseline, SCHEMA_VERSION)
    scene_objs = [_as_scene(s) for s in scenes]
    if tag is not None:
        from impactval.scenarios.scene import load_catalogue

        tagged = load_catalogue(tag)
        if not tagged:
            from impactval.scenarios.scene import load_catalogue as all_scenes

            known = sorted({t for s in all_scenes() for t in s.tags})
            raise ImpactvalError(f"tag {tag!r}: no catalogue scene carries it; known tags: {', '.join(known)}.")
        scene_objs += [s for s in tagged if s.name not in {x.name for x in scene_objs}]
    if not scene_objs:
        raise ImpactvalError("no scene given; see `impactval scenes`.")
    scene_objs = unique_scenes(scene_objs)          # before anything is written
    if out is not None:
        Path(out).mkdir(parents=True, exist_ok=True)
        if store is None:
            store = Path(out) / "impactval.sqlite"
    db = store if isinstance(store, Store) else Store(store)
    jobs = build_jobs(scene_objs, specs, variants, tol)
    cmd = command if command is not None else "run(" + ", ".join(s.name for s in scene_objs) + "; " + \
        ",".join(specs) + ")"
    run_id = str(uuid.uuid4())
    interrupted: RunInterrupted | None = None
    solved = References()          # the references the jobs are compared with, handed on to the report
    try:
        rows = execute(jobs, store=db, run_id=run_id, workers=workers, scheduler=scheduler, force=force, progress=progress,
                       out=out, command=cmd, tag=tag, keep_series=keep_series, on_row=on_row, references=solved)
    except RunInterrupted as err:
        interrupted, rows = err, err.rows
    df = pd.DataFrame(rows, columns=list(COLUMNS))
    df.attrs.update(store=db.url, n_reused=0)
    cmp = None
    if old is not None and len(df):
        from impactval import history

        cmp = history.compare(df, old, threshold)
        df.attrs["baseline"] = cmp
        df.attrs["baseline_rows"] = old
    extra = ""
    if interrupted is not None:
        extra += (f"\n**Interrupted** ({signal.Signals(interrupted.signum).name}): {len(rows)} of "
                  f"{interrupted.total} jobs finished; rerun the same command to run the rest.\n")
    if len(variants) > 1 and len(df):
        from impactval.reports.sweep import speed_accuracy_plot, speed_accuracy_table

        extra += speed_accuracy_table(df)
        if out is not None:
            png = speed_accuracy_plot(df, Path(out) / "speed_accuracy.png")
            if png is not None:
                extra += f"\n![wall time vs error]({png.name})\n"
    notes: list[str] = []
    if out is not None:
        from impactval.reports.build import write_report
        from impactval.store import export

        notes = export(db, out)
        # report.md + figures + report.html, from the store (presentation lives in reports/)
        write_report(db, run_id, out, rows=df, cmp=cmp, baseline=None if baseline is None else f"`{baseline}`",
                     checks=threshold, settings=settings, tol=tol, extra_md=extra,
                     scenes={s.name: s for s in scene_objs},
                     references=solved.by_name(scene_objs, tol))
    df.attrs["notes"] = notes
    info = db.run_info(run_id)
    df.attrs.update(run_id=info["id"], n_reused=info["n_reused"], status=info["status"])
    if not isinstance(store, Store):
        db.close()
    if interrupted is not None:
        interrupted.rows = df
        raise interrupted
    return df


def failed_rows(df: pd.DataFrame) -> pd.Series:
    """Per row: a failing status (see FAILED_STATUSES), or an engine result the reference could not be solved for
    (an ok row without ref_t_m: nothing was checked)."""
    unchecked = (df["status"] == "ok") & df["ref_t_m"].isna() if "ref_t_m" in df else False
    return df["status"].isin(FAILED_STATUSES) | unchecked


def any_failed(df: pd.DataFrame) -> bool:
    """True when a row failed (`failed_rows`): the run exits 1."""
    return bool(failed_rows(df).any())


# presentation lives in reports/ (data flows one way); re-exported for existing callers
from impactval.reports.run_report import markdown_report, table_rows, text_table  # noqa: E402,F401
