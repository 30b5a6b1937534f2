"""Figures of a run report: force curves engine vs reference, and trends over the nights.

matplotlib is imported only inside the functions (the core never needs it); each function returns
the PNG path, or None when matplotlib is missing or there is nothing to draw. Colours come from
reports.style: one colour per engine everywhere.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from impactval.reports.style import LINEAR_THEORY_STYLE, REFERENCE_STYLE, REGRESSION_MARKER, engine_colour

#: trend panels: (column, y label, scale)
TREND_PANELS = (("err_t_m", "t_m error [%]", 100.0), ("err_f_m", "f_m error [%]", 100.0),
                ("err_delta_m", "delta_m error [%]", 100.0), ("wall_time_step_s", "stepping wall time [ms]", 1e3))
_DASHES = ("-", "--", ":", "-.")


def _pyplot():
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    return plt


def force_curves_plot(scene: str, reference: tuple[np.ndarray, np.ndarray] | None,
                      engines: Mapping[str, tuple[np.ndarray, np.ndarray]], path: str | Path,
                      linear: tuple[np.ndarray, np.ndarray] | None = None) -> Path | None:
    """Contact force f [N] against time [us] for one scene: the reference (black), each engine (its
    colour; keys "engine" or "engine label"), and the linear-theory curve (grey dashed) where a linear
    contact is used. `reference`, `linear`, engine values: (t [s], f [N])."""
    plt = _pyplot()
    if plt is None or (reference is None and not engines):
        return None
    diff_panel = reference is not None and bool(engines)
    if diff_panel:
        fig, (ax, dax) = plt.subplots(2, 1, figsize=(6.4, 4.8), sharex=True, gridspec_kw={"height_ratios": [2.2, 1]})
    else:
        fig, ax = plt.subplots(figsize=(6.4, 3.6))
    if reference is not None:
        ax.plot(np.asarray(reference[0]) * 1e6, reference[1], label="reference (Hertz)", **REFERENCE_STYLE)
    if linear is not None:
        ax.plot(np.asarray(linear[0]) * 1e6, linear[1], label="linear theory (k0)", **LINEAR_THEORY_STYLE)
    seen: dict[str, int] = {}
    for label, (t, f) in engines.items():
        engine = label.split()[0]
        n = seen[engine] = seen.get(engine, -1) + 1
        ax.plot(np.asarray(t) * 1e6, f, color=engine_colour(engine), lw=1.3, ls=_DASHES[n % len(_DASHES)],
                label=label, alpha=0.9)
        if diff_panel:
            # engine minus reference on the reference's grid, in % of the reference peak force
            t_ref, f_ref = np.asarray(reference[0], float), np.asarray(reference[1], float)
            peak = float(np.max(f_ref)) if f_ref.size else 0.0
            if peak > 0:
                f_on_ref = np.interp(t_ref, np.asarray(t, float), np.asarray(f, float), left=0.0, right=0.0)
                dax.plot(t_ref * 1e6, 100 * (f_on_ref - f_ref) / peak, color=engine_colour(engine), lw=1.1,
                         ls=_DASHES[n % len(_DASHES)])
    if reference is not None and len(reference[0]):
        t_ref, f_ref = np.asarray(reference[0]), np.asarray(reference[1])
        end = t_ref[f_ref > 0].max() if (f_ref > 0).any() else t_ref.max()
        ax.set_xlim(0, 1.15 * end * 1e6)
    ax.set_ylabel("contact force [N]")
    if diff_panel:
        dax.axhline(0.0, color=REFERENCE_STYLE["color"], lw=0.8)
        dax.set_ylabel("engine - ref.\n[% of ref. f_m]", fontsize=8)
        dax.set_xlabel("time [us]")
        dax.grid(True, alpha=0.3)
    else:
        ax.set_xlabel("time [us]")
    ax.set_title(scene, fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _series_label(r) -> str:
    seg = str(r["segments"]) if str(r["segments"]) not in ("", "nan") else ""
    seg = seg[:-2] if seg.endswith(".0") else seg
    try:
        dt = f"{float(r['dt']):g}"
    except (TypeError, ValueError):
        dt = str(r["dt"])
    return f"{r['engine']} {r['contact']} dt={dt}" + (f" N={seg}" if seg else "")


def trend_plot(history: pd.DataFrame, scene: str, path: str | Path) -> Path | None:
    """Errors and stepping wall time of one scene over the nights, one line per engine and settings.

    `history`: rows with run_index (0 = oldest), night (label for the x axis), KEY columns, status,
    err_t_m, err_f_m, err_delta_m, wall_time_step_s and mark (this night against the one before).
    Nights marked `+` (worse) or `!` (newly failing) get a red marker on the error panels; rows with a
    truthy `wall_mark` (a persisting wall-time step, impactval.history.wall_time_steps) on the wall-time panel."""
    plt = _pyplot()
    h = history[history["scene"] == scene] if len(history) else history
    if plt is None or not len(h):
        return None
    nights = h[["run_index", "night"]].drop_duplicates().sort_values("run_index")
    fig, axes = plt.subplots(1, len(TREND_PANELS), figsize=(3.3 * len(TREND_PANELS), 2.9), squeeze=False)
    seen: dict[str, int] = {}
    h = h.assign(_label=[_series_label(r) for _, r in h.iterrows()])
    for label, g in h.groupby("_label", sort=False):
        g = g.sort_values("run_index")
        engine = str(g["engine"].iloc[0])
        n = seen[engine] = seen.get(engine, -1) + 1
        ok = g["status"].astype(str) == "ok"
        for ax, (col, _, scale) in zip(axes[0], TREND_PANELS):
            y = pd.to_numeric(g[col], errors="coerce").where(ok) * scale
            ax.plot(g["run_index"], y, marker="o", ms=3, color=engine_colour(engine), ls=_DASHES[n % len(_DASHES)],
                    lw=1.2, label=label)
            bad = g["mark"].isin(["+", "!"]) if "mark" in g else pd.Series(False, index=g.index)
            if col == "wall_time_step_s":                      # wall time has its own (history) check
                bad = g["wall_mark"].astype(bool) if "wall_mark" in g else pd.Series(False, index=g.index)
            if bad.any():
                yb = y[bad]
                yb = yb.where(yb.notna(), np.nanmin(y) if np.isfinite(y).any() else 0.0)
                ax.scatter(g.loc[bad, "run_index"], yb, label=None, **REGRESSION_MARKER)
    for ax, (_, ylabel, _) in zip(axes[0], TREND_PANELS):
        ax.set_ylabel(ylabel, fontsize=8)
        ax.set_xticks(nights["run_index"])
        ax.set_xticklabels([str(x) for x in nights["night"]], rotation=45, ha="right", fontsize=6)
        ax.tick_params(axis="y", labelsize=7)
        ax.grid(True, alpha=0.3)
    axes[0][0].legend(fontsize=6, loc="best")
    fig.suptitle(f"{scene}: last {len(nights)} runs (red: flagged worse or newly failing)", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def finite_series(t, f) -> tuple[np.ndarray, np.ndarray] | None:
    """(t, f) as float arrays, or None when empty or not finite anywhere."""
    t, f = np.asarray(t, float), np.asarray(f, float)
    if not t.size or t.size != f.size or not np.isfinite(f).any():
        return None
    keep = np.isfinite(t) & np.isfinite(f)
    return t[keep], f[keep]


def thin(t: np.ndarray, f: np.ndarray, n: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """At most about n points of a curve (keeps the peak), for small figures and stored blobs."""
    t, f = np.asarray(t, float), np.asarray(f, float)
    if t.size <= n:
        return t, f
    step = math.ceil(t.size / n)
    idx = np.unique(np.concatenate([np.arange(0, t.size, step), [int(np.argmax(f)), t.size - 1]]))
    return t[idx], f[idx]
