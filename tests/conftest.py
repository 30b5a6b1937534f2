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
