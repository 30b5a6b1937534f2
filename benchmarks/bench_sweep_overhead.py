"""Harness overhead of a sweep job (issue 13): the same MuJoCo and PyBullet models stepped by a bare
loop and inside a sweep job, the same steps, measured side by side in one run.

Wall-clock ratios on a shared 2-core machine swing 0.77-1.57x run to run (load), more than the 10 %
bar, so the benchmark measures two load-independent figures next to the wall time:

1. **instructions** (deterministic): the regions below run in ONE process under valgrind's callgrind
   with collection only inside `sys.call_tracing` (`--collect-atstart=no --toggle-collect=
   sys_call_tracing --dump-after=sys_call_tracing`; a debugger's call that no library in a job makes,
   unlike functools.reduce), so every region gets its own instruction count and imports, builds and
   warm-up runs are outside;
2. **CPU time** of this thread (`time.thread_time`, min of REPEATS interleaved runs, no valgrind).

Every figure is per step and taken as a difference between two step counts of the same model (the
job at dt and at dt/2, every loop over exactly the job's step counts), so what does not scale with
the steps (imports, build, planning, the result row) cancels. Loops, per case:

- `bare`: the engine's own step call with only what the physics needs (MuJoCo: mj_step with the
  Hertz callback; PyBullet: the injected Hertz force, the chain's spring torques, stepSimulation);
- `timed`: the job's timed region, `ts = clock(); adapter.step(model); t += clock() - ts`, the
  statements of engines.base's loop (the stepping time a row reports and the sweep's cost axis);
- `sampled`: adapter.step then adapter.observe (the engine adapter's own per-step sample: state
  read-back, energy), no base loop;
- `job`: the whole job in this process (`engines.base.execute_job`: the base loop, its sampling,
  checks and metrics); a sweep cell runs exactly this in its worker process.

Printed ratios (per step): `timed/bare` (the bar: the stepping a sweep job reports against the bare
loop), `job/bare` (everything the job does per step against physics alone), `sampled/bare` (the
adapter's measurement), `job/sampled` (the base loop and harness beyond the adapter's sample); then
the wall-clock figures of an isolated sweep cell (`sweep/bare`, the row's stepping time against the
bare loop, best of 3).

Run: python benchmarks/bench_sweep_overhead.py [REPEATS] [--no-callgrind] [--no-wall]   (~10 min)
"""
from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CASES = [  # engine, scene, segments, (dt, dt/2) for instructions, (dt, dt/2) for CPU time, dt for wall
    ("mujoco", "plate_steel", None, (1e-7, 5e-8), (1e-8, 5e-9), 1e-9),
    ("mujoco", "beam_ss_midspan", 41, (2e-7, 1e-7), (2e-8, 1e-8), 1e-8),
    ("pybullet", "plate_steel", None, (1e-7, 5e-8), (1e-8, 5e-9), 1e-9),
    ("pybullet", "beam_ss_midspan", 41, (2e-7, 1e-7), (4e-8, 2e-8), 2e-8),
]
LOOPS = ("bare", "timed", "sampled", "job")


def _settings(dt: float, segments):
    from impactval.engines.base import EngineSettings

    return EngineSettings(dt=dt, segments=segments)


def _built(engine: str, scene, dt: float, segments):
    """(adapter, live model) exactly as a job builds it (MuJoCo Euler samples with lag 1, as in a job)."""
    from impactval.engines.base import load_adapter

    adapter = load_adapter(engine)
    return adapter, adapter.build(scene, adapter.check_settings(_settings(dt, segments)))


