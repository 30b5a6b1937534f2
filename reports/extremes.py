"""Reports of stability maps (`impactval extremes`, issue 14): heatmaps, the safe region in words,
extremes.md.

Heatmaps: one panel per engine, a cell per grid point coloured by its status, the error contour at
--under (and 10x it) and the predicted limits drawn on top: dt = dt_limit (the adapter's explicit
stability limit, solid) and v0*dt = delta_m (tunnelling, dashed). A one-axis map is a status strip
per engine above a plot of the largest |error| along the axis, with each engine's predicted limit
as a vertical line. matplotlib is imported only when a figure is drawn.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from impactval.extremes import CellStatus, ok_ranges, onsets

#: cell status -> colour (ok green, inaccurate amber, broken reds/purples, not run greys)
STATUS_COLOURS: dict[str, str] = {
    "ok": "#1a9850", "inaccurate": "#fdae61", "unstable": "#d73027", "no-contact": "#7b3294",
    "crashed": "#000000", "timeout": "#542788", "skipped": "#bdbdbd", "not-installed": "#e0e0e0",
    "no-reference": "#f7f7f7",
}
#: engine colours: reports/style.py where that module exists (sweep/nightly branches), else these
_LOCAL_ENGINE_COLOURS = {"mujoco": "#0072B2", "pybullet": "#D55E00", "exudyn": "#009E73"}


def engine_colour(name: str, i: int = 0) -> str:
    try:
        from impactval.reports.style import ENGINE_COLOURS  # type: ignore[import-not-found]
    except ImportError:
        ENGINE_COLOURS = _LOCAL_ENGINE_COLOURS
    extra = ("#56B4E9", "#CC79A7", "#E69F00", "#8C564B")
    return ENGINE_COLOURS.get(name, extra[i % len(extra)])


def _fmt(v: Any) -> str:
    if isinstance(v, (float, np.floating)):
        return f"{v:.3g}" if math.isfinite(v) else ""
    return str(v)


def _along(g: pd.DataFrame, axis) -> pd.DataFrame:
    """Rows in the axis's order (works for mixed material names and numbers)."""
    order = {v: i for i, v in enumerate(axis.values)}
    return g.assign(_order=g[axis.name].map(order)).sort_values("_order").drop(columns="_order")


def _pos(values: list, x: float) -> float:
    """Index position of x along an axis's sorted numeric values (log-interpolated); NaN outside."""
    v = np.asarray(values, float)
    if not (math.isfinite(x) and x > 0 and np.all(v > 0)) or x < v[0] or x > v[-1]:
        return math.nan
    return float(np.interp(math.log(x), np.log(v), np.arange(len(v))))


# ---------------------------------------------------------------------------- words
def _setting(g: pd.DataFrame) -> str:
    parts = []
    integ = next((str(x) for x in g.get("integrator", []) if isinstance(x, str) and x), "")
    segs = sorted({int(x) for x in g.get("segments", []) if str(x).isdigit()})
    if integ:
        parts.append(integ)
    if segs:
        parts.append(f"N = {segs[0]}" if len(segs) == 1 else f"N = {segs[0]}..{segs[-1]}")
    return f" ({', '.join(parts)})" if parts else ""


