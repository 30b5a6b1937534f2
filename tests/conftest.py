"""Shared test helpers: optional engines (style.md, pattern 11)."""
import importlib.util
import subprocess
import sys

import pytest


def importorskip_mark(module: str):
    has = importlib.util.find_spec(module) is not None
    return has, pytest.mark.skipif(not has, reason=f"{module} not installed")


has_mujoco, requires_mujoco = importorskip_mark("mujoco")
has_pybullet, requires_pybullet = importorskip_mark("pybullet")
has_exudyn, requires_exudyn = importorskip_mark("exudyn")


def run_py(code: str) -> str:
    """Run code in a fresh interpreter; return its stdout (stripped)."""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.strip()


@pytest.fixture(scope="module")
def plate_scene():
    """The catalogue's rigid-plate scene (worked case of physics.md)."""
    import impactval

    return impactval.load_scene("plate_steel")


@pytest.fixture(scope="module")
def plate(plate_scene):
    """Closed-form Hertz impact of the plate scene."""
    from impactval.reference.hertz import plate_impact

    return plate_impact(plate_scene.ball.mass, plate_scene.alpha, plate_scene.ball.velocity)
