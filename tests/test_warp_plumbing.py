"""Shared Warp plumbing (engines/_warp.py) that needs no engine: the window rule on sampled series and
the kernel-cache location."""
from pathlib import Path

import numpy as np

import impactval
from impactval.engines._warp import cache_dir, window_end
from impactval.engines.base import EngineSettings


def _series(n_on: int, n_after: int):
    t = np.arange(n_on + n_after)
    delta = np.where(t < n_on, 1e-5 * np.sin(np.pi * (t + 0.5) / n_on), -1e-7 * (t - n_on + 1))
    f = np.where(delta > 0, 1e8 * delta, 0.0)
    return np.column_stack([delta, f])


def test_window_closes_one_sample_after_the_contact_or_tail_later():
    sc = impactval.load_scene("plate_steel")
    s = _series(40, 30)
    assert window_end(s, EngineSettings(dt=1e-6), sc) == 40
    assert window_end(s, EngineSettings(dt=1e-6, tail=10.5e-6), sc) == 51       # ceil(tail/dt) more
    assert window_end(s, EngineSettings(dt=1e-6, tail=100e-6), sc) is None      # not stepped far enough
    assert window_end(s[:30], EngineSettings(dt=1e-6), sc) is None              # contact still open


def test_window_closes_at_a_blow_up():
    sc = impactval.load_scene("plate_steel")
    s = _series(40, 30)
    s[12, 0] = np.nan
    assert window_end(s, EngineSettings(dt=1e-6), sc) == 12
    s = _series(40, 30)
    s[7, 0] = 2 * sc.ball.radius                      # the ball went through the target
    assert window_end(s, EngineSettings(dt=1e-6), sc) == 7


def test_kernel_cache_in_the_project_cache_folder(monkeypatch, tmp_path):
    monkeypatch.delenv("WARP_CACHE_PATH", raising=False)
    monkeypatch.delenv("IMPACTVAL_CACHE", raising=False)
    assert cache_dir() == Path.home() / ".cache" / "impactval" / "warp"
    monkeypatch.setenv("IMPACTVAL_CACHE", str(tmp_path))
    assert cache_dir() == tmp_path / "warp"
    monkeypatch.setenv("WARP_CACHE_PATH", str(tmp_path / "w"))
    assert cache_dir() == tmp_path / "w"
