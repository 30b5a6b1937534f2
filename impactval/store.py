"""The result store: every run and every engine job, in one database (issue 12).

SQLAlchemy Core over SQLite (the default: one file, WAL journal, every write one transaction, so
concurrent runs lose nothing) or any URL SQLAlchemy understands (`postgresql://...`). Tables:

- `schema_version(version)`: one row, `STORE_SCHEMA_VERSION`.
- `runs`: `id` (UUID text), `command`, `tag`, `out` (absolute --out directory or ""),
  `impactval_version`, `reference_version` (hash of the reference solver's source), `machine`,
  `python`, `started_at` / `ended_at` (UTC, ISO 8601 text), `status` (`RunStatus`: running,
  finished, interrupted, failed), `n_jobs`, `n_reused` (jobs taken from the store), `n_failed`,
  `pid` and `host` of the process that runs it. A run killed with SIGKILL never says how it ended:
  whenever a store is opened, a "running" run of this host whose process is gone (or whose pid now
  belongs to a process started after the run) becomes "interrupted", `ended_at` left empty
  (`Store.mark_dead_runs`). The two columns are added to an older store's runs table when it is
  opened; its runs without a pid stay as they are.
- `run_engines(run_id, engine, version)`: the version of each engine a run used.
- `jobs`: keyed by `job_key` (see `impactval.jobs`); one column per row field of `COLUMN_TYPES`
  (SI units, errors as signed fractions), plus `engine_version`, `adapter_version`,
  `reference_version`, `tol`, `settings`, `diagnostics`, `validity` (JSON text), `created_at` and
  `series` (optional: the engine's time series, `numpy.savez_compressed` bytes; see `load_series`).
  Columns added since (`ADDED_JOB_COLUMNS`) are added to an older store's jobs table when it is opened.
- `contacts(job_key, idx, t_start, t_end, f_max, delta_max)`: every contact phase of a job [s, N, m].
- `run_jobs(run_id, job_key, position, reused)`: which jobs each run used, in its order.

Exports (`export`) regenerate `results.csv` (and `results.parquet` when pyarrow is installed, and
`frequencies.csv`) from the store; their columns are documented in docs/results.md.
"""
from __future__ import annotations

import enum
import io
import json
import math
import os
import platform
import socket
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterable

import pandas as pd

from impactval.errors import ImpactvalError

STORE_SCHEMA_VERSION = 1
#: results row schema (results.csv `schema_version`; 3: errors exported in %, job_key, new columns;
#: 4: structure_err/numerics_err/theory_gap/vs_mujoco_c columns added, every schema-3 column unchanged)
SCHEMA_VERSION = 4
#: results schemas whose rows can be compared with this one (impactval.history): 4 only added columns
COMPARABLE_SCHEMAS = (3, 4)


class RunStatus(str, enum.Enum):
    """How a run ended (the `runs.status` column)."""

    RUNNING = "running"            # started; still running (or killed on another host: not checkable here)
    FINISHED = "finished"          # every job has a row
    INTERRUPTED = "interrupted"    # stopped by Ctrl-C / SIGTERM, or its process found gone (SIGKILL: no ended_at)
    FAILED = "failed"              # the run itself raised (a bug or bad input found late)

    def __str__(self) -> str:
        return self.value


