"""`impactval tune ENGINE SCENE` and `impactval materials` (issue 15); registered in cli.py by one line.

A thin layer: `impactval.tune.tune` fits, `reports.tune` presents. Exit codes: 0 fine, 1 the fit's
final engine runs failed, 2 bad input.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import click

from impactval.errors import ImpactvalError


@click.command(name="tune")
@click.argument("engine")
@click.argument("scene")
@click.option("--speeds", default="0.1:10:5", show_default=True,
              help="Approach speeds [m/s]: 'a:b:n' (n speeds log-spaced from a to b), 'v1,v2,...' or a mix.")
@click.option("--contact", default="native", show_default=True, type=click.Choice(["native", "native-hertz"]),
              help="native: a linear spring (the best compromise over the speeds); native-hertz: a Hertz-shaped law "
                   "(MuJoCo solimp shape, Exudyn exponent 1.5).")
@click.option("--dt", default=None, type=float,
              help="Engine time step [s] (default: shortest Hertz contact / 500, rounded down to 1-2-5: the engines' "
                   "step error on t_m, f_m, delta_m < 1e-5; at most half the engine's stability limit at every speed).")
@click.option("--out", "out", default="impactval-tune", show_default=True, type=click.Path(file_okay=False),
              help="Directory for tuned.json, tune.md, tune_force.png and the fit's store tune.sqlite.")
@click.option("--store", default=None, metavar="PATH|URL", help="Result store of the fit's engine runs "
              "[default: OUT/tune.sqlite]; a rerun resumes from it.")
@click.option("--restitution", "restitutions", default="1,0.9,0.7,0.5", show_default=True,
              help="Restitution coefficients to convert into damping (comma-separated, each in (0, 1]).")
@click.option("--start", default=None, type=float, help="Starting stiffness of the fit (default: the closed form).")
@click.option("--max-evals", default=30, show_default=True, type=click.IntRange(min=1),
              help="Most least-squares evaluations (each runs one engine job per speed).")
@click.option("-j", "--jobs", "jobs", default=None, type=click.IntRange(min=1), help="Engine jobs at once.")
@click.option("--tol", default=1e-6, show_default=True, type=float, help="Reference solver tolerance.")
@click.option("--no-plot", is_flag=True, help="Skip the f(t) plot.")
def tune(engine, scene, speeds, contact, dt, out, store, restitutions, start, max_evals, jobs, tol, no_plot) -> None:
    """Fit ENGINE's native contact parameters so its impacts on SCENE match the reference over a speed range.

    Writes OUT/tuned.json ({"engine", "options", "residuals", "engine_runs", ...}; every option usable as
    `impactval run --contact native --option KEY=VALUE`), OUT/tune.md (tables, restitution, ready-to-paste
    snippet) and OUT/tune_force.png (engine vs reference f(t), before and after).
    """
    import impactval
    from impactval import tune as T
    from impactval.reports import tune as R

    try:
        e_list = tuple(float(x) for x in restitutions.split(",") if x.strip())
    except ValueError:
        raise ImpactvalError(f"--restitution takes numbers in (0, 1], comma-separated, got {restitutions!r}.") from None
    for e in e_list:
        T.damping_ratio(e)
    if dt is not None and not (math.isfinite(dt) and 0 < dt <= 1e-2):
        raise ImpactvalError(f"--dt must be a time step in s with 0 < dt <= 1e-2, got {dt!r}.")
    sc = impactval.load_scene(scene)
    vs = T.parse_speeds(speeds)
    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    store_where = store or str(out_dir / "tune.sqlite")
    click.echo(f"impactval tune: {engine} on {sc.name}, {len(vs)} speeds, contact {contact}", err=True)
    from impactval.progress import make_progress
    from impactval.runner import RunInterrupted

    def said(objective, options, residuals):     # a line per fit evaluation (each runs one job per speed)
        click.echo(f"impactval tune: {_evaluation_line(objective, options, residuals, max_evals)}", err=True)

    try:
        result = T.tune(engine, sc, vs, contact=contact, dt=dt, store=store_where, workers=jobs, tol=tol, start=start,
                        max_nfev=max_evals, progress=_once_noting(make_progress), on_evaluation=said)
    except RunInterrupted as stop:
        click.echo(f"impactval tune: interrupted; the finished engine runs are stored in {store_where}: rerun the "
                   f"same command to resume the fit", err=True)
        sys.exit(stop.exit_code)
    path = T.write(result, out_dir)
    data = result.as_json()
    plot = None
    if not no_plot:
        plot = _plot(data, result, sc, store_where, out_dir / "tune_force.png")
    (out_dir / "tune.md").write_text(R.markdown(data, e_list, plot.name if plot else None))
    click.echo(_console(data))
    for note in result.notes:       # a fit that lost to the default: said where the options are read too
        if note.startswith("The engine's default options"):
            click.echo(f"impactval tune: warning: {note}", err=True)
    click.echo(f"tuned: {path}; report: {out_dir / 'tune.md'}; {result.engine_runs} engine runs", err=True)
    if any(r["status"] != "ok" for r in result.residuals):
        sys.exit(1)


def _plot(data, result, sc, store_where, path):
    from impactval import tune as T
    from impactval.reports import tune as R
    from impactval.store import Store

    db = Store(store_where)
    try:
        series = {}
        for which, rows in (("after", result.residuals), ("before", result.before_residuals)):
            series[which] = {}
            for r in rows:
                s = db.load_series(r["job_key"]) if r.get("job_key") else None
                if s is not None:
                    series[which][r["speed"]] = s
    finally:
        db.close()
    ref = {}
    for t in result.targets:
        if sc.target.kind == "rigid-plate":
            import numpy as np

            from impactval.reference.hertz import plate_impact

            p = plate_impact(sc.ball.mass, sc.alpha, t.speed)
            tt = np.linspace(0, 1.3 * p.t_m, 400)
            ref[t.speed] = (tt, p.force(tt))
        else:
            import impactval

            r = impactval.solve(T.at_speed(sc, t.speed))
            ref[t.speed] = (r.t, r.f)
    return R.force_plot(data, series, ref, path)


def _once_noting(make_progress):
    """A factory of progress displays (one per fit evaluation) that print each engine note once per fit: the same
    job's caveat ("chain capped at 113 links ...") came back for every speed of every evaluation (60 lines)."""
    seen: set[str] = set()

    def factory():
        display = make_progress("auto")
        note = getattr(display, "note", None)
        if callable(note):
            def once(text: str) -> None:
                if text not in seen:
                    seen.add(text)
                    note(text)
            display.note = once
        return display
    return factory


