"""Command line: a thin layer over functions that return results or DataFrames (style.md, pattern 7).

Exit codes: 0 fine, 1 a regression or failure flagged, 2 bad input.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import click

from impactval.errors import ImpactvalError


def _pm(value: float, unc: float) -> str:
    """'value ± uncertainty' with the value to the uncertainty's second significant digit."""
    if not math.isfinite(value):
        return "n/a"
    if not unc > 0:
        return f"{value:.9g}"
    digits = max(0, min(12, 1 - math.floor(math.log10(unc))))
    return f"{value:.{digits}f} ± {unc:.1g}"


def _warn_if_compiling() -> None:
    from impactval.reference import kernel

    try:
        path = Path(kernel.solve_pair._cache._cache_path)
        cached = any(path.glob("kernel.solve_pair-*.nbi"))
    except Exception:  # noqa: BLE001 - only a hint
        cached = True
    if not cached:
        click.echo("impactval: first run: compiling the solver kernel (one time, ~20 s; cached afterwards)",
                   err=True)


class _Group(click.Group):
    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except ImpactvalError as err:
            click.echo(f"impactval: error: {err}", err=True)
            ctx.exit(2)


@click.group(cls=_Group)
@click.version_option(package_name="impactval")
def main() -> None:
    """impactval: validation suite for physics engines on elastic impact (SI units)."""


@main.command()
@click.option("--tag", default=None, help="Only scenes carrying this tag.")
def scenes(tag: str | None) -> None:
    """List the built-in scene catalogue."""
    from impactval.scenarios.scene import load_catalogue

    for s in load_catalogue(tag):
        click.echo(f"{s.name:26s} {s.target.kind:12s} [{', '.join(s.tags)}]  {s.description}")


@main.command()
@click.argument("scene", nargs=-1)
@click.option("--tol", default=1e-6, show_default=True, type=float, help="Relative tolerance on t_m, f_m, delta_m.")
@click.option("--window", default=0.0, show_default=True, type=float,
              help="Time [s] to follow after the first contact ends (re-contacts).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object per scene (SI units).")
@click.option("--curve", type=click.Path(dir_okay=False, writable=True), default=None,
              help="Write the time series (t, delta, f, x_ball, x_structure, energy) to this CSV file.")
def reference(scene: tuple[str, ...], tol: float, window: float, as_json: bool, curve: str | None) -> None:
    """Reference solution of SCENE (catalogue names or TOML paths; none = the whole catalogue)."""
    import impactval
    from impactval.scenarios.scene import catalogue_names

    names = list(scene) or catalogue_names()
    if curve and len(names) != 1:
        raise ImpactvalError("--curve writes one scene's series: give exactly one SCENE.")
    scenes_ = [impactval.load_scene(n) for n in names]
    _warn_if_compiling()
    if not as_json:
        click.echo(f"{'scene':24s} {'t_m [us]':>22s} {'f_m [N]':>24s} {'delta_m [um]':>22s} "
                   f"{'modes':>5s} {'contacts':>8s}")
    for sc in scenes_:
        r = impactval.solve(sc, tol=tol, window=window)
        u = r.uncertainty
        if as_json:
            click.echo(json.dumps({"scene": r.scene, "t_m": r.t_m, "f_m": r.f_m, "delta_m": r.delta_m,
                                   "uncertainty": u.as_dict(), "modes": r.modes,
                                   "rebound_velocity": r.rebound_velocity, "energy_error": r.energy_error,
                                   "contacts": [c.__dict__ for c in r.contacts]}))
        else:
            click.echo(f"{r.scene:24s} {_pm(r.t_m * 1e6, u.t_m * 1e6):>22s} {_pm(r.f_m, u.f_m):>24s} "
                       f"{_pm(r.delta_m * 1e6, u.delta_m * 1e6):>22s} {r.modes:5d} {len(r.contacts):8d}")
        if curve:
            import numpy as np

            data = np.column_stack([r.t, r.delta, r.f, r.x_ball, r.x_structure, r.energy])
            np.savetxt(curve, data, delimiter=",", header="t_s,delta_m,f_N,x_ball_m,x_structure_m,energy_J",
                       comments="")


# ---------------------------------------------------------------------------- impactval run
def _run_settings(dt, contact, integrator, segments, timeout, tail):
    from impactval.engines.base import EngineSettings

    return EngineSettings(dt=dt, contact=contact, integrator=integrator, segments=segments, timeout_s=timeout,
                          tail=tail)


@main.command(name="run")
@click.argument("scene", nargs=-1)
@click.option("--engines", "engines", default="mujoco", show_default=True,
              help="Comma-separated engine names (mujoco, pybullet, exudyn) or 'package.module:Class' adapters.")
@click.option("--dt", default=1e-6, show_default=True, type=float, help="Engine time step [s].")
@click.option("--contact", default="hertz", show_default=True, type=click.Choice(["hertz", "native", "native-hertz"]),
              help="hertz: exact law injected; native: engine contact as the linear spring k0; "
                   "native-hertz: engine contact shaped toward Hertz.")
@click.option("--integrator", default=None, help="Engine integrator (e.g. MuJoCo: Euler, implicitfast, RK4).")
@click.option("--segments", default=None, type=click.IntRange(min=1), help="Beam chain segments (default: engine's).")
@click.option("--timeout", default=600.0, show_default=True, type=float, help="Time limit per engine job [s].")
@click.option("--tail", default=0.0, show_default=True, type=float,
              help="Simulated time [s] after the first contact ends (re-contacts).")
@click.option("--tol", default=1e-6, show_default=True, type=float, help="Reference solver tolerance.")
@click.option("--out", "out", default="impactval-results", show_default=True, type=click.Path(file_okay=False),
              help="Directory for results.csv (rows appended as they finish) and report.md.")
def run_command(scene, engines, dt, contact, integrator, segments, timeout, tail, tol, out) -> None:
    """Run the reference and ENGINES on SCENE (catalogue names or TOML paths; none = whole catalogue).

    Prints relative errors in % (engine - reference) / reference and wall times. Exit code 0, or 1
    when a row crashed, timed out, went unstable or found no contact.
    """
    from impactval.runner import any_failed, resolve_engine, run, text_table
    from impactval.scenarios.scene import catalogue_names

    specs = [resolve_engine(e.strip()) for e in engines.split(",") if e.strip()]
    settings = _run_settings(dt, contact, integrator, segments, timeout, tail)
    names = list(scene) or catalogue_names()
    _warn_if_compiling()

    def progress(row):
        click.echo(f"  {row['scene']} / {row['engine']}: {row['status']}", err=True)

    df = run(names, specs, settings, tol=tol, out=out, on_row=progress)
    click.echo(text_table(df))
    click.echo(f"results: {Path(out) / 'results.csv'}, report: {Path(out) / 'report.md'}")
    if any_failed(df):
        sys.exit(1)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
