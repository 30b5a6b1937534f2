"""Throughput of `impactval run` (issue 12 bar): a 40-job MuJoCo plate sweep with --jobs 2 against a
1-job run of the same kind, measured side by side in one session (the machine is shared: compare
ratios, not seconds). Each run is the real command line in a fresh process with a fresh --out (no
reuse): interpreter start, reference solve, workers, store and exports included.

Also shown: the same 40 jobs the old way (one spawned process per job, `engines.base.run_isolated`)
in this process, for scale. Usage: python benchmarks/bench_throughput.py [--jobs 2] [--n 40]
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _dts(n: int) -> list[str]:
    # n distinct steps within 5 % of 1e-6 s: every job costs about what the 1-job run costs
    return [f"{1e-6 * (1 - 0.05 * i / max(n - 1, 1)):.6g}" for i in range(n)]


def cli_run(dts: list[str], jobs: int, out: Path) -> float:
    cmd = [sys.executable, "-m", "impactval.cli", "run", "plate_steel", "--engines", "mujoco", "--dt", ",".join(dts),
           "--jobs", str(jobs), "--out", str(out)]
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"run failed ({res.returncode}): {res.stderr[-2000:]}")
    return wall


def old_way(dts: list[str]) -> float | None:
    import impactval
    from impactval.engines import base

    run_isolated, EngineSettings = getattr(base, "run_isolated", None), base.EngineSettings
    if run_isolated is None:                # engines v2 dropped the one-process-per-job helper
        return None

    scene = impactval.load_scene("plate_steel")
    t0 = time.perf_counter()
    for dt in dts:
        assert run_isolated("mujoco", scene, EngineSettings(dt=float(dt))).success
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--n", type=int, default=40)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    dts = _dts(args.n)
    with tempfile.TemporaryDirectory() as tmp:
        cli_run(dts[:1], 1, Path(tmp) / "warm")           # compile caches, page cache
        ones, many = [], []
        for r in range(args.repeat):                       # interleaved: load changes hit both alike
            ones.append(cli_run(dts[:1], 1, Path(tmp) / f"one{r}"))
            many.append(cli_run(dts, args.jobs, Path(tmp) / f"many{r}"))
    one, sweep = min(ones), min(many)
    old = old_way(dts)
    print(f"1-job run:                         {one:6.2f} s   (best of {args.repeat})")
    print(f"{args.n}-job run, --jobs {args.jobs}:              {sweep:6.2f} s   ({args.n / sweep:.1f} jobs/s)")
    print(f"ratio {args.n}-job / 1-job:                {sweep / one:6.2f}   (bar: <= 3)")
    if old is not None:
        print(f"old way, {args.n} spawned processes:     {old:6.2f} s   ({args.n / old:.1f} jobs/s, engine part only)")


if __name__ == "__main__":
    main()
