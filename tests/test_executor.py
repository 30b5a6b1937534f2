"""Engine workers and executors (issue 12): reuse, isolation, Dask, and the README script."""
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

import impactval
from conftest import requires_mujoco
from impactval import executor as ex
from impactval.engines.base import EngineSettings

ROOT = Path(__file__).resolve().parents[1]
#: columns that measure time on this machine: never equal between two runs
TIMING = ("run_id", "wall_time_build_s", "wall_time_step_s", "wall_time_s", "steps_per_s")


@requires_mujoco
def test_worker_is_reused_and_replaced_after_a_crash_or_timeout(plate_scene):
    """One worker serves consecutive jobs of an engine (the second job pays no start-up); a crash or
    a timeout is a row and the next job gets a fresh worker."""
    ex.kill_workers()
    w = ex.EngineWorker("mujoco")
    try:
        a = w.run(plate_scene, EngineSettings(dt=1e-6))
        b = w.run(plate_scene, EngineSettings(dt=1e-6))
        assert a.success and b.success and w.alive and w.jobs_done == 2
        assert a.f_m == b.f_m                               # same job, same worker: same number
        assert pid_after(w) == w.proc.pid
    finally:
        w.kill()
    started = ex.STARTED["count"]
    with ex.local_executor(1) as pool:
        rows = [f.result() for f in [pool.submit(ex.run_job, "mujoco", plate_scene, EngineSettings(dt=1e-6))
                                     for _ in range(4)]
                + [pool.submit(ex.run_job, "fake_engines:KillSelf", plate_scene, EngineSettings()),
                   pool.submit(ex.run_job, "fake_engines:KillSelf", plate_scene, EngineSettings()),
                   pool.submit(ex.run_job, "fake_engines:Hang", plate_scene, EngineSettings(timeout_s=1)),
                   pool.submit(ex.run_job, "mujoco", plate_scene, EngineSettings(dt=1e-6))]]
    assert [str(r.status) for r in rows] == ["ok"] * 4 + ["crashed", "crashed", "timeout", "ok"]
    assert "SIGKILL" in rows[4].message and "no result after 1 s" in rows[6].message
    # 1 mujoco worker for 4 jobs, a new one for each crash, one for the hang; the mujoco worker survived
    assert ex.STARTED["count"] - started == 1 + 2 + 1
    assert len({r.f_m for r in rows[:4] + rows[7:]}) == 1
    ex.kill_workers()
    assert ex.worker_pids() == []


def pid_after(w):
    return w.proc.pid if w.alive else None


def test_bad_jobs_count_is_bad_input():
    from impactval.errors import EngineError

    with pytest.raises(EngineError, match="jobs must be a positive whole number"):
        ex.local_executor(0)


@requires_mujoco
@pytest.mark.slow
def test_dask_local_cluster_rows_are_bit_identical_to_local():
    """Bar: --scheduler on a (in-process) LocalCluster gives the same rows, errors bit-identical."""
    pytest.importorskip("dask.distributed")
    from dask.distributed import LocalCluster

    from impactval.runner import run

    kw = dict(dt=[1e-6, 4e-7], contact="hertz", tol=1e-6)
    local = run(["plate_steel"], ["mujoco", "fake_engines:KillSelf"], workers=2, **kw)
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cluster:
        remote = run(["plate_steel"], ["mujoco", "fake_engines:KillSelf"], scheduler=cluster, **kw)
    assert list(local["status"]) == list(remote["status"]) == ["ok", "crashed", "ok", "crashed"]
    for col in local.columns:
        if col in TIMING or col == "message":
            continue
        for x, y in zip(local[col], remote[col]):
            same = (x == y) or (isinstance(x, float) and math.isnan(x) and math.isnan(y))
            assert same, (col, x, y)
    assert local["err_f_m"].iloc[0] == remote["err_f_m"].iloc[0] and abs(local["err_f_m"].iloc[0]) < 5e-4


def _readme_python_block() -> str:
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Python API"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


@requires_mujoco
@pytest.mark.slow
def test_readme_python_example_works_as_a_script_without_main_guard(tmp_path):
    """Bar: the README's Python block, pasted into a script file (no `if __name__ == "__main__"`),
    runs engine jobs that succeed (spawn used to re-import the script and crash the job)."""
    script = tmp_path / "example.py"
    script.write_text(_readme_python_block() + "\nprint('STATUS', list(df['status']))\n")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.count("STATUS") == 1                 # the script ran once, not once per worker
    assert "STATUS ['ok']" in out.stdout
