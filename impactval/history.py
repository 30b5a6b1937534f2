"""Nightly history: compare a run with a baseline `results.csv` (style.md, pattern 12; asv's marks).

Rows are matched on (scene, engine, contact, integrator, dt, segments). A pair is comparable only
when both rows have the same `scene_hash` (the canonical scene plus the reference version), so a
changed scene file or reference is never reported as an engine change. The score of a row is its
largest |relative error| over t_m, f_m, delta_m. Marks:

| mark | meaning |
|---|---|
| `x` | not comparable (no baseline row, or the scene or reference changed) |
| `!` | newly failing (the baseline row was ok, this one is not) |
| `*` | fixed (the baseline row failed, this one is ok) |
| `+` | worse: the score grew by more than the threshold (relative) and by more than 1e-5 |
| `-` | better: the score shrank by more than the threshold and by more than 1e-5 |
"""
from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from impactval.errors import ImpactvalError

KEY = ("scene", "engine", "contact", "integrator", "dt", "segments")
#: smallest absolute change of the score that can be flagged
ABS_FLOOR = 1e-5


def load_results(path: str | Path, schema_version: int) -> pd.DataFrame:
    """A results.csv written by `impactval run`; an older schema is refused with a message."""
    p = Path(path)
    if not p.is_file():
        raise ImpactvalError(f"{p}: baseline file does not exist (give a results.csv of an earlier run).")
    try:
        df = pd.read_csv(p, keep_default_na=True)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as err:
        raise ImpactvalError(f"{p}: not a results.csv ({err}).") from None
    for col in ("err_t_m", "err_f_m", "err_delta_m"):     # schema 3 exports errors in % as NAME_pct
        if col not in df and f"{col}_pct" in df:
            df[col] = pd.to_numeric(df[f"{col}_pct"], errors="coerce") / 100.0
    missing = [c for c in (*KEY, "status", "schema_version", "err_t_m", "err_f_m", "err_delta_m") if c not in df]
    if missing:
        raise ImpactvalError(f"{p}: not a results.csv of impactval run (missing column {missing[0]!r}).")
    versions = set(pd.to_numeric(df["schema_version"], errors="coerce").dropna().astype(int))
    if versions != {schema_version}:
        raise ImpactvalError(f"{p}: results schema {sorted(versions)} cannot be compared with schema "
                             f"{schema_version}; rerun the baseline with this impactval version.")
    # several runs appended to one file: the newest row per key is the baseline
    return df.drop_duplicates(list(KEY), keep="last")


def score(row) -> float:
    """Largest |relative error| over t_m, f_m, delta_m (NaN when the row has no numbers)."""
    vals = [abs(float(row[k])) for k in ("err_t_m", "err_f_m", "err_delta_m")]
    vals = [v for v in vals if math.isfinite(v)]
    return max(vals) if vals else math.nan


def _key(row) -> tuple:
    out = []
    for k in KEY:
        v = row[k]
        if k == "dt":
            v = float(v)
        elif isinstance(v, float) and math.isnan(v):
            v = ""
        else:
            v = str(v)
            if k == "segments" and v.endswith(".0"):
                v = v[:-2]
        out.append(v)
    return tuple(out)


def compare(new: pd.DataFrame, old: pd.DataFrame, threshold: float = 0.2) -> pd.DataFrame:
    """One row per new row: key, old and new score, relative change and the mark (see module doc)."""
    if not (isinstance(threshold, (int, float)) and threshold > 0):
        raise ImpactvalError(f"threshold must be a positive fraction (0.2 = 20 %), got {threshold!r}.")
    base = {_key(r): r for _, r in old.iterrows()}
    rows = []
    for _, r in new.iterrows():
        o = base.get(_key(r))
        s_new = score(r)
        s_old = score(o) if o is not None else math.nan
        mark, change = "", math.nan
        if o is None or str(o.get("scene_hash", "")) != str(r.get("scene_hash", "")):
            mark = "x"
        elif o["status"] == "ok" and r["status"] != "ok":
            mark = "!"
        elif o["status"] != "ok" and r["status"] == "ok":
            mark = "*"
        elif r["status"] == "ok" and math.isfinite(s_new) and math.isfinite(s_old):
            change = (s_new - s_old) / s_old if s_old > 0 else math.inf if s_new > 0 else 0.0
            if abs(s_new - s_old) > ABS_FLOOR:
                mark = "+" if change > threshold else "-" if change < -threshold else ""
        rows.append({**{k: r[k] for k in KEY}, "old_status": "" if o is None else o["status"],
                     "status": r["status"], "old_score": s_old, "score": s_new, "change": change, "mark": mark})
    return pd.DataFrame(rows)


def regressions(cmp: pd.DataFrame) -> bool:
    """True when a row is worse (`+`) or newly failing (`!`)."""
    return bool(cmp["mark"].isin(["+", "!"]).any()) if len(cmp) else False


def markdown(cmp: pd.DataFrame, baseline: str | Path, threshold: float) -> str:
    """The report section: marks first, then every compared row."""
    def pct(x: float) -> str:
        return "" if not math.isfinite(x) else f"{100 * x:.3f}"

    out = ["", "## Against the baseline", "",
           f"Baseline: `{baseline}`. Score = largest |error| of t_m, f_m, delta_m in %; marks: `+` worse by more "
           f"than {threshold:.0%}, `-` better, `!` newly failing, `*` fixed, `x` not comparable (scene or "
           f"reference changed, or no baseline row).", "",
           "| mark | scene | engine | contact | dt [s] | N | baseline % | now % | change |",
           "|---|---|---|---|---:|---:|---:|---:|---:|"]
    order = {"!": 0, "+": 1, "*": 2, "-": 3, "x": 4, "": 5}
    for _, r in cmp.sort_values("mark", key=lambda s: s.map(order), kind="stable").iterrows():
        ch = "" if not math.isfinite(r["change"]) else f"{100 * r['change']:+.0f} %"
        out.append(f"| {r['mark']} | {r['scene']} | {r['engine']} | {r['contact']} | {float(r['dt']):g} | "
                   f"{r['segments']} | {pct(r['old_score'])} | {pct(r['score'])} | {ch} |")
    return "\n".join(out) + "\n"
