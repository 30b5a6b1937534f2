"""Speed of the reference solver, measured side by side in one run (issue 8).

Prints ratios, not absolute targets:
1. impactval.solve on the 160-mode simply supported worked beam (after a warm-up call) vs scipy's
   DOP853 on the ODE form, both tuned the same way: the loosest setting (solve's tol, DOP853's rtol on
   a scaled state) that still gets all three metrics within 1e-6 of a tight solution; solve(tol=1e-6)
   is shown too (its uncertainty is a conservative bound, so it over-delivers);
2. cost vs mode count: 2,560 modes against 160 modes, for solve and for DOP853 (DOP853 at 2,560 modes
   is estimated from its measured N^2.5 growth unless --full is given);
3. a fresh-process `impactval reference plate_steel` (once compilation is cached);
4. a fresh-process `impactval reference heavy_ball_slender_beam --window 1000` (issue 14: < 1 min, < 2 GB):
   wall time and peak resident memory.
DOP853 is tuned two ways: to the tolerance solve promises (real error <= 1e-6) and to the real error
solve(tol=1e-6) actually reaches. The machine's load average is printed: the machine is shared, so only
the ratios (measured side by side) mean something; every time is taken on two clocks, wall and CPU
(time.process_time: the process's own CPU time, which leaves out the time other processes hold the core).

5. with --before REV: the compiled kernel of git revision REV (reference/kernel.py as it was there) against
   today's, interleaved in this process on the same inputs (160 modes, tol 1e-4 and 1e-6): kernel time per
   call on both clocks and the largest relative difference of the metrics (identical to roundoff expected).

Run: python benchmarks/bench_reference.py [--full] [--before REV [--only-before]]
"""
from __future__ import annotations

import importlib.util
import os
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
from impactval.reference.solve import structure_modes


#: the clock of every timing: "cpu" (time.process_time, all threads of this process: on a shared, loaded machine
#: it leaves out the time other processes hold the core, so one core is compared with one core) or "wall"
CLOCK = {"cpu": time.process_time, "wall": time.perf_counter}


def best_time(fn, repeat: int = 5, min_time: float = 0.2, clock: str = "wall") -> float:
    """Best time of fn() [s] on `clock` over `repeat` rounds, each repeated to last >= min_time."""
    now = CLOCK[clock]
    fn()
    best = np.inf
    for _ in range(repeat):
        k, t0 = 0, now()
        while True:
            fn()
            k += 1
            el = now() - t0
            if el >= min_time:
                break
        best = min(best, el / k)
    return best


def both_times(fn, repeat: int = 5) -> dict[str, float]:
    """{"wall": best wall time, "cpu": best CPU time} of fn() [s], the two measured in turn."""
    return {c: best_time(fn, repeat, clock=c) for c in ("wall", "cpu")}


def _us(t: dict[str, float]) -> str:
    return f"{t['wall'] * 1e6:9.1f} us wall, {t['cpu'] * 1e6:9.1f} us CPU"


def _ratio(a: dict[str, float], b: dict[str, float]) -> str:
    return f"{a['wall'] / b['wall']:6.0f}x wall, {a['cpu'] / b['cpu']:6.0f}x CPU"


