"""A run killed with SIGKILL does not stay "running" forever: the runs table records pid and host,
and opening the store marks the runs of this host whose process is gone as interrupted."""
from __future__ import annotations

import os
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pg_server import postgres_server, postgres_url  # noqa: F401 - fixtures
from impactval.store import Store, process_alive

TESTS = Path(__file__).resolve().parent


def _runs(db: Path) -> list[tuple]:
    if not db.exists():
        return []
    try:
        with sqlite3.connect(db) as c:
            return c.execute("select status, pid, host, ended_at from runs").fetchall()
    except sqlite3.OperationalError:          # the table is being created
        return []


def _wait_for(pred, timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def test_a_sigkilled_run_is_interrupted_when_the_store_is_next_opened(tmp_path):
    """The real CLI, an engine job that hangs, the whole process group SIGKILLed (as a CI runner would)."""
    db, out = tmp_path / "s.sqlite", tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "impactval.cli", "run", "plate_steel", "--engines",
                             "fake_engines:Hang", "--timeout", "600", "--store", str(db), "--out", str(out)],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    try:
        _wait_for(lambda: _runs(db) or proc.poll() is not None, 120, "the run to be recorded")
        assert proc.poll() is None, proc.stderr.read().decode()
        (status, pid, host, ended), = _runs(db)
        assert (status, pid, host, ended) == ("running", proc.pid, socket.gethostname(), None)
        Store(db).close()                                   # a live run is left alone
        assert _runs(db)[0][0] == "running"
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(30)
    assert proc.returncode == -signal.SIGKILL
    assert _runs(db)[0][0] == "running"                     # nobody has looked yet
    s = Store(db)
    try:
        info = s.run_info(_only_run(db))
    finally:
        s.close()
    assert info["status"] == "interrupted" and info["ended_at"] is None and info["pid"] == proc.pid
    listing = subprocess.run([sys.executable, "-m", "impactval.cli", "report", str(db), "--list"], env=env,
                             capture_output=True, text=True, timeout=120)
    assert listing.returncode == 0 and "interrupted" in listing.stdout and "running" not in listing.stdout, listing


def _only_run(db: Path) -> str:
    with sqlite3.connect(db) as c:
        (run_id,), = c.execute("select id from runs").fetchall()
    return run_id


def test_a_reused_pid_another_host_and_an_old_run_without_pid(tmp_path):
    db = tmp_path / "s.sqlite"
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    try:
        s = Store(db)
        for run_id in ("reused", "elsewhere", "old", "mine"):
            s.begin_run(run_id, "test", None, {}, "ref")
        s.close()
        with sqlite3.connect(db) as c:
            # the pid of a live process that started an hour after the run did: the run's process is gone
            c.execute("update runs set pid = ?, started_at = '2000-01-01T00:00:00.000+00:00' where id = 'reused'",
                      (sleeper.pid,))
            c.execute("update runs set pid = 999999999, host = 'another-host' where id = 'elsewhere'")
            c.execute("update runs set pid = NULL, host = NULL where id = 'old'")
        assert process_alive(sleeper.pid) and not process_alive(sleeper.pid, "2000-01-01T00:00:00+00:00")
        s = Store(db)
        status = {r: s.run_info(r)["status"] for r in ("reused", "elsewhere", "old", "mine")}
        s.close()
    finally:
        sleeper.kill()
        sleeper.wait()
    assert status == {"reused": "interrupted", "elsewhere": "running", "old": "running", "mine": "running"}


def test_a_store_written_before_pid_and_host_gets_the_columns(tmp_path):
    db = tmp_path / "old.sqlite"
    Store(db).close()
    with sqlite3.connect(db) as c:                       # the runs table as impactval wrote it before
        c.execute("alter table runs drop column pid")
        c.execute("alter table runs drop column host")
        c.execute("insert into runs (id, command, status) values ('r0', 'old run', 'running')")
    s = Store(db)
    s.begin_run("r1", "new run", None, {}, "ref")
    old, new = s.run_info("r0"), s.run_info("r1")
    s.close()
    assert old["status"] == "running" and old["pid"] is None
    assert new["pid"] == os.getpid() and new["host"] == socket.gethostname()


@pytest.mark.parametrize("pid", [2 ** 22 + 12345, 2 ** 70])
def test_no_such_process_is_not_alive(pid):
    assert not process_alive(pid)


def test_postgresql_store_gets_the_columns_and_marks_dead_runs(postgres_url):
    """The same on a PostgreSQL store (Debian's server, started by the fixture)."""
    import sqlalchemy as sa

    s = Store(postgres_url)
    with s.engine.begin() as c:                          # an older store: no pid/host in runs
        c.execute(sa.text("ALTER TABLE runs DROP COLUMN pid"))
        c.execute(sa.text("ALTER TABLE runs DROP COLUMN host"))
    s.close()
    s = Store(postgres_url)
    s.begin_run("gone", "test", None, {}, "ref")
    s.begin_run("alive", "test", None, {}, "ref")
    with s.engine.begin() as c:
        c.execute(sa.text("UPDATE runs SET pid = 999999999 WHERE id = 'gone'"))
    s.close()
    s = Store(postgres_url)
    try:
        assert (s.run_info("gone")["status"], s.run_info("alive")["status"]) == ("interrupted", "running")
    finally:
        s.close()
