"""Issue 11's Exudyn bars on every tests/unseen beam and the catalogue's beams (docs/exudyn.md table).

Per scene: the converged reference of the scene's own theory (tol 1e-5), then Exudyn with every default (an
Euler-Bernoulli scene gets the fe-beam ANCF mesh, a Timoshenko scene the solid) and with
`beam_model=reference-modes`; optionally (`--solid`) also the solid model on every scene (slow: one FE
build each, cached afterwards). Errors t_m / f_m / delta_m in %, signed (engine - reference)/reference.
Each job runs in this process (execute_job: failures are rows). Timings are under the machine's load.

    python benchmarks/exudyn_fe_beam_bars.py [--solid] [scene ...]
"""
import argparse
import glob
import os
import time

import impactval
from impactval.engines.base import EngineSettings, execute_job

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CATALOGUE = ["beam_ss_midspan", "beam_ss_quarter", "beam_cc_midspan", "beam_cantilever_tip", "heavy_ball_slender_beam",
             "light_ball_heavy_beam", "beam_ss_stubby_timoshenko"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenes", nargs="*")
    ap.add_argument("--solid", action="store_true", help="also the solid (hex27) model on every scene")
    a = ap.parse_args()
    scenes = a.scenes or sorted(glob.glob(os.path.join(HERE, "tests", "unseen", "*.toml"))) + CATALOGUE
    runs = [("default", ())]
    runs.append(("reference-modes", (("beam_model", "reference-modes"),)))
    if a.solid:
        runs.append(("solid", (("beam_model", "solid"),)))
    print(f"{'scene':32s} {'theory':8s} {'run':16s} {'status':8s} {'t_m / f_m / delta_m [%]':>26s} "
          f"{'model_err%':>10s} {'steps':>6s} {'step_s':>7s}  model")
    worst = {name: 0.0 for name, _ in runs}
    for path in scenes:
        sc = impactval.load_scene(path)
        ref = impactval.solve(sc, tol=1e-5)
        theory = getattr(sc.target, "theory", "-")[:8]
        for name, opts in runs:
            t0 = time.perf_counter()
            r = execute_job("exudyn", sc, EngineSettings(options=opts))
            errs = [100 * (g / w - 1) for g, w in ((r.t_m, ref.t_m), (r.f_m, ref.f_m), (r.delta_m, ref.delta_m))]
            if r.status == "ok":
                worst[name] = max(worst[name], *(abs(e) for e in errs))
            else:
                worst[name] = float("inf")
            txt = " / ".join(f"{e:+.3f}" for e in errs)
            print(f"{sc.name[:32]:32s} {theory:8s} {name:16s} {r.status.value:8s} {txt:>26s} "
                  f"{100 * r.model_error:10.3f} {r.n_steps:6d} {r.wall_time_step_s:7.2f}  {r.model} "
                  f"[{time.perf_counter() - t0:.1f} s]", flush=True)
    print("largest |error| per run [%]: " + ", ".join(f"{k} {v:.3f}" for k, v in worst.items()))


if __name__ == "__main__":
    main()
