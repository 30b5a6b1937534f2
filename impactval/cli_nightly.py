"""`impactval nightly` and `impactval report` (registered in impactval/cli.py with one line each).

Exit codes of nightly: 0 no regression, 1 regression or newly failing job (or a persistent wall-time
step), 2 bad input / nothing could run / nothing comparable, 130 / 143 interrupted.
"""
from __future__ import annotations

import sys
from pathlib import Path

import click

from impactval.errors import ImpactvalError


@click.command(name="nightly")
@click.argument("scene", nargs=-1)
@click.option("--suite", default="nightly", show_default=True, help="Catalogue tag of the scenes to run.")
@click.option("--engines", default=None, help="Comma-separated engines  [default: every installed engine]")
@click.option("--store", default=None, metavar="PATH|URL",
              help="Result store holding the history: SQLite file or database URL (postgresql://user@host/db)  "
                   "[default: OUT/impactval.sqlite]")
@click.option("--out", default="impactval-nightly", show_default=True, type=click.Path(file_okay=False),
              help="Directory for report.md, report.html, figures and results.csv.")
@click.option("--fail-on", "fail_on", multiple=True, metavar="METRIC:+N%|+Npp",
              help="Threshold of one metric, repeatable: t_m, f_m, delta_m, curve (growth of |error|), wall_time "
                   "(persistent step of the stepping time), e.g. 'f_m:+20%' or 'curve:+0.5pp'.")
@click.option("--threshold", default=0.2, show_default=True, type=float,
              help="Relative growth of |error| that flags metrics not named in --fail-on.")
@click.option("--baseline", default=None, metavar="RUN_ID", help="Compare with this run  [default: the last good night]")
@click.option("--history", "history_nights", default=14, show_default=True, type=click.IntRange(min=2),
              help="Nights in the trend plots and the wall-time step search.")
@click.option("--dt", default="5e-8", show_default=True,
              help="Engine time step [s] (documented nightly setting, below every engine's stability limit on the "
                   "catalogue scenes), or auto (each engine picks a step under its predicted stability limit, as "
                   "`run --dt auto`; for your own scenes).")
@click.option("--contact", default="hertz", show_default=True, type=click.Choice(["hertz", "native", "native-hertz"]))
@click.option("--integrator", default=None, help="Engine integrator (default: each engine's).")
@click.option("--segments", default=None, type=click.IntRange(min=1), help="Beam chain segments (default: engine's).")
@click.option("--modes", default=None, type=click.IntRange(min=1), help="Modes of a modal beam (default: engine's).")
@click.option("--option", "options", multiple=True, metavar="[ENGINE.]KEY=VALUE", help="Engine option, repeatable.")
@click.option("--timeout", default=600.0, show_default=True, type=float, help="Time limit per engine job [s].")
@click.option("--tol", default=1e-6, show_default=True, type=float, help="Reference solver tolerance.")
@click.option("-j", "--jobs", "jobs", default=None, type=click.IntRange(min=1), help="Engine jobs at once.")
@click.option("--no-html", is_flag=True, help="Skip report.html.")
def nightly_command(scene, suite, engines, store, out, fail_on, threshold, baseline, history_nights, dt, contact,
                    integrator, segments, modes, options, timeout, tol, jobs, no_html) -> None:
    """Run the scenes tagged SUITE (or SCENE...) on the installed engines, compare with the last good
    night in the store, write report.md + report.html, exit 0 / 1 (regression) / 2 (nothing comparable)."""
    from impactval.cli import _run_settings
    from impactval.nightly import nightly
    from impactval.runner import RunInterrupted

    try:
        from impactval.progress import make_progress

        progress = make_progress("auto")
    except ImportError:  # pragma: no cover - the runs-at-scale progress module
        progress = None
    settings = _run_settings(_one_dt(dt), contact, integrator, segments, timeout, 0.0, modes, options)
    from impactval.cli import command_line

    command = command_line("nightly")
    try:
        res = nightly(list(scene) or None, engines, settings, suite=suite, store=store, out=out, fail_on=fail_on,
                      threshold=threshold, baseline=baseline, history_nights=history_nights, tol=tol, workers=jobs,
                      progress=progress, command=command, html=not no_html)
    except RunInterrupted as stop:
        click.echo(f"impactval: {stop}; partial report: {Path(out) / 'report.md'}; rerun to resume the night", err=True)
        sys.exit(stop.exit_code)
    from impactval.reports.run_report import text_table

    click.echo(text_table(res.rows))
    for line in res.flagged:
        click.echo(line)
    click.echo(f"nightly run {res.run_id} (night {res.night}): report {res.report}"
               + (f", {res.html}" if res.html else ""))
    if res.exit_code == 2:
        raise ImpactvalError(res.message)
    click.echo(res.message)
    sys.exit(res.exit_code)


def _one_dt(text: str):
    """--dt of a night: one time step [s] or "auto", parsed as `run --dt` parses it (impactval.cli._parse_dts)."""
    from impactval.checks import RUN_LIMITS
    from impactval.cli import _parse_dts

    low, high, unit, _ = RUN_LIMITS["--dt"]
    one = f"one time step from {low:g} to {high:g} {unit} (e.g. 5e-8) or auto"
    try:
        dts = _parse_dts(text)
    except ImpactvalError:        # (the shared parser's wording offers lists and ranges: not for a night)
        raise ImpactvalError(f"--dt must be {one}, got {text!r}.") from None
    if len(dts) != 1:
        raise ImpactvalError(f"--dt: a night runs {one}, got {len(dts)} steps ({text!r}); to compare several steps "
                             "use `impactval sweep --dt`.")
    return dts[0]


@click.command(name="report")
@click.argument("store_or_dir")
@click.option("--run", "run_id", default=None, help="Run id (default: the newest run in the store).")
@click.option("--out", default=None, type=click.Path(file_okay=False),
              help="Directory for report.md, report.html and figures  [default: DIR, or ./impactval-report for a URL]")
@click.option("--tol", default=None, type=float,
              help="Reference solver tolerance of the report's reference values  [default: the run's own]")
@click.option("--list", "list_runs", is_flag=True, help="List the runs in the store and exit.")
def report_command(store_or_dir, run_id, out, tol, list_runs) -> None:
    """Re-render the report of a run from the store: STORE_OR_DIR is an --out directory (its
    impactval.sqlite), an SQLite file or a database URL."""
    from impactval.checks import check_tol
    from impactval.nightly import render_stored

    if tol is not None:
        tol = check_tol(tol, "--tol")       # one line, exit 2 (it went on silently: a plate needs no tolerance)
    lines, paths = render_stored(store_or_dir, run_id, out, tol, list_runs)
    for line in lines:
        click.echo(line)
    if paths:
        click.echo(f"report: {', '.join(str(p) for p in paths if p)}")
