"""Nightly comparison with a baseline results.csv (impactval.history)."""
import math
import subprocess
import sys

import pandas as pd
import pytest

from conftest import requires_mujoco
from impactval.errors import ImpactvalError
from impactval.history import compare, load_results, regressions


def row(scene="plate_steel", status="ok", err=1e-3, h="abc", **kw):
    base = dict(scene=scene, engine="mujoco", contact="hertz", integrator="Euler", dt=1e-6, segments="",
                status=status, scene_hash=h, err_t_m=err, err_f_m=-err / 2, err_delta_m=math.nan)
    base.update(kw)
    return base


def marks(old_rows, new_rows, threshold=0.2):
    return list(compare(pd.DataFrame(new_rows), pd.DataFrame(old_rows), threshold)["mark"])


def test_marks():
    assert marks([row(err=1e-3)], [row(err=1.5e-3)]) == ["+"]              # 50 % worse
    assert marks([row(err=1e-3)], [row(err=1.1e-3)]) == [""]               # within the threshold
    assert marks([row(err=1e-3)], [row(err=0.5e-3)]) == ["-"]
    assert marks([row(err=1e-7)], [row(err=3e-7)]) == [""]                 # below the absolute floor
    assert marks([row()], [row(status="unstable", err=math.nan)]) == ["!"]
    assert marks([row(status="crashed", err=math.nan)], [row()]) == ["*"]
    assert marks([row(h="old")], [row(h="new", err=9.0)]) == ["x"]          # scene or reference changed
    assert marks([row(scene="other")], [row()]) == ["x"]                   # no baseline row
    assert marks([row(dt=1e-6)], [row(dt=1e-7, err=9.0)]) == ["x"]         # other settings: other key


def test_regressions_are_worse_or_newly_failing():
    new = pd.DataFrame([row(err=2e-3), row(scene="b")])
    old = pd.DataFrame([row(err=1e-3), row(scene="b")])
    assert regressions(compare(new, old))
    assert not regressions(compare(old, old))


def test_bad_baseline_files(tmp_path):
    with pytest.raises(ImpactvalError, match="does not exist"):
        load_results(tmp_path / "none.csv", 2)
    p = tmp_path / "r.csv"
    pd.DataFrame([{**row(), "schema_version": 1}]).to_csv(p, index=False)
    with pytest.raises(ImpactvalError, match="schema \\[1\\] cannot be compared with schema 2"):
        load_results(p, 2)
    q = tmp_path / "q.csv"
    q.write_text("a,b\n1,2\n")
    with pytest.raises(ImpactvalError, match="missing column"):
        load_results(q, 2)


@requires_mujoco
def test_nightly_run_flags_a_regression_and_exits_1(tmp_path):
    """Run, then pretend the baseline was better: the second run is marked '+' and exits 1."""
    cmd = [sys.executable, "-m", "impactval.cli", "run", "plate_steel", "--engines", "mujoco", "--tol", "1e-5",
           "--dt", "1e-6"]
    first = subprocess.run(cmd + ["--out", str(tmp_path / "a")], capture_output=True, text=True)
    assert first.returncode == 0, first.stderr
    base = tmp_path / "a" / "results.csv"
    same = subprocess.run(cmd + ["--out", str(tmp_path / "b"), "--baseline", str(base)], capture_output=True,
                          text=True)
    assert same.returncode == 0, same.stdout + same.stderr
    assert "0 of 1 rows marked" in same.stdout
    df = pd.read_csv(base)
    for k in ("err_t_m_pct", "err_f_m_pct", "err_delta_m_pct"):   # schema 3: errors in %
        df[k] = df[k] / 10                  # a baseline ten times better
    better = tmp_path / "better.csv"
    df.to_csv(better, index=False)
    worse = subprocess.run(cmd + ["--out", str(tmp_path / "c"), "--baseline", str(better)], capture_output=True,
                           text=True)
    assert worse.returncode == 1
    assert "+ plate_steel / mujoco" in worse.stdout
    report = (tmp_path / "c" / "report.md").read_text()
    assert "## Against the baseline" in report and "| + | plate_steel | mujoco |" in report


def test_bad_threshold_fails_before_any_job(tmp_path):
    out = subprocess.run([sys.executable, "-m", "impactval.cli", "run", "plate_steel", "--threshold", "-1",
                          "--out", str(tmp_path)], capture_output=True, text=True)
    assert out.returncode == 2 and "threshold must be a positive fraction" in out.stderr
    assert not (tmp_path / "results.csv").exists()
