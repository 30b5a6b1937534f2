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


def _fed_like_the_adapters(series, cuts, settings, scene):
    """WindowTracker fed block by block against window_end on every prefix (what the adapters computed before)."""
    from impactval.engines._warp import WindowTracker

    tracker = WindowTracker(settings, scene)
    bounds = [0, *sorted(set(cuts)), len(series)]
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        assert tracker.feed(series[lo:hi]) == window_end(series[:hi], settings, scene), (lo, hi)


def test_window_tracker_equals_the_rule_on_every_prefix():
    """Random contacts (several humps, re-contacts, a blow-up or none, tails) cut into random blocks: after every
    block the tracker says what window_end says on all the samples so far."""
    from hypothesis import given, settings as hsettings, strategies as st

    sc = impactval.load_scene("plate_steel")

    @hsettings(max_examples=300, deadline=None)
    @given(n_on=st.integers(1, 60), n_after=st.integers(0, 60), tail=st.sampled_from([0.0, 3e-6, 10.5e-6, 1e-4]),
           lead=st.integers(0, 5), recontact=st.integers(-1, 40), blow=st.integers(-1, 130),
           cuts=st.lists(st.integers(0, 130), max_size=12))
    def check(n_on, n_after, tail, lead, recontact, blow, cuts):
        s = np.vstack([np.zeros((lead, 2)), _series(n_on, n_after)])     # f = 0 samples before the touch
        if 0 <= recontact < n_after:
            s[lead + n_on + recontact, :] = [1e-7, 10.0]                 # a re-contact after the end
        if 0 <= blow < len(s):
            s[blow, 0] = np.nan if blow % 2 else 2 * sc.ball.radius
        _fed_like_the_adapters(s, [c for c in cuts if c <= len(s)], EngineSettings(dt=1e-6, tail=tail), sc)

    check()


def test_window_tracker_is_linear_in_the_samples():
    """One visit per sample: a 200,000-step series fed in 64-step blocks stays in step with window_end's answer on
    the whole series, and the tracker does not re-read earlier blocks (it keeps none)."""
    from impactval.engines._warp import WindowTracker

    sc = impactval.load_scene("plate_steel")
    s = _series(150_000, 50_000)
    settings = EngineSettings(dt=1e-6, tail=20e-3)
    tracker = WindowTracker(settings, sc)
    ends = [tracker.feed(s[k:k + 64]) for k in range(0, len(s), 64)]
    assert ends[-1] == window_end(s, settings, sc) == 150_000 + 20_000
    assert sum(e is not None for e in ends) == len(ends) - (150_000 + 20_000) // 64
    assert not any(isinstance(v, np.ndarray) for v in vars(tracker).values())