_T, _I, _F = "text", "int", "float"
#: every field of a results row and its type (units: s, N, m, J, m/s; errors are signed fractions)
COLUMN_TYPES: dict[str, str] = {
    "schema_version": _I, "job_key": _T, "run_id": _T, "scene": _T, "scene_hash": _T, "engine": _T, "version": _T,
    "model": _T, "contact": _T, "integrator": _T, "dt": _F, "segments": _T, "status": _T, "message": _T,
    "t_m": _F, "f_m": _F, "delta_m": _F, "ref_t_m": _F, "ref_f_m": _F, "ref_delta_m": _F,
    "err_t_m": _F, "err_f_m": _F, "err_delta_m": _F, "err_curve": _F,
    "contact_law": _T, "contact_stiffness": _F, "lin_t_m": _F, "lin_f_m": _F, "lin_delta_m": _F,
    "lin_err_t_m": _F, "lin_err_f_m": _F, "lin_err_delta_m": _F, "lin_err_curve": _F,
    "rebound_velocity": _F, "energy_error": _F, "dt_limit": _F, "model_error": _F,
    "n_contacts": _I, "n_steps": _I, "steps_per_s": _F,
    "wall_time_build_s": _F, "wall_time_step_s": _F, "wall_time_s": _F,
    "structure_frequencies": _T, "continuum_frequencies": _T,
    # schema 4 (issue 17 item 2, issue 19): the error split per metric, the scene's theory gap, C vs Warp
    **{f"{part}_{m}": _F for part in ("structure_err", "numerics_err", "theory_gap", "vs_mujoco_c")
       for m in ("t_m", "f_m", "delta_m")},
    "beam_theory": _T, "timoshenko_frequencies": _T,
}
#: job columns added after stores existed (results schema 4): added to an older store's jobs table when
#: it is opened, its old rows reading NaN / "" there (as the runs table gets pid and host)
ADDED_JOB_COLUMNS = tuple(c for c in COLUMN_TYPES if c.startswith(
    ("structure_err_", "numerics_err_", "theory_gap_", "vs_mujoco_c_")) or c in ("beam_theory",
                                                                                  "timoshenko_frequencies"))
#: fraction columns exported in % as NAME_pct
PERCENT_COLUMNS = ("err_t_m", "err_f_m", "err_delta_m", "err_curve", "lin_err_t_m", "lin_err_f_m",
                   "lin_err_delta_m", "lin_err_curve", "energy_error", "model_error",
                   *(c for c in COLUMN_TYPES if c.startswith(("structure_err_", "numerics_err_", "theory_gap_",
                                                              "vs_mujoco_c_"))))
#: list-valued columns kept out of results.csv (they go to frequencies.csv, one row per mode)
LIST_COLUMNS = ("structure_frequencies", "continuum_frequencies", "timoshenko_frequencies")
#: results.csv / results.parquet columns, in order
EXPORT_COLUMNS = tuple(f"{c}_pct" if c in PERCENT_COLUMNS else c for c in COLUMN_TYPES if c not in LIST_COLUMNS)


#: columns of the runs table naming the process of a run (liveness of "running" runs)
_RUN_PROCESS_COLUMNS = {"pid": _I, "host": _T}


