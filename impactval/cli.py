"""Command line: a thin layer over functions that return results or DataFrames (style.md, pattern 7).

Exit codes: 0 fine, 1 a regression or failure flagged, 2 bad input.
"""
from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import click

from impactval.errors import ImpactvalError
from impactval.checks import (MAX_ENGINE_MODES, MAX_SEGMENTS, check_answer, check_engine_steps, check_run_number,
                              check_tol, load_scenes)
from impactval.checks import check_window as check_window_arg
from impactval.paths import check_output_dir, check_output_file, write_guard


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
        path = Path(kernel.solve_auto._cache._cache_path)
        cached = any(path.glob("kernel.solve_auto-*.nbi"))
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
        except (MemoryError, RecursionError) as err:
            click.echo(f"impactval: error: the request needs more {'memory' if isinstance(err, MemoryError) else 'nesting'}"
                       f" than this machine has ({type(err).__name__}); make it smaller (fewer modes, a shorter window).",
                       err=True)
            ctx.exit(2)
        except BrokenPipeError:       # the reader went away (`impactval scenes | head -1`): stop quietly
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            ctx.exit(0)
        except (click.exceptions.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise                     # click's own exits (`--help`, usage errors, aborted prompts): not bugs
        except Exception as err:  # noqa: BLE001 - a bug: one line, the traceback on request (issue 18)
            if os.environ.get("IMPACTVAL_DEBUG"):
                raise
            click.echo(f"impactval: internal error: {type(err).__name__}: {err} (a bug in impactval; please report it "
                       f"with the command line; IMPACTVAL_DEBUG=1 shows the traceback)", err=True)
            ctx.exit(3)


@click.group(cls=_Group)
@click.version_option(package_name="impactval")
def main() -> None:
    """impactval: validation suite for physics engines on elastic impact (SI units)."""


main.add_command(__import__("impactval.cli_engines", fromlist=["engines_command"]).engines_command)
main.add_command(__import__("impactval.cli_sweep").cli_sweep.sweep_command)   # impactval sweep (issue 13)


@main.command()
@click.option("--tag", default=None, help="Only scenes carrying this tag.")
def scenes(tag: str | None) -> None:
    """List the built-in scene catalogue."""
    from impactval.scenarios.scene import load_catalogue

    if tag is not None and not load_catalogue(tag):
        known = sorted({t for s in load_catalogue() for t in s.tags})
        raise ImpactvalError(f"--tag {tag!r} matches no scene; known tags: {', '.join(known)}.")
    for s in load_catalogue(tag):
        click.echo(f"{s.name:26s} {s.target.kind:12s} [{', '.join(s.tags)}]  {s.description}")


@main.command()
@click.argument("scene", nargs=-1)
@click.option("--tol", default=1e-6, show_default=True, type=float, help="Relative tolerance on t_m, f_m, delta_m.")
@click.option("--window", default=0.0, show_default=True, type=float,
              help="Time [s] to follow after the first contact ends (re-contacts).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object per scene (SI units).")
@click.option("--curve", type=str, default=None,
              help="Write the time series (t, delta, f, x_ball, x_structure, energy) to this CSV file.")
@click.option("--model", type=click.Choice(["nonlinear", "linear", "perturbation"]), default="nonlinear",
              show_default=True, help="Hertz contact (exact), linear contact k0 (exact) or first-order perturbation.")
@click.option("--explain", is_flag=True, help="Also show the modes that matter, their weights, the chosen count "
              "and whether a rigid plate would do.")
def reference(scene: tuple[str, ...], tol: float, window: float, as_json: bool, curve: str | None,
              model: str = "nonlinear", explain: bool = False) -> None:
    """Reference solution of SCENE (catalogue names or TOML paths; none = the whole catalogue)."""
    import impactval
    from impactval.reference.explicit_modes import explicit_count, truncation_check, with_warning
    from impactval.scenarios.scene import catalogue_names

    names = list(scene) or catalogue_names()
    if curve is not None and len(names) != 1:
        raise ImpactvalError("--curve writes one scene's series: give exactly one SCENE.")
    if curve is not None:
        check_output_file(curve, "--curve")
    check_tol(tol)
    check_window_arg(window)
    scenes_ = load_scenes(names)
    if model != "nonlinear":
        return _reference_theory(scenes_, model, tol, window, as_json, curve, explain)
    if window:
        from impactval.reference.hertz import plate_impact
        from impactval.reference.solve import _check_tol, check_window

        if not (math.isfinite(window) and window >= 0):
            raise ImpactvalError(f"--window must be a non-negative time in s, got {window!r}.")
        for sc in scenes_:      # refuse up front, before any output
            check_window(window, plate_impact(sc.ball.mass, sc.alpha, sc.ball.velocity).t_m, _check_tol(tol))
    _warn_if_compiling()
    if not as_json:
        click.echo(f"{'scene':24s} {'t_m [us]':>22s} {'f_m [N]':>24s} {'delta_m [um]':>22s} "
                   f"{'modes':>5s} {'contacts':>8s}")
    for sc in scenes_:
        r = impactval.solve(sc, tol=tol, window=window)
        if explicit_count(sc) is not None:      # modes = n: the n-mode model, checked against the continuum
            r = with_warning(r, truncation_check(sc, r, tol)[1])
        u = r.uncertainty
        check_answer(sc.name, t_m=r.t_m, f_m=r.f_m, delta_m=r.delta_m, uncertainty_t_m=u.t_m,
                     uncertainty_f_m=u.f_m, uncertainty_delta_m=u.delta_m, rebound_velocity=r.rebound_velocity,
                     energy_error=r.energy_error)
        if as_json:
            click.echo(json.dumps({"scene": r.scene, "t_m": r.t_m, "f_m": r.f_m, "delta_m": r.delta_m,
                                   "uncertainty": u.as_dict(), "modes": r.modes,
                                   "rebound_velocity": r.rebound_velocity, "energy_error": r.energy_error,
                                   "contacts": [c.__dict__ for c in r.contacts], "validity": list(r.validity)}))
        else:
            click.echo(f"{r.scene:24s} {_pm(r.t_m * 1e6, u.t_m * 1e6):>22s} {_pm(r.f_m, u.f_m):>24s} "
                       f"{_pm(r.delta_m * 1e6, u.delta_m * 1e6):>22s} {r.modes:5d} {len(r.contacts):8d}")
            for warning in r.validity:
                click.echo(f"  ! {warning}")
        if curve:
            import numpy as np

            data = np.column_stack([r.t, r.delta, r.f, r.x_ball, r.x_structure, r.energy])
            with write_guard("--curve", curve):
                Path(curve).parent.mkdir(parents=True, exist_ok=True)
                np.savetxt(curve, data, delimiter=",", header="t_s,delta_m,f_N,x_ball_m,x_structure_m,energy_J",
                           comments="")
        if explain and not as_json:
            _explain(sc, tol)


def _explain(sc, tol: float) -> None:
    """The modes that matter for `sc` at relative tolerance `tol` (first-order weights, issue 3)."""
    import numpy as np

    from impactval.reference.modechoice import SAFETY, required_modes

    c = required_modes(sc, min(max(tol, 1e-8), 0.5))
    if len(c.s) == 0:
        click.echo("  ball target: no structure modes (a second free sphere: two-body Hertz)" if sc.target.kind == "ball"
                   else "  rigid plate: no structure modes")
        return
    e = c.structure_effect
    from impactval.reference.validity import perturbation_validity

    # the rule --model perturbation uses: a first-order shift <= -100 % has no first-order answer (n/a)
    warnings, usable = perturbation_validity(e.t_m, e.delta_m)
    enough = f"rigid plate enough at tol {c.tol:g}: {'yes' if c.rigid_plate_enough else 'no'}"
    if not usable:
        reason = warnings[0].split(": ", 1)[1]
        click.echo(f"  structure effect (first order): n/a ({reason}); {enough}")
        click.echo("  ! the mode weights and the first-order mode count below come from the same expansion: "
                   "a rough guide only here")
    else:
        click.echo(f"  structure effect (first order): t_m {100 * e.t_m:+.3f} %, f_m {100 * e.f_m:+.3f} %, "
                   f"delta_m {100 * e.delta_m:+.3f} %; {enough}")
        for warning in warnings:
            click.echo(f"  ! structure effect and mode weights are first-order: {warning.split(': ', 1)[1]}")
    click.echo(f"  modes needed (first-order weights, a-priori, safety factor {1 / SAFETY:g}): "
               f"{'at least ' if c.count_capped else ''}{c.count} with the residual "
               f"static flexibility, {'at least ' if c.plain_count_capped else ''}{c.count_without_residual} "
               f"without it")
    if sc.target.kind in ("beam", "plate") and getattr(sc.target, "modes", None) is None:
        import impactval

        solved = impactval.solve(sc, tol=c.tol).modes
        each = ", each with the residual," if sc.target.kind == "beam" else ""
        click.echo(f"  modes the solve used at tol {c.tol:g}: {solved} (measured: doubled until the n- and 2n-mode "
                   f"models{each} agree within tol; the first-order count above is a bound "
                   f"from weights, so it is {'larger' if c.count > solved else 'smaller' if c.count < solved else 'the same'})")
    elif sc.target.kind != "rigid-plate":
        click.echo(f"  modes the solve used: {len(sc.target.omega) if sc.target.kind == 'modal' else sc.target.modes} "
                   f"(the scene's)")
    if sc.target.kind == "beam":
        _explain_theory(sc)
    size = np.maximum(np.abs(c.d_t), np.abs(c.d_f))
    top = sorted(int(i) for i in np.argsort(-size)[:8] if size[i] > 0)
    click.echo(f"  {'mode':>6s} {'omega [rad/s]':>14s} {'w':>9s} {'s':>9s} {'s*TH (t_m)':>11s} {'1.5s*MH (f_m)':>13s}")
    for j in top:
        click.echo(f"  {j + 1:6d} {c.omega[j]:14.6g} {c.w[j]:9.4g} {c.s[j]:9.4g} {c.d_t[j]:+11.3e} {c.d_f[j]:+13.3e}")


def _explain_theory(sc) -> None:
    """How much the beam theory alone moves the answer, and whether to use Timoshenko (`reports.theory`, shared with
    the theory page)."""
    from impactval.reports.theory import beam_theory_line

    click.echo(f"  {beam_theory_line(sc)}")


def _reference_theory(scenes_, model: str, tol: float, window: float, as_json: bool, curve: str | None,
                      explain: bool) -> None:
    """`reference --model linear|perturbation`: the exact linear-contact or the first-order solution."""
    import numpy as np

    from impactval.reference.linear import solve_linear
    from impactval.reference.perturbation import perturbation, perturbation_curve

    if not as_json:
        click.echo(f"{'scene':24s} {'t_m [us]':>22s} {'f_m [N]':>24s} {'delta_m [um]':>22s} {'modes':>5s}  model")
    for sc in scenes_:
        if model == "linear":
            r = solve_linear(sc, tol=tol, window=window)
            m, u, n, label = r.metrics, r.uncertainty, r.modes, r.model
            series = (r.t, r.delta, r.f)
            validity = r.validity
        else:
            p = perturbation(sc, "hertz")
            m, u, n, label, validity = p.metrics, None, len(p.weights.s), "hertz-first-order", p.validity
            if curve and not math.isfinite(m.t_m):
                raise ImpactvalError(f"--curve: {sc.name} has no first-order answer ({validity[0]}).")
            series = perturbation_curve(sc, "hertz") if curve else None
        if model == "linear":           # (first-order answers that do not exist are shown as n/a)
            check_answer(sc.name, t_m=m.t_m, f_m=m.f_m, delta_m=m.delta_m)
        if as_json:
            finite = (lambda x: x if math.isfinite(x) else None)
            click.echo(json.dumps({"scene": sc.name, "model": label, "t_m": finite(m.t_m), "f_m": finite(m.f_m),
                                   "delta_m": finite(m.delta_m), "uncertainty": None if u is None else u.as_dict(),
                                   "modes": n, "validity": list(validity)}))
        else:
            pm = (lambda x, du, k: _pm(x * k, du * k)) if u is not None else (lambda x, du, k: _pm(x * k, 0.0))
            click.echo(f"{sc.name:24s} {pm(m.t_m, u.t_m if u else 0, 1e6):>22s} {pm(m.f_m, u.f_m if u else 0, 1):>24s} "
                       f"{pm(m.delta_m, u.delta_m if u else 0, 1e6):>22s} {n:5d}  {label}")
            for warning in validity:
                click.echo(f"  ! {warning}")
        if curve:
            with write_guard("--curve", curve):
                Path(curve).parent.mkdir(parents=True, exist_ok=True)
                np.savetxt(curve, np.column_stack(series), delimiter=",", header="t_s,delta_m,f_N", comments="")
        if explain and not as_json:
            _explain(sc, tol)


@main.command()
@click.argument("scene", nargs=-1)
@click.option("--out", "out_dir", default="theory-report", show_default=True, type=str,
              help="Directory for the markdown pages and PNG plots.")
@click.option("--tol", default=1e-6, show_default=True, type=float, help="Relative tolerance of the exact solvers.")
@click.option("--no-plot", is_flag=True, help="Skip the PNG plots (no matplotlib needed).")
def theory(scene: tuple[str, ...], out_dir: str, tol: float, no_plot: bool) -> None:
    """Compare nonlinear, linear and perturbation theory for SCENE (none = the whole catalogue): one markdown
    page per scene (metrics, model-form error of a linear contact, modes that matter, force plot) and an index."""
    import impactval
    from impactval.reports.theory import theory_index, theory_page
    from impactval.scenarios.scene import catalogue_names

    names = list(scene) or catalogue_names()
    check_output_dir(out_dir, "--out")
    check_tol(tol)
    scenes_ = load_scenes(names)
    plot = not no_plot
    if plot:
        import importlib.util

        if importlib.util.find_spec("matplotlib") is None:
            click.echo("impactval: matplotlib not installed (pip install 'impactval[plots]'): pages without plots",
                       err=True)
            plot = False
    _warn_if_compiling()
    comparisons = []
    for sc in scenes_:
        with write_guard("--out", out_dir):
            page, cmp = theory_page(sc, out_dir, tol=tol, plot=plot)
        comparisons.append(cmp)
        e = cmp.model_form_error
        check_answer(sc.name, model_form_error_t_m=e.t_m, model_form_error_f_m=e.f_m, model_form_error_delta_m=e.delta_m)
        click.echo(f"{sc.name:24s} linear-contact model-form error: t_m {100 * e.t_m:+8.3f} %  "
                   f"f_m {100 * e.f_m:+8.3f} %  delta_m {100 * e.delta_m:+8.3f} %   -> {page}")
    with write_guard("--out", out_dir):
        click.echo(f"index: {theory_index(comparisons, out_dir)}")


# ---------------------------------------------------------------------------- impactval run
def _option_value(text: str):
    """An --option value: int, float, true/false, or the string itself."""
    low = text.lower()
    if low in ("true", "false"):
        return low == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _parse_options(items: tuple[str, ...]) -> tuple[tuple[str, object], ...]:
    out = []
    for item in items:
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise ImpactvalError(f"--option takes KEY=VALUE or ENGINE.KEY=VALUE (e.g. exudyn.beam_model=reference-modes), "
                                 f"got {item!r}.")
        out.append((key.strip(), _option_value(value.strip())))
    return tuple(out)


def command_line(name: str) -> str:
    """The command line a run stores ("impactval NAME ARGS..."): NAME is the command actually running, whatever
    sys.argv holds (a test's CliRunner, `python -m impactval.cli`), so reports can say which command made a run."""
    import shlex

    args = sys.argv[1:]
    if args[:1] == [name]:
        args = args[1:]
    return f"impactval {name} " + " ".join(shlex.quote(a) for a in args)


def _parse_dts(text: str) -> list:
    """--dt: "auto" (each engine picks), or time steps [s]: a comma list of values and ``a:b:n`` log ranges
    (the one range grammar of sweep, tune and extremes, `impactval.ranges`)."""
    from impactval.ranges import parse_list

    if str(text).strip().lower() == "auto":
        return ["auto"]
    dts = parse_list(text, "--dt", unit="s", example="1e-6,5e-7 or 1e-5:1e-7:3")
    return [check_run_number("--dt", x) for x in dict.fromkeys(dts)]


def _run_settings(dt, contact, integrator, segments, timeout, tail, modes=None, options=()):
    from impactval.engines.base import EngineSettings

    return EngineSettings(dt=dt, contact=contact, integrator=integrator, segments=segments, timeout_s=timeout,
                          tail=tail, modes=modes, options=_parse_options(options))


@main.command(name="run")
@click.argument("scene", nargs=-1)
@click.option("--engines", "engines", default="mujoco", show_default=True,
              help="Comma-separated engine names (mujoco, pybullet, exudyn, mujoco-warp, newton; see `impactval "
                   "engines`) or 'package.module:Class' adapters.")
@click.option("--dt", default="auto", show_default=True,
              help="Engine time step [s], or auto (each engine picks a step under its predicted stability limit); "
                   "several, comma-separated (1e-6,5e-7,2e-7) or a log range a:b:n (1e-5:1e-7:5), sweep speed against accuracy.")
@click.option("--contact", default="hertz", show_default=True, type=click.Choice(["hertz", "native", "native-hertz"]),
              help="hertz: exact law injected; native: engine contact as the linear spring k0; "
                   "native-hertz: engine contact shaped toward Hertz.")
@click.option("--integrator", default=None, help="Engine integrator (e.g. MuJoCo: Euler, implicitfast, RK4).")
@click.option("--segments", default=None, type=click.IntRange(1, MAX_SEGMENTS),
              help=f"Beam chain segments, 1..{MAX_SEGMENTS} (default: engine's).")
@click.option("--modes", default=None, type=click.IntRange(1, MAX_ENGINE_MODES),
              help=f"Modes of a modal (FFRF) beam, 1..{MAX_ENGINE_MODES} (default: engine's).")
@click.option("--option", "options", multiple=True, metavar="[ENGINE.]KEY=VALUE",
              help="Engine-specific option, repeatable; ENGINE. limits it to one engine "
                   "(e.g. exudyn.beam_model=reference-modes, pybullet.native_route=per-body).")
@click.option("--timeout", default=600.0, show_default=True, type=float, help="Time limit per engine job [s].")
@click.option("--tail", default=0.0, show_default=True, type=float,
              help="Simulated time [s] after the first contact ends (re-contacts).")
@click.option("--tol", default=1e-6, show_default=True, type=float, help="Reference solver tolerance.")
@click.option("--tag", default=None, help="Also run the catalogue scenes carrying this tag (see `impactval scenes`).")
@click.option("--out", "out", default="impactval-results", show_default=True, type=str,
              help="Directory for the exports (results.csv, frequencies.csv, results.parquet) and report.md.")
@click.option("--store", "store", default=None, metavar="PATH|URL",
              help="Result store: an SQLite file or a database URL (postgresql://...)  [default: OUT/impactval.sqlite]")
@click.option("-j", "--jobs", "jobs", default=None, type=click.IntRange(min=1),
              help="Engine jobs run at once on this machine  [default: number of cores]")
@click.option("--scheduler", default=None, metavar="ADDR",
              help="Run the engine jobs on a Dask distributed scheduler (tcp://host:8786); needs impactval[dask].")
@click.option("--force", is_flag=True, help="Recompute jobs already in the store (default: reuse them).")
@click.option("--keep-series/--no-keep-series", default=True, show_default=True,
              help="Store each job's time series (compressed) in the store; the report draws its force curves from them.")
@click.option("--json", "as_json", is_flag=True, help="Print the rows as JSON lines (SI units, errors as fractions).")
@click.option("--baseline", default=None, type=click.Path(dir_okay=False),
              help="results.csv of an earlier run: mark rows worse (+), better (-), newly failing (!), fixed (*).")
@click.option("--threshold", default=0.2, show_default=True, type=float,
              help="Relative change of a row's largest error that counts as worse or better.")
def run_command(scene, engines, dt, contact, integrator, segments, modes, options, timeout, tail, tol, tag, out,
                store, jobs, scheduler, force, keep_series, as_json, baseline, threshold) -> None:
    """Run the reference and ENGINES on SCENE (catalogue names or TOML paths; none and no --tag = whole catalogue).

    Every job is stored in the result store as it finishes; a rerun reuses stored jobs (--force
    recomputes). Prints relative errors in % (engine - reference) / reference and wall times.
    Exit code 0; 1 when a row crashed, timed out, went unstable or found no contact, a scene's
    reference was refused (its rows are kept, uncompared), or (with --baseline) got worse; 2 bad input; 130 / 143 interrupted (Ctrl-C / SIGTERM: the finished jobs
    are stored and reported).
    """
    from impactval.progress import make_progress
    from impactval.runner import RunInterrupted, any_failed, resolve_engine, run, text_table
    from impactval.scenarios.scene import catalogue_names

    specs = [resolve_engine(e.strip()) for e in engines.split(",") if e.strip()]
    dts = _parse_dts(dt)
    check_output_dir(out, "--out")
    if store is not None and "://" not in store:
        check_output_file(store, "--store")
    check_tol(tol)
    check_run_number("--timeout", timeout)
    check_run_number("--tail", tail)
    settings = _run_settings(dts[0], contact, integrator, segments, timeout, tail, modes, options)
    names = list(scene) or ([] if tag else catalogue_names())
    import impactval
    from impactval.scenarios.scene import load_catalogue

    check_engine_steps(load_scenes(names) + (load_catalogue(tag) if tag else []), dts,
                       float(tail))
    _warn_if_compiling()
    command = command_line("run")
    try:
        df = run(names, specs, settings, dt=dts if len(dts) > 1 else None, tol=tol, out=out, store=store,
                 workers=jobs, scheduler=scheduler, force=force, progress=make_progress("auto"), tag=tag,
                 keep_series=keep_series, command=command, baseline=baseline, threshold=threshold)
    except RunInterrupted as stop:
        _print_rows(stop.rows, as_json, text_table)
        click.echo(f"impactval: {stop}; report: {Path(out) / 'report.md'}", err=True)
        sys.exit(stop.exit_code)
    _print_rows(df, as_json, text_table)
    for note in df.attrs.get("notes", []):
        click.echo(f"impactval: {note}", err=True)
    regressed = False
    if "baseline" in df.attrs:
        from impactval.history import flagged_lines, regressions, require_comparable

        cmp = df.attrs["baseline"]
        for line in flagged_lines(cmp):
            click.echo(line, err=as_json)
        click.echo(f"against {baseline}: {int((cmp['mark'] != '').sum())} of {len(cmp)} rows marked", err=as_json)
        require_comparable(cmp, df, df.attrs["baseline_rows"], baseline)   # a drifted setup is exit 2, never a pass
        regressed = regressions(cmp)
    click.echo(f"run {df.attrs['run_id']}: {len(df)} rows ({df.attrs['n_reused']} reused from the store); "
               f"results: {Path(out) / 'results.csv'}, report: {Path(out) / 'report.md'}, store: {df.attrs['store']}",
               err=as_json)
    if any_failed(df) or regressed:
        sys.exit(1)


def _print_rows(df, as_json: bool, text_table) -> None:
    """The rows as a table, or as JSON lines (NaN -> null)."""
    if not as_json:
        click.echo(text_table(df))
        return
    for rec in df.to_dict(orient="records"):
        clean = {k: (None if isinstance(v, float) and not math.isfinite(v) else
                     v.item() if hasattr(v, "item") else v) for k, v in rec.items()}
        click.echo(json.dumps(clean))


main.add_command(__import__("impactval.cli_extremes", fromlist=["extremes"]).extremes)  # issue 14
from impactval import cli_nightly as _cli_nightly  # noqa: E402 - commands in their own module
main.add_command(_cli_nightly.nightly_command)
main.add_command(_cli_nightly.report_command)

__import__("impactval.cli_tune").cli_tune.register(main)    # impactval tune, impactval materials (issue 15)

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
