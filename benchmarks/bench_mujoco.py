"""MuJoCo: error vs wall time over time steps and integrators (for choosing dt; issue 4).

Runs `impactval.runner.run` (each job in its own process) on the plate and the worked beam for
dt in {1e-7 .. 1e-5}, integrators Euler / implicitfast / RK4 and the three contact modes, and
prints one table; rows are appended to OUT/results.csv as they finish. Several minutes; not a test.

Run: python benchmarks/bench_mujoco.py [OUT]   (default OUT: bench-mujoco)
"""
from __future__ import annotations

import sys

import pandas as pd

from impactval.engines.base import EngineSettings
from impactval.runner import run, text_table


def main(out: str = "bench-mujoco") -> pd.DataFrame:
    frames = []
    for contact in ("hertz", "native", "native-hertz"):
        for integrator in ("Euler", "implicitfast", "RK4"):
            for dt in (1e-7, 3e-7, 1e-6, 3e-6, 1e-5):
                s = EngineSettings(dt=dt, integrator=integrator, contact=contact, segments=81, timeout_s=600)
                frames.append(run(["plate_steel", "beam_ss_midspan"], ["mujoco"], s, out=out))
                print(text_table(frames[-1].iloc[:, :]), flush=True)
    df = pd.concat(frames, ignore_index=True)
    print(text_table(df))
    return df


if __name__ == "__main__":
    main(*sys.argv[1:2])