def safe_region(df: pd.DataFrame) -> list[str]:
    """The safe region per engine in words, e.g. "mujoco (Euler, N = 40): ok for dt in [1e-7, 4e-6] s;
    first unstable at 8e-6 s (predicted 5.1e-6 s, ratio 1.57)"."""
    axes = df.attrs.get("axes", [])
    under = df.attrs.get("under", 0.01)
    lines = []
    if not axes:
        return lines
    x = axes[0] if len(axes) == 1 or axes[0].name == "dt" else axes[0]
    other = next((a for a in axes if a.name != x.name), None)
    ons = {(o.engine, o.other): o for o in onsets(df, "dt")} if any(a.name == "dt" for a in axes) else {}
    for engine, g in df.groupby("engine", sort=False):
        groups = [(None, g)] if other is None else list(g.groupby(other.name, sort=False))
        for ov, gg in groups:
            gg = _along(gg, x)
            runs = ok_ranges(list(gg[x.name]), list(gg["cell_status"]))
            ou = f" {other.unit}" if other is not None and other.unit and isinstance(ov, (int, float)) else ""
            when = "" if other is None else f" when {other.name} = {_fmt(ov)}{ou}"
            unit = f" {x.unit}" if x.unit else ""
            if runs:
                spans = ", ".join(f"{_fmt(a)}{unit}" if a == b else f"[{_fmt(a)}, {_fmt(b)}]{unit}" for a, b in runs)
                text = f"ok (all errors under {100 * under:g} %) for {x.name} in {spans}"
            else:
                counts = gg["cell_status"].value_counts()
                text = "never ok: " + ", ".join(f"{k} x{v}" for k, v in counts.items())
            o = ons.get((engine, ov if other is not None and x.name == "dt" else None))
            if x.name == "dt" and o is not None:
                if o.whole_axis:
                    text += (f"; broken over the whole axis, already at dt = {o.first_unstable:.3g} s = "
                             f"{o.ratio:.2f} x the predicted {o.predicted:.3g} s: not a time-step limit")
                elif math.isfinite(o.first_unstable):
                    pred = f"predicted {o.predicted:.3g} s, observed/predicted {o.ratio:.2f}" \
                        if math.isfinite(o.predicted) else "no predicted limit"
                    text += f"; broken from dt = {o.first_unstable:.3g} s on ({pred})"
                elif math.isfinite(o.predicted):
                    text += f"; no instability up to {max(gg[x.name]):.3g} s (predicted limit {o.predicted:.3g} s)"
            lines.append(f"{engine}{_setting(gg)}{when}: {text}.")
    return lines


# ---------------------------------------------------------------------------- figures
def _plt():
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.colors import ListedColormap
    except ImportError:
        return None, None
    return plt, ListedColormap


