"""Speed against accuracy, presented: sweep.md and plots (PNG + SVG) of a sweep's rows.

`impactval sweep` writes `sweep_markdown` and the two plots; `impactval run --dt a,b,c` uses
`speed_accuracy_table` and `speed_accuracy_plot`. The numbers come from the pure functions of
`impactval.sweep`; this module only presents them. matplotlib is imported only when a plot is drawn.
Colours: one per engine everywhere (reports/style.py).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from impactval import sweep as sw
from impactval.reports.style import engine_colour

#: marker per integrator position within an engine (the engine is the colour)
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
#: line style per structure size position
LINESTYLES = ("-", "--", ":", "-.")


# ---------------------------------------------------------------------------- text helpers
def _pct(x, digits: int = 3) -> str:
    x = pd.to_numeric(x, errors="coerce")
    return "" if not (isinstance(x, (int, float)) and math.isfinite(x)) else f"{100 * x:.{digits}g}"


def _g(x, fmt: str = "{:.3g}") -> str:
    x = pd.to_numeric(x, errors="coerce")
    return "" if not (isinstance(x, (int, float)) and math.isfinite(x)) else fmt.format(x)


def _ms(x) -> str:
    x = pd.to_numeric(x, errors="coerce")
    return "" if not (isinstance(x, (int, float)) and math.isfinite(x)) else f"{1e3 * x:.3g}"


def _n(seg) -> str:
    seg = "" if seg is None or (isinstance(seg, float) and math.isnan(seg)) else str(seg)
    return seg.removesuffix(".0") or "default"


def _table(header: list[str], rows: list[list[str]], right_from: int = 99) -> list[str]:
    out = ["| " + " | ".join(header) + " |",
           "|" + "|".join("---:" if i >= right_from else "---" for i in range(len(header))) + "|"]
    out += ["| " + " | ".join(str(c).replace("|", "\\|") for c in r) + " |" for r in rows]
    return out


def _label(integrator: str, segments) -> str:
    seg = str(segments).removesuffix(".0") if segments == segments and segments not in (None, "") else ""
    return f"{integrator} N={seg}" if seg else str(integrator)


def _setting(r) -> str:
    seg = str(r["segments"] if r["segments"] == r["segments"] else "").removesuffix(".0")
    return f"{r['integrator']}, dt = {_g(r['dt'])} s" + (f", N = {seg}" if seg else "")


# ---------------------------------------------------------------------------- sweep.md
#: a floor's cause in words when several structure sizes share it (details in the Floors table)
_FLOOR_WORDS = {
    "structure discretisation": "structure discretisation: the error follows the segment count, not dt "
                                "(details in the Floors table)",
    "reference": "the reference's own tolerance: tighten --tol",
    "float precision": "float precision (roundoff)",
    "contact law": "contact law: the native contact is a linear spring, the reference is Hertz",
}
def cell_counts(df: pd.DataFrame) -> str:
    """How the cells ended, in words (sweep.md's first line and the sweep's last line on stderr): cells refused
    before stepping (dt above the predicted limit, never stepped) are counted apart from cells that were stepped
    and went unstable, since only the latter observed a blow-up."""
    n = sw.status_counts(df)
    return (f"{n['cells']} cells: {n['ok']} ok, {n['refused']} refused before stepping (dt above the predicted "
            f"stability limit), {n['unstable_stepped']} unstable when stepped, {n['failed']} failed otherwise, "
            f"{n['skipped']} skipped")


def sweep_markdown(df: pd.DataFrame, unders: list[float], scene_kinds: dict[str, str] | None = None,
                   plots: list[Path] | None = None, tol: float | None = None) -> str:
    """The sweep report: per scene and engine what a person reads in a minute (cheapest setting under
    each X, order, floor and cause, stability limit), then the plots and the full tables."""
    d = sw.pareto_front(df)
    orders = sw.fit_orders(df, scene_kinds)
    floors = sw.floors(df, scene_kinds)
    stab = sw.stability(df)
    cheap = sw.cheapest(df, unders)
    why: list[str] = []          # explanations of the orders, numbered once for the whole report
    out = ["# impactval sweep", "",
           f"{cell_counts(d)}. "
           f"Error = largest |relative error| of t_m, f_m, delta_m against the reference"
           f"{f' (tol {tol:g})' if tol else ''}; cost = stepping wall time (build excluded) as steps x the median "
           f"time per step of the same engine, integrator and N in this sweep (one cell's timing is noisy on a "
           f"shared machine; the measured time of each cell is in the last table): compare costs within one "
           f"sweep, not across machines.", ""]
    out += ["## In a minute", ""]
    for (scene, engine), g in d.groupby(["scene", "engine"], sort=False):
        out.append(f"### {scene} / {engine}")
        out.append("")
        for _, c in cheap[(cheap["scene"] == scene) & (cheap["engine"] == engine)].iterrows():
            if c["found"]:
                out.append(f"- **Cheapest under {_pct(c['under'])} %**: {_setting(c)}: {_ms(c['cost_s'])} ms "
                           f"of stepping, largest error {_pct(c['score'])} %.")
            elif math.isfinite(c["best_score"]):
                out.append(f"- **Under {_pct(c['under'])} %: none in this grid** (best reached "
                           f"{_pct(c['best_score'])} % with {_setting(c)}).")
            else:
                out.append(f"- **Under {_pct(c['under'])} %: none in this grid** (no cell has a result: see the "
                           f"cells' status and message).")
        o = orders[(orders["scene"] == scene) & (orders["engine"] == engine)]
        for integ, og in o.groupby("integrator", sort=False):
            out.append(f"- **Order in dt**, {integ}: {_orders_sentence(og, why)}")
        f = floors[(floors["scene"] == scene) & (floors["engine"] == engine)]
        for (integ, kind), fg in f.groupby(["integrator", "cause_kind"], sort=False):
            if kind == "no floor":
                sizes = ", ".join(f"{_pct(r['floor'])} % at {_g(r['dt_finest'])} s" for _, r in fg.iterrows())
                out.append(f"- **Floor**, {integ}: not reached in this grid ({sizes}; still falling: refine dt).")
                continue
            if kind == "one stable step":
                sizes = ", ".join((f"N = {r['segments']}: " if r["segments"] else "") +
                                  f"{_pct(r['floor'])} % at {_g(r['dt_finest'])} s" for _, r in fg.iterrows())
                out.append(f"- **Floor**, {integ}: not known ({sizes}): one stable step in this grid cannot show a "
                           f"trend in dt; step at least two stable dt (below the stability limit) to find a floor.")
                continue
            sizes = ", ".join((f"N = {r['segments']}: " if r["segments"] else "") +
                              (f"{_pct(r['floor'])} % from dt <= {_g(r['dt_floor'])} s" if r["reached"] else
                               f"{_pct(r['floor'])} % at {_g(r['dt_finest'])} s") for _, r in fg.iterrows())
            detail = fg["cause"].iloc[0] if len(fg) == 1 else _FLOOR_WORDS.get(kind, fg["cause"].iloc[0])
            if len(fg) > 1 and fg["cause"].str.contains("own model-error estimate").all():
                detail = ("structure discretisation: each floor matches the engine's own model-error estimate "
                          "for its N (Floors table)")
            out.append(f"- **Floor**, {integ} ({sizes}): {detail}.")
        s = stab[(stab["scene"] == scene) & (stab["engine"] == engine)]
        out.append(f"- **Stability**: {_stability_summary(s)}")
        out.append("")
    if why:
        out += ["Why these orders:", ""] + [f"{k + 1}. {text}" for k, text in enumerate(why)] + [""]
    if plots:
        out += ["## Plots", ""] + [f"![{p.stem}]({p.name})" for p in plots] + [""]
    out += ["## Cheapest setting under each tolerance", ""]
    out += _table(["scene", "engine", "under %", "setting", "cost ms", "largest error %", "best in grid %"],
                  [[c["scene"], c["engine"], _pct(c["under"]), _setting(c) if c["found"] else "none in this grid",
                    _ms(c["cost_s"]) if c["found"] else "", _pct(c["score"]), _pct(c["best_score"])]
                   for _, c in cheap.iterrows()], right_from=4)
    out += ["", "## Orders of convergence in dt", "",
            "Fitted on differences of successive steps of the same model (so a structure or contact-law floor "
            "cancels), over the widest dt range where one power law holds (points within "
            f"{sw.ORDER_RESIDUAL_FACTOR:g}x, local slopes within {sw.ORDER_SLOPE_SPREAD:g}); where none does, a "
            "least-squares envelope with its scatter.", ""]
    out += _table(["scene", "engine", "integrator", "N", "metric", "order", "nominal", "dt range [s]", "scatter",
                   "why"],
                  [[r["scene"], r["engine"], r["integrator"], _n(r["segments"]), r["metric"], _g(r["order"], "{:.2f}"),
                    _g(r["nominal_order"], "{:g}"),
                    f"{_g(r['dt_min'])} - {_g(r['dt_max'])}" if math.isfinite(r["order"]) else "",
                    _g(r["scatter"], "{:.2f}") + ("" if r["clean"] else " (envelope)"), r["explanation"]]
                   for _, r in orders.iterrows()])
    out += ["", "## Floors (where refining dt stops helping)", ""]
    out += _table(["scene", "engine", "integrator", "N", "floor %", "from dt [s]", "reached", "cause"],
                  [[r["scene"], r["engine"], r["integrator"], r["segments"], _pct(r["floor"]), _g(r["dt_floor"]),
                    "yes" if r["reached"] else "no", r["cause"]] for _, r in floors.iterrows()])
    out += ["", "## Stability limits (observed in stepped cells vs predicted by the engine model)", "",
            "A cell whose dt is above the engine's predicted explicit limit is refused before stepping (status "
            "unstable, 0 steps, message \"refused before stepping\"): it is not an observation, so only stepped cells "
            "bracket the real limit and test the prediction.", ""]
    out += _table(["scene", "engine", "integrator", "N", "largest stable dt [s]", "smallest unstable dt, stepped [s]",
                   "refused above the predicted limit (not stepped), from dt [s]", "predicted limit [s]",
                   "prediction", "failed cells"],
                  [[r["scene"], r["engine"], r["integrator"], _n(r["segments"]), _g(r["dt_stable_max"]),
                    _g(r["dt_unstable_stepped"]) or "none", _g(r["dt_refused_min"]) or "none",
                    _g(r["dt_limit_predicted"]) or "n/a", _prediction_verdict(r),
                    str(r["n_failed"]) + (f" ({r['n_refused']} refused)" if r["n_refused"] else "")]
                   for _, r in stab.iterrows()])
    out += ["", f"## Pareto front (each cell more than {100 * sw.FRONT_GAIN:g} % more accurate than every cheaper one)",
            ""]
    front = d[d["on_front"]].sort_values(["scene", "engine", "cost_s"])
    out += _table(["scene", "engine", "setting", "cost ms", "largest error %"],
                  [[r["scene"], r["engine"], _setting(r), _ms(r["cost_s"]), _pct(r["score"])]
                   for _, r in front.iterrows()], right_from=3)
    out += ["", "## All cells", ""]
    rows = []
    for _, r in d.sort_values(["scene", "engine", "integrator", "segments", "dt"],
                              ascending=[True, True, True, True, False]).iterrows():
        rows.append([r["scene"], r["engine"], r["integrator"], _n(r["segments"]), _g(r["dt"]), str(r["status"]),
                     _pct(r["err_t_m"], 4), _pct(r["err_f_m"], 4), _pct(r["err_delta_m"], 4), _pct(r["score"], 4),
                     _ms(r["cost_s"]), _ms(r["step_time_s"]), _g(r["n_steps"], "{:.0f}"), _g(r.get("steps_per_s"), "{:.3g}"),
                     _pct(r.get("model_error")), _g(r.get("dt_limit")), "*" if r["on_front"] else "",
                     "" if str(r["status"]) == "ok" else str(r["message"])[:120]])
    out += _table(["scene", "engine", "integrator", "N", "dt [s]", "status", "t_m %", "f_m %", "delta_m %",
                   "largest %", "cost ms", "measured ms", "steps", "steps/s", "model error %", "dt limit [s]", "front",
                   "message"], rows)
    return "\n".join(out) + "\n"


def nothing_finished_markdown(n_cells: int, why: str = "", command: str = "") -> str:
    """sweep.md of a sweep stopped before any cell finished: nothing to analyse, and how to go on."""
    out = ["# impactval sweep", "",
           f"**No cell finished**: the sweep was interrupted before any of its {n_cells} cells was stored"
           + (f" ({why})" if why else "") + ", so there is no result to analyse: no cheapest setting, order, "
           "floor or stability limit.", "",
           "Rerun the same command to run them: cells are stored as they finish, so a rerun runs only the ones "
           "missing, and an interrupted run's report covers the cells that finished."]
    if command:
        out += ["", f"Command: `{command}`"]
    return "\n".join(out) + "\n"


def _orders_sentence(og: pd.DataFrame, why: list[str]) -> str:
    """'2.03 (t_m, f_m, delta_m; N = 21, 41; nominal 1) [1]': metrics and sizes of one integrator
    with the same explanation merged; explanations go to `why` and are cited by number."""
    parts = []
    fitted = og[og["order"].notna()]
    for text, wg in fitted.groupby("explanation", sort=False):
        if text not in why:
            why.append(text)
        lo, hi = wg["order"].min(), wg["order"].max()
        val = f"{lo:.2f}" if hi - lo < 0.05 else f"{lo:.2f}-{hi:.2f}"
        mets = ", ".join(dict.fromkeys(wg["metric"]))
        sizes = ", ".join(_n(x) for x in dict.fromkeys(wg["segments"]))
        nominal = wg["nominal_order"].iloc[0]
        nom = f"; nominal {nominal:g}" if math.isfinite(nominal) else ""
        spread = pd.to_numeric(wg["slope_spread"], errors="coerce") if "slope_spread" in wg else pd.Series(dtype=float)
        env = ("" if wg["clean"].all() else
               ", envelope, no clean order" if (spread > sw.ORDER_SLOPE_SCATTER_NONE).any() else ", envelope")
        parts.append(f"**{val}** ({mets}; N = {sizes}{nom}{env}) [{why.index(text) + 1}]")
    for text, mg in og[og["order"].isna()].groupby("explanation", sort=False):
        if text not in why:
            why.append(text)
        parts.append(f"none for {', '.join(dict.fromkeys(mg['metric']))} [{why.index(text) + 1}]")
    return "; ".join(parts) + "."


def _series_name(r) -> str:
    seg = str(r["segments"]).removesuffix(".0") if r["segments"] == r["segments"] else ""
    return f"{r['integrator']}" + (f" N = {seg}" if seg else "")


def _stability_summary(s: pd.DataFrame) -> str:
    """One line: each series that went unstable when stepped or had cells refused above its predicted limit
    (with the predicted limit and, for stepped cells only, whether it brackets the observation), then the rest
    in one phrase, flagging predictions the grid contradicts."""
    bits = []
    for _, r in s[s["dt_unstable_stepped"].notna()].iterrows():
        bits.append(f"{_series_name(r)}: {_stability_sentence(r)}")
    refused_only = s[s["dt_unstable_stepped"].isna() & s["dt_refused_min"].notna()]
    if len(refused_only) == 1:
        r = refused_only.iloc[0]
        bits.append(f"{_series_name(r)}: {_stability_sentence(r)}")
    elif len(refused_only):
        each = ", ".join(f"{_series_name(r)} ({_stable_text(r['dt_stable_max'])}, predicted limit "
                         f"{_g(r['dt_limit_predicted'])} s, refused from {_g(r['dt_refused_min'])} s)"
                         for _, r in refused_only.iterrows())
        bits.append(f"{each}: every dt above a predicted limit was refused above the predicted limit (not "
                    f"stepped) and no stepped cell went unstable, so this grid does not observe these limits")
    rest = s[s["dt_unstable_stepped"].isna() & s["dt_refused_min"].isna()]
    if len(rest):
        top = rest["dt_stable_max"].max()
        raw = pd.to_numeric(rest["dt_limit_predicted"], errors="coerce")
        pred = raw.where(np.isfinite(raw))          # inf: an implicit integrator, no explicit limit
        if not math.isfinite(top):
            bits.append(f"{'the others' if bits else 'every series'}: no cell has a result (skipped or failed: see "
                        f"the cells' status and message)")
            return "; ".join(bits) + "."
        phrase = f"{'the others' if bits else 'every series'} stable at every step tried (up to {_g(top)} s)"
        if pred.notna().any():
            low = rest[pred < rest["dt_stable_max"]]
            one = _g(pred.min()) == _g(pred.max())
            span = _g(pred.min()) if one else f"{_g(pred.min())} to {_g(pred.max())}"
            phrase += f"; predicted limit{'' if one else 's'} {span} s"
            if len(low):
                phrase += (" (" + ", ".join(_series_name(r) for _, r in low.iterrows()) +
                           " ran stably above its predicted limit: conservative there)")
        elif (raw == math.inf).any():
            phrase += "; no explicit stability limit (implicit integrator)"
        else:
            phrase += "; no predicted limits"
        bits.append(phrase)
    return "; ".join(bits) + "."


def _stable_text(ok: float) -> str:
    return f"stable up to {_g(ok)} s" if math.isfinite(ok) else "no stable cell"


def _brackets(r) -> bool | None:
    """Whether the predicted limit lies between the largest stable and the smallest unstable *stepped* dt
    (None: no such bracket of stepped cells, or no finite prediction)."""
    obs, ok, pred = r["dt_unstable_stepped"], r["dt_stable_max"], r["dt_limit_predicted"]
    if not (math.isfinite(obs) and math.isfinite(ok) and math.isfinite(pred)):
        return None
    return ok <= pred * 1.0001 and pred <= obs * 1.0001


def _prediction_verdict(r) -> str:
    """The Stability table's verdict on the predicted limit, from stepped cells only."""
    pred, ok = r["dt_limit_predicted"], r["dt_stable_max"]
    hit = _brackets(r)
    if hit is not None:
        return "brackets the observed limit" if hit else "misses the observed bracket"
    if math.isfinite(pred) and math.isfinite(ok) and ok > pred:
        return "conservative (ran stably above it)"
    if math.isfinite(r["dt_refused_min"]) and not math.isfinite(r["dt_unstable_stepped"]):
        return "not tested: the cells above it were refused, not stepped"
    return ""


