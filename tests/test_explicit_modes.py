"""A beam scene with an explicit `modes = n` (s20 fuzz2 findings 1 and 6): the reference is the n-mode model (kept),
but never silently: a validity warning measured against the continuum, engines sized against the continuum, the
row's structure error = the engine's structure against the n-mode reference (structure + numerics = error), the
theory gap on the continuum; `--modes` on MuJoCo's modal target and chains labelled and noted."""
from __future__ import annotations

import dataclasses
import math

import pytest
from click.testing import CliRunner
from conftest import requires_mujoco

import impactval
from impactval.cli import main
from impactval.engines.base import EngineSettings
from impactval.reference.explicit_modes import (TRUNCATION_WARN_FACTOR, TRUNCATION_WARN_FLOOR, continuum_scene,
                                                explicit_count, truncation_check, truncation_gap)

#: an unseen beam (not the fuzz scene): clamped-clamped steel, hit off-centre by a glass ball
BEAM = """
name = "{name}"
[ball]
radius = 0.006
velocity = 0.8
material = "glass"
[target]
kind = "beam"
material = "structural-steel"
support = "clamped-clamped"
length = 0.22
width = 0.018
height = 0.009
impact_at = 0.31
{modes}
"""

MOD3 = """
name = "mod3_unseen"
[ball]
radius = 0.005
velocity = 1.5
material = "titanium"
[target]
kind = "modal"
material = "aluminium"
omega = [12000.0, 55000.0, 190000.0]
modal_mass = [0.25, 0.3, 0.5]
phi = [0.85, -0.55, 0.35]
"""


def _scene(tmp_path, modes: int | None, name: str = "cc_unseen_m5"):
    p = tmp_path / f"{name}.toml"
    p.write_text(BEAM.format(name=name, modes="" if modes is None else f"modes = {modes}"))
    return impactval.load_scene(str(p))


def test_modes_5_warns_with_the_measured_continuum_difference(tmp_path):
    sc = _scene(tmp_path, 5)
    ref = impactval.solve(sc, tol=1e-6)
    assert ref.modes == 5
    assert not any("modes = 5" in v for v in ref.validity)          # solve itself stays as it was (hot path)
    cont, warning = truncation_check(sc, ref, 1e-6)
    auto = impactval.solve(_scene(tmp_path, None, "cc_unseen_auto"), tol=1e-6)   # the automatic count, solved apart
    assert cont.modes == auto.modes > 5
    gap = truncation_gap(ref, cont)
    for m in ("t_m", "f_m", "delta_m"):
        assert gap[m] == pytest.approx(getattr(ref, m) / getattr(auto, m) - 1.0, rel=1e-4, abs=1e-8)
    assert max(map(abs, gap.values())) > TRUNCATION_WARN_FACTOR * 1e-6
    assert warning.startswith("modes = 5 (the scene's) define the reference model")
    assert f"t_m {100 * gap['t_m']:+.3g} %" in warning and "remove `modes`" in warning
    # the command line shows it with the reference's other warnings
    out = CliRunner().invoke(main, ["reference", str(tmp_path / "cc_unseen_m5.toml")])
    assert out.exit_code == 0, out.output
    assert "! modes = 5 (the scene's) define the reference model" in out.output


def test_near_converged_explicit_count_does_not_warn():
    worked = impactval.load_scene("beam_ss_midspan")
    sc = dataclasses.replace(worked, target=dataclasses.replace(worked.target, modes=160))
    assert explicit_count(sc) == 160 and explicit_count(worked) is None
    assert continuum_scene(worked) is worked
    ref = impactval.solve(sc, tol=1e-6)
    cont, warning = truncation_check(sc, ref, 1e-6)
    assert cont is not None and warning == ""
    # 20x tol, but below TRUNCATION_WARN_FLOOR (invisible in any row): no warning
    assert 1e-6 < max(map(abs, truncation_gap(ref, cont).values())) < TRUNCATION_WARN_FLOOR
    assert truncation_check(worked, impactval.solve(worked, tol=1e-6), 1e-6) == (None, "")


def test_chain_sizing_and_step_ignore_the_scene_mode_count(tmp_path):
    pytest.importorskip("numpy")
    from impactval.engines.base import contact_time
    from impactval.engines.chain import continuum_metrics, segments_for

    m5, full = _scene(tmp_path, 5), _scene(tmp_path, None, "cc_unseen_auto")
    assert continuum_metrics(m5) == continuum_metrics(full)
    assert segments_for(m5).n == segments_for(full).n
    assert contact_time(m5) == contact_time(full)


@requires_mujoco
def test_run_splits_the_truncation_into_structure_and_notes_it(tmp_path):
    from impactval.runner import run

    m5_path = tmp_path / "cc_unseen_m5.toml"
    _scene(tmp_path, 5)
    _scene(tmp_path, None, "cc_unseen_auto")
    df = run([str(m5_path), str(tmp_path / "cc_unseen_auto.toml")], ["mujoco"], workers=1)
    a, b = df.iloc[0], df.iloc[1]
    assert a["scene"] == "cc_unseen_m5" and a["status"] == "ok"
    assert a["segments"] == b["segments"] and a["dt"] == b["dt"]          # the chain of the beam, not of 5 modes
    assert a["f_m"] == pytest.approx(b["f_m"], rel=1e-9)                   # the same engine model
    for m in ("t_m", "f_m", "delta_m"):
        # numerics as on the scene without modes; the truncation is in the structure error
        assert a[f"numerics_err_{m}"] == pytest.approx(b[f"numerics_err_{m}"], abs=2e-5)
        assert a[f"structure_err_{m}"] + a[f"numerics_err_{m}"] == pytest.approx(a[f"err_{m}"], abs=1e-9)
        assert a[f"theory_gap_{m}"] == pytest.approx(b[f"theory_gap_{m}"], rel=1e-3)   # on the continuum
    assert "the reference is the scene's 5-mode model (modes = 5)" in a["message"]
    assert "try a smaller --dt" not in a["message"]
    assert "modes = 5" not in str(b["message"])


@requires_mujoco
def test_modes_option_on_mujoco_modal_target_and_chain_is_labelled_and_noted(tmp_path):
    from impactval.runner import run

    (tmp_path / "mod3.toml").write_text(MOD3)
    beam = _scene(tmp_path, None, "cc_unseen_auto")
    assert beam.target.modes is None
    paths = [str(tmp_path / "mod3.toml"), str(tmp_path / "cc_unseen_auto.toml")]
    plain = run(paths[:1], ["mujoco"], workers=1)
    asked = run(paths, ["mujoco"], EngineSettings(modes=2), workers=1)
    m, c = asked.iloc[0], asked.iloc[1]
    assert str(m["segments"]) == "3"                        # the model built: all 3 modes, not "2"
    assert m["f_m"] == plain.iloc[0]["f_m"]
    assert "--modes 2 does not apply to mujoco's modal target" in m["message"]
    assert "--modes 2 does not apply to mujoco's beam" in c["message"]
    assert math.isfinite(c["err_t_m"])