def _evaluation_line(objective, options: dict, residuals, max_nfev: int | None = None) -> str:
    """One line on a fit evaluation just done: its number (of at most max_nfev, the Jacobian's steps not counted
    by least_squares' budget), the options tried, the largest |error| of the metrics the objective fits
    (`objective.quantities`, e.g. t_m and f_m: "largest fitted |error| (t_m, f_m)") over the speeds in % and the work
    so far."""
    import numpy as np

    r = objective.record
    worst = float(np.max(np.abs(residuals))) if len(residuals) else math.nan
    fitted = ", ".join(getattr(objective, "quantities", ()) or ())
    what = f"largest fitted |error| ({fitted})" if fitted else "largest |error|"
    opts = ", ".join(f"{k}={v}" for k, v in options.items())
    if getattr(objective, "phase", "fit") == "scan":
        of = " (scanning the spring before the fit)"
    else:
        of = f" (budget {max_nfev} + Jacobian steps)" if max_nfev else ""
    return (f"evaluation {r.evaluations}{of}: {opts}: {what} {100 * worst:.3g} % over "
            f"{len(objective.speeds)} speeds; {r.engine_runs} engine runs, {r.jobs_reused} reused")


def _console(data) -> str:
    lines = [f"{data['engine']} {data['scene']} ({data['contact']}), dt = {data['dt']:g} s, "
             f"{data['engine_runs']} engine runs",
             "options: " + " ".join(f"--option {k}={v}" for k, v in data["options"].items()),
             f"{'v0 [m/s]':>9} {'status':>8} {'t_m %':>8} {'f_m %':>8} {'delta_m %':>10}"]

    def pct(x):
        return f"{100 * x:+8.3f}" if x is not None and math.isfinite(x) else f"{'':>8}"
    for r in data["residuals"]:
        lines.append(f"{r['speed']:9.4g} {r['status']:>8} {pct(r['err_t_m'])} {pct(r['err_f_m'])} "
                     f"{pct(r['err_delta_m']):>10}")
    return "\n".join(lines)


@click.command(name="materials")
@click.argument("scene", required=False)
def materials(scene) -> None:
    """List the material catalogue (E, nu, rho, yield stress, source); with SCENE also that scene's materials."""
    from impactval.scenarios.materials import BUILTIN_MATERIALS

    mats = dict(BUILTIN_MATERIALS)
    used: dict[str, list[str]] = {}         # material name -> the scene's parts made of it ("ball", "target")
    if scene:
        import impactval

        sc = impactval.load_scene(scene)
        for part, m in (("ball", sc.ball.material), ("target", sc.target.material)):
            mats[m.name] = m
            used.setdefault(m.name, []).append(part)
        click.echo(f"this scene ({sc.name}): ball {sc.ball.material.name}, target {sc.target.material.name} "
                   f"({sc.target.kind}); marked <- below")
    click.echo(f"{'material':<18} {'E [GPa]':>9} {'nu':>6} {'rho [kg/m^3]':>13} {'yield [MPa]':>12}  source")
    for m in mats.values():
        y = getattr(m, "yield_stress", None)
        y_s = f"{y / 1e6:12.4g}" if y else f"{'-':>12}"
        mark = f"  <- {', '.join(used[m.name])}" if m.name in used else ""
        click.echo(f"{m.name:<18} {m.young / 1e9:9.4g} {m.poisson:6.3g} {m.density:13.6g} {y_s}  "
                   f"{m.source or 'not given'}{mark}")


def register(group: click.Group) -> None:
    """Add the commands of this module to the `impactval` group."""
    group.add_command(tune)
    group.add_command(materials)