def _stability_sentence(r) -> str:
    obs, ok, pred = r["dt_unstable_stepped"], r["dt_stable_max"], r["dt_limit_predicted"]
    refused = r["dt_refused_min"]
    pred_s = (f"predicted limit {_g(pred)} s" if math.isfinite(pred) else
              "no explicit stability limit (implicit integrator)" if pred == math.inf else
              "no predicted limit from the engine model")
    refused_s = (f"; refused above the predicted limit from {_g(refused)} s (not stepped)"
                 if math.isfinite(refused) else "")
    if math.isfinite(obs):
        lo = f"stable at {_g(ok)} s, " if math.isfinite(ok) else ""
        hit = _brackets(r)
        agree = "" if hit is None else (" (the prediction brackets it)" if hit
                                        else " (the prediction misses the observed bracket)")
        return f"{lo}unstable from {_g(obs)} s (stepped); {pred_s}{agree}{refused_s}"
    if math.isfinite(refused):
        lo = f"stable at every dt stepped (up to {_g(ok)} s)" if math.isfinite(ok) else "no stable cell"
        beyond = (" (ran stably above the predicted limit: the prediction is conservative)"
                  if math.isfinite(pred) and math.isfinite(ok) and ok > pred else "")
        return (f"{lo}; {pred_s}{beyond}{refused_s}: no stepped cell went unstable, so this grid does not "
                f"observe the limit")
    if math.isfinite(ok):
        beyond = ""
        if math.isfinite(pred) and ok > pred:
            beyond = " (ran stably above the predicted limit: the prediction is conservative)"
        return f"stable at every step tried (up to {_g(ok)} s); {pred_s}{beyond}"
    return f"no stable cell; {pred_s}"


