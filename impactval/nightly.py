"""`impactval nightly`: run a suite, compare with the last good night, report, and exit as CI expects.

One night = one run of the scenes tagged for the suite on the installed engines with the suite's
documented settings (NIGHTLY_SETTINGS unless overridden). Every night recomputes its jobs (wall
times are measured anew and the environment is exercised), but a night that was killed and is
started again resumes: its job keys carry the night's id, so the rerun reuses what finished and the
history holds each job of the night once. Runs are recorded in the result store with the tag
"nightly/SUITE/NIGHT"; the verdict of each night (exit code, baseline) in the table `nightly_verdicts`.

Exit codes: 0 no regression; 1 a metric got worse past its threshold, a job newly fails, or the
stepping wall time stepped up over several nights; 2 bad input, nothing could run, or nothing
comparable with the baseline (a drifted setup is an error, never a pass). The first night of a
suite has no baseline: it exits 0 (1 when a job failed) and becomes the baseline.

The baseline is the last *good* night of the same suite and store (finished, no regression against
its own baseline; the first night counts as good even when some of its jobs failed: they are the
starting point, and later nights flag only what is new), or the run given with `baseline=`; a
regression therefore stays red until it is fixed, or accepted by running once with `--baseline` set
to the regressed night.
"""
from __future__ import annotations

import hashlib
import math
import signal
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable

import pandas as pd

from impactval.errors import ImpactvalError

#: the suite's documented settings (README, "nightly"): dt = 5e-8 s keeps every engine's explicit
#: beam chain below its stability limit on the catalogue scenes (not on every user scene: a heavy ball on a
#: thin beam needs a finer step, dt = "auto" sizes each engine's own); engine-default structure sizes;
#: Hertz contact injected
NIGHTLY_SETTINGS = {"dt": 5e-8, "contact": "hertz", "timeout_s": 600.0}
#: nights shown in the trend plots and searched for wall-time steps
HISTORY_NIGHTS = 14
TAG_PREFIX = "nightly"


@dataclass(frozen=True)
class NightlyOutcome:
    """What a night produced: `exit_code` (0/1/2), `message` (one line), run and night ids, the
    baseline run id (None on a first night), rows, comparison, wall-time trend and report paths."""

    exit_code: int
    message: str
    run_id: str
    night: str
    baseline_run_id: str | None
    rows: pd.DataFrame
    cmp: pd.DataFrame | None
    trend: pd.DataFrame
    report: Path | None
    html: Path | None
    flagged: list[str] = field(default_factory=list)


def _night_job(job, night: str):
    """The job with a key salted by the night (see module doc)."""
    from impactval.jobs import Job, job_key

    @dataclass(frozen=True)
    class NightJob(Job):
        night: str = ""

        @property
        def key(self) -> str:
            return hashlib.sha256(f"{job_key(self)}\x1fnight={self.night}".encode()).hexdigest()[:32]

    return NightJob(job.scene, job.spec, job.settings, job.tol, night)


# ---------------------------------------------------------------------------- the store's nightly side
def _verdicts(store):
    """The `nightly_verdicts` table (created on first use): run_id, suite, night, exit_code,
    baseline_run_id, message, checks (the thresholds used, as --fail-on texts), good (may serve as a baseline:
    no regression against its own baseline, or the first night of the suite, and something was comparable)."""
    import sqlalchemy as sa

    md = sa.MetaData()
    table = sa.Table("nightly_verdicts", md, sa.Column("run_id", sa.String(36), primary_key=True),
                     sa.Column("suite", sa.Text), sa.Column("night", sa.Text), sa.Column("exit_code", sa.Integer),
                     sa.Column("baseline_run_id", sa.Text), sa.Column("message", sa.Text),
                     sa.Column("checks", sa.Text), sa.Column("good", sa.Boolean))
    md.create_all(store.engine, checkfirst=True)
    return table


