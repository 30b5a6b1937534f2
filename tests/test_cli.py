"""The command line for the reference (issue 8)."""
import json
import subprocess
import sys

import numpy as np
import pytest

import impactval
from conftest import run_py


def cli(*args):
    return subprocess.run([sys.executable, "-m", "impactval.cli", *args], capture_output=True, text=True)


def test_scenes_lists_the_catalogue():
    out = cli("scenes")
    assert out.returncode == 0
    assert "beam_ss_midspan" in out.stdout and "plate_steel" in out.stdout


def test_reference_json_has_the_public_keys():
    out = cli("reference", "plate_steel", "--json")
    assert out.returncode == 0, out.stderr
    d = json.loads(out.stdout)
    assert {"t_m", "f_m", "delta_m", "uncertainty", "modes"} <= set(d)
    assert set(d["uncertainty"]) == {"t_m", "f_m", "delta_m"}
    r = impactval.solve(impactval.load_scene("plate_steel"))
    assert d["t_m"] == pytest.approx(r.t_m, rel=1e-12)


def test_reference_curve_csv(tmp_path):
    f = tmp_path / "c.csv"
    out = cli("reference", "modal_two_mode", "--curve", str(f), "--tol", "1e-5")
    assert out.returncode == 0, out.stderr
    data = np.loadtxt(f, delimiter=",", skiprows=1)
    assert data.shape[1] == 6 and data.shape[0] > 20
    f_m = float(out.stdout.splitlines()[1].split()[-8])   # row: scene, t_m ± u, f_m ± u, delta_m ± u, modes, contacts
    assert 0.99 * f_m <= data[:, 2].max() <= f_m * (1 + 1e-9)       # nodes never exceed the refined peak
    scene = impactval.load_scene("modal_two_mode")
    inside = data[:, 1] > 0
    assert np.allclose(data[inside, 2], scene.alpha * data[inside, 1] ** 1.5, rtol=1e-12)


def test_reference_table_for_the_whole_catalogue():
    out = cli("reference", "--tol", "1e-4")
    assert out.returncode == 0, out.stderr
    assert sum(1 for l in out.stdout.splitlines() if l.split() and l.split()[0] in
               impactval.scenarios.scene.catalogue_names()) == len(impactval.scenarios.scene.catalogue_names())


def test_core_never_imports_an_engine():
    code = ("import impactval, impactval.reference.solve, impactval.scenarios.scene, impactval.cli, "
            "impactval.engines, impactval.engines.base; import sys; "
            "print(sorted({'mujoco', 'pybullet', 'exudyn', 'matplotlib'} & set(sys.modules)) or '')")
    assert run_py(code) == ""


def test_first_run_says_it_compiles(tmp_path):
    """With an empty numba cache the CLI says on stderr that it compiles (once)."""
    import os
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    code = ("import impactval.cli as c; from impactval.reference import kernel; from pathlib import Path; "
            "print(any(Path(kernel.solve_auto._cache._cache_path).glob('kernel.solve_auto-*.nbi')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert out.stdout.strip() == "False"
    warn = subprocess.run([sys.executable, "-c", "import impactval.cli as c; c._warn_if_compiling()"],
                          capture_output=True, text=True, env=env)
    assert "compiling" in warn.stderr