def heatmap(df: pd.DataFrame, path: str | Path) -> Path | None:
    """The map's figure as PNG (see the module doc); None without matplotlib or rows."""
    plt, ListedColormap = _plt()
    if plt is None or not len(df):
        return None
    axes = df.attrs["axes"]
    under = df.attrs.get("under", 0.01)
    engines = list(dict.fromkeys(df["engine"]))
    codes = {s.value: i for i, s in enumerate(CellStatus)}
    cmap = ListedColormap([STATUS_COLOURS[s.value] for s in CellStatus])
    path = Path(path)
    if len(axes) == 1:
        ax0 = axes[0]
        vals = list(ax0.values)
        fig, (top, bot) = plt.subplots(2, 1, figsize=(max(6.0, 0.55 * len(vals) + 2), 2.2 + 0.45 * len(engines) + 3.2),
                                       gridspec_kw={"height_ratios": [0.5 + 0.45 * len(engines), 3.2]})
        grid = np.full((len(engines), len(vals)), np.nan)
        for _, r in df.iterrows():
            grid[engines.index(r["engine"]), vals.index(r[ax0.name])] = codes[r["cell_status"]]
        top.imshow(grid, cmap=cmap, vmin=-0.5, vmax=len(codes) - 0.5, aspect="auto", interpolation="nearest")
        top.set_yticks(range(len(engines)), engines, fontsize=8)
        top.set_xticks(range(len(vals)), [_fmt(v) for v in vals], rotation=60, fontsize=7)
        top.set_title(f"{df.attrs.get('scene', '')}: status along {ax0.label()} "
                      f"(| = predicted dt_limit, : = v0*dt = delta_m)", fontsize=9)
        for i, e in enumerate(engines):
            g = _along(df[df["engine"] == e], ax0)
            for col, style in (("limit_ratio", "-"), ("tunnel_ratio", ":")):
                p = _crossing(list(g[ax0.name]), list(g[col]), vals) if ax0.numeric else math.nan
                if math.isfinite(p):
                    top.plot([p, p], [i - 0.5, i + 0.5], style, color="white", lw=3)
                    top.plot([p, p], [i - 0.5, i + 0.5], style, color="black", lw=1.4)
        for i, e in enumerate(engines):
            g = _along(df[df["engine"] == e], ax0)
            xs = np.arange(len(vals))
            err = pd.to_numeric(g["max_abs_err"], errors="coerce").to_numpy() if "max_abs_err" in g else np.full(len(g), np.nan)
            idx = [vals.index(v) for v in g[ax0.name]]
            bot.semilogy(xs[idx], 100 * err, "o-", color=engine_colour(e, i), label=e)
            lim = pd.to_numeric(g["dt_limit"], errors="coerce")
            if ax0.name == "dt" and lim.notna().any():
                p = _pos(vals, float(lim.median()))
                if math.isfinite(p):
                    bot.axvline(p, color=engine_colour(e, i), ls="--", lw=1)
        bot.axhline(100 * under, color="grey", ls=":", lw=1, label=f"--under {100 * under:g} %")
        bot.set_xticks(range(len(vals)), [_fmt(v) for v in vals], rotation=60, fontsize=7)
        bot.set_xlabel(ax0.label())
        bot.set_ylabel("largest |error| [%]")
        bot.grid(True, which="both", alpha=0.3)
        bot.legend(fontsize=7)
        _legend(fig, plt)
    else:
        xa, ya = axes
        xv, yv = list(xa.values), list(ya.values)
        fig, panels = plt.subplots(1, len(engines), figsize=(4.8 * len(engines), 4.6), squeeze=False)
        for ax, e in zip(panels.flat, engines):
            g = df[df["engine"] == e]
            grid = np.full((len(yv), len(xv)), np.nan)
            err = np.full_like(grid, np.nan)
            lr = np.full_like(grid, np.nan)
            tr = np.full_like(grid, np.nan)
            for _, r in g.iterrows():
                i, j = yv.index(r[ya.name]), xv.index(r[xa.name])
                grid[i, j] = codes[r["cell_status"]]
                err[i, j] = r.get("max_abs_err", np.nan)
                lr[i, j], tr[i, j] = r["limit_ratio"], r["tunnel_ratio"]
            ax.imshow(grid, cmap=cmap, vmin=-0.5, vmax=len(codes) - 0.5, origin="lower", aspect="auto",
                      interpolation="nearest")
            X, Y = np.meshgrid(np.arange(len(xv)), np.arange(len(yv)))
            with np.errstate(divide="ignore", invalid="ignore"):
                le = np.log10(err)
                if np.isfinite(le).sum() >= 4 and len(xv) > 1 and len(yv) > 1:
                    cs = ax.contour(X, Y, np.where(np.isfinite(le), le, np.nanmax(le[np.isfinite(le)])),
                                    levels=sorted({math.log10(under), math.log10(10 * under)}), colors="white",
                                    linewidths=1)
                    ax.clabel(cs, fmt={lv: f"{100 * 10**lv:g} %" for lv in cs.levels}, fontsize=7)
                for ratio, style, name in ((lr, "-", "dt_limit"), (tr, "--", "v0 dt = delta_m")):
                    lg = np.log(ratio)
                    fin = np.isfinite(lg)
                    if fin.sum() >= 4 and np.nanmin(lg) < 0 < np.nanmax(lg) and len(xv) > 1 and len(yv) > 1:
                        ax.contour(X, Y, np.where(fin, lg, 0.0), levels=[0.0], colors="black", linestyles=style,
                                   linewidths=1.6)
            ax.set_xticks(range(len(xv)), [_fmt(v) for v in xv], rotation=60, fontsize=7)
            ax.set_yticks(range(len(yv)), [_fmt(v) for v in yv], fontsize=7)
            ax.set_xlabel(xa.label())
            ax.set_ylabel(ya.label())
            ax.set_title(f"{e}  (white: |error| {100 * under:g} %, {1000 * under:g} %; black: dt_limit, "
                         f"-- tunnelling)", fontsize=8)
        _legend(fig, plt)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _crossing(xs: list, ratios: list, vals: list) -> float:
    """Index position where a ratio (dt/limit) crosses 1 along the axis (log-interpolated)."""
    r = np.asarray(ratios, float)
    for k in range(len(xs) - 1):
        a, b = r[k], r[k + 1]
        if math.isfinite(a) and math.isfinite(b) and a > 0 and b > 0 and (a - 1) * (b - 1) <= 0 and a != b:
            t = math.log(a) / (math.log(a) - math.log(b))
            i0, i1 = vals.index(xs[k]), vals.index(xs[k + 1])
            return i0 + t * (i1 - i0)
    return math.nan