def nightly_runs(store, suite: str) -> pd.DataFrame:
    """Every nightly run of `suite` in the store, oldest first: id, night, status, started_at, ended_at,
    exit_code (NaN while unknown), baseline_run_id, message."""
    import sqlalchemy as sa

    v = _verdicts(store)
    runs = store.runs
    prefix = f"{TAG_PREFIX}/{suite}/"
    q = (sa.select(runs.c.id, runs.c.tag, runs.c.status, runs.c.started_at, runs.c.ended_at, v.c.exit_code,
                   v.c.baseline_run_id, v.c.message, v.c.checks, v.c.good)
         .select_from(runs.outerjoin(v, v.c.run_id == runs.c.id))
         .where(runs.c.tag.like(prefix.replace("%", r"\%").replace("_", r"\_") + "%", escape="\\"))
         .order_by(runs.c.started_at, runs.c.id))
    with store.engine.connect() as c:
        recs = [dict(r) for r in c.execute(q).mappings()]
    df = pd.DataFrame(recs, columns=["id", "tag", "status", "started_at", "ended_at", "exit_code", "baseline_run_id",
                                     "message", "checks", "good"])
    df["night"] = df["tag"].str.slice(len(prefix))
    return df


def _record_verdict(store, run_id: str, suite: str, night: str, code: int, baseline: str | None, msg: str,
                    checks: str = "", good: bool = False) -> None:
    v = _verdicts(store)
    values = dict(run_id=run_id, suite=suite, night=night, exit_code=code, baseline_run_id=baseline, message=msg,
                  checks=checks, good=bool(good))
    with store.engine.begin() as c:
        c.execute(v.delete().where(v.c.run_id == run_id))
        c.execute(v.insert().values(**values))


def resume_night(runs: pd.DataFrame) -> str | None:
    """The night to resume: the newest nightly run's night when that run did not finish (killed or
    interrupted) and no finished run of that night exists; else None (a new night)."""
    if not len(runs):
        return None
    last = runs.iloc[-1]
    if str(last["status"]) == "finished":
        return None
    done = runs[(runs["night"] == last["night"]) & (runs["status"] == "finished")]
    return None if len(done) else str(last["night"])


def last_good(runs: pd.DataFrame, night: str) -> pd.Series | None:
    """The newest finished run of another night marked good (no regression against its own baseline,
    or the first night of the suite: failures it had are the starting point), else None."""
    good = runs["good"].map(lambda x: bool(x) if x is not None and x == x else False)
    ok = runs[(runs["status"] == "finished") & (runs["night"] != night) & good]
    return ok.iloc[-1] if len(ok) else None


def history_rows(store, runs: pd.DataFrame, current_run: str, nights: int = HISTORY_NIGHTS,
                 checks=None) -> pd.DataFrame:
    """Rows of the last `nights` finished runs (plus the current one), oldest first, with run_index,
    night (start time, for plot labels) and mark (each night against the finished night before it)."""
    from impactval import history

    done = runs[(runs["status"] == "finished") | (runs["id"] == current_run)]
    done = done.drop_duplicates("night", keep="last").tail(nights)
    frames, prev = [], None
    for i, (_, run) in enumerate(done.iterrows()):
        rows = store.rows(run_id=run["id"])
        if not len(rows):
            continue
        if prev is not None:
            cmp = history.compare(rows, prev, checks)
            rows = rows.assign(mark=list(cmp["mark"]))
        else:
            rows = rows.assign(mark="")
        frames.append(rows.assign(run_index=i, night=str(run["started_at"])[5:16].replace("T", " "),
                                  run_id=run["id"]))
        prev = rows
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


# ---------------------------------------------------------------------------- what a report's header says
def suite_line(suite: str, n_scenes: int, n_engines: int, night: str) -> str:
    """The header's suite fact: 'nightly (7 scenes x 3 engines), night 3f2a...' (no scene: a stored night killed
    before any job finished, whose scenes the store does not hold)."""
    if not n_scenes:
        return f"{suite} ({n_engines} engines; scenes unknown: no job finished), night {night}"
    return f"{suite} ({n_scenes} scenes x {n_engines} engines), night {night}"


#: stored settings that decide a job's numbers besides its time step and engine options: a run whose jobs
#: disagree on one of them (a sweep over integrators or structure sizes) has no single settings line
_ONE_SETTING = ("contact", "integrator", "segments", "modes", "tail")
#: stored settings the header's settings line shows (reports.run_report.header_section; dt from the rows first)
_SHOWN_SETTINGS = ("dt", "contact", "integrator", "segments", "timeout_s")


