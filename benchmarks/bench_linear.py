"""Time and peak memory of the exact linear-contact solution (`solve_linear`, what `impactval theory` and
`impactval reference --model linear` spend most of their time in) on a plate that needs thousands of modes, measured
side by side in one run: today's reference/linear.py against the one of git revision REV, each in a fresh process.

The scene: a 48 mm titanium ball at 0.115 m/s on a simply supported 468 x 143 x 4.8 mm PMMA plate (a random unseen
user scene, fuzz seed 2520): the automatic mode count doubles to 7,424 modes (plates converge like 1/n). Round 16
found it took 105 s of a 115 s `impactval theory` page and peaked at 5.4 GB: the whole state (every mode) was
formed at every series sample, and each secular root took ~52-100 bisections.

Prints per variant: wall time, peak resident memory (the child's own VmHWM), metrics; then the ratios before / now
and the largest relative difference of t_m, f_m, delta_m (roundoff expected).

Run: python benchmarks/bench_linear.py [--before REV]      (REV's run alone took ~2 min at round 16's REV 6a61bed)
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: the scene (tests' data: a random unseen user scene)
SCENE = Path(__file__).resolve().parents[1] / "tests" / "data" / "plate_thousands_of_modes.toml"

CHILD = """
import json, sys, time
source = sys.argv[2]
if source:                       # the linear module of another revision, in place of today's
    import importlib.util, impactval.reference
    spec = importlib.util.spec_from_file_location("impactval.reference.linear", source)
    module = importlib.util.module_from_spec(spec)
    sys.modules["impactval.reference.linear"] = module
    spec.loader.exec_module(module)
    impactval.reference.linear = module
import impactval
from impactval.reference.linear import solve_linear
scene = impactval.load_scene(sys.argv[1])
t0 = time.perf_counter()
r = solve_linear(scene)
wall = time.perf_counter() - t0
hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM")][0].split()[1]
print(json.dumps({"wall": wall, "rss_mb": int(hwm) / 1024, "t_m": r.t_m, "f_m": r.f_m, "delta_m": r.delta_m,
                  "modes": r.modes}))
"""


def measure(scene: Path, source: str = "") -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, str(scene), source], capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _show(label: str, m: dict) -> None:
    print(f"  {label:22s} {m['wall']:7.2f} s, peak RSS {m['rss_mb']:6.0f} MB   t_m {m['t_m']:.12g} s, f_m "
          f"{m['f_m']:.12g} N, delta_m {m['delta_m']:.12g} m ({m['modes']} modes)")


def main(before: str | None) -> None:
    root = Path(__file__).resolve().parents[1]
    folder = Path(tempfile.mkdtemp(prefix="impactval-bench-linear-"))
    scene = SCENE
    print("solve_linear on a plate needing thousands of modes (fresh process each)")
    now = measure(scene)
    _show("today", now)
    if before is None:
        return
    src = subprocess.run(["git", "show", f"{before}:reference/linear.py"], cwd=root, capture_output=True, text=True,
                         check=True).stdout
    path = folder / "linear_before.py"
    path.write_text(src)
    old = measure(scene, str(path))
    _show(f"at {before}", old)
    diff = max(abs(now[k] / old[k] - 1) for k in ("t_m", "f_m", "delta_m"))
    print(f"before / today: {old['wall'] / now['wall']:.1f}x the time, {old['rss_mb'] / now['rss_mb']:.1f}x the peak "
          f"memory; metrics within {diff:.1e} (relative)")


if __name__ == "__main__":
    args = sys.argv[1:]
    rev = args[args.index("--before") + 1] if "--before" in args else None
    t0 = time.perf_counter()
    main(rev)
    print(f"({time.perf_counter() - t0:.0f} s)")
