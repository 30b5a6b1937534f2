"""Round 19 presentation fixes (fuzz report finding 8): the run report's settings line at --dt auto, and which
materials a scene uses in `impactval materials SCENE`."""
import subprocess
import sys

import pandas as pd

from impactval.engines.base import EngineSettings
from impactval.reports.run_report import header_section


def _settings_line(settings, df):
    return next(ln for ln in header_section({"run_id": "r1"}, settings, df) if ln.startswith("- **settings**"))


def test_settings_line_says_the_engines_chose_the_step_at_dt_auto():
    rows = pd.DataFrame({"dt": [2e-7, 5e-8, 2e-7]})
    line = _settings_line(EngineSettings(dt="auto", timeout_s=300.0), rows)
    assert line.startswith("- **settings**: dt = 2e-07, 5e-08 s, contact = hertz")
    assert line.endswith("timeout = 300 s (--dt auto: the engines chose these steps)")
    # a fixed step the user asked for reads as before, without the note
    fixed = _settings_line(EngineSettings(dt=1e-6, timeout_s=300.0), pd.DataFrame({"dt": [1e-6]}))
    assert fixed.startswith("- **settings**: dt = 1e-06 s, ") and "auto" not in fixed


def test_settings_line_of_a_run_with_no_step_has_no_unit_after_auto():
    """Every row skipped (no dt): "dt = auto (no row stepped)", not "dt = auto s"."""
    line = _settings_line(EngineSettings(dt="auto", timeout_s=60.0), pd.DataFrame({"dt": [float("nan")] * 2}))
    assert "dt = auto (no row stepped), contact = " in line and "auto s" not in line


def test_materials_of_a_scene_marks_its_ball_and_target(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text('[ball]\nradius = 0.004\nvelocity = 2.0\nmaterial = "steel"\n[target]\nkind = "beam"\n'
                     'material = "titanium"\nsupport = "simply-supported"\nlength = 0.18\nwidth = 0.007\n'
                     'height = 0.0026\nimpact_at = 0.09\n')
    out = subprocess.run([sys.executable, "-m", "impactval.cli", "materials", str(scene)], capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == "this scene (s): ball steel, target titanium (beam); marked <- below"
    marks = {ln.split()[0]: ln.rsplit("<- ", 1)[1] for ln in lines[2:] if "<- " in ln}
    assert marks == {"steel": "ball", "titanium": "target"}
    # the same material for both parts is marked once with both
    scene.write_text(scene.read_text().replace('"titanium"', '"steel"'))
    out = subprocess.run([sys.executable, "-m", "impactval.cli", "materials", str(scene)], capture_output=True,
                         text=True, timeout=300)
    assert [ln.rsplit("<- ", 1)[1] for ln in out.stdout.splitlines()[2:] if "<- " in ln] == ["ball, target"]
