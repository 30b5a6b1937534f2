"""User test s20 fuzz2, findings 4, 5 and 7: explicit Euler's (absent) stability limit, the clock of the job after a
timeout, options that do not apply to the row's contact mode and the law a "hertz" row ran."""
import math
import textwrap
import time

import pytest

import impactval
from impactval import executor as ex
from impactval.engines.base import EngineSettings
from impactval.engines.options import inapplicable_notes

PLATE = """
[ball]
radius = 0.005
velocity = 1.5
material = "steel"
[target]
kind = "rigid-plate"
material = "aluminium"
"""


@pytest.fixture()
def plate_scene(tmp_path):
    p = tmp_path / "pl_al.toml"
    p.write_text(PLATE)
    return impactval.load_scene(str(p))


def _exudyn():
    pytest.importorskip("exudyn")
    from impactval.engines.exudyn_ import ExudynAdapter

    return ExudynAdapter()


# ------------------------------------------------------------------ finding 4

def test_explicit_euler_has_no_finite_limit_and_refuses_auto(plate_scene):
    a = _exudyn()
    s = a.check_settings(EngineSettings(integrator="explicit-euler"))
    assert math.isinf(a.plan(plate_scene, s).dt_limit)
    from impactval.engines.base import execute_job

    r = execute_job("exudyn", plate_scene, EngineSettings(integrator="explicit-euler"))
    assert str(r.status) == "skipped"
    assert "no stable step" in r.message and "dt = auto is refused" in r.message and "\n" not in r.message
    assert a.plan(plate_scene, a.check_settings(EngineSettings(integrator="rk44"))).dt_limit < 1   # rk44 keeps its limit


def test_explicit_euler_failure_states_the_growth_not_a_limit(plate_scene):
    a = _exudyn()
    r = a.run(plate_scene, EngineSettings(integrator="explicit-euler", dt=1e-6))
    assert str(r.status) == "unstable"
    assert "predicted limit" not in r.message and "no stability limit" in r.message
    assert "none (implicit)" not in r.message
    ok = a.run(plate_scene, EngineSettings(integrator="explicit-euler", dt=1e-8))
    assert str(ok.status) == "ok"


# ------------------------------------------------------------------ finding 5

SLOW_IMPORT = textwrap.dedent('''
    """A fake engine whose import takes 1.5 s and whose scene "hang" never returns."""
    import time

    from impactval.engines.fake_ import HertzSpringAdapter

    time.sleep(1.5)


    class SlowStart(HertzSpringAdapter):
        name = "slowstart"
        module = "os"

        def simulate(self, scene, settings):
            if scene.name.startswith("hang"):
                time.sleep(3600)
            return super().simulate(scene, settings)
''')


def test_job_after_a_timeout_gets_its_full_timeout(tmp_path, monkeypatch, plate_scene):
    (tmp_path / "fz20b_slowstart.py").write_text(SLOW_IMPORT)
    (tmp_path / "hang_pl.toml").write_text(PLATE)
    monkeypatch.syspath_prepend(str(tmp_path))
    hang = impactval.load_scene(str(tmp_path / "hang_pl.toml"))
    spec = "fz20b_slowstart:SlowStart"
    ex.kill_workers()
    settings = EngineSettings(timeout_s=1.2)
    t0 = time.monotonic()
    with ex.local_executor(1) as pool:
        rows = [pool.submit(ex.run_job, spec, sc, settings).result() for sc in (plate_scene, hang, plate_scene)]
    ex.kill_workers()
    # the first job of a fresh worker and the job after a timeout: the 1.5 s start-up is not charged to them
    assert [str(r.status) for r in rows] == ["ok", "timeout", "ok"], [r.message for r in rows]
    assert time.monotonic() - t0 < 20


def test_a_worker_that_never_gets_ready_is_a_timeout_row(tmp_path, monkeypatch, plate_scene):
    (tmp_path / "fz20b_neverready.py").write_text(
        "import time\nfrom impactval.engines.fake_ import HertzSpringAdapter\ntime.sleep(3600)\n"
        "class Never(HertzSpringAdapter):\n    name = 'never'\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(ex, "STARTUP_TIMEOUT_S", 1.0)
    w = ex.EngineWorker("fz20b_neverready:Never")
    try:
        r = w.run(plate_scene, EngineSettings(timeout_s=1.0))
    finally:
        w.kill()
    assert str(r.status) == "timeout" and "not ready" in r.message and not w.alive


# ------------------------------------------------------------------ finding 7

def test_pybullet_native_option_under_hertz_is_noted():
    pytest.importorskip("pybullet")
    from impactval.engines.pybullet_ import PybulletAdapter

    a = PybulletAdapter()
    s = a.check_settings(EngineSettings(options=(("contact_stiffness", 1e8),)))
    notes = inapplicable_notes(s, "pybullet")
    assert len(notes) == 1 and "contact_stiffness" in notes[0] and "'hertz'" in notes[0] and "native" in notes[0]
    native = a.check_settings(EngineSettings(contact="native", options=(("contact_stiffness", 1e8),)))
    assert inapplicable_notes(native, "pybullet") == ()
    assert inapplicable_notes(a.check_settings(EngineSettings()), "pybullet") == ()


def test_pybullet_row_carries_the_note(tmp_path):
    pytest.importorskip("pybullet")
    from impactval.engines.pybullet_ import PybulletAdapter

    p = tmp_path / "pl.toml"
    p.write_text(PLATE)
    sc = impactval.load_scene(str(p))
    r = PybulletAdapter().run(sc, EngineSettings(options=(("contact_stiffness", 1e8),)))
    assert any("contact_stiffness" in v and "ignored" in v for v in r.validity), r.validity


def test_exudyn_python_user_function_under_native_is_noted(plate_scene):
    a = _exudyn()
    s = a.check_settings(EngineSettings(contact="native", options=(("user_function", "python"),)))
    assert any("user_function" in n for n in a.plan(plate_scene, s).validity)


def test_table_shows_the_law_that_ran():
    import pandas as pd

    from impactval.reports.run_report import _contact_cell

    assert _contact_cell(pd.Series({"contact": "hertz", "contact_law": "linear"})) == "hertz (law linear)"
    assert _contact_cell(pd.Series({"contact": "hertz", "contact_law": "hertz"})) == "hertz"
    assert _contact_cell(pd.Series({"contact": "native", "contact_law": "linear"})) == "native"
    assert _contact_cell(pd.Series({"contact": "hertz", "contact_law": float("nan")})) == "hertz"