def process_alive(pid: int, started_at: str | None = None) -> bool:
    """Whether process `pid` of this host may still be the one that started a run at `started_at`
    (UTC ISO text): False when no such process exists, it is a zombie, or (Linux /proc) it started
    more than 2 s after the run did (the pid was reused). True when it cannot be told (no /proc)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:       # exists, owned by another user
        pass
    except OverflowError:
        return False
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        boot = next(float(line.split()[1]) for line in Path("/proc/stat").read_text().splitlines()
                    if line.startswith("btime "))
    except (OSError, StopIteration, ValueError):
        return True
    fields = stat[stat.rindex(")") + 2:].split()        # after "pid (comm) ": state is field 3 of stat(5)
    if fields[0] in ("Z", "X"):
        return False
    if started_at:
        try:
            run_start = datetime.fromisoformat(str(started_at)).timestamp()
        except ValueError:
            return True
        proc_start = boot + int(fields[19]) / os.sysconf("SC_CLK_TCK")     # starttime, field 22
        if proc_start > run_start + 2.0:
            return False
    return True


def _utc() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def machine() -> str:
    """'host (Linux x86_64, 2 cores)'."""
    return f"{socket.gethostname()} ({platform.system()} {platform.machine()}, {os.cpu_count()} cores)"


def _sa():
    try:
        import sqlalchemy as sa
    except ImportError:  # pragma: no cover - a core dependency
        raise ImpactvalError("the result store needs SQLAlchemy: pip install sqlalchemy") from None
    return sa


def _url(where: str | Path | None) -> str:
    if where is None:
        return "sqlite://"                                   # in memory: a run without --out
    text = str(where)
    if "://" in text:
        scheme, rest = text.split("://", 1)
        if scheme in ("postgresql", "postgres"):
            # plain postgresql:// means psycopg2 to SQLAlchemy; the [postgres] extra installs psycopg 3
            import importlib.util

            if importlib.util.find_spec("psycopg2") is None and importlib.util.find_spec("psycopg") is not None:
                return f"postgresql+psycopg://{rest}"
            return f"postgresql://{rest}"
        return text
    p = Path(text).expanduser().resolve()
    if p.is_dir():
        raise ImpactvalError(f"--store {text}: is a directory; give a file path (e.g. {p / 'impactval.sqlite'}) "
                             "or a database URL (postgresql://...).")
    p.parent.mkdir(parents=True, exist_ok=True)
    return f"sqlite:///{p}"


class Store:
    """An open result store (see the module docstring). `Store(path_or_url)`; None = in memory."""

    def __init__(self, where: str | Path | None = None) -> None:
        sa = _sa()
        self.url = _url(where)
        self.sqlite = self.url.startswith("sqlite")
        kw: dict[str, Any] = {}
        if self.sqlite:
            kw["connect_args"] = {"timeout": 120, "check_same_thread": False}
            if self.url == "sqlite://":
                kw["poolclass"] = sa.pool.StaticPool
        try:
            self.engine = sa.create_engine(self.url, **kw)
        except (sa.exc.ArgumentError, sa.exc.NoSuchModuleError, ImportError) as err:
            raise ImpactvalError(f"--store {where}: not a usable database URL or path ({err}).") from None
        if self.sqlite:
            @sa.event.listens_for(self.engine, "connect")
            def _pragmas(dbapi_conn, _record):  # noqa: ANN001 - SQLAlchemy callback
                cur = dbapi_conn.cursor()
                if self.url != "sqlite://":
                    cur.execute("PRAGMA journal_mode=WAL")
                cur.execute("PRAGMA busy_timeout=120000")
                cur.execute("PRAGMA synchronous=NORMAL")
                cur.close()
        self._define(sa)
        try:
            self._create(sa)
        except sa.exc.OperationalError as err:   # unreachable server, refused login, unwritable file
            reason = str(getattr(err, "orig", err)).strip().splitlines()[0]
            raise ImpactvalError(f"--store {where}: cannot open the store ({reason}); check the URL, that the "
                                 f"server is running and the credentials, or use a local SQLite file path.") from None

    # ------------------------------------------------------------------ schema
    def _define(self, sa) -> None:
        md = self.meta = sa.MetaData()
        types = {_T: sa.Text, _I: sa.Integer, _F: sa.Double}
        self.schema = sa.Table("schema_version", md, sa.Column("version", sa.Integer, nullable=False))
        self.runs = sa.Table(
            "runs", md, sa.Column("id", sa.String(36), primary_key=True), sa.Column("command", sa.Text),
            sa.Column("tag", sa.Text), sa.Column("out", sa.Text), sa.Column("impactval_version", sa.Text),
            sa.Column("reference_version", sa.Text), sa.Column("machine", sa.Text), sa.Column("python", sa.Text),
            sa.Column("started_at", sa.Text), sa.Column("ended_at", sa.Text), sa.Column("status", sa.Text),
            sa.Column("n_jobs", sa.Integer), sa.Column("n_reused", sa.Integer), sa.Column("n_failed", sa.Integer),
            *(sa.Column(c, types[t]) for c, t in _RUN_PROCESS_COLUMNS.items()))
        self.run_engines = sa.Table(
            "run_engines", md, sa.Column("run_id", sa.String(36), sa.ForeignKey("runs.id"), primary_key=True),
            sa.Column("engine", sa.Text, primary_key=True), sa.Column("version", sa.Text))
        cols = [sa.Column("job_key", sa.String(32), primary_key=True)]
        cols += [sa.Column(c, types[t]) for c, t in COLUMN_TYPES.items() if c != "job_key"]
        cols += [sa.Column(c, sa.Text) for c in ("engine_version", "adapter_version", "reference_version",
                                                  "settings", "diagnostics", "validity", "created_at")]
        cols += [sa.Column("tol", sa.Double), sa.Column("series", sa.LargeBinary, nullable=True)]
        self.jobs = sa.Table("jobs", md, *cols)
        self.contacts = sa.Table(
            "contacts", md, sa.Column("job_key", sa.String(32), primary_key=True),
            sa.Column("idx", sa.Integer, primary_key=True), sa.Column("t_start", sa.Double),
            sa.Column("t_end", sa.Double), sa.Column("f_max", sa.Double), sa.Column("delta_max", sa.Double))
        self.run_jobs = sa.Table(
            "run_jobs", md, sa.Column("run_id", sa.String(36), sa.ForeignKey("runs.id"), primary_key=True),
            sa.Column("job_key", sa.String(32), primary_key=True), sa.Column("position", sa.Integer),
            sa.Column("reused", sa.Boolean))

    def _create(self, sa) -> None:
        for attempt in range(5):      # two runs creating one new store at once: the loser retries
            try:
                self.meta.create_all(self.engine, checkfirst=True)
                with self.engine.begin() as c:
                    have = c.execute(sa.select(self.schema.c.version)).scalars().all()
                    if not have:
                        c.execute(self.schema.insert().values(version=STORE_SCHEMA_VERSION))
                    elif max(have) != STORE_SCHEMA_VERSION:
                        raise ImpactvalError(f"{self.url}: store schema {max(have)}, this impactval writes "
                                             f"{STORE_SCHEMA_VERSION}; use another --store.")
                self._add_run_process_columns(sa)
                self._add_job_columns(sa)
                self.mark_dead_runs()
                return
            except sa.exc.OperationalError:
                if attempt == 4:
                    raise
                time.sleep(0.2 * (attempt + 1))

    def _write(self, fn) -> Any:
        """Run `fn(conn)` in one transaction, retrying a few times when SQLite reports a lock."""
        sa = _sa()
        for attempt in range(10):
            try:
                with self.engine.begin() as c:
                    return fn(c)
            except sa.exc.OperationalError as err:
                if "locked" not in str(err) or attempt == 9:
                    raise
                time.sleep(0.05 * (attempt + 1))

    def _insert(self, table, values: dict, update: bool):
        """INSERT ... ON CONFLICT DO NOTHING (or DO UPDATE when `update`), for SQLite and PostgreSQL."""
        name = self.engine.dialect.name
        if name == "sqlite":
            from sqlalchemy.dialects.sqlite import insert
        elif name == "postgresql":
            from sqlalchemy.dialects.postgresql import insert
        else:  # pragma: no cover - other databases: plain insert (a duplicate raises)
            return table.insert().values(**values)
        stmt = insert(table).values(**values)
        pk = [c.name for c in table.primary_key.columns]
        if update:
            return stmt.on_conflict_do_update(index_elements=pk,
                                              set_={k: stmt.excluded[k] for k in values if k not in pk})
        return stmt.on_conflict_do_nothing(index_elements=pk)

    def _add_run_process_columns(self, sa) -> None:
        """A store written before runs had `pid` and `host`: add the columns (NULL for its old runs)."""
        have = {c["name"] for c in sa.inspect(self.engine).get_columns("runs")}
        missing = [c for c in _RUN_PROCESS_COLUMNS if c not in have]
        if missing:
            with self.engine.begin() as c:
                for col in missing:
                    kind = {_I: "INTEGER", _T: "TEXT"}[_RUN_PROCESS_COLUMNS[col]]
                    guard = " IF NOT EXISTS" if self.engine.dialect.name == "postgresql" else ""   # two openers at once
                    c.execute(sa.text(f"ALTER TABLE runs ADD COLUMN{guard} {col} {kind}"))

    def _add_job_columns(self, sa) -> None:
        """A store written before the error-split, theory-gap and C-vs-Warp columns: add them (NULL,
        read as NaN / "" for its old rows)."""
        have = {c["name"] for c in sa.inspect(self.engine).get_columns("jobs")}
        missing = [c for c in ADDED_JOB_COLUMNS if c not in have]
        if missing:
            prep = self.engine.dialect.identifier_preparer
            # two openers at once: PostgreSQL skips what the other added; SQLite raises "duplicate column"
            # (OperationalError) and _create retries, then finds nothing missing
            guard = " IF NOT EXISTS" if self.engine.dialect.name == "postgresql" else ""
            with self.engine.begin() as c:
                for col in missing:
                    kind = self.jobs.c[col].type.compile(dialect=self.engine.dialect)
                    c.execute(sa.text(f"ALTER TABLE jobs ADD COLUMN{guard} {prep.quote(col)} {kind}"))

    # ------------------------------------------------------------------ runs
    def mark_dead_runs(self) -> list[str]:
        """Mark as interrupted every "running" run of this host whose process is gone (killed with
        SIGKILL, or the machine rebooted); return their ids. Runs of other hosts, and runs of a live
        process (this one included), are left alone."""
        sa = _sa()
        r = self.runs
        q = sa.select(r.c.id, r.c.pid, r.c.started_at).where(r.c.status == str(RunStatus.RUNNING),
                                                             r.c.host == socket.gethostname(), r.c.pid.is_not(None))
        with self.engine.connect() as c:
            dead = [row.id for row in c.execute(q) if not process_alive(int(row.pid), row.started_at)]
        for run_id in dead:    # only if still "running": a run finishing meanwhile keeps its own status
            self._write(lambda c, i=run_id: c.execute(r.update().where(r.c.id == i, r.c.status == str(RunStatus.RUNNING))
                                                      .values(status=str(RunStatus.INTERRUPTED))))
        return dead

    def begin_run(self, run_id: str, command: str, out: str | Path | None, engines: dict[str, str],
                  reference_version: str, tag: str | None = None, n_jobs: int = 0) -> None:
        """Record a new run (status running)."""
        import impactval

        row = dict(id=run_id, command=command, tag=tag or "", out=str(Path(out).resolve()) if out else "",
                   impactval_version=impactval.__version__, reference_version=reference_version,
                   machine=machine(), python=sys.version.split()[0], started_at=_utc(), ended_at=None,
                   status=str(RunStatus.RUNNING), n_jobs=n_jobs, n_reused=0, n_failed=0, pid=os.getpid(),
                   host=socket.gethostname())

        def fn(c):
            c.execute(self.runs.insert().values(**row))
            for eng, ver in engines.items():
                c.execute(self.run_engines.insert().values(run_id=run_id, engine=eng, version=ver))
        self._write(fn)

    def end_run(self, run_id: str, status: RunStatus, n_reused: int, n_failed: int) -> None:
        """Record how a run ended."""
        self._write(lambda c: c.execute(self.runs.update().where(self.runs.c.id == run_id).values(
            status=str(status), ended_at=_utc(), n_reused=n_reused, n_failed=n_failed)))

    def run_info(self, run_id: str) -> dict[str, Any]:
        sa = _sa()
        with self.engine.connect() as c:
            r = c.execute(sa.select(self.runs).where(self.runs.c.id == run_id)).mappings().first()
            if r is None:
                raise ImpactvalError(f"no run {run_id!r} in {self.url}.")
            out = dict(r)
            out["engines"] = dict(c.execute(sa.select(self.run_engines.c.engine, self.run_engines.c.version)
                                            .where(self.run_engines.c.run_id == run_id)).all())
        return out

    # ------------------------------------------------------------------ jobs
    def find(self, keys: Iterable[str], statuses: Iterable[str]) -> dict[str, dict[str, Any]]:
        """Stored rows of these job keys whose status is one of `statuses`, by key."""
        sa = _sa()
        keys, statuses = list(keys), [str(s) for s in statuses]
        found: dict[str, dict[str, Any]] = {}
        cols = [self.jobs.c[c] for c in COLUMN_TYPES]
        with self.engine.connect() as c:
            for i in range(0, len(keys), 500):
                q = sa.select(*cols).where(self.jobs.c.job_key.in_(keys[i:i + 500]),
                                           self.jobs.c.status.in_(statuses))
                for r in c.execute(q).mappings():
                    found[r["job_key"]] = _from_db(dict(r))
        return found

    def put(self, row: dict[str, Any], *, run_id: str, position: int, reused: bool, force: bool = False,
            meta: dict[str, Any] | None = None, series: bytes | None = None,
            contacts: Iterable = ()) -> dict[str, Any]:
        """Store a job row (unless its key is already stored and not `force`) with its contact
        phases (objects with t_start, t_end [s], f_max [N], delta_max [m]) and link it to the run,
        in one transaction; return the row now in the store for that key."""
        values = {c: _to_db(row.get(c)) for c in COLUMN_TYPES}
        values.update(meta or {})
        values["created_at"] = _utc()
        values["series"] = series
        sa = _sa()

        phases = [dict(job_key=row["job_key"], idx=i, t_start=_to_db(p.t_start), t_end=_to_db(p.t_end),
                       f_max=_to_db(p.f_max), delta_max=_to_db(p.delta_max)) for i, p in enumerate(contacts)]

        def fn(c):
            if not reused:
                inserted = c.execute(self._insert(self.jobs, values, update=force)).rowcount
                if inserted and force:
                    c.execute(self.contacts.delete().where(self.contacts.c.job_key == row["job_key"]))
                if inserted:
                    for ph in phases:
                        c.execute(self._insert(self.contacts, ph, update=False))
            c.execute(self._insert(self.run_jobs, dict(run_id=run_id, job_key=row["job_key"], position=position,
                                                       reused=reused), update=True))
            r = c.execute(sa.select(*[self.jobs.c[k] for k in COLUMN_TYPES])
                          .where(self.jobs.c.job_key == row["job_key"])).mappings().first()
            return _from_db(dict(r))
        return self._write(fn)

    def run_tol(self, run_id: str) -> float | None:
        """The smallest reference tolerance a run's jobs were compared at (None: no job, or none recorded)."""
        sa = _sa()
        q = (sa.select(sa.func.min(self.jobs.c.tol)).join(self.run_jobs, self.run_jobs.c.job_key == self.jobs.c.job_key)
             .where(self.run_jobs.c.run_id == run_id))
        with self.engine.connect() as c:
            v = c.execute(q).scalar()
        return float(v) if v is not None else None

    def run_settings(self, run_id: str) -> list[dict[str, Any]]:
        """The distinct settings (EngineSettings.as_dict, as stored with each job) of a run's jobs: those the run
        computed first, then those it reused (a reused job keeps the settings of the run that computed it, e.g. its
        timeout); empty when no job of the run recorded any."""
        sa = _sa()
        q = (sa.select(self.jobs.c.settings, self.run_jobs.c.reused)
             .join(self.run_jobs, self.run_jobs.c.job_key == self.jobs.c.job_key)
             .where(self.run_jobs.c.run_id == run_id).order_by(self.run_jobs.c.position))
        with self.engine.connect() as c:
            recs = c.execute(q).all()
        out: list[dict[str, Any]] = []
        for text, _ in sorted(recs, key=lambda r: bool(r[1])):      # stable: computed first, in job order
            try:
                d = json.loads(text) if text else None
            except ValueError:
                d = None
            if isinstance(d, dict) and d not in out:
                out.append(d)
        return out

    def rows(self, *, run_id: str | None = None, out: str | Path | None = None) -> pd.DataFrame:
        """Rows (COLUMN_TYPES columns, errors as fractions) of one run in its order, or of every run
        that wrote to the directory `out`, each job once, ordered by scene, engine and settings."""
        sa = _sa()
        cols = [self.jobs.c[c] for c in COLUMN_TYPES]
        if run_id is not None:
            q = (sa.select(*cols).join(self.run_jobs, self.run_jobs.c.job_key == self.jobs.c.job_key)
                 .where(self.run_jobs.c.run_id == run_id).order_by(self.run_jobs.c.position))
        else:
            sel = sa.select(self.run_jobs.c.job_key).join(self.runs, self.runs.c.id == self.run_jobs.c.run_id)
            if out is not None:
                sel = sel.where(self.runs.c.out == str(Path(out).resolve()))
            q = (sa.select(*cols).where(self.jobs.c.job_key.in_(sel))
                 .order_by(self.jobs.c.scene, self.jobs.c.engine, self.jobs.c.contact, self.jobs.c.integrator,
                           self.jobs.c.dt.desc(), self.jobs.c.segments, self.jobs.c.job_key))
        with self.engine.connect() as c:
            recs = [_from_db(dict(r)) for r in c.execute(q).mappings()]
        return pd.DataFrame(recs, columns=list(COLUMN_TYPES))

    def contact_phases(self, job_key: str) -> pd.DataFrame:
        """Every contact phase of a job: idx (0 = first), t_start, t_end [s], f_max [N], delta_max [m]."""
        sa = _sa()
        t = self.contacts
        with self.engine.connect() as c:
            recs = [dict(r) for r in c.execute(sa.select(t.c.idx, t.c.t_start, t.c.t_end, t.c.f_max, t.c.delta_max)
                                               .where(t.c.job_key == job_key).order_by(t.c.idx)).mappings()]
        return pd.DataFrame(recs, columns=["idx", "t_start", "t_end", "f_max", "delta_max"])

    def load_series(self, job_key: str) -> dict[str, Any] | None:
        """The stored series of a job (t [s], f [N], delta [m], x_ball, x_structure [m], energy [J])
        as numpy arrays, or None when the run did not keep them (`keep_series`)."""
        import numpy as np

        sa = _sa()
        with self.engine.connect() as c:
            blob = c.execute(sa.select(self.jobs.c.series).where(self.jobs.c.job_key == job_key)).scalar()
        if blob is None:
            return None
        with np.load(io.BytesIO(blob)) as z:
            return {k: z[k] for k in z.files}

    def close(self) -> None:
        self.engine.dispose()


