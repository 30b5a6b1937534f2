"""Assemble a run's report from the result store: report.md, figures, report.html (issue 16).

`write_report(store, run_id, out)` is what `impactval run`, `impactval nightly` and `impactval report`
share: it reads the run's rows and facts from the store, solves each scene's reference again (the
same solver and tolerance give the same curve; a scene whose hash changed since is said so and not
drawn), draws the force curves (reference, each engine from its stored series, the linear-theory
curve where a linear contact was used), adds the trend plots and comparison given by the caller,
and writes the markdown and the self-contained HTML page side by side.
"""
from __future__ import annotations

import math
import re
from pathlib import Path
from collections.abc import Mapping
from typing import Any

import pandas as pd

from impactval.errors import ImpactvalError


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", str(name))


def _label(r, several: bool) -> str:
    if not several:
        return str(r["engine"])
    seg = str(r["segments"])
    seg = seg[:-2] if seg.endswith(".0") else seg
    from impactval.reports.run_report import _dt

    return f"{r['engine']} {r['contact']} dt={_dt(r['dt'])}" + (f" N={seg}" if seg not in ("", "nan") else "")


def scenes_from_command(command: str) -> dict[str, Any]:
    """Scene files (*.toml) named in a stored run's command line that load here, by scene name: a re-rendered
    report of a run of scene files gets its references back (scene_figures checks each one's hash against the
    rows', so an edited file is reported as changed, not used)."""
    import shlex

    import impactval

    try:
        tokens = shlex.split(command)
    except ValueError:
        return {}
    out = {}
    for tok in tokens:
        if tok.endswith(".toml") and Path(tok).is_file():
            try:
                scene = impactval.load_scene(tok)
            except ImpactvalError:
                continue
            out.setdefault(scene.name, scene)
    return out


def scene_figures(store, rows: pd.DataFrame, out: Path, tol: float = 1e-6, plots: bool = True,
                  scenes: Mapping[str, Any] | None = None, references: Mapping[str, Any] | None = None
                  ) -> tuple[list[tuple[str, str]], pd.DataFrame, list[str]]:
    """Force-curve figures (caption, file name), the reference table (reports.provenance records)
    and notes, for every scene of `rows`. `scenes`: the run's Scene objects by name (scene files given as
    paths are not in the catalogue); a scene not there is looked up in the catalogue. `references`: the
    references the run already solved at `tol` (ImpactResult by scene name; a failed one holds the
    refusal), used instead of solving again (a refused scene's refusal can take tens of seconds)."""
    import impactval
    from impactval.reports.plots import finite_series, force_curves_plot, thin
    from impactval.reports.provenance import reference_record
    from impactval.runner import scene_hash

    figures, refs, notes = [], [], []
    for name in dict.fromkeys(rows["scene"]):
        g = rows[rows["scene"] == name]
        try:
            scene = (scenes or {}).get(name) or impactval.load_scene(name)
        except ImpactvalError:
            notes.append(f"{name}: not in the catalogue here, and no scene file of that name on the run's command line "
                         f"is found from here (the store keeps no scene definitions; re-render from the directory the "
                         f"run started in); no reference curve or provenance")
            continue
        if str(g["scene_hash"].iloc[0]) != scene_hash(scene):
            notes.append(f"{name}: the scene or reference changed since this run (scene hash "
                         f"{g['scene_hash'].iloc[0]} -> {scene_hash(scene)}); reference values and curve not redrawn")
            continue
        ref = (references or {}).get(name)
        if ref is not None and not ref.success:     # refused in the run (its rows are uncompared)
            notes.append(f"{name}: no reference at tol {tol:g}: {ref.message}")
            continue
        if ref is None and (g["status"].astype(str) == "interrupted").all():
            # no job of the scene ran (an interrupted run): solving its reference now would hold up a report written
            # after Ctrl-C for as long as the solve takes
            notes.append(f"{name}: no job of this scene ran (interrupted); its reference was not solved")
            continue
        if ref is None:
            try:
                ref = impactval.solve(scene, tol=tol)
            except ImpactvalError as exc:       # refused (its rows are uncompared, see compare.NO_REFERENCE)
                notes.append(f"{name}: no reference at tol {tol:g}: {exc}")
                continue
        moved = _reference_moved(g, ref)
        if moved:
            notes.append(f"{name}: the reference's values moved since this run ({moved}, relative): the rows' errors "
                         f"are against the run's reference, the reference values and curve shown are today's")
        refs.append(reference_record(scene, ref))
        if not plots:
            continue
        ok = g[g["status"].astype(str) == "ok"]
        several = ok.duplicated(["engine"]).any()
        curves, linear = {}, None
        for _, r in ok.iterrows():
            series = store.load_series(str(r["job_key"])) if str(r.get("job_key", "")) else None
            s = finite_series(series["t"], series["f"]) if series else None
            if s is not None:
                curves[_label(r, several)] = thin(*s)
            k = pd.to_numeric(pd.Series([r.get("contact_stiffness")]), errors="coerce").iloc[0]
            law = str(r.get("contact_law", "") or "")
            is_linear = law == "linear" or (not law and str(r["contact"]) == "native")   # older adapters: no law
            if linear is None and is_linear and math.isfinite(k) and k > 0:
                from impactval.reference.linear import solve_linear

                lin = solve_linear(scene, tol=tol, stiffness=float(k))
                linear = thin(lin.t, lin.f)
        if not curves and len(ok):
            notes.append(f"{name}: no engine series stored for this run (run with --keep-series to draw them)")
        path = force_curves_plot(name, thin(ref.t, ref.f), curves, out / f"curves_{_safe(name)}.png", linear=linear)
        if path is not None:
            figures.append((f"{name}: contact force, engines against the reference"
                            + (" and the linear theory (k0 of the engine's contact)" if linear is not None else ""),
                            path.name))
    return figures, pd.DataFrame(refs), notes


