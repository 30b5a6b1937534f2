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
    b = tmp_path / "binary.csv"
    b.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(ImpactvalError, match="^--baseline .*binary.csv: not a results.csv"):
        load_results(b, 2)


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


# ---------------------------------------------------------------------------- issue 16: thresholds, keys, wall-time steps
from impactval.history import (differing_keys, parse_fail_on, require_comparable, thresholds,  # noqa: E402
                               wall_time_steps)


def test_parse_fail_on():
    c = parse_fail_on("f_m:+20%")
    assert (c.metric, c.rel, c.abs_pp) == ("f_m", 0.2, None)
    c = parse_fail_on("curve:+0.5pp")
    assert (c.metric, c.rel, c.abs_pp) == ("curve", None, 0.5)
    for bad, msg in (("f_m", "METRIC:\\+N%"), ("fm:+20%", "unknown metric 'fm'"), ("f_m:+0%", "positive"),
                     ("wall_time:+2pp", "relative step")):
        with pytest.raises(ImpactvalError, match=msg):
            parse_fail_on(bad)


def test_per_metric_thresholds():
    old, new = [row(err=1e-3)], [row(err=1.3e-3)]                  # t_m and f_m |error| +30 %
    assert marks(old, new) == ["+"]
    loose = thresholds(["t_m:+50%", "f_m:+50%"])
    assert list(compare(pd.DataFrame(new), pd.DataFrame(old), loose)["mark"]) == [""]
    # absolute: 0.03 percentage points of growth; the t_m error grew by 0.03 pp exactly -> not past
    pp = thresholds(["t_m:+0.02pp", "f_m:+1pp"])
    cmp = compare(pd.DataFrame(new), pd.DataFrame(old), pp)
    assert list(cmp["mark"]) == ["+"] and "t_m +0.1 % -> +0.13 %" in cmp["why"][0] and "f_m" not in cmp["why"][0]


def test_reason_names_the_numbers_and_the_engine_version():
    cmp = compare(pd.DataFrame([row(err=2e-3, version="3.3")]), pd.DataFrame([row(err=1e-3, version="3.2")]))
    why = cmp["why"][0]
    assert cmp["mark"][0] == "+" and "t_m +0.1 % -> +0.2 % (+100 % in size)" in why
    assert "engine version 3.2 -> 3.3" in why


def test_nothing_comparable_names_the_keys_that_differ():
    old = pd.DataFrame([row(segments="81"), row(scene="b", segments="81")])
    new = pd.DataFrame([row(segments="40"), row(scene="b", segments="40")])
    cmp = compare(new, old)
    assert list(cmp["mark"]) == ["x", "x"]
    assert differing_keys(new, old) == ["segments: baseline 81; now 40"]
    with pytest.raises(ImpactvalError, match="nothing comparable with base.csv.*segments: baseline 81; now 40"):
        require_comparable(cmp, new, old, "base.csv")
    require_comparable(compare(old, old), old, old, "base.csv")      # comparable: no error


def _hist(walls):
    return pd.DataFrame([{**row(), "run_index": i, "wall_time_step_s": w} for i, w in enumerate(walls)])


def test_wall_time_steps_need_a_persisting_step():
    def state(walls):
        return wall_time_steps(_hist(walls), threshold=0.5, window=3)["state"][0]

    assert state([1.0] * 5) == "not enough history (5 of 6 nights)"
    assert state([1.0, 1.1, 0.9, 1.0, 1.0, 1.05]) == "steady"
    assert state([1.0, 1.1, 0.9, 1.0, 3.0, 1.05]) == "steady"          # one noisy night is not a step
    assert state([1.0, 1.1, 0.9, 2.0, 2.1, 1.9]) == "slower"           # three nights past +50 %
    assert state([1.0, 1.1, 0.9, 2.0, 2.1, 1.4]) == "steady"           # the last is within +50 %
    assert state([1.0, 1.1, 0.9, 0.5, 0.5, 0.6]) == "faster"
    r = wall_time_steps(_hist([1.0, 1.0, 1.0, 2.0, 2.0, 2.0]))
    assert r["ratio"][0] == pytest.approx(2.0) and r["nights"][0] == 6


def test_a_reference_that_moved_is_not_compared_one_that_did_not_is():
    """Round 20 (fuzz): the scene hash holds impactval's version, not the reference solver's, so a night after a
    reference change compared engines against a different truth ('0 of 1 rows marked' across reference versions
    5810... -> f1cd...). Rows are comparable only when their stored reference values agree within
    REFERENCE_MOVE_LIMIT (5e-6 relative): a reference that moved by 1e-4 makes the row `x` with the move named, even
    where the engine's error grew (a moved truth is not an engine regression); one that moved by 1e-7 (the same
    solver's roundoff, or a refactor) keeps it compared."""
    from impactval.history import REFERENCE_MOVE_LIMIT

    ref = dict(ref_t_m=1e-4, ref_f_m=2e3, ref_delta_m=5e-5)
    moved = dict(ref, ref_t_m=1e-4 * (1 + 1e-4))
    cmp = compare(pd.DataFrame([row(err=2e-3, **moved)]), pd.DataFrame([row(err=1e-3, **ref)]))
    assert list(cmp["mark"]) == ["x"] and "reference changed" in cmp["why"][0] and "t_m +0.0001" in cmp["why"][0]
    same = dict(ref, ref_t_m=1e-4 * (1 + 1e-7))
    assert marks([row(err=1e-3, **ref)], [row(err=2e-3, **same)]) == ["+"]
    assert marks([row(err=1e-3, **ref)], [row(err=1e-3, **same)]) == [""]
    # at the limit itself still comparable, just past it not
    edge = dict(ref, ref_f_m=2e3 * (1 + 0.9 * REFERENCE_MOVE_LIMIT))
    past = dict(ref, ref_f_m=2e3 * (1 + 1.1 * REFERENCE_MOVE_LIMIT))
    assert marks([row(**ref)], [row(**edge)]) == [""] and marks([row(**ref)], [row(**past)]) == ["x"]
    # a failed row has no reference values: its status still compares
    assert marks([row(**ref)], [row(status="unstable", err=math.nan)]) == ["!"]
    with pytest.raises(ImpactvalError, match="matched a baseline row but the reference changed: its values moved by "
                                             "t_m \\+0.0001.*Rerun the baseline with this version"):
        require_comparable(cmp, pd.DataFrame([row(**moved)]), pd.DataFrame([row(**ref)]), "base.csv")


@requires_mujoco
def test_baseline_of_another_reference_is_not_comparable(tmp_path):
    """End to end: a real run's results.csv as the baseline, its reference t_m moved by 1e-4 (what a changed solver
    writes): the next run against it exits 2 naming the move, not 0 with '0 of 1 rows marked'."""
    cmd = [sys.executable, "-m", "impactval.cli", "run", "plate_steel", "--engines", "mujoco", "--tol", "1e-5",
           "--dt", "1e-6"]
    first = subprocess.run(cmd + ["--out", str(tmp_path / "a")], capture_output=True, text=True)
    assert first.returncode == 0, first.stderr
    df = pd.read_csv(tmp_path / "a" / "results.csv")
    df["ref_t_m"] = df["ref_t_m"] * (1 + 1e-4)
    other = tmp_path / "other_reference.csv"
    df.to_csv(other, index=False)
    out = subprocess.run(cmd + ["--out", str(tmp_path / "b"), "--baseline", str(other)], capture_output=True, text=True)
    assert out.returncode == 2, out.stdout + out.stderr
    assert "reference changed: its values moved by t_m -0.0001" in out.stderr