def _legend(fig, plt) -> None:
    from matplotlib.patches import Patch

    handles = [Patch(color=STATUS_COLOURS[s.value], label=s.value) for s in CellStatus]
    fig.legend(handles=handles, loc="lower center", ncol=5, fontsize=7, frameon=False)


# ---------------------------------------------------------------------------- extremes.md
def _pct(x: Any) -> str:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return ""
    return f"{100 * x:+.3g}" if math.isfinite(x) else ""


def _axis_value(axis, v: Any) -> str:
    """`velocity = 100 m/s`, `stiffness = steel`."""
    unit = f" {axis.unit}" if axis.unit and isinstance(v, (int, float, np.number)) else ""
    return f"{axis.name} = {_fmt(v)}{unit}"


def _validity_by_cell(df: pd.DataFrame, axes) -> list[str]:
    """The reference's warnings (`ref_validity`), each once, prefixed with the cells it belongs to: their values on
    the axes that change the scene (every axis but dt), e.g. "velocity = 100 m/s: Hertz: ..."; with no such axis,
    the scene's name. In the axes' order."""
    if "ref_validity" not in df:
        return []
    scene_axes = [a for a in axes if a.name != "dt" and a.name in df]
    where: dict[str, list[tuple]] = {}
    for _, r in df.iterrows():
        w = r["ref_validity"]
        if not isinstance(w, str) or not w:
            continue
        coords = tuple(r[a.name] for a in scene_axes) if scene_axes else (r.get("scene", ""),)
        if coords not in where.setdefault(w, []):
            where[w].append(coords)

    def rank(coords: tuple) -> tuple:
        if not scene_axes:
            return ()
        return tuple(list(a.values).index(v) if v in a.values else len(a.values) for a, v in zip(scene_axes, coords))

    out = []
    for w, cells in sorted(where.items(), key=lambda kv: (min(rank(c) for c in kv[1]), kv[0])):
        cells = sorted(cells, key=rank)
        if scene_axes:
            label = "; ".join(", ".join(_axis_value(a, v) for a, v in zip(scene_axes, c)) for c in cells)
        else:
            label = ", ".join(str(c[0]) for c in cells)
        out.append(f"{label}: {w}")
    return out