# ---------------------------------------------------------------------------- plots
def _pyplot():
    from impactval.reports.plots import _pyplot as pyplot      # one Agg/ImportError rule for all plots

    return pyplot()


def _under_lines(ax, unders) -> None:
    """A dashed horizontal line per --under tolerance, labelled in % at the right edge."""
    for under in unders:
        ax.axhline(100 * under, color="0.35", ls="--", lw=1)
        ax.annotate(f"{100 * under:g} %", xy=(1.0, 100 * under), xycoords=("axes fraction", "data"),
                    xytext=(3, 0), textcoords="offset points", va="center", fontsize=8, color="0.25")


def _log_axes(ax, xlabel: str, ylabel: str) -> None:
    from matplotlib.ticker import LogFormatterSciNotation, LogLocator

    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(LogLocator(base=10, numticks=8))
        axis.set_major_formatter(LogFormatterSciNotation(base=10, labelOnlyBase=True))
        axis.set_minor_locator(LogLocator(base=10, subs=(2, 5), numticks=12))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, which="major", alpha=0.35)
    ax.grid(True, which="minor", alpha=0.12)


def _no_error_panel(ax, xs: pd.Series, x_default: tuple[float, float]) -> None:
    """A log-log panel where no cell has an error (every cell failed, was unstable or was refused): matplotlib
    cannot pick log limits without positive data, so the panel gets a decade of x around the cells' finite positive
    x values (else `x_default`), 1e-3 .. 1e2 % in y, and says why it holds no points."""
    x = pd.to_numeric(xs, errors="coerce")
    x = x[(x > 0) & np.isfinite(x)]
    lo, hi = (float(x.min()) / 3.0, float(x.max()) * 3.0) if len(x) else x_default
    ax.set_xlim(lo, hi)
    ax.set_ylim(1e-3, 1e2)
    ax.text(0.5, 0.5, "no cell gave an error\n(all failed, unstable or refused before stepping: marks above)",
            transform=ax.transAxes, ha="center", va="center", fontsize=9, color="0.35")


