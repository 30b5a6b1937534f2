"""The Python API and the run report as the README writes them (round 20, user test fuzz2: findings 2, 3, 8)."""
from pathlib import Path

import numpy as np
import pytest

import impactval
from impactval.errors import ImpactvalError
from impactval.runner import run


def test_run_takes_progress_by_name_as_the_readme_says(tmp_path, capsys):
    """README: `run(...)` takes `progress="auto"`; it raised AttributeError ('str' object has no attribute 'start'),
    and so did progress=False. Names and booleans now work; anything else is a one-line ImpactvalError."""
    for i, kind in enumerate(("auto", "plain", False, True, None, "none")):
        df = run(["plate_steel"], ["impactval.engines.fake_:HertzSpringAdapter"], dt=1e-6, store=str(tmp_path / f"s{i}.sqlite"),
                 progress=kind, workers=1)
        assert df["status"].tolist() == ["ok"]
    err = capsys.readouterr().err
    assert "plate_steel" in err                          # the lines of "auto"/"plain" (not a terminal here)
    for bad in ("fast", 3, object()):
        with pytest.raises(ImpactvalError, match="^progress must be one of 'auto', 'plain', 'rich', 'none'"):
            run(["plate_steel"], ["impactval.engines.fake_:HertzSpringAdapter"], dt=1e-6, store=str(tmp_path / "bad.sqlite"), progress=bad)


def test_structure_modes_takes_a_name_or_path_and_checks_n():
    """`impactval.structure_modes('file.toml', 5)` raised AttributeError ('str' object has no attribute 'target'),
    unlike `solve`, and n = 10**7 ran. A name or path loads like `solve`'s; n outside 1 .. 100000 and a non-scene
    are one-line errors. The worked beam's first mode against Euler-Bernoulli's closed form, (pi/L)^2 sqrt(EI/(rho A))."""
    md = impactval.structure_modes("beam_ss_midspan", 3)
    scene = impactval.load_scene("beam_ss_midspan")
    b = scene.target
    w1 = (np.pi / b.length) ** 2 * np.sqrt(b.material.young * b.width * b.height**3 / 12
                                           / (b.material.density * b.width * b.height))
    assert md.omega[0] == pytest.approx(w1, rel=1e-9)
    assert np.array_equal(md.omega, impactval.structure_modes(scene, 3).omega)
    for bad_n in (0, 10**7, 2.5, True):
        with pytest.raises(ImpactvalError, match="^n must be a whole number from 1 to 100000"):
            impactval.structure_modes("beam_ss_midspan", bad_n)
    for bad in (None, 3.0):
        with pytest.raises(ImpactvalError, match="a scene is a"):
            impactval.structure_modes(bad, 5)


def test_a_run_report_opens_with_the_verdict_its_exit_code_gives(tmp_path):
    """README: every report gives its verdict first; a run report had none (an exit-1 run said "finished" and a
    summary). The verdict line is the command's own exit code and why, checked against the real exit code of
    `impactval run` for a clean run and for one whose engine raises."""
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "impactval.cli", "run", "plate_steel", "--dt", "1e-6"]
    good = subprocess.run(cmd + ["--engines", "impactval.engines.fake_:HertzSpringAdapter", "--out",
                                 str(tmp_path / "good")], capture_output=True, text=True)
    bad = subprocess.run(cmd + ["--engines", "fake_engines:Raises", "--out", str(tmp_path / "bad")],
                         capture_output=True, text=True, cwd=str(Path(__file__).parent))   # tests/fake_engines.py
    assert good.returncode == 0 and bad.returncode == 1, (good.stderr, bad.stderr)
    good_md = (tmp_path / "good" / "report.md").read_text()
    bad_md = (tmp_path / "bad" / "report.md").read_text()
    head = lambda md: md[:md.index("## ")]          # noqa: E731
    assert "- **verdict**: exit 0: no row failed (ok 1)" in head(good_md)
    assert "- **verdict**: exit 1: 1 of 1 rows failed (crashed 1)" in head(bad_md)


def test_an_engine_named_twice_runs_once(tmp_path):
    """`--engines mujoco,mujoco` ran each job twice: the table printed it twice and the summary said "jobs 2, ok 2"
    while results.csv kept one row. An engine named twice (also as the same adapter spelt twice) runs once."""
    fake = "impactval.engines.fake_:HertzSpringAdapter"
    df = run(["plate_steel"], f"{fake},{fake}", dt=1e-6, store=str(tmp_path / "s.sqlite"), progress=None, workers=1)
    assert len(df) == 1 and df["status"].tolist() == ["ok"]


def test_a_modal_targets_frequencies_are_not_labelled_euler_bernoulli(tmp_path):
    """The report's structure-frequency list labelled a modal target's given omegas "EB +0.00 %" (there is no beam);
    they are "given", and a beam's row still reads EB."""
    pytest.importorskip("mujoco", reason="pip install 'impactval[mujoco]'")
    pytest.importorskip("exudyn", reason="pip install 'impactval[exudyn]'")       # its modal rows list frequencies
    path = tmp_path / "mod3.toml"
    path.write_text('name = "mod3"\n[ball]\nradius = 0.006\nvelocity = 2.0\nmaterial = "titanium"\n'
                    '[target]\nkind = "modal"\nmaterial = "steel"\nomega = [15000.0, 60000.0, 210000.0]\n'
                    'modal_mass = [0.2, 0.35, 0.6]\nphi = [0.9, -0.6, 0.4]\n')
    run([str(path)], ["exudyn"], out=tmp_path / "modal", store=str(tmp_path / "s.sqlite"), progress=None, workers=1)
    run(["beam_ss_midspan"], ["mujoco"], out=tmp_path / "beam", store=str(tmp_path / "s.sqlite"), progress=None,
        workers=1)
    lines = [ln for d in ("modal", "beam") for ln in (tmp_path / d / "report.md").read_text().splitlines()]
    modal = next(ln for ln in lines if ln.startswith("- mod3 / exudyn (N"))
    beam = next(ln for ln in lines if ln.startswith("- beam_ss_midspan / mujoco (N = ") and "(EB" in ln)
    assert "15000.0 (given +0.00 %)" in modal and "EB" not in modal, modal
    assert "EB " in beam and "Timoshenko" in beam, beam
