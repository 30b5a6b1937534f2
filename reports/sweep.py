"""Speed against accuracy: the same jobs at several time steps (wall time vs error, per engine).

Used by `impactval run --dt a,b,c`. The score of a row is its largest |relative error| over t_m,
f_m, delta_m; wall time is the stepping time (build excluded), so the trade a user makes when
choosing dt is visible at a glance. matplotlib is imported only when a plot is drawn.
"""
from __future__ import annotations

import math
from pathlib import Path

import pandas as pd


def _score(df: pd.DataFrame) -> pd.Series:
    errs = df[["err_t_m", "err_f_m", "err_delta_m"]].apply(pd.to_numeric, errors="coerce").abs()
    return errs.max(axis=1, skipna=True)


def speed_accuracy_table(df: pd.DataFrame) -> str:
    """Markdown section: per scene and engine, each dt with its largest error [%], stepping wall
    time [ms], steps and status."""
    d = df.assign(score=_score(df), dt=pd.to_numeric(df["dt"], errors="coerce"))
    out = ["", "## Speed against accuracy", "",
           "Largest |error| of t_m, f_m, delta_m against the reference, and the stepping wall time, for each "
           "time step.", "",
           "| scene | engine | dt [s] | largest error % | step wall time [ms] | steps | status |",
           "|---|---|---:|---:|---:|---:|---|"]
    for (scene, engine), g in d.groupby(["scene", "engine"], sort=False):
        for _, r in g.sort_values("dt", ascending=False).iterrows():
            err = "" if not math.isfinite(r["score"]) else f"{100 * r['score']:.4f}"
            wall = pd.to_numeric(r["wall_time_step_s"], errors="coerce")
            wall_s = "" if not math.isfinite(wall) else f"{1e3 * wall:.1f}"
            out.append(f"| {scene} | {engine} | {r['dt']:g} | {err} | {wall_s} | {r['n_steps']} | {r['status']} |")
    return "\n".join(out) + "\n"


def speed_accuracy_plot(df: pd.DataFrame, path: str | Path) -> Path | None:
    """Log-log plot of largest error [%] against stepping wall time [s], one panel per scene, one
    line per engine (points labelled with dt). Returns the PNG path, or None without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    d = df.assign(score=_score(df), dt=pd.to_numeric(df["dt"], errors="coerce"),
                  wall=pd.to_numeric(df["wall_time_step_s"], errors="coerce"))
    d = d[(d["status"] == "ok") & (d["score"] > 0) & (d["wall"] > 0)]
    scenes = list(dict.fromkeys(d["scene"]))
    if not scenes:
        return None
    cols = min(3, len(scenes))
    rows = math.ceil(len(scenes) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.6 * rows), squeeze=False)
    for ax, scene in zip(axes.flat, scenes):
        for engine, g in d[d["scene"] == scene].groupby("engine", sort=False):
            g = g.sort_values("wall")
            ax.loglog(g["wall"], 100 * g["score"], "o-", label=engine)
            for _, r in g.iterrows():
                ax.annotate(f"{r['dt']:g}", (r["wall"], 100 * r["score"]), fontsize=7,
                            xytext=(3, 3), textcoords="offset points")
        ax.set_title(scene, fontsize=10)
        ax.set_xlabel("stepping wall time [s]")
        ax.set_ylabel("largest error [%]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    for ax in list(axes.flat)[len(scenes):]:
        ax.set_visible(False)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
