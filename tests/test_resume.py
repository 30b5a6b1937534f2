"""Resume, interrupts and concurrent runs of `impactval run` (issue 12 bars), for real: subprocesses,
signals, the SQLite store on disk."""
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from conftest import requires_mujoco

TESTS = Path(__file__).parent
#: 12 distinct time steps [s]: 12 jobs of the plate scene
DTS = ",".join(f"{x:g}" for x in (1e-6, 9e-7, 8e-7, 7e-7, 6e-7, 5e-7, 4e-7, 3.5e-7, 3e-7, 2.5e-7, 2e-7, 1.5e-7))


def _cmd(out: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "impactval.cli", "run", "plate_steel", "--engines", "fake_engines:SlowMujoco",
            "--dt", DTS, "--out", str(out), "--tol", "1e-5", *extra]


def _env(slow_s: float = 0.6) -> dict:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]),
            "IMPACTVAL_TEST_SLOW_S": str(slow_s)}


def _stored(db: Path) -> int:
    if not db.exists():
        return 0
    try:
        with sqlite3.connect(db, timeout=5) as c:
            return c.execute("select count(*) from jobs").fetchone()[0]
    except sqlite3.OperationalError:       # tables not created yet
        return 0


def _workers_of(pid: int) -> list[int]:
    """Live engine workers started by process `pid` (their command line names the parent pid)."""
    out = []
    for p in Path("/proc").iterdir():
        if not p.name.isdigit():
            continue
        try:
            args = (p / "cmdline").read_bytes().split(b"\0")
            state = (p / "stat").read_text().split()[2]
        except OSError:
            continue
        if b"impactval._worker" in args and str(pid).encode() in args and state != "Z":
            out.append(int(p.name))
    return out


def _wait_for(cond, timeout: float, what: str) -> None:
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def _start_and_kill_halfway(out: Path, sig: int, jobs: str = "2") -> tuple[subprocess.Popen, int]:
    proc = subprocess.Popen(_cmd(out, "--jobs", jobs), env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    db = out / "impactval.sqlite"
    _wait_for(lambda: _stored(db) >= 4 or proc.poll() is not None, 240, "4 stored jobs")
    assert proc.poll() is None, proc.communicate()
    _wait_for(lambda: _workers_of(proc.pid), 30, "a live worker")        # a job is running right now
    n_before = _stored(db)
    os.kill(proc.pid, sig)
    proc.wait(60)
    return proc, n_before


@requires_mujoco
@pytest.mark.slow
def test_sigkill_halfway_then_rerun_runs_each_job_once(tmp_path):
    """Bar: a 12-job run SIGKILLed halfway leaves no engine process; the rerun reuses the finished
    jobs (and says so), computes the rest, and every job is in the store and the export exactly once."""
    out = tmp_path / "o"
    proc, n_before = _start_and_kill_halfway(out, signal.SIGKILL)
    assert proc.returncode == -signal.SIGKILL
    _wait_for(lambda: not _workers_of(proc.pid), 10, "the workers of the killed run to die")
    db = out / "impactval.sqlite"
    with sqlite3.connect(db) as c:
        first = dict(c.execute("select job_key, created_at from jobs").fetchall())
        (killed_status,) = c.execute("select status from runs").fetchone()
    assert 4 <= len(first) < 12 and len(first) >= n_before
    assert killed_status == "running"                   # killed: it never got to say how it ended
    again = subprocess.run(_cmd(out, "--jobs", "2"), env=_env(0.0), capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert f"{len(first)} of 12 jobs reused from the store" in again.stderr
    assert f"12 rows ({len(first)} reused from the store)" in again.stdout
    with sqlite3.connect(db) as c:
        rows = c.execute("select job_key, created_at, status from jobs").fetchall()
        runs = c.execute("select status, n_reused from runs order by started_at").fetchall()
    assert len(rows) == 12 and {s for _, _, s in rows} == {"ok"}
    assert {k: t for k, t, _ in rows if k in first} == first       # finished jobs not recomputed
    assert runs == [("interrupted", 0), ("finished", len(first))]     # the rerun found the killed run gone
    csv = pd.read_csv(out / "results.csv")
    assert len(csv) == 12 and csv["job_key"].is_unique and sorted(csv["dt"]) == sorted(map(float, DTS.split(",")))


@requires_mujoco
@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_interrupt_records_interrupted_writes_report_and_exits_128_plus_signal(tmp_path, sig):
    """SIGTERM -> 143, Ctrl-C (SIGINT) -> 130: the run is recorded as interrupted, the finished jobs
    are stored, exported and reported, no engine process is left."""
    out = tmp_path / "o"
    proc, _ = _start_and_kill_halfway(out, sig)
    stdout, stderr = proc.communicate()
    name = signal.Signals(sig).name
    assert proc.returncode == 128 + sig, stderr
    assert f"interrupted by {name}" in stderr and "Traceback" not in stderr
    assert not _workers_of(proc.pid)
    with sqlite3.connect(out / "impactval.sqlite") as c:
        status, ended, n_stored = c.execute("select status, ended_at, (select count(*) from jobs) from runs").fetchone()
    assert status == "interrupted" and ended and 4 <= n_stored < 12
    report = (out / "report.md").read_text()
    assert f"**Interrupted** ({name}): {n_stored} of 12 jobs finished" in report
    assert report.count("| plate_steel | slow-mujoco | hertz |") == n_stored     # the summary table
    assert len(pd.read_csv(out / "results.csv")) == n_stored


@requires_mujoco
@pytest.mark.slow
def test_two_runs_at_once_into_one_store_and_out(tmp_path):
    """Bar: two runs started together into the same --out (and store), with 8 jobs in common: every
    job once in the store and the export, both runs finished, the exports readable."""
    out = tmp_path / "o"
    dts = DTS.split(",")
    a = [sys.executable, "-m", "impactval.cli", "run", "plate_steel", "--engines", "fake_engines:SlowMujoco",
         "--tol", "1e-5", "--out", str(out), "--jobs", "1"]
    procs = [subprocess.Popen(a + ["--dt", ",".join(part)], env=_env(0.2), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for part in (dts[:10], dts[2:])]
    for p in procs:
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
    with sqlite3.connect(out / "impactval.sqlite") as c:
        keys = [k for (k,) in c.execute("select job_key from jobs")]
        runs = c.execute("select status, n_jobs from runs").fetchall()
        links = c.execute("select count(*) from run_jobs").fetchone()[0]
    assert len(keys) == 12 and len(set(keys)) == 12
    assert sorted(runs) == [("finished", 10), ("finished", 10)] and links == 20
    csv = pd.read_csv(out / "results.csv")
    assert len(csv) == 12 and csv["job_key"].is_unique and (csv["status"] == "ok").all()
    assert pd.read_parquet(out / "results.parquet")["job_key"].tolist() == csv["job_key"].tolist()