def _to_db(v: Any) -> Any:
    if isinstance(v, float) and math.isnan(v):
        return None
    if isinstance(v, enum.Enum):
        return v.value
    if hasattr(v, "item") and not isinstance(v, (str, bytes)):   # numpy scalars
        return v.item()
    return v


def _from_db(r: dict[str, Any]) -> dict[str, Any]:
    out = {}
    for k, v in r.items():
        t = COLUMN_TYPES.get(k)
        if v is None:
            v = math.nan if t == _F else "" if t == _T else v
        out[k] = v
    return out


def pack_series(res) -> bytes | None:
    """An engine result's series as compressed .npz bytes (None when it has none)."""
    import numpy as np

    arrays = {k: np.asarray(getattr(res, k)) for k in ("t", "f", "delta", "x_ball", "x_structure", "energy")}
    if not arrays["t"].size:
        return None
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


# ---------------------------------------------------------------------------- exports
def export_frame(df: pd.DataFrame) -> pd.DataFrame:
    """Rows as exported: fractions -> % (`NAME_pct`), list columns dropped (see frequencies_frame)."""
    out = df.drop(columns=[c for c in LIST_COLUMNS if c in df])
    for c in PERCENT_COLUMNS:
        if c in out:
            out[c] = pd.to_numeric(out[c], errors="coerce") * 100.0
    out = out.rename(columns={c: f"{c}_pct" for c in PERCENT_COLUMNS})
    return out[[c for c in EXPORT_COLUMNS if c in out]]