def stored_settings(store, run_id: str):
    """The EngineSettings a stored run ran with, rebuilt from the settings stored with its jobs (those it computed
    first: a reused job keeps the timeout of the run that computed it), for its re-rendered report's header as
    the live report had it. Engine options are left out (split per engine; the header does not show them). None
    when no job recorded the shown settings or the jobs disagree beyond dt (a sweep's grid)."""
    from dataclasses import fields

    from impactval.engines.base import EngineSettings

    recs = [r for r in store.run_settings(run_id) if all(k in r for k in _SHOWN_SETTINGS)]
    if not recs or len({tuple(repr(r.get(k)) for k in _ONE_SETTING) for r in recs}) > 1:
        return None
    names = {f.name for f in fields(EngineSettings)} - {"options"}
    try:
        return EngineSettings(**{k: v for k, v in recs[0].items() if k in names})
    except (ImpactvalError, TypeError):      # a record this impactval cannot read: no settings line, not a failure
        return None


# ---------------------------------------------------------------------------- an interrupted night
def _planned(scene: str, engine: str, scene_hash: str, job_key: str, version: str, settings) -> dict[str, Any]:
    """One job a night was to run, as `with_not_run` takes it (dt [s], NaN at "auto": each engine would have
    chosen its own)."""
    dt = getattr(settings, "dt", math.nan) if settings is not None else math.nan
    return dict(scene=scene, engine=engine, scene_hash=scene_hash, job_key=job_key, version=version,
                contact=getattr(settings, "contact", "") if settings is not None else "",
                dt=float(dt) if isinstance(dt, (int, float)) else math.nan)


def with_not_run(rows: pd.DataFrame, planned: Iterable[dict[str, Any]], message: str, run_id: str) -> pd.DataFrame:
    """`rows` of an interrupted night (run `run_id`) in the order of `planned` (its jobs: scene, engine,
    scene_hash, job_key, version, contact, dt), with a row of status `interrupted` (reference.result.Status.INTERRUPTED:
    the run was stopped before this job finished), no result and `message` for each planned (scene, engine) without
    a row: an engine that never ran is listed as such, not left out of the report."""
    from impactval.reference.result import Status
    from impactval.store import COLUMN_TYPES, SCHEMA_VERSION

    recs = rows.to_dict("records")
    by_pair: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in recs:
        by_pair.setdefault((str(r["scene"]), str(r["engine"])), []).append(r)
    out: list[dict[str, Any]] = []
    for p in planned:
        pair = (str(p["scene"]), str(p["engine"]))
        if pair in by_pair:
            out += by_pair.pop(pair)
            continue
        row: dict[str, Any] = {c: "" if t == "text" else math.nan for c, t in COLUMN_TYPES.items()}
        row.update({k: p.get(k, row[k]) for k in ("scene", "engine", "scene_hash", "job_key", "version", "contact",
                                                  "dt")},
                   schema_version=SCHEMA_VERSION, run_id=run_id,
                   status=str(Status.INTERRUPTED), message=message)
        by_pair[pair] = []          # once per pair
        out.append(row)
    out += [r for pair_rows in by_pair.values() for r in pair_rows]      # rows of no planned job (none expected)
    return pd.DataFrame(out, columns=list(COLUMN_TYPES))


def _interrupted_verdict(how: str, n_done: int, n_jobs: int, never_ran: Iterable[str], fix: str) -> str:
    """Why a night that did not finish has no verdict (the header says "none: " before it, the Verdict section
    "No verdict: "): it is incomplete; `never_ran`: the engines none of whose jobs finished."""
    never_ran = list(never_ran)
    lost = f" (no job of {', '.join(never_ran)} finished)" if never_ran else ""
    return f"the night was {how} with {n_done} of {n_jobs} jobs finished{lost}, so it is incomplete; {fix}"


def _stored_night_rows(store, run: pd.Series, rows: pd.DataFrame) -> tuple[pd.DataFrame, int]:
    """A stored night that did not finish (interrupted: stopped, or killed and found gone): its rows plus an
    `interrupted` row for each engine it was to run (the run's recorded engines) that has no row for a scene of the
    night, and the number of jobs it planned (the run's n_jobs)."""
    info = store.run_info(str(run["id"]))
    settings = stored_settings(store, str(run["id"]))
    scenes = list(dict.fromkeys(rows["scene"].astype(str)))
    hashes = dict(zip(rows["scene"].astype(str), rows["scene_hash"].astype(str)))
    engines = list(dict.fromkeys([*rows["engine"].astype(str), *(info.get("engines") or {})]))
    versions = {**(info.get("engines") or {}), **dict(zip(rows["engine"].astype(str), rows["version"].astype(str)))}
    planned = [_planned(s, e, hashes[s], "", versions.get(e, ""), settings) for s in scenes for e in engines]
    message = ("did not run: the night was interrupted (stopped, or killed and found gone) before this job finished; "
               "rerun the night's command to resume it")
    total = int(run["n_jobs"]) if pd.notna(run["n_jobs"]) else len(planned)
    return with_not_run(rows, planned, message, str(run["id"])), max(total, len(planned))