def _styles(d: pd.DataFrame):
    """Marker per integrator and line style per segment count, within each engine."""
    marks, lines = {}, {}
    for engine, g in d.groupby("engine", sort=False):
        for i, integ in enumerate(dict.fromkeys(g["integrator"])):
            marks[(engine, integ)] = MARKERS[i % len(MARKERS)]
        for i, seg in enumerate(dict.fromkeys(g["segments"])):
            lines[(engine, seg)] = LINESTYLES[i % len(LINESTYLES)]
    return marks, lines


def _save(fig, stem: Path) -> list[Path]:
    paths = []
    for ext in ("png", "svg"):
        p = stem.with_suffix(f".{ext}")
        fig.savefig(p, dpi=120, bbox_inches="tight")
        paths.append(p)
    return paths


#: legend labels of the cells without an error along the top of a panel: stepped and went unstable (or failed
#: otherwise), and refused before stepping (dt above the predicted limit: never stepped, no blow-up observed)
FAILED_LABEL = "unstable when stepped / failed (no error)"
REFUSED_LABEL = "refused before stepping (dt above the predicted limit; no error)"


def _failed_band(ax, failed: pd.DataFrame, xcol: str, colours, label_done: set) -> None:
    """Cells without an error on a band at the top of the axes: stepped-and-unstable or otherwise failed cells
    as x markers, cells refused before stepping (`impactval.sweep.refused_before_stepping`) as hollow
    triangles pointing right (towards larger dt, where the refusals are) just below them, each kind with its
    own legend entry."""
    import matplotlib.transforms as mtransforms

    trans = mtransforms.blended_transform_factory(ax.transData, ax.transAxes)
    refused = sw.refused_before_stepping(failed) if len(failed) else pd.Series(False, index=failed.index)
    for i, r in failed.iterrows():
        x = r[xcol]
        kind = "refused" if bool(refused.loc[i]) else "failed"
        lab = None if kind in label_done else (REFUSED_LABEL if kind == "refused" else FAILED_LABEL)
        label_done.add(kind)
        style = (dict(marker=">", mfc="none", ms=7, mew=1.5) if kind == "refused" else dict(marker="x", ms=8, mew=2))
        y = 0.91 if kind == "refused" else 0.97
        if isinstance(x, (int, float)) and math.isfinite(x) and x > 0:
            ax.plot([x], [y], color=colours(r["engine"]), transform=trans, clip_on=False, linestyle="none",
                    label=lab, **style)
        else:               # no time measured (refused, or failed at build or first step): at the left edge
            ax.plot([0.02], [y], color=colours(r["engine"]), transform=ax.transAxes, clip_on=False,
                    linestyle="none", label=lab, **style)


