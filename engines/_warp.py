"""Shared Warp plumbing for the Warp-based engines (MuJoCo Warp, Newton): kernel cache, CPU graph
capture. Imported only inside adapter methods (it imports warp at top level).

Warp compiles every kernel module to C++ on first use (14-18 s cold on this machine) and caches the
binaries in a directory keyed by the kernel source; from the cache a model is ready in ~0.3 s. The
cache lives in the project's cache folder: $WARP_CACHE_PATH when set, else $IMPACTVAL_CACHE/warp,
else ~/.cache/impactval/warp. Stepping uses Warp's CPU graph capture: the ~100 kernel launches of one
step are recorded once and replayed (`wp.capture_launch`), 12-15 us per step instead of ~2 ms.
"""
from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np


def cache_dir() -> Path:
    """Warp kernel cache directory (see the module docstring)."""
    if os.environ.get("WARP_CACHE_PATH"):
        return Path(os.environ["WARP_CACHE_PATH"])
    root = os.environ.get("IMPACTVAL_CACHE")
    return Path(root) / "warp" if root else Path.home() / ".cache" / "impactval" / "warp"


def import_warp():
    """warp, initialised quietly on the CPU with the project's kernel cache."""
    path = cache_dir()
    path.mkdir(parents=True, exist_ok=True)
    os.environ["WARP_CACHE_PATH"] = str(path)      # read by warp.init(): binaries go to <path>/<warp version>
    import warp as wp

    wp.config.log_level = 30          # warnings only: no banner, no per-module load lines
    wp.init()
    return wp


class CapturedStep:
    """One step (a Python function launching Warp kernels) captured as a CPU graph and replayed.

    The first call runs `fn` once uncaptured (this compiles or loads the kernels: `compile_s`), then
    records it; `run(n)` replays the graph n times. `capture=False` keeps plain launches (debugging).
    """

    def __init__(self, wp, fn, capture: bool = True) -> None:
        self.wp, self.fn, self.capture = wp, fn, capture
        self.graph = None
        self.compile_s = 0.0

    def warm_up(self) -> None:
        """Run fn once (compiling/loading kernels), then capture it; the warm-up step is real."""
        wp = self.wp
        t0 = time.perf_counter()
        self.fn()
        wp.synchronize()
        self.compile_s = time.perf_counter() - t0
        if self.capture:
            with wp.ScopedCapture(device="cpu") as cap:
                self.fn()
            self.graph = cap.graph

    def run(self, n: int) -> None:
        wp = self.wp
        if self.graph is None:
            for _ in range(n):
                self.fn()
        else:
            for _ in range(n):
                wp.capture_launch(self.graph)
        wp.synchronize()


def window_end(samples: np.ndarray, settings, scene) -> int | None:
    """Index of the last sample the run keeps (samples: rows of delta [m], force [N]; settings: the
    job's EngineSettings), or None while the window is open. The base's rule
    (engines/base.py): the first sample after the first contact with f <= 0 and delta <= 0, plus
    ceil(tail/dt) samples; a blow-up (non-finite, or the ball through the target) ends it at once."""
    delta, f = samples[:, 0], samples[:, 1]
    bad = ~np.isfinite(delta) | ~np.isfinite(f) | (delta > scene.ball.radius)
    if bad.any():
        return int(np.argmax(bad))
    on = f > 0
    if not on.any():
        return None
    first = int(np.argmax(on))
    ends = np.flatnonzero(~on[first:] & (delta[first:] <= 0))
    if not ends.size:
        return None
    last = first + int(ends[0]) + int(math.ceil(settings.tail / float(settings.dt)))
    return last if last < len(delta) else None
