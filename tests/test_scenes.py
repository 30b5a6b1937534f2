"""Scene files: the catalogue, and one clear line for every kind of bad input (issue 8)."""
import math
import subprocess
import sys
import textwrap

import pytest

import impactval
from impactval.errors import ImpactvalError, SceneError
from impactval.scenarios.scene import catalogue_names, load_catalogue

GOOD = """
[ball]
radius = 0.01
velocity = 1.0
material = "steel"
[target]
kind = "beam"
material = "steel"
support = "simply-supported"
length = 0.5
width = 0.01
height = 0.01
impact_at = 0.5
"""


def write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def test_catalogue_has_the_scenes_the_issue_asks_for():
    names = set(catalogue_names())
    assert {"plate_steel", "beam_ss_midspan", "beam_ss_quarter", "beam_cc_midspan", "beam_cantilever_tip",
            "light_ball_heavy_beam", "heavy_ball_slender_beam"} <= names
    for s in load_catalogue():
        assert s.description and s.tags
    assert {s.name for s in load_catalogue("nightly")} >= {"plate_steel", "beam_ss_midspan"}


def test_heavy_ball_scene_has_first_frequency_below_impact_frequency():
    from impactval.reference.hertz import plate_impact
    from impactval.reference.solve import structure_modes
    s = impactval.load_scene("heavy_ball_slender_beam")
    p = plate_impact(s.ball.mass, s.alpha, s.ball.velocity)
    assert structure_modes(s, 1).omega[0] < p.omega_m


def test_light_ball_scene_is_close_to_the_rigid_plate():
    from impactval.reference.hertz import plate_impact
    s = impactval.load_scene("light_ball_heavy_beam")
    p = plate_impact(s.ball.mass, s.alpha, s.ball.velocity)
    r = impactval.solve(s, tol=1e-5)
    assert abs(r.t_m / p.t_m - 1) < 0.05 and abs(r.f_m / p.f_m - 1) < 0.05


def test_good_file_and_materials_override(tmp_path):
    p = write(tmp_path, GOOD.replace('material = "steel"\n[target]', 'material = "mine"\n[target]')
              + "\n[materials.mine]\nyoung = 2e11\npoisson = 0.29\ndensity = 7850\n")
    s = impactval.load_scene(p)
    assert s.name == "s" and s.ball.material.young == 2e11
    assert s.ball.mass == pytest.approx(7850 * 4 / 3 * math.pi * 0.01**3)


BAD = [
    ("radius = 0.01\n", "radius = nan\n", "radius must be a positive finite number"),
    ("velocity = 1.0\n", "velocity = -1.0\n", "velocity must be a positive finite number"),
    ("velocity = 1.0\n", "", "missing required key 'velocity'"),
    ("velocity = 1.0\n", "velocity = 1.0\nspeed = 2\n", "unknown key 'speed'"),
    ('material = "steel"\n[target]', 'material = "unobtainium"\n[target]', "material 'unobtainium' is unknown"),
    ("impact_at = 0.5", "impact_at = 1.5", "impact_at must be a fraction"),
    ("impact_at = 0.5", "impact_at = 1.0", "is on a support"),
    ('support = "simply-supported"', 'support = "glued"', "support must be one of"),
    ('kind = "beam"', 'kind = "shell"', "kind must be one of"),
    ("length = 0.5", "length = 0", "length must be a positive"),
    ("height = 0.01", "height = \"thick\"", "height must be a positive"),
    ("impact_at = 0.5", "impact_at = 0.5\nmodes = 0", "modes must be a whole number"),
    ("[ball]", "[ball\n", "malformed TOML"),
]


@pytest.mark.parametrize("old,new,message", BAD, ids=[b[2][:30] for b in BAD])
def test_bad_input_names_field_and_fix(tmp_path, old, new, message):
    p = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(SceneError) as err:
        impactval.load_scene(p)
    assert message in str(err.value)
    assert str(p) in str(err.value)
    assert isinstance(err.value, ValueError) and isinstance(err.value, ImpactvalError)


def test_modal_arrays_of_unequal_length(tmp_path):
    p = write(tmp_path, """
        [ball]
        radius = 0.01
        velocity = 1.0
        material = "steel"
        [target]
        kind = "modal"
        material = "steel"
        omega = [1000.0, 2000.0]
        modal_mass = [1.0]
        phi = [1.0, 0.5]
        """)
    with pytest.raises(SceneError, match="equal lengths, got 2, 1 and 2"):
        impactval.load_scene(p)


def test_missing_file_and_unknown_name():
    with pytest.raises(SceneError, match="does not exist"):
        impactval.load_scene("/nonexistent/scene.toml")
    with pytest.raises(SceneError, match="no scene named 'nope'"):
        impactval.load_scene("nope")


def test_solve_rejects_bad_tolerance():
    s = impactval.load_scene("plate_steel")
    for bad in (0.0, -1e-6, float("nan"), 1.0, "1e-6"):
        with pytest.raises(ImpactvalError, match="tol must be"):
            impactval.solve(s, tol=bad)


def test_cli_bad_input_is_one_line_exit_2(tmp_path):
    p = write(tmp_path, GOOD.replace("radius = 0.01", "radius = -3"))
    out = subprocess.run([sys.executable, "-m", "impactval.cli", "reference", str(p)], capture_output=True, text=True)
    assert out.returncode == 2
    assert "Traceback" not in out.stderr
    lines = [l for l in out.stderr.splitlines() if l.strip() and "compiling" not in l]
    assert len(lines) == 1 and "radius must be a positive" in lines[0]