# ---------------------------------------------------------------------------- the command
def nightly(scenes: Iterable | None = None, engines: Iterable[str] | str | None = None, settings=None, *,
            suite: str = "nightly", store: Any = None, out: str | Path = "impactval-nightly",
            fail_on: Iterable[str] = (), threshold: float = 0.2, baseline: str | None = None,
            history_nights: int = HISTORY_NIGHTS, tol: float = 1e-6, workers: int | None = None,
            scheduler: Any = None, progress: Any = None, on_row: Callable[[dict], None] | None = None,
            command: str = "", html: bool = True) -> NightlyOutcome:
    """Run one night of `suite` and compare it with the last good night.

    Parameters
    ----------
    scenes : scene names or paths, optional (default: the catalogue scenes tagged `suite`)
    engines : engine names, optional (default: every installed engine)
    settings : EngineSettings, optional (default: NIGHTLY_SETTINGS); `dt="auto"` lets each engine size its own
        stable step (each row records the step it ran, so nights at auto compare with each other)
    store : result store path or URL (default: OUT/impactval.sqlite)
    out : directory for report.md, report.html, figures and the exports
    fail_on : thresholds such as "f_m:+20%" or "curve:+0.5pp" (impactval.history.parse_fail_on);
        metrics not named use `threshold` (relative growth of |error|, 0.2 = 20 %)
    baseline : run id to compare with (default: the last good night)
    history_nights : nights in the trend plots and the wall-time step search
    Raises ImpactvalError for bad input; returns a NightlyOutcome (exit_code 2 also for nothing
    comparable and nothing run, with the report written).
    """
    from impactval import history
    from impactval.engines import ENGINES, engine_status
    from impactval.engines.base import EngineSettings
    from impactval.reports.build import write_report
    from impactval.jobs import engine_version
    from impactval.runner import (References, RunInterrupted, build_jobs, execute, failed_rows, resolve_engine,
                                  scene_hash)
    from impactval.scenarios.scene import catalogue_names, load_catalogue
    from impactval.store import Store, export

    checks = history.thresholds(fail_on, threshold)
    if scenes:
        from impactval.checks import load_scenes

        scenes = list(scenes)
        # every refused scene at once, a line each, and nothing run (as `run` and `sweep`)
        loaded = iter(load_scenes([s for s in scenes if not hasattr(s, "target")]))
        scene_objs = [s if hasattr(s, "target") else next(loaded) for s in scenes]
    else:
        scene_objs = load_catalogue(suite)
        if not scene_objs:
            tags = sorted({t for n in catalogue_names() for t in impactval_tags(n)})
            raise ImpactvalError(f"--suite {suite!r}: no catalogue scene carries this tag; tags: {', '.join(tags)}.")
    from impactval.runner import unique_scenes

    scene_objs = unique_scenes(scene_objs)          # two different scenes with one name: refused before any write
    if engines is None:
        specs = [n for n, s in engine_status().items() if s == "ok"]
        if not specs:
            raise ImpactvalError("nothing can run: no engine is installed; pip install 'impactval[mujoco]' (or "
                                 f"pybullet, exudyn), or name engines with --engines ({', '.join(ENGINES)}).")
    else:
        if isinstance(engines, str):
            engines = [e.strip() for e in engines.split(",") if e.strip()]
        specs = [resolve_engine(e) for e in engines]
        if not specs:
            raise ImpactvalError("--engines: give at least one engine.")
    settings = settings or EngineSettings(**NIGHTLY_SETTINGS)
    from impactval.engines.options import check_prefixes
    from impactval.runner import _check_settings_somewhere

    check_prefixes(settings.options, specs)           # "bullet.x": no such engine tonight -> exit 2
    _check_settings_somewhere(specs, settings)        # settings no engine accepts -> exit 2 before any job
    out = Path(out)
    db = Store(store if store is not None else out / "impactval.sqlite")
    try:
        runs = nightly_runs(db, suite)
        if baseline is not None and baseline not in set(runs["id"]):
            raise ImpactvalError(f"--baseline {baseline!r}: no nightly run of suite {suite!r} with this id in "
                                 f"{db.url}; runs: {', '.join(runs['id'].tail(5)) or 'none'}.")
        night = resume_night(runs) or uuid.uuid4().hex[:12]
        resumed = night in set(runs["night"])
        jobs = [_night_job(j, night) for j in build_jobs(scene_objs, specs, [settings], tol)]
        run_id = str(uuid.uuid4())
        solved = References()      # the references the jobs are compared with, handed on to the report
        try:
            rows = execute(jobs, store=db, workers=workers, scheduler=scheduler, progress=progress, out=out,
                           command=command or f"impactval nightly --suite {suite}", tag=f"{TAG_PREFIX}/{suite}/{night}",
                           keep_series=True, on_row=on_row, run_id=run_id, references=solved)
        except RunInterrupted as stop:
            export(db, out)
            how = f"interrupted by {signal.Signals(stop.signum).name}"
            done = db.rows(run_id=stop.run_id)
            # every job the night was to run: one that never finished is a row saying so, not a missing engine
            planned = [_planned(j.scene.name, j.spec, scene_hash(j.scene), j.key, engine_version(j.spec), j.settings)
                       for j in jobs]
            never_ran = [e for e in specs if e not in set(done["engine"].astype(str))]
            verdict = _interrupted_verdict(how, len(done), stop.total, never_ran,
                                           "rerun the same command to resume the night")
            write_report(db, stop.run_id, out, title=f"impactval nightly ({suite}): interrupted", settings=settings,
                         rows=with_not_run(done, planned, f"did not run: the night was {how} before this job "
                                                          f"finished; rerun the same command to resume the night",
                                          stop.run_id),
                         tol=tol, html=html, extra_info={"suite": suite_line(suite, len(scene_objs), len(specs), night),
                                                         "verdict": f"none: {verdict}"},
                         extra_md=f"\n## Verdict\n\nNo verdict: {verdict}.\n",
                         scenes={s.name: s for s in scene_objs}, references=solved.by_name(scene_objs, tol))
            raise
        df = pd.DataFrame(rows)
        export(db, out)
        runs = nightly_runs(db, suite)
        base = runs[runs["id"] == baseline].iloc[-1] if baseline is not None else last_good(runs, night)
        hist = history_rows(db, runs, run_id, history_nights, checks)
        trend = history.wall_time_steps(hist, checks["wall_time"].rel) if len(hist) else history.wall_time_steps(None)
        cmp = None
        code, message, good = 0, "", False
        failed = failed_rows(df)
        ran = ~df["status"].isin(["not-installed", "skipped"])
        if not ran.any():
            code = 2
            message = ("nothing could run: every job is not-installed or skipped ("
                       + "; ".join(sorted(set(df["message"].astype(str))))[:400] + ")")
        elif base is None:
            code = 1 if failed.any() else 0
            good = True
            message = "first night of this suite in the store: no baseline yet; this run becomes the baseline"
            if failed.any():
                message += (f"; {int(failed.sum())} jobs failed (exit 1 tonight; later nights flag only what is "
                            f"new)")
        else:
            base_rows = db.rows(run_id=base["id"])
            cmp = history.compare(df, base_rows, checks)
            slower = trend[trend["state"] == "slower"]
            if history.comparable(cmp) == 0:
                code = 2
                diff = history.differing_keys(df, base_rows)
                message = (f"nothing comparable with the baseline run {base['id']}: none of the {len(df)} rows has a "
                           f"baseline row with the same scene, engine, settings and scene hash"
                           + (f"; differing: {' | '.join(diff)}" if diff else "")
                           + ". Use the baseline's settings, or start a new history (another --store).")
            elif history.regressions(cmp) or len(slower):
                code = 1
                n_plus, n_bang = int((cmp["mark"] == "+").sum()), int((cmp["mark"] == "!").sum())
                message = f"regression against the baseline run {base['id']}: {n_plus} worse, {n_bang} newly failing"
                if len(slower):
                    message += f", {len(slower)} slower over the last nights"
            else:
                good = True
                counts = history.summary_counts(cmp)
                skipped = (f" ({counts['skipped_both']} of them skipped in both nights)" if counts["skipped_both"]
                           else "")
                message = (f"no regression against the baseline run {base['id']} ({history.comparable(cmp)} of "
                           f"{len(cmp)} rows compared{skipped}, {counts['changed']} changed, {counts['-']} better, "
                           f"{counts['*']} fixed)")
        base_id = None if base is None else str(base["id"])
        _record_verdict(db, run_id, suite, night, code, base_id, message, history.check_names(checks), good)
        verdict_md = (f"\n## Verdict\n\nExit code **{code}**: {message}.\n"
                      + (f"\nResumed night {night}: the jobs that finished before the interruption were reused.\n"
                         if resumed else ""))
        report, page = write_report(
            db, run_id, out, title=f"impactval nightly ({suite})", rows=df, cmp=cmp,
            baseline=None if base is None else f"run `{base['id']}` of {str(base['started_at'])[:19]}",
            checks=checks, history=hist, trend=trend, settings=settings, tol=tol, html=html,
            scenes={s.name: s for s in scene_objs}, references=solved.by_name(scene_objs, tol),
            extra_info={"suite": suite_line(suite, len(scene_objs), len(specs), night),
                        "verdict": f"exit {code}: {message}"},
            extra_md=verdict_md)
        flagged = history.flagged_lines(cmp) if cmp is not None else []
        flagged += [f"  + {r['scene']} / {r['engine']}: stepping wall time x{r['ratio']:.2f} over the last "
                    f"{history.WALL_WINDOW} nights" for _, r in trend[trend["state"] == "slower"].iterrows()]
        return NightlyOutcome(code, message, run_id, night, base_id, df, cmp, trend, report, page, flagged)
    finally:
        db.close()