def _bare_region(engine: str, run, n_steps: int):
    """A loop of n_steps with only what the physics needs, on a live model."""
    if engine == "mujoco":
        import mujoco

        def region():
            m, d, step = run.model, run.data, mujoco.mj_step
            for _ in range(n_steps):
                step(m, d)
        return region

    def region():
        c, p = run.client, run.p
        getpos, step, ext = c.getBasePositionAndOrientation, c.stepSimulation, c.applyExternalForce
        ball, alpha, radius = run.ball_body, run.alpha, run.radius
        if run.chain is None:
            surface_z = run.surface_z
            for _ in range(n_steps):
                pos = getpos(ball)[0]
                d = surface_z - (pos[2] - radius)
                if d > 0:
                    ext(ball, -1, [0, 0, alpha * d**1.5], pos, p.WORLD_FRAME)
                step()
        else:
            body, rev, k_rev, link, local = run.body, run.rev, run.k_rev, run.link, list(run.local)
            for _ in range(n_steps):
                pos = getpos(ball)[0]
                q = np.fromiter((s[0] for s in c.getJointStates(body, rev)), float, len(rev))
                st = c.getLinkState(body, link, computeForwardKinematics=1)
                point = c.multiplyTransforms(st[4], st[5], local, [0, 0, 0, 1])[0]
                c.setJointMotorControlArray(body, rev, p.TORQUE_CONTROL, forces=(-(k_rev @ q)).tolist())
                d = point[2] - (pos[2] - radius)
                if d > 0:
                    f = alpha * d**1.5
                    ext(ball, -1, [0, 0, f], pos, p.WORLD_FRAME)
                    ext(body, link, [0, 0, -f], point, p.WORLD_FRAME)
                step()
    return region


def _timed_region(adapter, run, n_steps: int):
    def region():
        step, clock = adapter.stepper(run), time.perf_counter
        step_s = 0.0
        for _ in range(n_steps):            # the base loop's timed statements
            ts = clock()
            step()
            step_s += clock() - ts
    return region


def _sampled_region(adapter, run, n_steps: int):
    def region():
        step, observe, model = adapter.step, adapter.observe, run
        for _ in range(n_steps):
            step(model)
            observe(model)
    return region


def _measure(region, timer) -> float:
    """Run `region` inside sys.call_tracing (the callgrind collection window); its duration by `timer`."""
    t0 = timer()
    sys.call_tracing(region, ())
    return timer() - t0


def run_loops(engine: str, scene_name: str, segments, dts: tuple[float, float], timer, repeats: int = 1
              ) -> tuple[dict[str, list[float]], tuple[int, int]]:
    """Each loop at both steps of `dts`, interleaved `repeats` times: {loop: [value at dt, value at dt/2],
    min over repeats} by `timer`, and the job's step counts. Warm-up runs first (outside the window)."""
    import impactval
    from impactval.engines.base import execute_job

    scene = impactval.load_scene(scene_name)
    n = []
    for dt in dts:                                            # warm-up: lazy imports, first-call caches
        res = execute_job(engine, scene, _settings(dt, segments))
        if str(res.status) != "ok":
            raise SystemExit(f"{engine} {scene_name} dt={dt}: job {res.status}: {res.message}")
        n.append(int(res.n_steps))
    best = {loop: [math.inf, math.inf] for loop in LOOPS}
    for _ in range(repeats):
        for i, dt in enumerate(dts):
            for loop in LOOPS:
                if loop == "job":
                    out = {}

                    def region():
                        out["r"] = execute_job(engine, scene, _settings(dt, segments))
                    value = _measure(region, timer)
                    assert out["r"].n_steps == n[i], (out["r"].n_steps, n[i])
                else:
                    adapter, run = _built(engine, scene, dt, segments)
                    try:
                        make = {"bare": lambda: _bare_region(engine, run, n[i]),
                                "timed": lambda: _timed_region(adapter, run, n[i]),
                                "sampled": lambda: _sampled_region(adapter, run, n[i])}[loop]
                        value = _measure(make(), timer)
                    finally:
                        adapter.close(run)
                best[loop][i] = min(best[loop][i], value)
    return best, (n[0], n[1])