def _reference_moved(rows: pd.DataFrame, ref) -> str:
    """`history.reference_moved` between the reference values stored on a scene's rows (the first row that has them)
    and the reference `ref` solved now: "" when they agree (or no row has them)."""
    from impactval.history import REFERENCE_COLUMNS, reference_moved

    cols = list(REFERENCE_COLUMNS.values())
    if not set(cols) <= set(rows.columns):
        return ""
    have = rows[pd.to_numeric(rows["ref_t_m"], errors="coerce").notna()]
    if not len(have):
        return ""
    now = {col: float(getattr(ref, m)) for m, col in REFERENCE_COLUMNS.items()}
    return reference_moved(have.iloc[0], now)


def run_info(store, run_id: str, title: str | None = None) -> dict[str, Any]:
    """Header facts of a run from the store; `title` defaults to the command that made the run ("impactval sweep"
    for a sweep's store: a re-rendered sweep was titled "impactval run")."""
    info = store.run_info(run_id)
    words = str(info.get("command") or "").split()
    title = title or (f"impactval {words[1]}" if len(words) > 1 and words[0] == "impactval" else "impactval run")
    versions = {"impactval": info.get("impactval_version", ""), "reference": info.get("reference_version", "")}
    versions.update({k: v for k, v in (info.get("engines") or {}).items()})
    return {"title": title, "run_id": run_id, "command": f"`{info.get('command', '')}`" if info.get("command") else "",
            "started": info.get("started_at", ""), "finished": info.get("ended_at") or "not finished",
            "ended": info.get("status", ""), "versions": versions,
            "machine": f"{info.get('machine', '')}, Python {info.get('python', '')}"}