def markdown(df: pd.DataFrame, png: str | None = None, predict: pd.DataFrame | None = None) -> str:
    """extremes.md: the safe region in words, the dt onsets against the predictions, the figure, the
    cell table and the predictability check."""
    axes = df.attrs.get("axes", [])
    under = df.attrs.get("under", 0.01)
    out = [f"# Stability map: {df.attrs.get('scene', '')}", "",
           f"Axes: {', '.join(a.label() for a in axes)}; engines: {', '.join(df.attrs.get('engines', []))}; a cell is "
           f"ok when every |error| of t_m, f_m, delta_m is under {100 * under:g} %. Explicit time steps are run "
           f"past the predicted limit (impactval.unguarded) so the map shows what really happens there.", "",
           "## Safe region", ""]
    out += [f"- {line}" for line in safe_region(df)] or ["- (no rows)"]
    if any(a.name == "dt" for a in axes):
        out += ["", "## First unstable dt against the prediction", "",
                "Observed: the smallest grid dt from which every larger dt is broken (unstable, no-contact, crashed, "
                "timeout); it lies within one grid step above the true onset. Predicted: the adapter's dt_limit.", "",
                "| engine | other axis | largest ok dt [s] | first unstable dt [s] | predicted dt_limit [s] | "
                "observed / predicted | predicted for |", "|---|---|---:|---:|---:|---:|---|"]
        for o in onsets(df, "dt"):
            r = ("<= " if o.whole_axis else "") + f"{o.ratio:.2f}" if math.isfinite(o.ratio) else ""
            out.append(f"| {o.engine} | {'' if o.other is None else _fmt(o.other)} | {_fmt(o.largest_ok)} | "
                       f"{_fmt(o.first_unstable)} | {_fmt(o.predicted)} | {r} | {o.what} |")
    if png:
        out += ["", f"![stability map]({png})"]
    out += ["", "## Cells", "",
            "Errors are signed relative (engine - reference) / reference in %; dt/limit = dt / predicted dt_limit; "
            "dt/tunnel = v0 dt / delta_m.", "",
            "| engine | " + " | ".join(a.name for a in axes) + " | status | t_m % | f_m % | delta_m % | dt [s] | "
            "dt/limit | dt/tunnel | ref unc. | message |",
            "|---|" + "---:|" * len(axes) + "---|" + "---:|" * 7 + "---|"]
    for _, r in df.iterrows():
        msg = str(r.get("message", "") or "")
        msg = (msg[:140] + "...") if len(msg) > 143 else msg
        unc = r.get("ref_uncertainty", math.nan)
        out.append(f"| {r['engine']} | " + " | ".join(_fmt(r[a.name]) for a in axes) + f" | {r['cell_status']} | "
                   f"{_pct(r.get('err_t_m'))} | {_pct(r.get('err_f_m'))} | {_pct(r.get('err_delta_m'))} | "
                   f"{_fmt(r.get('dt'))} | {_fmt(r.get('limit_ratio'))} | {_fmt(r.get('tunnel_ratio'))} | "
                   f"{'' if not isinstance(unc, float) or not math.isfinite(unc) else f'{unc:.1e}'} | "
                   f"{msg.replace('|', '/')} |")
    warn = _validity_by_cell(df, axes)
    tol = df.attrs.get("tol")
    if tol and "ref_uncertainty" in df:
        unc = pd.to_numeric(df.drop_duplicates("scene")["ref_uncertainty"], errors="coerce")
        loose = df.drop_duplicates("scene")[unc > max(tol, 0.1 * under)]
        for _, r in loose.iterrows():
            warn.append(f"{r['scene']}: reference uncertainty {r['ref_uncertainty']:.2g} (relative) is above "
                        f"max(tol, --under / 10) = {max(tol, 0.1 * under):.2g}: its cells are not judged reliably")
    if warn:
        out += ["", "## Where the reference's assumptions fail", ""] + [f"- {w}" for w in warn]
    if predict is not None and len(predict):
        out += ["", "## Predictability (Chung and Pollard 2016)", "",
                "Each setting is rerun with v0 x (1 + 1e-6) and, on a beam, the impact point moved by a fraction of a "
                "segment; a jump is a contact event gained or lost, a status change, or a metric whose change "
                "differs from the reference's by more than the jump threshold.", "",
                "| engine | dt [s] | perturbation | status | contacts | jumped | why |", "|---|---:|---|---|---|---|---|"]
        for _, r in predict.iterrows():
            out.append(f"| {r['engine']} | {r['dt']:.3g} | {r['perturbation']} | {r['status']} -> {r['status_perturbed']}"
                       f" | {r['n_contacts']} -> {r['n_contacts_perturbed']} | {'**yes**' if r['jumped'] else 'no'} | "
                       f"{r['why']} |")
    return "\n".join(out) + "\n"


def write(df: pd.DataFrame, out: str | Path, predict: pd.DataFrame | None = None) -> Path:
    """extremes.md, extremes.png and extremes.csv in `out`; returns the markdown path."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    png = heatmap(df, out / "extremes.png")
    df.to_csv(out / "extremes.csv", index=False)
    if predict is not None:
        predict.to_csv(out / "predictability.csv", index=False)
    md = out / "extremes.md"
    md.write_text(markdown(df, png.name if png else None, predict))
    return md