# ---------------------------------------------------------------------------- instructions (callgrind)
def _driver() -> None:
    """Under callgrind: every case's loops once; writes the region order and step counts as JSON."""
    manifest = []
    for engine, scene, segments, dts, _, _ in CASES:
        _, steps = run_loops(engine, scene, segments, dts, time.perf_counter)
        manifest.append(dict(engine=engine, scene=scene, steps=steps,
                             regions=[f"{loop}@{i}" for i in range(2) for loop in LOOPS]))
    Path(sys.argv[2]).write_text(json.dumps(manifest))


def _warm_up() -> None:
    """One job per case (natively): fills the caches the callgrind driver then finds (numba's, generic CPU)."""
    import impactval
    from impactval.engines.base import execute_job

    for engine, scene, segments, dts, _, _ in CASES:
        execute_job(engine, impactval.load_scene(scene), _settings(dts[0], segments))


def instructions(script: str = __file__) -> list[dict]:
    """Per case: instructions per step of each loop (difference between the job's two step counts).
    `script` runs the driver (`script --driver MANIFEST`; another one can patch the code under test first)."""
    if shutil.which("valgrind") is None:
        print("valgrind not found: instruction counts skipped (apt-get install valgrind)")
        return []
    with tempfile.TemporaryDirectory() as tmp:
        manifest_path = Path(tmp) / "regions.json"
        cmd = ["valgrind", "--tool=callgrind", "--collect-atstart=no", "--toggle-collect=sys_call_tracing",
               "--dump-after=sys_call_tracing", f"--callgrind-out-file={tmp}/cg.out", sys.executable, script,
               "--driver", str(manifest_path)]
        # numba's cache (the reference kernels the beam plans use) is keyed by CPU; valgrind's emulated CPU
        # would miss it and compile for many minutes inside the run: both runs use the generic target, and a
        # native warm-up fills that cache first. One BLAS thread (no spinning threads under valgrind).
        env = {**os.environ, "PYTHONHASHSEED": "0", "NUMBA_CPU_NAME": "generic", "OPENBLAS_NUM_THREADS": "1",
               "OMP_NUM_THREADS": "1"}
        subprocess.run([sys.executable, __file__, "--warm-up"], env=env, check=True, capture_output=True)
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if proc.returncode != 0 or not manifest_path.exists():
            raise SystemExit(f"callgrind driver failed:\n{proc.stderr[-3000:]}")
        manifest = json.loads(manifest_path.read_text())
        dumps = sorted(Path(tmp).glob("cg.out.*"), key=lambda p: int(p.suffix[1:]))
        counts = [_total(p) for p in dumps]
    n_regions = sum(len(m["regions"]) for m in manifest)
    if len(counts) != n_regions:        # another sys.call_tracing inside a region would split it
        raise SystemExit(f"callgrind: {len(counts)} dumps for {n_regions} regions; the windows are not clean")
    out, k = [], 0
    for m in manifest:
        per = dict(zip(m["regions"], counts[k:k + len(m["regions"])]))
        k += len(m["regions"])
        dn = m["steps"][1] - m["steps"][0]
        out.append(dict(engine=m["engine"], scene=m["scene"], steps=m["steps"],
                        **{loop: (per[f"{loop}@1"] - per[f"{loop}@0"]) / dn for loop in LOOPS}))
    return out


def _total(path: Path) -> int:
    for line in path.read_text(errors="replace").splitlines():
        if line.startswith(("totals:", "summary:")):
            return int(line.split()[1])
    raise SystemExit(f"{path}: no instruction total")


# ---------------------------------------------------------------------------- CPU time and wall time
def cpu_times(repeats: int) -> list[dict]:
    out = []
    for engine, scene, segments, _, dts, _ in CASES:
        best, steps = run_loops(engine, scene, segments, dts, time.thread_time, repeats)
        dn = steps[1] - steps[0]
        out.append(dict(engine=engine, scene=scene, steps=steps,
                        **{loop: (best[loop][1] - best[loop][0]) / dn for loop in LOOPS}))
    return out