def impactval_tags(name: str) -> tuple[str, ...]:
    """Tags of a catalogue scene."""
    import impactval

    return tuple(impactval.load_scene(name).tags)


# ---------------------------------------------------------------------------- impactval report
def _open_store(where: str):
    from impactval.store import Store

    text = str(where)
    if "://" in text:
        return Store(text), None
    p = Path(text)
    if p.is_dir():
        db = p / "impactval.sqlite"
        if not db.is_file():
            raise ImpactvalError(f"{p}: no impactval.sqlite in this directory; give the --out directory of a run, "
                                 "an SQLite store file or a database URL.")
        return Store(db), p
    if not p.is_file():
        raise ImpactvalError(f"{p}: no such store file or directory; give the --out directory of a run, an SQLite "
                             "store file or a database URL.")
    return Store(p), None


def all_runs(store) -> pd.DataFrame:
    """Every run in the store, oldest first (id, command, tag, status, started_at, ended_at, n_jobs)."""
    import sqlalchemy as sa

    r = store.runs
    q = sa.select(r.c.id, r.c.command, r.c.tag, r.c.status, r.c.started_at, r.c.ended_at, r.c.n_jobs).order_by(
        r.c.started_at, r.c.id)
    with store.engine.connect() as c:
        return pd.DataFrame([dict(x) for x in c.execute(q).mappings()],
                            columns=["id", "command", "tag", "status", "started_at", "ended_at", "n_jobs"])