def run_verdict(rows: pd.DataFrame, cmp: pd.DataFrame | None, ended: str, command: str = "") -> str:
    """The verdict line of an `impactval run` report, the exit code the command gives for these rows: 1 when a row
    failed (`runner.failed_rows`) or the baseline comparison `cmp` has a worse or newly failing row, 2 when nothing
    was comparable with the baseline, else 0; "none" for a run that did not finish (it exits 130 / 143)."""
    from impactval.history import comparable, regressions
    from impactval.runner import failed_rows

    if ended and ended != "finished":
        return f"none: the run is {ended} (rerun its command to resume it; the rows below are those that finished)"
    n = len(rows)
    bad = failed_rows(rows) if n else pd.Series([], dtype=bool)
    parts = []
    if bad.any():
        counts = rows[bad]["status"].astype(str).value_counts()
        parts.append(f"{int(bad.sum())} of {n} rows failed ({', '.join(f'{k} {v}' for k, v in counts.items())})")
    if cmp is not None and len(cmp):
        if comparable(cmp) == 0:
            return "exit 2: nothing was comparable with the baseline (see Against the baseline)"
        marks = cmp["mark"].astype(str)
        worse, newly = int((marks == "+").sum()), int((marks == "!").sum())
        if worse or newly:
            parts.append(f"against the baseline {worse} worse, {newly} newly failing")
    code = 1 if bad.any() or (cmp is not None and len(cmp) and regressions(cmp)) else 0
    if not parts:
        counts = rows["status"].astype(str).value_counts() if n else {}
        parts.append(f"no row failed ({', '.join(f'{k} {v}' for k, v in counts.items()) or 'no rows'})")
    again = ("; its --baseline comparison is not re-done in a re-rendered report"
             if cmp is None and "--baseline" in command else "")
    return f"exit {code}: " + "; ".join(parts) + again


def write_report(store, run_id: str, out: str | Path, *, title: str | None = None, rows: pd.DataFrame | None = None,
                 cmp: pd.DataFrame | None = None, baseline: str | None = None, checks=None,
                 history: pd.DataFrame | None = None, trend: pd.DataFrame | None = None, settings=None,
                 tol: float = 1e-6, extra_info: dict[str, Any] | None = None, extra_md: str = "",
                 html: bool = True, plots: bool = True, scenes: Mapping[str, Any] | None = None,
                 references: Mapping[str, Any] | None = None) -> tuple[Path, Path | None]:
    """Write out/report.md (+ PNG figures) and out/report.html for run `run_id` of `store`.

    `history`: rows of the last nights (run_index, night, mark, ...) for the trend plots; `trend`:
    impactval.history.wall_time_steps; `cmp`, `baseline`, `checks`: the comparison; `references`: the references the
    run already solved at `tol`, by scene name (not solved again; see `scene_figures`). Returns the paths."""
    import importlib.util

    from impactval.reports.html import write_html
    from impactval.reports.run_report import markdown_report

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = store.rows(run_id=run_id) if rows is None else rows
    plots = plots and importlib.util.find_spec("matplotlib") is not None
    if scenes is None:          # a re-render: the scene files named on the run's command line, where still found
        scenes = scenes_from_command(str(store.run_info(run_id).get("command") or ""))
    figures, refs, notes = scene_figures(store, rows, out, tol=tol, plots=plots, scenes=scenes,
                                         references=references)
    if plots and history is not None and len(history) and history["run_index"].nunique() > 1:
        from impactval.history import row_key
        from impactval.reports.plots import trend_plot

        slow = set() if trend is None or not len(trend) else {
            row_key(r) for _, r in trend[trend["state"] == "slower"].iterrows()}
        last = history["run_index"].max()
        history = history.assign(wall_mark=[bool(slow) and ri == last and row_key(r) in slow
                                            for ri, (_, r) in zip(history["run_index"], history.iterrows())])

        for name in dict.fromkeys(rows["scene"]):
            p = trend_plot(history, name, out / f"trend_{_safe(name)}.png")
            if p is not None:
                figures.append((f"{name}: errors and stepping wall time over the last "
                                f"{history['run_index'].nunique()} runs", p.name))
    info = run_info(store, run_id, title)
    info.update(extra_info or {})
    if "verdict" not in info and str(info.get("title", "")).startswith("impactval run"):
        info["verdict"] = run_verdict(rows, cmp, str(info.get("ended", "")), str(info.get("command", "")))
    md = markdown_report(rows, settings, info=info, cmp=cmp, baseline=baseline, checks=checks, trend=trend,
                         references=refs, figures=sorted(figures, key=lambda f: f[1].startswith("trend_")))
    if notes:
        md += "\n## Notes\n\n" + "\n".join(f"- {n}" for n in notes) + "\n"
    md += extra_md
    if not plots:
        md += "\n*Figures left out: matplotlib is not installed (pip install 'impactval[plots]').*\n"
    report = out / "report.md"
    report.write_text(md)
    page = write_html(report) if html else None
    return report, page
