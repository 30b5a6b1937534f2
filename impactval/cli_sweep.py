"""`impactval sweep`: speed against accuracy over a grid of settings (issue 13).

A thin layer: parse the axes (impactval.sweep.parse_axis), build and run the jobs
(impactval.sweep), write DIR/results.csv, DIR/orders.csv, DIR/cheapest.csv, DIR/sweep.md and the
plots (reports/sweep.py). Exit 0, or 2 on bad input. Failed cells are rows, not errors.
"""
from __future__ import annotations

import sys
from pathlib import Path

import click

from impactval.errors import ImpactvalError


def parse_unders(text: str | None) -> list[float]:
    """--under: tolerances as '1%', '0.5 %' or fractions '0.01', comma-separated -> fractions."""
    out = []
    for item in (text or "").split(","):
        item = item.strip()
        if not item:
            continue
        pct = item.endswith("%")
        try:
            v = float(item.rstrip("%").strip())
        except ValueError:
            raise ImpactvalError(f"--under takes tolerances like 1% or 0.5%,0.1% (or fractions 0.01), "
                                 f"got {item!r}.") from None
        v = v / 100 if pct else v
        if not (0 < v < 10):
            raise ImpactvalError(f"--under: a tolerance must be above 0 (1% = 0.01), got {item!r}.")
        out.append(v)
    return out


@click.command(name="sweep")
@click.argument("scene", nargs=-1, required=True)
@click.option("--engines", default="mujoco", show_default=True, help="Comma-separated engine names.")
@click.option("--dt", default="1e-5:1e-8:12", show_default=True,
              help="Time steps [s]: a log range a:b:n, a list 1e-6,5e-7, auto, or per engine (mujoco.1e-6:1e-8:6).")
@click.option("--integrator", default=None,
              help="Integrators, per engine by prefix (mujoco.Euler,mujoco.RK4,pybullet.semi-implicit-euler); "
                   "default: each engine's default.")
@click.option("--segments", default=None, help="Chain segment counts (21,41,81,161 or auto; per engine by prefix).")
@click.option("--modes", default=None, help="Mode counts of modal bodies (list or auto; per engine by prefix).")
@click.option("--contact", default="hertz", show_default=True, type=click.Choice(["hertz", "native", "native-hertz"]),
              help="Contact mode (see `impactval run --help`).")
@click.option("--option", "options", multiple=True, metavar="[ENGINE.]KEY=VALUE", help="Engine option, repeatable.")
@click.option("--under", default="1%", show_default=True,
              help="Tolerances for the cheapest setting, comma-separated (1%,0.1%).")
@click.option("--tol", default=1e-9, show_default=True, type=float,
              help="Relative tolerance of the reference (tight, so it never sets the floor).")
@click.option("--timeout", default=600.0, show_default=True, type=float, help="Time limit per cell [s].")
@click.option("-j", "--jobs", "jobs", default=None, type=click.IntRange(min=1),
              help="Cells run at once on this machine (each isolated in an engine worker)  [default: number of cores]")
@click.option("--scheduler", default=None, metavar="ADDR",
              help="Run the cells on a Dask distributed scheduler (tcp://host:8786); needs impactval[dask].")
@click.option("--store", "store", default=None, metavar="PATH|URL",
              help="Result store: an SQLite file or a database URL  [default: OUT/impactval.sqlite]")
@click.option("--force", is_flag=True, help="Recompute cells already in the store (default: reuse them).")
@click.option("--out", "out", default="impactval-sweep", show_default=True, type=click.Path(file_okay=False),
              help="Directory for results.csv, orders.csv, cheapest.csv, sweep.md and the plots.")