def plot_error_vs_time(df: pd.DataFrame, unders: list[float], stem: str | Path) -> list[Path]:
    """Largest error [%] against stepping time [s], one panel per scene, colour = engine, marker =
    integrator; the Pareto front as a step line, the --under tolerances as dashed lines, failed
    and unstable cells as x marks along the top, cells refused before stepping as hollow triangles below them.
    Returns the PNG and SVG paths ([] without matplotlib)."""
    plt = _pyplot()
    if plt is None:
        return []
    d = sw.pareto_front(df)
    scenes = list(dict.fromkeys(d["scene"]))
    if not scenes:
        return []
    marks, _ = _styles(d)
    fig, axes = plt.subplots(1, len(scenes), figsize=(6.2 * len(scenes), 4.6), squeeze=False)
    for ax, scene in zip(axes.flat, scenes):
        g = d[d["scene"] == scene]
        ok = g[g["score"].notna() & (g["score"] > 0) & (g["cost_s"] > 0)]
        done: set = set()
        for (engine, integ), h in ok.groupby(["engine", "integrator"], sort=False):
            ax.scatter(h["cost_s"], 100 * h["score"], color=engine_colour(engine), marker=marks[(engine, integ)],
                       s=26, alpha=0.8, label=f"{engine} {integ}", zorder=3)
        for engine, h in ok[ok["on_front"]].groupby("engine", sort=False):
            h = h.sort_values("cost_s")
            ax.step(h["cost_s"], 100 * h["score"], where="post", color=engine_colour(engine), lw=1.6, alpha=0.9,
                    label=f"{engine} Pareto front", zorder=2)
            ax.scatter(h["cost_s"], 100 * h["score"], facecolors="none", edgecolors="black", s=70, lw=1.0, zorder=4)
        failed = g[g["score"].isna() & ~g["status"].astype(str).isin(["skipped", "not-installed"])]
        _failed_band(ax, failed.assign(cost_s=failed["cost_s"].where(failed["cost_s"] > 0)), "cost_s", engine_colour,
                     done)
        _under_lines(ax, unders)
        ax.set_xscale("log")
        ax.set_yscale("log")
        if ok.empty:
            _no_error_panel(ax, g["cost_s"], (1e-3, 1e1))
        _log_axes(ax, "cost: stepping wall time [s]", "largest |error| [%]")
        ax.set_title(f"{scene}: error vs cost (front circled)", fontsize=10)
        if ax.get_legend_handles_labels()[0]:          # a panel of skipped cells only has none
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.08, 1.0), frameon=False)
    fig.tight_layout()
    paths = _save(fig, Path(stem))
    plt.close(fig)
    return paths