def is_dt_sweep(rows: pd.DataFrame) -> bool:
    """True when one scene/engine/contact/integrator ran at several time steps (`run --dt a,b,c`); a run at
    dt = auto has one step per engine and scene, several in all."""
    if not len(rows) or "dt" not in rows:
        return False
    d = rows.assign(_dt=pd.to_numeric(rows["dt"], errors="coerce")).dropna(subset=["_dt"])
    keys = [k for k in ("scene", "engine", "contact", "integrator") if k in d]
    return bool(len(d)) and bool((d.groupby(keys, dropna=False)["_dt"].nunique() > 1).any())


def render_stored(where: str, run_id: str | None = None, out: str | Path | None = None, tol: float | None = None,
                  list_only: bool = False) -> tuple[list[str], list[Path | None]]:
    """Re-render the report of a stored run (a nightly run with its comparison and trends as on its
    night). `tol`: the reference tolerance of the report's reference values (default: the one the run's rows were
    compared at, so a sweep at 1e-9 is not shown next to references re-solved at 1e-6). Returns (lines for the
    console, written paths)."""
    from impactval import history
    from impactval.reports.build import write_report

    db, directory = _open_store(where)
    try:
        runs = all_runs(db)
        if list_only:
            return [f"{r['id']}  {str(r['started_at'])[:19]}  {r['status']:11s} {r['n_jobs']:4d} jobs  "
                    f"{r['tag'] or ''}  {r['command']}" for _, r in runs.iterrows()], []
        if not len(runs):
            raise ImpactvalError(f"{db.url}: the store holds no run.")
        if run_id is None:
            run = runs.iloc[-1]
        else:
            match = runs[runs["id"].str.startswith(run_id)]
            if len(match) != 1:
                raise ImpactvalError(f"--run {run_id!r}: {'no' if not len(match) else 'more than one'} run with this "
                                     f"id in {db.url}; see `impactval report {where} --list`.")
            run = match.iloc[0]
        dest = Path(out) if out is not None else directory if directory is not None else Path("impactval-report")
        tag = str(run["tag"] or "")
        if tag.startswith(f"{TAG_PREFIX}/"):
            suite = tag.split("/")[1]
            nruns = nightly_runs(db, suite)
            upto = nruns[nruns["started_at"] <= run["started_at"]]
            me = nruns[nruns["id"] == run["id"]].iloc[-1]
            rows = db.rows(run_id=run["id"])
            tol = tol if tol is not None else (db.run_tol(run["id"]) or 1e-6)
            cmp, base_label = None, None
            base_id = me["baseline_run_id"]
            checks = history.thresholds(str(me["checks"]).split(", ") if isinstance(me["checks"], str) and me["checks"]
                                        else ())
            if isinstance(base_id, str) and base_id:
                base = nruns[nruns["id"] == base_id]
                cmp = history.compare(rows, db.rows(run_id=base_id), checks)
                base_label = f"run `{base_id}`" + (f" of {str(base['started_at'].iloc[0])[:19]}" if len(base) else "")
            hist = history_rows(db, upto, run["id"], checks=checks)
            trend = history.wall_time_steps(hist, checks["wall_time"].rel) if len(hist) else history.wall_time_steps(None)
            code = me["exit_code"]
            verdict = "" if pd.isna(code) else f"\n## Verdict\n\nExit code **{int(code)}**: {me['message']}.\n"
            title, info = f"impactval nightly ({suite})", {}
            if not pd.isna(code):
                info["verdict"] = f"exit {int(code)}: {me['message']}"
            elif str(run["status"]) == "interrupted":
                # as the live report of an interrupted night: every engine it was to run, no verdict, incomplete
                n_done, ran = len(rows), set(rows["engine"].astype(str))
                rows, n_jobs = _stored_night_rows(db, run, rows)
                never_ran = [e for e in (db.run_info(run["id"]).get("engines") or {}) if e not in ran]
                why = _interrupted_verdict("interrupted", n_done, n_jobs, never_ran,
                                           "rerun the night's command to resume it")
                title += ": interrupted"
                info["verdict"] = f"none: {why}"
                verdict = f"\n## Verdict\n\nNo verdict: {why}.\n"
            engines = db.run_info(run["id"]).get("engines") or {}
            info["suite"] = suite_line(suite, rows["scene"].nunique(), len(engines) or rows["engine"].nunique(),
                                       me["night"])
            paths = write_report(db, run["id"], dest, title=title, rows=rows, cmp=cmp, baseline=base_label,
                                 checks=checks, history=hist, trend=trend, tol=tol, extra_info=info, extra_md=verdict,
                                 settings=stored_settings(db, run["id"]))
        else:
            rows = db.rows(run_id=run["id"])
            tol = tol if tol is not None else (db.run_tol(run["id"]) or 1e-6)
            extra = ""
            if is_dt_sweep(rows):      # a speed/accuracy sweep (not dt = auto: each engine its own step)
                from impactval.reports.sweep import speed_accuracy_plot, speed_accuracy_table

                extra = speed_accuracy_table(rows)
                dest.mkdir(parents=True, exist_ok=True)
                png = speed_accuracy_plot(rows, dest / "speed_accuracy.png")
                if png is not None:
                    extra += f"\n![wall time vs error]({png.name})\n"
            paths = write_report(db, run["id"], dest, rows=rows, tol=tol, extra_md=extra,
                                 settings=stored_settings(db, run["id"]))
        return [f"run {run['id']} ({run['status']}, {str(run['started_at'])[:19]})"], list(paths)
    finally:
        db.close()
