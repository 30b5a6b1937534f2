"""Shared Warp plumbing for the Warp-based engines (MuJoCo Warp, Newton): kernel cache, CPU graph
capture. Warp itself is imported by `import_warp()`, inside adapter methods; the module-level constants are not.

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


#: float32 axial noise of the Warp chains (MuJoCo Warp, Newton): the chain's motion along the beam made by rounding the x
#: positions is kept out of the energy check; a row gets a validity note beyond AXIAL_NOISE_NOTE x the impact energy
#: (the worked beam has 10 %, the heavy beams 1-2x at the defaults), and is unstable only beyond both AXIAL_NOISE_STOP x
#: the impact energy and AXIAL_FLOOR_STOP x the engine's float32 floor (the noise's size, set by float32 and the chain,
#: not by the impact: measured 0.05-342x it on 15 beams at the defaults, while a slow or small ball's impact energy can
#: be 1e-11 J: 10 of 14 unseen beams, balls at 2 mm/s - 2.3 m/s, were stopped by the impact-energy limit alone, at
#: 56-9.7e9x it, all within their model error once run). A blow-up past the stability limit grows far beyond both (Newton's
#: worked beam at 1.02 of its limit: 9.8e3x the impact energy, ~1.3e5x its floor)
AXIAL_NOISE_NOTE, AXIAL_NOISE_STOP, AXIAL_FLOOR_STOP = 1.0, 10.0, 1e4


#: a float32 contact whose approach or whose per-step ball motion is resolved worse than this gets a validity note
FLOAT32_NOTE = 1e-3
#: ... and is refused before stepping (a one-line reason) when the approach spans fewer float32 steps than this ...
FLOAT32_MIN_STEPS = 20.0
#: ... or a step moves the ball by fewer than this many (each step's motion rounded: a bias up to 1/(2 x) of it)
FLOAT32_MIN_STEP_ULPS = 2.0
#: the per-step rounding is noted when its bound ulp / (2 v0 dt) passes this (fewer than 25 float32 steps per step; the
#: bias measured is ~1/10 of the bound: 2.9 steps, bound 17 %, t_m -1.5 %; the worked beam's 215, bound 0.23 %, is not
#: seen in its rows)
FLOAT32_STEP_NOTE = 0.02


def float32_contact_note(engine: str, z_contact: float, delta_m: float, step: float | None = None) -> str:
    """'' or one validity sentence when float32 at the contact's world height `z_contact` [m] resolves the approach
    `delta_m` [m] (the rigid-plate estimate) worse than FLOAT32_NOTE of it, or (with `step` = v0 dt [m], an engine that
    integrates the ball's world position) rounds each step's motion with a bias bound ulp / (2 v0 dt) beyond
    FLOAT32_STEP_NOTE. Beyond FLOAT32_MIN_STEPS / FLOAT32_MIN_STEP_ULPS the sentence is an EngineError
    (the row is skipped with it). Measured (native contact, unseen beams): 1-1.7 ulp per step gave energy +6-23 %
    (unstable), 2.9 ulp t_m -1.5 %, an approach of 5 float32 steps energy +17 %."""
    from impactval.errors import EngineError

    ulp = float(np.spacing(np.float32(abs(z_contact))))
    parts, severe = [], False
    if ulp > FLOAT32_NOTE * delta_m:
        parts.append(f"the approach ~{delta_m:.2g} m is {delta_m / ulp:.3g} float32 steps of the contact's height "
                     f"{z_contact:.3g} m")
        severe = delta_m < FLOAT32_MIN_STEPS * ulp
    if step is not None and ulp > 2.0 * FLOAT32_STEP_NOTE * step:
        parts.append(f"a step moves the ball v0 dt = {step / ulp:.3g} float32 steps there (each rounded: a bias up to "
                     f"{100 * ulp / (2.0 * step):.2g} %)")
        severe = severe or step < FLOAT32_MIN_STEP_ULPS * ulp
    if not parts:
        return ""
    text = (f"{engine}: float32 at the native contact: {'; '.join(parts)}; --contact hertz forms delta from the "
            f"displacements (resolved at their own size)")
    if severe:
        raise EngineError(f"{text}; refused (fewer than {FLOAT32_MIN_STEPS:g} steps in the approach or "
                          f"{FLOAT32_MIN_STEP_ULPS:g} per step)")
    return text


def axial_noise_blows_up(noise_j: float, impact_energy: float, floor_j: float, stop: float = AXIAL_NOISE_STOP,
                         floor_stop: float = AXIAL_FLOOR_STOP) -> bool:
    """True when the axial noise `noise_j` [J] is beyond both `stop` x the impact energy [J] and `floor_stop` x the
    engine's float32 floor [J]: a blow-up, not rounding (the rule of both Warp engines)."""
    return not (noise_j <= stop * impact_energy or noise_j <= floor_stop * floor_j)


def floor_text(noise_j: float, floor_j: float) -> str:
    """The axial noise [J] against its float32 floor [J] (`axial_noise_floor_J`), for a row's note: '22x its float32
    floor' (a slow ball's noise can be 1e6x the impact energy and still be rounding: the floor says so)."""
    return f"{noise_j / floor_j:.3g}x its float32 floor" if floor_j > 0 else "its float32 floor unknown"


def share_text(fraction: float) -> str:
    """A share of the impact energy as '14 %' below 10x and '5.6e+04x' above (a slow ball's noise can be 1e7 %)."""
    return f"{100 * fraction:.3g} %" if fraction < 10 else f"{fraction:.3g}x"


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


#: most bytes of recorded rows a Warp run keeps on the host (the states of every step up to the window's end)
RECORD_BUDGET_BYTES = 2 * 1024**3


class ChunkedRecord:
    """The rows a recording kernel writes, one per step, in a device buffer of `rows` rows that the host empties after
    each replayed chunk: the kernel writes global row k at k - base[0] (`base`, a 1-element int array the host moves
    on, shared by the recorders of one run), so memory is bounded by a chunk, not by the window cap (200 rigid-plate
    contact times: a 52 mm PMMA ball at 1.4 cm/s at dt = 5e-8 s asked Newton for 29.5 GB up front and crashed).
    `take(count)` copies the rows written since the last call (global rows done+1 .. count) to the host and returns
    them; more than `budget` bytes kept on the host is refused (EngineError naming the step count and a larger dt)."""

    def __init__(self, wp, rows: int, width: int, what: str, dt: float, budget: int | None = None,
                 base=None) -> None:
        self.rows, self.width, self.what, self.dt = rows, width, what, dt
        self.budget = RECORD_BUDGET_BYTES if budget is None else budget
        self.buffer = wp.zeros((rows, width), dtype=float, device="cpu")
        self.base = wp.zeros(1, dtype=int, device="cpu") if base is None else base
        self.blocks: list[np.ndarray] = []
        self.kept = 0
        self.done = 0

    def copy(self, lo: int, hi: int, count: int) -> np.ndarray:
        """Device rows lo .. hi-1 to the host (kept; refused beyond the budget, `count` = steps so far)."""
        from impactval.errors import EngineError

        block = self.buffer.numpy()[lo:hi].copy()
        self.blocks.append(block)
        self.kept += block.nbytes
        if self.kept > self.budget:
            raise EngineError(f"{self.what}: the run recorded {count} steps ({self.kept / 1e9:.2g} GB of states) and the "
                              f"contact had not ended; at dt = {self.dt:.3g} s it needs more than the budget of "
                              f"{self.budget / 1e9:.2g} GB: use a larger dt (e.g. dt = auto)")
        return block

    def advance(self, count: int) -> None:
        """Global row count is the last one taken: the kernel writes the next one at device row 1."""
        self.done = count
        self.base.assign(np.array([count], dtype=np.int32))

    def take(self, count: int) -> np.ndarray:
        """Rows done+1 .. count (global), copied to the host; the device buffer is free again."""
        block = self.copy(1, count - self.done + 1, count)
        self.advance(count)
        return block

    def all(self, first: np.ndarray | None = None) -> np.ndarray:
        """`first` (row 0, if given) then the rows taken so far."""
        head = [first[None, :].astype(np.float32)] if first is not None else []
        return np.concatenate([*head, *self.blocks])


def window_end(samples: np.ndarray, settings, scene) -> int | None:
    """Index of the last sample the run keeps (samples: rows of delta [m], force [N]; settings: the
    job's EngineSettings), or None while the window is open (the rule's definition; the adapters apply it block by
    block with `WindowTracker`, which the tests hold to it). The base's rule
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


class WindowTracker:
    """`window_end` over a series that arrives in blocks (one per replayed chunk), each sample looked at once: after
    every `feed` it returns what `window_end` would return on all the samples fed so far. (The adapters called
    `window_end` on the whole series after each 64-step chunk: quadratic in the chunk count, ~N^2/128 sample visits for
    N steps, which a long --tail turns into minutes.)"""

    def __init__(self, settings, scene) -> None:
        self.radius = scene.ball.radius
        self.tail_steps = int(math.ceil(settings.tail / float(settings.dt)))
        self.count = 0                  # samples fed so far
        self.first: int | None = None   # first sample with f > 0
        self.last: int | None = None    # the window's last sample, once the first contact has ended
        self.bad: int | None = None     # first non-finite sample or ball through the target

    def feed(self, samples: np.ndarray) -> int | None:
        """Add the next block (rows of delta [m], force [N]); the window's last sample index, or None while open."""
        start, n = self.count, len(samples)
        self.count += n
        if self.bad is not None:
            return self.bad
        if n:
            delta, f = samples[:, 0], samples[:, 1]
            bad = ~np.isfinite(delta) | ~np.isfinite(f) | (delta > self.radius)
            if bad.any():
                self.bad = start + int(np.argmax(bad))
                return self.bad
            if self.last is None:
                on = f > 0
                lo = 0
                if self.first is None:
                    if on.any():
                        lo = int(np.argmax(on))
                        self.first = start + lo
                if self.first is not None:
                    ends = np.flatnonzero(~on[lo:] & (delta[lo:] <= 0))
                    if ends.size:
                        self.last = start + lo + int(ends[0]) + self.tail_steps
        return self.last if self.last is not None and self.last < self.count else None
