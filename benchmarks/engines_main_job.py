"""Main job (README) cost: this tree against another git ref (default main), measured side by side.

Issue 11's bar: sizing the engine models from the scene must not make the main job more than 20 % slower.
Runs `impactval run --engines mujoco,pybullet,exudyn --dt DT` on the whole catalogue with the code of
REF (extracted with `git archive` and put first on the import path of every process, engine children
included, through a sitecustomize hook) and with this tree, alternately (old, new, old, new ...), and prints
the wall times and their ratio. Also runs this tree with --dt auto (the new default). The machine is
shared: compare the ratio, not the seconds.

    python benchmarks/engines_main_job.py [--ref main] [--dt 5e-8] [--repeat 1] [--scenes a,b] [--no-warm]
    [--no-auto]      (measured against 8a2eec3, main before engines v2: see docs/mujoco.md)
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent

HOOK = textwrap.dedent('''
    import importlib.abc, importlib.util, os, sys
    _root = os.environ.get("IMPACTVAL_BENCH_ROOT")
    if _root:
        _MAP = {"impactval": "impactval", "impactval.reference": "reference", "impactval.engines": "engines",
                "impactval.scenarios": "scenarios", "impactval.reports": "reports"}

        class _Finder(importlib.abc.MetaPathFinder):
            def find_spec(self, name, path, target=None):
                if name in _MAP:
                    d = os.path.join(_root, _MAP[name])
                    return importlib.util.spec_from_file_location(name, os.path.join(d, "__init__.py"),
                                                                  submodule_search_locations=[d])
                return None

        sys.meta_path.insert(0, _Finder())
''')


def run_job(root: str | None, dt: str, out: str, scenes: list[str]) -> float:
    env = dict(os.environ)
    if root:
        env["IMPACTVAL_BENCH_ROOT"] = root
        env["PYTHONPATH"] = os.pathsep.join([root + "-hook", env.get("PYTHONPATH", "")])
    cmd = [sys.executable, "-m", "impactval.cli", "run", *scenes, "--engines", "mujoco,pybullet,exudyn",
           "--dt", dt, "--out", out]
    t0 = time.perf_counter()
    res = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode not in (0, 1):
        raise SystemExit(f"{'old' if root else 'new'} run failed:\n{res.stderr[-2000:]}")
    ok = res.stderr.count(": ok")
    print(f"  {'old' if root else 'new'} dt={dt}: {wall:.1f} s ({ok} rows ok)", flush=True)
    return wall


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ref", default="main")
    ap.add_argument("--dt", default="5e-8")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--scenes", default="")
    ap.add_argument("--no-warm", action="store_true", help="skip the warm-up runs (caches already warm)")
    ap.add_argument("--no-auto", action="store_true", help="skip the run of this tree at --dt auto")
    args = ap.parse_args()
    scenes = [s for s in args.scenes.split(",") if s]
    with tempfile.TemporaryDirectory() as tmp:
        root = os.path.join(tmp, "old")
        os.makedirs(root)
        archive = subprocess.run(["git", "-C", str(HERE), "archive", args.ref], capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", root], input=archive, check=True)
        os.makedirs(root + "-hook")
        Path(root + "-hook", "sitecustomize.py").write_text(HOOK)
        print(f"main job: catalogue{' ' + ','.join(scenes) if scenes else ''}, engines mujoco,pybullet,exudyn; "
              f"old = {args.ref}, new = this tree")
        if not args.no_warm:
            run_job(root, args.dt, os.path.join(tmp, "warm-old"), scenes)        # warm caches (FE beams, kernels)
            run_job(None, args.dt, os.path.join(tmp, "warm-new"), scenes)
        old, new = [], []
        for i in range(args.repeat):
            old.append(run_job(root, args.dt, os.path.join(tmp, f"o{i}"), scenes))
            new.append(run_job(None, args.dt, os.path.join(tmp, f"n{i}"), scenes))
        auto = None if args.no_auto else run_job(None, "auto", os.path.join(tmp, "auto"), scenes)
    o, n = min(old), min(new)
    print(f"new / old at dt = {args.dt}: {n / o:.2f}  (old {o:.1f} s, new {n:.1f} s; bar: <= 1.20)")
    if auto is not None:
        print(f"new at dt = auto / old at dt = {args.dt}: {auto / o:.2f}  (new auto {auto:.1f} s)")


if __name__ == "__main__":
    main()