def wall_times(repeats: int = 3) -> list[dict]:
    """An isolated sweep cell (store, executor, worker process): the stepping time its row reports
    against the bare loop over the same steps (wall clock, best of `repeats`)."""
    import impactval
    from impactval import sweep as sw

    out = []
    for engine, name, segments, _, _, dt in CASES:
        scene = impactval.load_scene(name)
        job = sw.Job(scene, engine, _settings(dt, segments), 1e-6)
        cost, bare = math.inf, math.inf
        for _ in range(repeats):
            row = sw.run_sweep([job], workers=1).iloc[0]
            if row["status"] != "ok":
                raise SystemExit(f"{engine} {name}: sweep job {row['status']}: {row['message']}")
            n_steps = int(row["n_steps"])
            cost = min(cost, float(row["wall_time_step_s"]))
            adapter, run = _built(engine, scene, dt, segments)
            try:
                bare = min(bare, _measure(_bare_region(engine, run, n_steps), time.perf_counter))
            finally:
                adapter.close(run)
        out.append(dict(engine=engine, scene=name, dt=dt, n_steps=n_steps, cost=cost, bare=bare))
    return out


def _print_per_step(title: str, rows: list[dict], unit: str, scale: float) -> float:
    print(f"\n{title}")
    print(f"{'engine':9s} {'scene':16s} {'steps':>11s} {'bare ' + unit:>13s} {'timed/bare':>10s} {'job/bare':>9s} "
          f"{'sampled/bare':>12s} {'job/sampled':>11s}")
    worst = 0.0
    for r in rows:
        worst = max(worst, r["timed"] / r["bare"] - 1)
        print(f"{r['engine']:9s} {r['scene']:16s} {r['steps'][0]:5d}-{r['steps'][1]:<5d} {scale * r['bare']:13.4g} "
              f"{r['timed'] / r['bare']:10.3f} {r['job'] / r['bare']:9.3f} {r['sampled'] / r['bare']:12.3f} "
              f"{r['job'] / r['sampled']:11.3f}")
    return worst


def main(repeats: int = 5, callgrind: bool = True, wall: bool = True) -> dict:
    results: dict = {}
    if callgrind:
        results["instructions"] = instructions()
        if results["instructions"]:
            worst = _print_per_step("Instructions per step (callgrind; deterministic)", results["instructions"],
                                    "instr", 1.0)
            print(f"timed region (the stepping a sweep job reports) vs bare loop, instructions: largest overhead "
                  f"{100 * worst:.1f} % (bar: 10 %) -> {'met' if worst <= 0.10 else 'MISSED'}")
    results["cpu"] = cpu_times(repeats)
    worst = _print_per_step(f"CPU time per step (time.thread_time, min of {repeats} interleaved)", results["cpu"],
                            "us", 1e6)
    print(f"timed region vs bare loop, CPU time: largest overhead {100 * worst:.1f} % (bar: 10 %) -> "
          f"{'met' if worst <= 0.10 else 'MISSED'}")
    if wall:
        results["wall"] = wall_times()
        print("\nWall clock, isolated sweep cell (store, executor, worker process), best of 3")
        print(f"{'engine':9s} {'scene':16s} {'dt [s]':>7s} {'steps':>6s} {'bare us/step':>12s} {'sweep/bare':>10s}")
        for r in results["wall"]:
            print(f"{r['engine']:9s} {r['scene']:16s} {r['dt']:7.0e} {r['n_steps']:6d} "
                  f"{1e6 * r['bare'] / r['n_steps']:12.2f} {r['cost'] / r['bare']:10.3f}")
    return results


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--driver":
        _driver()
    elif len(sys.argv) > 1 and sys.argv[1] == "--warm-up":
        _warm_up()
    else:
        args = [a for a in sys.argv[1:] if not a.startswith("--")]
        main(int(args[0]) if args else 5, callgrind="--no-callgrind" not in sys.argv, wall="--no-wall" not in sys.argv)
