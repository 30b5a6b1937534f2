"""`impactval extremes SCENE --engines E[,..] --axis NAME=SPEC [--axis NAME=SPEC] [--under 1%] [--out DIR]`
(issue 14): a stability/accuracy map, see `impactval.extremes` and `reports/extremes.py`."""
from __future__ import annotations

import math
from pathlib import Path

import click

from impactval.errors import ImpactvalError


def parse_under(text: str) -> float:
    """--under: "1%" or "0.01" -> 0.01."""
    t = str(text).strip()
    try:
        value = float(t[:-1]) / 100.0 if t.endswith("%") else float(t)
    except ValueError:
        raise ImpactvalError(f"--under takes a relative error such as 1% or 0.01, got {text!r}.") from None
    if not (math.isfinite(value) and 0 < value < 10):
        raise ImpactvalError(f"--under must be a positive relative error (1% or 0.01), got {text!r}.")
    return value


@click.command(name="extremes")
@click.argument("scene")
@click.option("--engines", default="mujoco", show_default=True,
              help="Comma-separated engines (mujoco, pybullet, exudyn, mujoco-warp, newton) or 'package.module:Class' adapters.")
@click.option("--axis", "axes", multiple=True, metavar="NAME[=SPEC]",
              help="dt, velocity, mass_ratio, stiffness, frequency_ratio or a TOML path (ball.velocity, target.height); "
                   "SPEC = a:b:n (n log-spaced values) | a,b,c | a mix (dt may use t_m: t_m/1e4:t_m:13). Once or twice.")
@click.option("--under", default="1%", show_default=True, help="A cell is ok when every |error| is under this.")
@click.option("--dt", default="auto", show_default=True, help="Time step [s] when dt is not an axis (auto: engine picks).")
@click.option("--contact", default="hertz", show_default=True, type=click.Choice(["hertz", "native", "native-hertz"]))
@click.option("--integrator", default=None, help="Engine integrator (e.g. MuJoCo: Euler, implicitfast, RK4).")
@click.option("--segments", default=None, type=click.IntRange(min=1), help="Beam chain segments (default: engine's).")
@click.option("--option", "options", multiple=True, metavar="[ENGINE.]KEY=VALUE", help="Engine option, repeatable.")
@click.option("--timeout", default=120.0, show_default=True, type=float, help="Time limit per engine job [s].")
@click.option("--tol", default=1e-6, show_default=True, type=float, help="Reference solver tolerance.")
@click.option("--guarded", is_flag=True,
              help="Let engines refuse a dt above their predicted limit (default: step past it and observe).")
@click.option("--predictability", is_flag=True,
              help="Also rerun every dt with v0 x (1 + 1e-6) and the impact point moved by 0.1 segment; flag jumps.")
@click.option("--out", default="impactval-extremes", show_default=True, type=click.Path(file_okay=False),
              help="Directory for extremes.md, extremes.png, extremes.csv and the store.")
@click.option("--store", default=None, metavar="PATH|URL", help="Result store [default: OUT/impactval.sqlite].")
@click.option("-j", "--jobs", "jobs", default=None, type=click.IntRange(min=1), help="Engine jobs at once.")
@click.option("--force", is_flag=True, help="Recompute jobs already in the store.")
def extremes(scene, engines, axes, under, dt, contact, integrator, segments, options, timeout, tol, guarded,
             predictability, out, store, jobs, force) -> None:
    """Map where each engine is right, wrong or broken over one or two axes of SCENE.

    Every cell's reference is solved; every engine job runs isolated with its timeout and is stored
    (a rerun resumes). Exit 0 when the map finished (whatever its cells say), 2 on bad input.
    """
    import impactval
    from impactval.cli import _parse_dts, _run_settings
    from impactval.extremes import parse_axis, predictability as predict_fn, run_map
    from impactval.progress import make_progress
    from impactval.reports.extremes import safe_region, write

    if not axes:
        raise ImpactvalError("give at least one --axis (e.g. --axis dt or --axis velocity=1e-3:1e2:11).")
    sc = impactval.load_scene(scene)
    ref = impactval.solve(sc, tol=tol)
    t_m = ref.t_m if ref.success and math.isfinite(ref.t_m) else None
    parsed = [parse_axis(a, t_m) for a in axes]
    settings = _run_settings(_parse_dts(dt)[0], contact, integrator, segments, timeout, 0.0, None, options)
    Path(out).mkdir(parents=True, exist_ok=True)
    db = store or str(Path(out) / "impactval.sqlite")
    names = [e.strip() for e in engines.split(",") if e.strip()]
    df = run_map(sc, names, parsed, settings=settings, under=parse_under(under), tol=tol, store=db, workers=jobs,
                 force=force, progress=make_progress("auto"), unguarded=not guarded, out=out,
                 command="extremes " + " ".join([scene, "--engines", engines, *(f"--axis {a}" for a in axes)]),
                 reference=ref)
    pred = None
    if predictability:
        dts = sorted({float(x) for x in df["dt"] if isinstance(x, float) and math.isfinite(x)})
        segs = [int(x) for x in df.get("segments", []) if str(x).isdigit()]
        pred = predict_fn(sc, names, dts, settings=settings, tol=tol, store=db, workers=jobs,
                          segments=segments or (min(segs) if segs else None), reference=ref if ref.success else None)
    md = write(df, out, pred)
    for line in safe_region(df):
        click.echo(line)
    if pred is not None and pred["jumped"].any():
        for _, r in pred[pred["jumped"]].iterrows():
            click.echo(f"jump: {r['engine']} dt={r['dt']:.3g} s, {r['perturbation']}: {r['why']}")
    counts = df["cell_status"].value_counts().to_dict()
    click.echo(f"{len(df)} cells: " + ", ".join(f"{k} {v}" for k, v in counts.items()) + f"; report: {md}", err=True)