def plot_error_vs_dt(df: pd.DataFrame, unders: list[float], stem: str | Path,
                     scene_kinds: dict[str, str] | None = None) -> list[Path]:
    """Per scene and engine: largest error [%] against dt (solid/dashed per segment count, marker
    per integrator), the dt-error estimate of the metric with the cleanest fitted order with its
    fitted power law (thin, slope written in the legend), --under lines, and failed/unstable cells
    as x marks along the top, cells refused before stepping as hollow triangles below them. Returns the PNG and SVG
    paths."""
    plt = _pyplot()
    if plt is None:
        return []
    d = sw.with_score(df)
    orders = sw.fit_orders(df, scene_kinds)
    pairs = list(dict.fromkeys(zip(d["scene"], d["engine"])))
    if not pairs:
        return []
    marks, lines = _styles(d)
    cols = min(2, len(pairs))
    nrows = math.ceil(len(pairs) / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(7.0 * cols, 4.6 * nrows), squeeze=False)
    for ax, (scene, engine) in zip(axes.flat, pairs):
        g = d[(d["scene"] == scene) & (d["engine"] == engine)]
        colour = engine_colour(engine)
        done: set = set()
        for (integ, seg), h in g[g["score"] > 0].groupby(["integrator", "segments"], sort=False):
            h = h.sort_values("dt")
            ax.plot(h["dt"], 100 * h["score"], color=colour, marker=marks[(engine, integ)],
                    ls=lines[(engine, seg)], lw=1.4, ms=5, label=f"{_label(integ, seg)}: largest error")
        o = orders[(orders["scene"] == scene) & (orders["engine"] == engine) & orders["order"].notna()]
        for (integ, seg), og in o.groupby(["integrator", "segments"], sort=False):
            best = og.sort_values(["clean", "scatter"], ascending=[False, True]).iloc[0]
            h = g[(g["integrator"] == integ) & (g["segments"] == seg) & g["score"].notna()].sort_values("dt",
                                                                                                      ascending=False)
            x = pd.to_numeric(h[best["metric"]], errors="coerce").to_numpy()
            ref = pd.to_numeric(h[f"ref_{best['metric']}"], errors="coerce").to_numpy()
            if len(x) < 2:
                continue
            fit = sw.OrderFit(best["order"], best["dt_min"], best["dt_max"], int(best["n_points"]), best["log_c"])
            dts = h["dt"].to_numpy()
            diff = abs(x[:-1] - x[1:])
            rho = dts[1:] / dts[:-1]
            est = diff / (1 - rho ** fit.order) / abs(ref[:-1])
            ax.plot(dts[:-1], 100 * est, color=colour, marker=marks[(engine, integ)], ms=3, ls="none", alpha=0.55,
                    mfc="none")
            span = dts[:-1][(dts[:-1] >= fit.dt_min * 0.999) & (dts[:-1] <= fit.dt_max * 1.001)]
            if len(span):
                line = 100 * fit.at(span) / abs(ref[0])
                ax.plot(span, line, color="black", lw=0.9, ls=lines[(engine, seg)], alpha=0.8,
                        label=f"{_label(integ, seg)}: dt-error of {best['metric']}, slope {best['order']:.2f}"
                              f"{'' if best['clean'] else ' (envelope)'}")
        failed = g[g["score"].isna() & ~g["status"].astype(str).isin(["skipped", "not-installed"])]
        _failed_band(ax, failed, "dt", engine_colour, done)
        _under_lines(ax, unders)
        ax.set_xscale("log")
        ax.set_yscale("log")
        if not (g["score"] > 0).any():
            _no_error_panel(ax, g["dt"], (1e-7, 1e-5))
        _log_axes(ax, "time step dt [s]", "|error| [%]")
        ax.set_title(f"{scene} / {engine}", fontsize=10, color=colour)
        if ax.get_legend_handles_labels()[0]:          # a panel of skipped cells only has none
            ax.legend(fontsize=6.5, loc="upper left", bbox_to_anchor=(1.08, 1.0), frameon=False)
    for ax in list(axes.flat)[len(pairs):]:
        ax.set_visible(False)
    fig.tight_layout()
    paths = _save(fig, Path(stem))
    plt.close(fig)
    return paths


