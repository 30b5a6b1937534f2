"""A real PostgreSQL server for the tests, from Debian's `postgresql` package (no mocks).

`postgres_server` (session): initdb + pg_ctl into a fresh temporary directory on a free loopback
port, as the `postgres` user when the tests run as root (initdb refuses root), stopped and removed
at the end. `postgres_url` (function): a fresh empty database on it, as a SQLAlchemy URL
(postgresql+psycopg://...). Both skip with a reason where the server binaries or psycopg are
missing (.ci/run installs them: apt-get install postgresql, pip install 'impactval[postgres]').
Import the fixtures into a test module: `from pg_server import postgres_server, postgres_url`.
"""
from __future__ import annotations

import glob
import itertools
import os
import shutil
import socket
import subprocess
import tempfile

import pytest

_counter = itertools.count()


def _bin_dir() -> str | None:
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"), key=lambda p: int(p.split("/")[4]))
    if found:
        return os.path.dirname(found[-1])
    initdb = shutil.which("initdb")
    return os.path.dirname(initdb) if initdb else None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _as_user(cmd: list[str]) -> list[str]:
    """Run as `postgres` when we are root (initdb and postgres refuse to run as root)."""
    if os.geteuid() != 0:
        return cmd
    runuser = shutil.which("runuser")
    return [runuser, "-u", "postgres", "--", *cmd] if runuser else ["su", "postgres", "-s", "/bin/sh", "-c",
                                                                     " ".join(cmd)]


class PostgresServer:
    """host, port, superuser name; `url(db)` gives a SQLAlchemy URL."""

    def __init__(self, host: str, port: int, user: str) -> None:
        self.host, self.port, self.user = host, port, user

    def url(self, db: str = "postgres") -> str:
        return f"postgresql+psycopg://{self.user}@{self.host}:{self.port}/{db}"

    def create_database(self, name: str) -> str:
        import psycopg

        with psycopg.connect(host=self.host, port=self.port, user=self.user, dbname="postgres",
                             autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)


@pytest.fixture(scope="session")
def postgres_server():
    """A PostgreSQL server started for this test session (see module doc)."""
    pytest.importorskip("psycopg", reason="psycopg not installed: pip install 'impactval[postgres]'")
    bindir = _bin_dir()
    if bindir is None:
        pytest.skip("PostgreSQL server binaries not found: apt-get install postgresql (Debian)")
    if os.geteuid() == 0:
        try:
            import pwd

            pw = pwd.getpwnam("postgres")
        except KeyError:
            pytest.skip("running as root and there is no 'postgres' user to run the server as")
    root = tempfile.mkdtemp(prefix="impactval-pg-")
    data, sock, log = os.path.join(root, "data"), os.path.join(root, "sock"), os.path.join(root, "server.log")
    os.makedirs(sock)
    if os.geteuid() == 0:
        for p in (root, sock):
            os.chown(p, pw.pw_uid, pw.pw_gid)
    user = "impactval"
    port = _free_port()
    try:
        subprocess.run(_as_user([f"{bindir}/initdb", "-D", data, "-U", user, "--auth=trust", "-E", "UTF8",
                                 "--no-sync"]), check=True, capture_output=True, text=True, timeout=120)
        subprocess.run(_as_user([f"{bindir}/pg_ctl", "-D", data, "-l", log, "-w", "-t", "60", "-o",
                                 f"-p {port} -k {sock} -c listen_addresses=127.0.0.1 -c fsync=off", "start"]),
                       check=True, capture_output=True, text=True, timeout=90)
    except (subprocess.CalledProcessError, subprocess.TimeoutExpired) as err:
        detail = getattr(err, "stderr", "") or ""
        shutil.rmtree(root, ignore_errors=True)
        pytest.skip(f"could not start PostgreSQL from {bindir}: {str(detail).strip()[-300:]}")
    try:
        yield PostgresServer("127.0.0.1", port, user)
    finally:
        subprocess.run(_as_user([f"{bindir}/pg_ctl", "-D", data, "-m", "fast", "-w", "stop"]),
                       capture_output=True, timeout=60)
        shutil.rmtree(root, ignore_errors=True)


@pytest.fixture
def postgres_url(postgres_server):
    """A fresh, empty database on the session's server (SQLAlchemy URL)."""
    return postgres_server.create_database(f"impactval_test_{os.getpid()}_{next(_counter)}")