@click.option("--no-plot", is_flag=True, help="Skip the plots.")
def sweep_command(scene, engines, dt, integrator, segments, modes, contact, options, under, tol, timeout, jobs,
                  scheduler, store, force, out, no_plot) -> None:
    """Run SCENE(s) over a grid of settings and find the cheapest setting under each tolerance.

    The grid is dt x integrator x segments x modes per engine. Every cell goes into the result
    store as it finishes; rerunning a killed or interrupted sweep runs only the missing cells. Exit 0;
    2 bad input; 130 / 143 interrupted (what finished is stored and reported). Writes DIR/sweep.md (read it in
    a minute), DIR/orders.csv, DIR/cheapest.csv and error-vs-cost and error-vs-dt plots.
    """
    import impactval
    from impactval import sweep as sw
    from impactval.cli import _parse_options, _warn_if_compiling
    from impactval.engines.base import EngineSettings
    from impactval.errors import EngineError
    from impactval.runner import _check_settings_somewhere, resolve_engine

    specs = [resolve_engine(e.strip()) for e in engines.split(",") if e.strip()]
    if not specs:
        raise ImpactvalError("--engines: give at least one engine (e.g. mujoco,pybullet).")
    unders = parse_unders(under)
    axes = dict(dt=sw.parse_axis(dt, "dt", "float", specs),
                integrator=sw.parse_axis(integrator, "integrator", "str", specs),
                segments=sw.parse_axis(segments, "segments", "int", specs),
                modes=sw.parse_axis(modes, "modes", "int", specs))
    try:
        base = EngineSettings(contact=contact, timeout_s=timeout, options=_parse_options(options))
    except EngineError as err:
        raise ImpactvalError(str(err)) from None
    from impactval.checks import load_scenes

    scenes = load_scenes(scene)
    cells = sw.build_jobs(scenes, specs, base, tol=tol, **axes)
    for spec in specs:           # a misspelt integrator fails here, before any job
        for job in [j for j in cells if j.spec == spec][:1]:
            _check_settings_somewhere([spec], job.settings)
    _warn_if_compiling()
    click.echo(f"impactval sweep: {len(cells)} cells ({len(scenes)} scenes x {len(specs)} engines) -> {out}", err=True)
    import shlex

    from impactval.progress import make_progress
    from impactval.runner import RunInterrupted

    kinds = {s.name: s.target.kind for s in scenes}
    from impactval.cli import command_line

    command = command_line("sweep")
    try:
        df = sw.run_sweep(cells, out=out, store=store, workers=jobs, scheduler=scheduler, force=force,
                          progress=make_progress("auto"), command=command)
    except RunInterrupted as stop:
        report = Path(out) / "sweep.md"
        try:
            if len(stop.rows):
                rows = sw.reference_columns(stop.rows, scenes, tol, getattr(stop, "references", None))
                write_outputs(rows, out, unders, kinds, plot=not no_plot, tol=tol)
                where = f"report of what finished: {report}"
            else:                       # nothing to analyse: say so in the report the line points to
                write_nothing_finished(out, stop, stop.total, command)
                where = f"no cell finished (see {report})"
        except KeyboardInterrupt:
            where = "interrupted again while writing the report (every finished cell is stored)"
        click.echo(f"impactval: {stop}; rerun the same command to run the rest; {where}", err=True)
        sys.exit(stop.exit_code)
    try:
        write_outputs(df, out, unders, kinds, plot=not no_plot, tol=tol)
    except KeyboardInterrupt:
        click.echo(f"impactval: interrupted while writing the report; every cell is stored: rerun the same command "
                   f"to write {Path(out) / 'sweep.md'}", err=True)
        sys.exit(130)
    from impactval.reports.sweep import cell_counts

    # how the cells ended, refused-before-stepping apart from stepped-and-unstable (the per-cell progress lines
    # above name each refusal too: impactval.progress)
    click.echo(f"impactval sweep: {cell_counts(df)}", err=True)
    cheap = sw.cheapest(df, unders)
    for _, c in cheap.iterrows():
        if c["found"]:
            size = f", N = {c['segments']}" if c["segments"] else ""     # none for a plate or a ball pair
            click.echo(f"{c['scene']} / {c['engine']} under {100 * c['under']:g} %: {c['integrator']}, dt = {c['dt']:g} s"
                       f"{size}: {1e3 * c['cost_s']:.3g} ms stepping, largest error {100 * c['score']:.3g} %")
        else:
            best = (f"best {100 * c['best_score']:.3g} %" if c["best_score"] == c["best_score"]
                    else "no cell has a result: see sweep.md")
            click.echo(f"{c['scene']} / {c['engine']} under {100 * c['under']:g} %: none in this grid ({best})")
    click.echo(f"report: {Path(out) / 'sweep.md'}")


#: cheapest.csv: the fractions of `impactval.sweep.cheapest` exported in % as NAME_pct (the convention of
#: results.csv, impactval.store.PERCENT_COLUMNS): under (the tolerance), score (the setting's largest error),
#: best_score (the least largest error in the grid)
CHEAPEST_PERCENT = {"under": "under_pct", "score": "largest_error_pct", "best_score": "best_score_pct"}
#: cheapest.csv columns, in order
CHEAPEST_COLUMNS = ("scene", "engine", "under_pct", "setting", "integrator", "dt", "segments", "contact",
                    "stepping_time_s", "largest_error_pct", "best_score_pct", "measured_step_time_s")


def write_nothing_finished(out, stop, n_cells: int, command: str) -> Path:
    """DIR/sweep.md of a sweep interrupted before any cell finished: says so (there is nothing to analyse)."""
    from impactval.reports.sweep import nothing_finished_markdown

    path = Path(out) / "sweep.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(nothing_finished_markdown(n_cells, str(stop), command))
    return path


def write_outputs(df, out, unders: list[float], scene_kinds: dict[str, str], plot: bool = True,
                  tol: float | None = None) -> dict[str, Path]:
    """DIR/orders.csv, DIR/cheapest.csv, the plots and DIR/sweep.md from a sweep's rows."""
    import pandas as pd

    from impactval import sweep as sw
    from impactval.reports.sweep import plot_error_vs_dt, plot_error_vs_time, sweep_markdown

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"orders": out / "orders.csv", "cheapest": out / "cheapest.csv", "report": out / "sweep.md"}
    sw.orders_table(df, scene_kinds).to_csv(paths["orders"], index=False)
    cheap = sw.cheapest(df, unders)
    cheap = cheap.rename(columns={"cost_s": "stepping_time_s", "step_time_s": "measured_step_time_s"})
    for frac, pct in CHEAPEST_PERCENT.items():     # fractions exported in % as NAME_pct, as results.csv does
        cheap[pct] = 100.0 * pd.to_numeric(cheap[frac], errors="coerce")
    cheap["setting"] = ["found" if f else "none in this grid" for f in cheap["found"]]
    cheap[list(CHEAPEST_COLUMNS)].to_csv(paths["cheapest"], index=False)
    plots = []
    if plot:
        plots += [p for p in plot_error_vs_time(df, unders, out / "error_vs_time") if p.suffix == ".png"]
        plots += [p for p in plot_error_vs_dt(df, unders, out / "error_vs_dt", scene_kinds) if p.suffix == ".png"]
    paths["report"].write_text(sweep_markdown(df, unders, scene_kinds, plots, tol=tol))
    return paths
