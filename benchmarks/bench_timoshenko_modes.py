"""Cost of clamped-clamped / cantilever Timoshenko mode shapes, old vs new, side by side in one run.

The shapes (modal mass and phi of max-normalised modes, reference/timoshenko.py) were evaluated on a grid over
the whole span per mode (`_clamped_shapes_grid`: O(n^2) for n modes); `_clamped_shapes` does O(1) work per mode
for all but a bounded number (closed-form modal mass; max |W| from the interior sinusoid or chosen beat passes).
For each mode count: the frequencies (shared, `clamped_frequencies`), old shapes, new shapes on CPU time
(time.process_time, best of `--repeat`), the ratio, and how the two agree: the modal mass integral and phi^2/m
(normalisation free: what the solver uses) to roundoff; max |W| (the normalisation) where the old grid read it low.
The machine's load average is printed: it is shared, so only the side-by-side ratios mean something.

Then, unless --no-solve: impactval.solve(tol=1e-6) on a slender Timoshenko cantilever (CPU time, cold caches),
with the old shapes patched in and with the new ones (every mode cache cleared before each).

Run: python benchmarks/bench_timoshenko_modes.py [--modes 1024 4096] [--repeat 2] [--no-solve]
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

import impactval
from impactval.reference import solve as ref_solve, structure, timoshenko as tim, timoshenko_shapes as tshapes
from impactval.scenarios.scene import scene_from_dict


def _scene(length=1.0, width=0.02, height=0.0075, material="aluminium", support="cantilever", radius=0.01,
           ball="steel", velocity=1.0):
    return scene_from_dict({"name": "bench", "ball": {"radius": radius, "velocity": velocity, "material": ball},
                            "target": {"kind": "beam", "material": material, "support": support, "length": length,
                                       "width": width, "height": height, "impact_at": 0.8, "theory": "timoshenko"}})


def _cpu(fn, repeat):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


def shapes(modes, repeat):
    print(f"load average {os.getloadavg()[0]:.1f} (2 cores shared); CPU seconds, best of {repeat}")
    print("beam: aluminium cantilever 1 m x 20 mm x 7.5 mm (L/h 133), impact at 0.8 L")
    print(f"{'modes':>6} {'support':>16} {'freq s':>7} {'old s':>7} {'new s':>7} {'old/new':>8} "
          f"{'mass diff':>9} {'phi2/m diff':>11} {'old peak low by':>15}")
    for n in modes:
        for support in ("cantilever", "clamped-clamped"):
            sec = tim.Section.of(_scene(support=support).target)
            x = 0.8 * sec.length
            t_f, om = _cpu(lambda: tim.clamped_frequencies.__wrapped__(sec, support, n), 1)
            t_old, (mm_old, phi_old) = _cpu(lambda: tshapes._clamped_shapes_grid(sec, support, om, x), repeat)
            t_new, (mm_new, phi_new) = _cpu(lambda: tshapes._clamped_shapes(sec, support, om, x), repeat)
            peak_ratio = phi_new / np.where(phi_old != 0, phi_old, np.nan)      # = old peak / new peak
            mass_diff = np.nanmax(np.abs(mm_new * peak_ratio**-2 / mm_old - 1))  # the integral itself
            g_old, g_new = phi_old**2 / mm_old, phi_new**2 / mm_new
            low = np.nanmax(1 - peak_ratio)
            print(f"{n:>6} {support:>16} {t_f:7.2f} {t_old:7.2f} {t_new:7.2f} {t_old / t_new:7.1f}x "
                  f"{mass_diff:9.1e} {np.max(np.abs(g_new - g_old)) / np.max(g_old):11.1e} {low:15.1e}")


def solve_cold(tol):
    sc = _scene(material="aluminium", ball="tungsten-carbide", radius=0.02, velocity=0.5)
    rows = []
    for name, fn in (("old shapes", tshapes._clamped_shapes_grid), ("new shapes", tshapes._clamped_shapes)):
        saved = tshapes._clamped_shapes
        tshapes._clamped_shapes = fn
        for cached in (tim.timoshenko_modes, tim.clamped_frequencies, ref_solve._beam_modes_cached):
            cached.cache_clear()
        structure._CACHE.clear()
        try:
            t, r = _cpu(lambda: impactval.solve(sc, tol=tol), 1)
        finally:
            tshapes._clamped_shapes = saved
        rows.append((name, t, r))
        print(f"solve(tol={tol:g}) slender Timoshenko cantilever, {name}: {t:.2f} s CPU, {r.modes} modes, "
              f"t_m {r.metrics.t_m:.9e} f_m {r.metrics.f_m:.9e} delta_m {r.metrics.delta_m:.9e}")
    (_, t_old, r_old), (_, t_new, r_new) = rows
    diff = max(abs(getattr(r_new.metrics, k) / getattr(r_old.metrics, k) - 1) for k in ("t_m", "f_m", "delta_m"))
    print(f"  old/new {t_old / t_new:.1f}x; metrics differ by {diff:.1e} (relative)")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--modes", type=int, nargs="+", default=[1024, 4096])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--no-solve", action="store_true")
    args = ap.parse_args()
    shapes(args.modes, args.repeat)
    if not args.no_solve:
        impactval.solve(_scene(length=0.3), tol=1e-4)             # compile the kernel first
        solve_cold(1e-6)


if __name__ == "__main__":
    main()
