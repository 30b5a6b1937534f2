"""Exudyn FFRF beams: impact errors of both beam models vs the reference, by mode count (issue 6).

Run: python benchmarks/exudyn_beam_models.py [scene] [modes,...] [dt] [integrator]
Prints, per mode count n: the FE model's first three frequency errors vs Euler-Bernoulli, the FE
model's impact errors vs the converged reference and vs the reference with the same n modes
(the FE model's own difference, without truncation), and the reference-modes model's errors vs the
reference with the same n modes (time integration alone). Not a test: it takes minutes.
"""
import sys
import time

import numpy as np

import impactval
from impactval.engines.base import EngineSettings
from impactval.engines.exudyn_ import ExudynAdapter


def main() -> None:
    scene = sys.argv[1] if len(sys.argv) > 1 else "beam_ss_midspan"
    counts = [int(x) for x in (sys.argv[2] if len(sys.argv) > 2 else "12,24,40").split(",")]
    dt = float(sys.argv[3]) if len(sys.argv) > 3 else 1e-6
    integrator = sys.argv[4] if len(sys.argv) > 4 else "generalized-alpha"
    sc = impactval.load_scene(scene)
    adapter = ExudynAdapter()
    converged = impactval.solve(sc)
    print(f"{scene}: converged reference ({converged.modes} modes): t_m {converged.t_m:.6g} s, "
          f"f_m {converged.f_m:.6g} N, delta_m {converged.delta_m:.6g} m; dt {dt:g} s, {integrator}")
    print("model            n  freq err 1-3 [%]            t_m [%]   f_m [%]  delta_m [%]  build [s]  step [s]")
    for n in counts:
        same_n = impactval.solve(sc, modes=n)
        for model, ref in (("fem", converged), ("fem vs same n", same_n), ("reference-modes", same_n)):
            t0 = time.perf_counter()
            r = adapter.run(sc, EngineSettings(dt=dt, integrator=integrator, contact="native", modes=n,
                                               options=(("beam_model", model.split()[0]),)))
            if r.status != "ok":
                print(f"{model:15s} {n:3d}  {r.status}: {r.message}")
                continue
            e = r.metrics.relative_to(ref.metrics)
            ferr = np.array(r.diagnostics.get("frequency_error", [0, 0, 0])[:3]) * 100
            print(f"{model:15s} {n:3d}  {ferr[0]:+.3f} {ferr[1]:+.3f} {ferr[2]:+.3f}   "
                  f"{100 * e.t_m:+8.3f}  {100 * e.f_m:+8.3f}  {100 * e.delta_m:+8.3f}   "
                  f"{r.wall_time_build_s:8.2f}  {r.wall_time_step_s:8.2f}   ({time.perf_counter() - t0:.1f} s)",
                  flush=True)


if __name__ == "__main__":
    main()
