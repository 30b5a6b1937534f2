"""The error estimate's step choice before and after the dense peak (issue 17 item 5), side by side in one run.

On the 160-mode worked beam (beam_ss_midspan, explicit 160 modes) at tol 1e-4, 1e-6, 1e-8: `kernel.solve_auto` of git
revision REV (default 35bdafc, with that revision's own unresolved-mode table) and of today's code, each with its own
constants: base steps n per rigid-plate time, nodes of the fine run, reported relative uncertainty, real error
(against today's solve at tol 1e-12 on the same 160 modes, and DOP853 at rtol 1e-13 as a check of that truth), and
the kernel time per call on two clocks, interleaved round by round (best of each). The machine is shared: only the
ratio now/before means something; the load average is printed.

Run: python benchmarks/bound_before_after.py [REV]
"""
from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import impactval
from impactval.reference import kernel
from impactval.reference import solve as ref_solve
from impactval.reference.hertz import plate_impact
from impactval.reference.ode import solve_ode

ROOT = Path(__file__).resolve().parents[1]
CLOCKS = {"cpu": time.process_time, "wall": time.perf_counter}


def _at(rev: str, path: str) -> str:
    return subprocess.run(["git", "show", f"{rev}:{path}"], cwd=ROOT, capture_output=True, text=True, check=True).stdout


def old_kernel(rev: str):
    """reference/kernel.py of `rev` as its own module, and its unresolved-mode table from reference/solve.py."""
    folder = Path(tempfile.mkdtemp(prefix="impactval-kernel-"))
    path = folder / "kernel_before.py"
    path.write_text(_at(rev, "reference/kernel.py"))
    spec = importlib.util.spec_from_file_location("kernel_before", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    src = _at(rev, "reference/solve.py")
    consts = {}
    for name in ("UNRESOLVED_THETA", "UNRESOLVED_C"):
        m = re.search(rf"^{name} = (.*?\)\)?)\n(?=\S)", src, re.S | re.M)
        consts[name] = eval(m.group(1), {"np": np})
    return module, consts


def main(rev: str = "35bdafc", rounds: int = 10) -> None:
    base = impactval.load_scene("beam_ss_midspan")
    md = ref_solve.structure_modes(base, 160)
    m0, alpha, v0 = base.ball.mass, base.alpha, base.ball.velocity
    omega, g, ew = ref_solve._select(md)
    plate = plate_impact(m0, alpha, v0)
    truth = ref_solve.solve_modes(md, m0, alpha, v0, 1e-12)[0].metrics
    ode, _ = solve_ode(md, m0, alpha, v0, rtol=1e-13, atol=1e-15)
    print(f"160-mode worked beam; truth: solve at tol 1e-12 (DOP853 rtol 1e-13 agrees to "
          f"{max(abs(ode.t_m / truth.t_m - 1), abs(ode.f_m / truth.f_m - 1), abs(ode.delta_m / truth.delta_m - 1)):.1e})")
    old, consts = old_kernel(rev)
    for tol in (1e-4, 1e-6, 1e-8):
        n0 = max(8.0, ref_solve._N_ANCHOR * (8.0 * ref_solve._ERR_ANCHOR / tol) ** (1.0 / (ref_solve.P_DEGREE + 1)))
        common = (omega, g, ew, m0, alpha, v0, md.residual_flexibility, tol, 0.0, plate.t_m, plate.delta_m,
                  ref_solve.P_DEGREE, ref_solve.GRADING_WINDOW, n0, ref_solve.ESTIMATE_ORDER)
        tail = (ref_solve.SMALLEST_STEP_FACTOR, ref_solve.UNRESOLVED_SHARE, ref_solve.node_cap(len(omega)),
                float(kernel.SERIES_SAMPLES), ref_solve.LIGHT_COUPLING)
        calls = {"before": (old.solve_auto, common + (consts["UNRESOLVED_THETA"], consts["UNRESOLVED_C"]) + tail),
                 "now": (kernel.solve_auto, common + (ref_solve.UNRESOLVED_THETA, ref_solve.UNRESOLVED_C) + tail
                         + (ref_solve.UNRESOLVED_CLASSES, ref_solve.MIN_STEPS, ref_solve.SMALLEST_STEP_C))}
        best = {(who, c): np.inf for who in calls for c in CLOCKS}
        rows = {}
        for who, (fn, args) in calls.items():
            out = fn(*args)
            c = out[9]
            t_m, d_m = c[0, 1] - c[0, 0], c[0, 2]
            f_m = alpha * d_m**1.5
            real = max(abs(t_m / truth.t_m - 1), abs(f_m / truth.f_m - 1), abs(d_m / truth.delta_m - 1))
            rows[who] = (out[11], out[1], out[10], real)
        for _ in range(rounds):
            for who, (fn, args) in calls.items():
                for c, now in CLOCKS.items():
                    t0 = now()
                    for _ in range(10):
                        fn(*args)
                    best[who, c] = min(best[who, c], (now() - t0) / 10)
        print(f"tol {tol:g}:")
        for who in calls:
            n, nodes, rep, real = rows[who]
            print(f"  {who:6s} n {n:7.1f}  nodes {nodes:5d}  reported {rep:.2e}  real {real:.2e} (reported/real "
                  f"{rep / real:5.1f})  kernel {best[who, 'cpu'] * 1e6:7.1f} us CPU {best[who, 'wall'] * 1e6:7.1f} us wall")
        print(f"  now/before: {best['now', 'cpu'] / best['before', 'cpu']:.2f} CPU, "
              f"{best['now', 'wall'] / best['before', 'wall']:.2f} wall")
    print(f"load average (1 min): {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main(*sys.argv[1:2])