# ---------------------------------------------------------------------------- run --dt a,b,c
def speed_accuracy_table(df: pd.DataFrame) -> str:
    """Markdown section for `run --dt a,b,c` (and a re-rendered sweep): per scene and engine, each dt with its
    integrator and structure size N, largest error [%], stepping wall time [ms], steps and status; a cell refused
    before stepping shows "-" for time and steps (it never ran), not 0."""
    d = sw.with_score(df)
    refused = sw.refused_before_stepping(d)
    out = ["", "## Speed against accuracy", "",
           "Largest |error| of t_m, f_m, delta_m against the reference, and the stepping wall time, for each "
           "time step. `impactval sweep` adds integrators, segment counts, orders, floors and the cheapest setting "
           "under a tolerance.", "",
           "| scene | engine | integrator | N | dt [s] | largest error % | step wall time [ms] | steps | status |",
           "|---|---|---|---:|---:|---:|---:|---:|---|"]
    for (scene, engine), g in d.groupby(["scene", "engine"], sort=False):
        cols = [c for c in ("dt", "integrator", "segments") if c in g]
        for i, r in g.sort_values(cols, ascending=False, key=_sort_key).iterrows():
            err = "" if not math.isfinite(r["score"]) else f"{100 * r['score']:.4f}"
            never = bool(refused.loc[i])
            status = f"{r['status']} (refused before stepping)" if never else r["status"]
            out.append(f"| {scene} | {engine} | {r.get('integrator', '') or ''} | {_n(r.get('segments'))} | "
                       f"{r['dt']:g} | {err} | {'-' if never else _ms(r['cost_s'])} | "
                       f"{'-' if never else r['n_steps']} | {status} |")
    return "\n".join(out) + "\n"


def _sort_key(col: pd.Series) -> pd.Series:
    """Sort dt as numbers, integrator and N as text (mixed values in a re-rendered store)."""
    return pd.to_numeric(col, errors="coerce") if col.name == "dt" else col.astype(str)


def speed_accuracy_plot(df: pd.DataFrame, path: str | Path) -> Path | None:
    """`run --dt a,b,c`: largest error against stepping time (the sweep's error-vs-cost plot).
    Returns the PNG path, or None without matplotlib."""
    paths = plot_error_vs_time(df, [], Path(path).with_suffix(""))
    return next((p for p in paths if p.suffix == ".png"), None)