def main(full: bool = False) -> None:
    base = impactval.load_scene("beam_ss_midspan")
    m0, alpha, v0 = base.ball.mass, base.alpha, base.ball.velocity
    print(f"scene: {base.name}, all three metrics within 1e-6; load average (1 min) at start "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    rows = []
    matched = {}
    for n in (160, 2560):
        truth = impactval.solve(base, modes=n, tol=1e-10).metrics
        res = impactval.solve(base, modes=n, tol=1e-6)
        err = res.metrics.relative_to(truth)
        t_solve = both_times(lambda: impactval.solve(base, modes=n, tol=1e-6))
        rows.append((n, t_solve, max(abs(err.t_m), abs(err.f_m), abs(err.delta_m))))
        print(f"  solve(tol=1e-6), {n:5d} modes: {_us(t_solve)}   real max rel. error {rows[-1][2]:.1e}"
              f" ({res.n_steps} nodes; its bound is conservative)")
        if n == 160:
            wrapper_share(base, res, t_solve)
        # matched accuracy, tuned like DOP853 below: the loosest tol whose real error is still <= 1e-6
        for tol in (1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6):
            r = impactval.solve(base, modes=n, tol=tol)
            e = r.metrics.relative_to(truth)
            if max(abs(e.t_m), abs(e.f_m), abs(e.delta_m)) <= 1e-6:
                break
        matched[n] = (tol, both_times(lambda: impactval.solve(base, modes=n, tol=tol)))
        print(f"  solve(tol={tol:g}), {n:5d} modes: {_us(matched[n][1])}   (loosest tol with real error <= 1e-6)")
    # DOP853: loosest rtol reaching a target real error on all three metrics (160 modes)
    md = structure_modes(base, 160)
    truth = impactval.solve(base, modes=160, tol=1e-10).metrics

    def tuned_dop(target):
        for rtol in (1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 3e-7, 1e-7, 3e-8, 1e-8, 3e-9, 1e-9, 3e-10, 1e-10):
            m, info = solve_ode(md, m0, alpha, v0, rtol=rtol, atol=rtol * 1e-2)
            e = m.relative_to(truth)
            if max(abs(e.t_m), abs(e.f_m), abs(e.delta_m)) <= target:
                break
        return rtol, info, both_times(lambda: solve_ode(md, m0, alpha, v0, rtol=rtol, atol=rtol * 1e-2), repeat=3)

    rtol, info, t_dop = tuned_dop(1e-6)
    print(f"  DOP853, 160 modes:  {t_dop['wall'] * 1e3:8.2f} ms wall, {t_dop['cpu'] * 1e3:8.2f} ms CPU   (rtol {rtol:g}, "
          f"{info['nfev']} evaluations; real error <= 1e-6)")
    rtol_same, info_same, t_dop_same = tuned_dop(max(rows[0][2], 1e-10))
    print(f"  DOP853, 160 modes:  {t_dop_same['wall'] * 1e3:8.2f} ms wall, {t_dop_same['cpu'] * 1e3:8.2f} ms CPU   (rtol "
          f"{rtol_same:g}, {info_same['nfev']} evaluations; real error <= {rows[0][2]:.1e}, solve(tol=1e-6)'s)")
    # DOP853 growth with mode count
    md40 = structure_modes(base, 40)
    t_dop40 = best_time(lambda: solve_ode(md40, m0, alpha, v0, rtol=rtol, atol=rtol * 1e-2), repeat=3, clock="cpu")
    growth = np.log(t_dop["cpu"] / t_dop40) / np.log(160 / 40)
    if full:
        md2560 = structure_modes(base, 2560)
        t0 = time.process_time()
        solve_ode(md2560, m0, alpha, v0, rtol=rtol, atol=rtol * 1e-2)
        t_dop2560 = time.process_time() - t0
        how = "measured"
    else:
        t_dop2560 = t_dop["cpu"] * 16**growth
        how = f"estimated from the measured growth N^{growth:.2f} (40 -> 160 modes)"
    print()
    print(f"machine load average (1 min) at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (CPU time = "
          f"this process's own; the fairer clock on a loaded machine)")
    print(f"ratio DOP853 / solve(tol=1e-6) at 160 modes:  {_ratio(t_dop, rows[0][1])}   (DOP853 at real error <= 1e-6; "
          f"target >= 300x)")
    print(f"  the same, DOP853 at solve's real error:     {_ratio(t_dop_same, rows[0][1])}   (both at {rows[0][2]:.1e})")
    print(f"ratio DOP853 / solve at matched accuracy:     {_ratio(t_dop, matched[160][1])}   (both tuned to the "
          f"loosest setting with real error <= 1e-6)")
    print(f"solve, 2560 modes / 160 modes:                {rows[1][1]['cpu'] / rows[0][1]['cpu']:8.1f}x CPU  (target <= 25x)")
    print(f"  at matched accuracy:                        {matched[2560][1]['cpu'] / matched[160][1]['cpu']:8.1f}x CPU")
    print(f"DOP853, 2560 modes / 160 modes:               {t_dop2560 / t_dop['cpu']:8.0f}x CPU  ({how})")
    # fresh process CLI
    cmd = [sys.executable, "-m", "impactval.cli", "reference", "plate_steel"]
    subprocess.run(cmd, capture_output=True, check=True)          # make sure compilation is cached
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        subprocess.run(cmd, capture_output=True, check=True)
        times.append(time.perf_counter() - t0)
    print(f"fresh-process `impactval reference plate_steel`: {min(times):.2f} s   (target < 1.5 s)")
    # a long window: wall time and the child's peak resident memory: VmHWM of its own address space (ru_maxrss
    # would also count this parent's RSS, which Linux hands to the child's high-water mark at exec)
    cmd = [sys.executable, "-c", "import resource, sys; from impactval.cli import main; sys.argv = ['impactval', "
           "'reference', 'heavy_ball_slender_beam', '--window', '1000']\ntry:\n    main()\nexcept SystemExit:\n    pass\n"
           "try:\n    hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM')][0].split()[1]\n"
           "except OSError:\n    hwm = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
           "print(hwm, file=sys.stderr)"]
    t0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    wall = time.perf_counter() - t0
    rss_mb = int(out.stderr.strip().splitlines()[-1]) / 1024
    contacts = out.stdout.splitlines()[1].split()[-1]
    print(f"fresh-process `impactval reference heavy_ball_slender_beam --window 1000`: {wall:.1f} s, peak RSS "
          f"{rss_mb:.0f} MB, {contacts} contacts   (target < 60 s, < 2048 MB)")


def _auto_args(md, m0: float, alpha: float, v0: float, tol: float, light: bool = True) -> tuple:
    """The arguments solve_modes passes to kernel.solve_auto for modes `md` at `tol` (window 0); `light` False
    leaves out the light-mode coupling argument (kernels before it existed)."""
    omega, g, ew = ref_solve._select(md)
    plate = plate_impact(m0, alpha, v0)
    n0 = max(8.0, ref_solve._N_ANCHOR * (8.0 * ref_solve._ERR_ANCHOR / tol) ** (1.0 / (ref_solve.P_DEGREE + 1)))
    args = (omega, g, ew, m0, alpha, v0, md.residual_flexibility, tol, 0.0, plate.t_m, plate.delta_m,
            ref_solve.P_DEGREE, ref_solve.GRADING_WINDOW, n0, ref_solve.ESTIMATE_ORDER, ref_solve.UNRESOLVED_THETA,
            ref_solve.UNRESOLVED_C, ref_solve.SMALLEST_STEP_FACTOR, ref_solve.UNRESOLVED_SHARE,
            ref_solve.node_cap(len(omega)), float(kernel.SERIES_SAMPLES))
    return args + (ref_solve.LIGHT_COUPLING, ref_solve.UNRESOLVED_CLASSES, ref_solve.MIN_STEPS,
                   ref_solve.SMALLEST_STEP_C) if light else args


def wrapper_share(base, res, t_solve: dict[str, float]) -> None:
    """Where a solve(tol=1e-6, modes=160) call goes: the compiled kernel (kernel.solve_auto_packed, i.e. solve_auto
    with its series packed in one array, on the arguments solve passes it) against the whole call, measured right
    after it; the rest is Python (argument checks, the mode and scene caches, the validity warnings, building the
    result)."""
    m0, alpha, v0 = base.ball.mass, base.alpha, base.ball.velocity
    args = _auto_args(structure_modes(base, 160), m0, alpha, v0, 1e-6)
    out = kernel.solve_auto_packed(*args)
    assert out[1] - 1 == res.n_steps, "the kernel call is not the one solve makes"
    t_kernel = both_times(lambda: kernel.solve_auto_packed(*args))
    rest = {c: t_solve[c] - t_kernel[c] for c in t_solve}
    print(f"    of which kernel.solve_auto:  {_us(t_kernel)}   the Python around it: {rest['cpu'] * 1e6:.1f} us CPU "
          f"({100 * rest['cpu'] / t_solve['cpu']:.0f} % of the call)")


def _kernel_at(rev: str):
    """reference/kernel.py of git revision `rev`, imported as its own module (compiled in a temporary folder)."""
    root = Path(__file__).resolve().parents[1]
    src = subprocess.run(["git", "show", f"{rev}:reference/kernel.py"], cwd=root, capture_output=True, text=True,
                         check=True).stdout
    folder = Path(tempfile.mkdtemp(prefix="impactval-kernel-"))
    path = folder / "kernel_before.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location("kernel_before", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def before_after(rev: str, rounds: int = 15) -> None:
    """Kernel time per call, revision `rev` vs today, interleaved round by round on the same inputs."""
    old = _kernel_at(rev)
    base = impactval.load_scene("beam_ss_midspan")
    md = structure_modes(base, 160)
    m0, alpha, v0 = base.ball.mass, base.alpha, base.ball.velocity
    print(f"\nkernel.solve_auto before ({rev}) and now, 160 modes, interleaved ({rounds} rounds, best of each):")
    for tol in (1e-4, 1e-6):
        args = _auto_args(md, m0, alpha, v0, tol)        # the call solve makes (kernels before the light-mode
        try:                                             # coupling arguments get the shorter list)
            old.solve_auto(*args)
        except Exception:
            args = _auto_args(md, m0, alpha, v0, tol, light=False)
        outs = [k.solve_auto(*args) for k in (old, kernel)]
        # t_m, delta_m of the first contact and the relative uncertainty, before vs now
        vals = [(o[9][0, 1] - o[9][0, 0], o[9][0, 2], o[10]) for o in outs]
        diff = max(abs(a - b) / abs(a) for a, b in zip(*vals))
        best = {(who, c): np.inf for who in ("before", "now") for c in CLOCK}
        for _ in range(rounds):
            for who, k in (("before", old), ("now", kernel)):
                for c, now in CLOCK.items():
                    t0 = now()
                    for _ in range(20):
                        k.solve_auto(*args)
                    best[who, c] = min(best[who, c], (now() - t0) / 20)
        print(f"  tol {tol:g}: before {best['before', 'wall'] * 1e6:7.1f} us wall {best['before', 'cpu'] * 1e6:7.1f} us CPU;"
              f" now {best['now', 'wall'] * 1e6:7.1f} us wall {best['now', 'cpu'] * 1e6:7.1f} us CPU; now/before "
              f"{best['now', 'wall'] / best['before', 'wall']:.2f} wall, {best['now', 'cpu'] / best['before', 'cpu']:.2f} CPU;"
              f" t_m, delta_m, uncertainty differ by <= {diff:.1e} (relative)")
    print(f"  load average (1 min): {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    if "--before" in sys.argv:
        before_after(sys.argv[sys.argv.index("--before") + 1])
        if "--only-before" in sys.argv:
            sys.exit(0)
    main(full="--full" in sys.argv)