def frequencies_frame(df: pd.DataFrame) -> pd.DataFrame:
    """One row per (job, model, mode): job_key, scene, engine, segments, model ("engine", "continuum"
    (Euler-Bernoulli, as the adapters report it) or "timoshenko"), mode (1-based), omega_rad_s."""
    recs = []
    for _, r in df.iterrows():
        for col, label in (("structure_frequencies", "engine"), ("continuum_frequencies", "continuum"),
                           ("timoshenko_frequencies", "timoshenko")):
            text = r.get(col, "")
            if isinstance(text, str) and text:
                for i, w in enumerate(json.loads(text), start=1):
                    recs.append(dict(job_key=r["job_key"], scene=r["scene"], engine=r["engine"],
                                     segments=r["segments"], model=label, mode=i, omega_rad_s=float(w)))
    return pd.DataFrame(recs, columns=["job_key", "scene", "engine", "segments", "model", "mode", "omega_rad_s"])


def _atomic_write(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    os.close(fd)
    try:
        write(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)   # mkstemp creates 0600; an export is as readable as any file
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def export(store: Store, out: str | Path) -> list[str]:
    """Regenerate `out/results.csv`, `out/frequencies.csv` and (with pyarrow) `out/results.parquet`
    from every job the store holds for runs into `out`; each file is replaced atomically. Returns
    notes (e.g. Parquet skipped) for the user."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    notes = []
    old = out / "results.csv"
    if old.is_file():           # a results.csv of an older impactval (not from a store): keep it, say where
        with old.open(newline="") as fh:
            header = fh.readline().strip().split(",")
        if header != list(EXPORT_COLUMNS):
            aside = out / f"results-old-{time.strftime('%Y%m%dT%H%M%S')}-{os.getpid()}.csv"
            os.replace(old, aside)
            notes.append(f"{old} had other columns (an older impactval?): moved to {aside.name}")
    df = store.rows(out=out)
    flat = export_frame(df)
    _atomic_write(out / "results.csv", lambda p: flat.to_csv(p, index=False))
    freq = frequencies_frame(df)
    _atomic_write(out / "frequencies.csv", lambda p: freq.to_csv(p, index=False))
    import importlib.util

    if importlib.util.find_spec("pyarrow") is None:
        return notes + ["results.parquet not written: pip install pyarrow (or 'impactval[parquet]')"]
    _atomic_write(out / "results.parquet", lambda p: flat.to_parquet(p, index=False))
    return notes
