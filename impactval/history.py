"""Compare a run with an earlier one, like with like (style.md, pattern 12; asv's marks).

Rows are matched on KEY = (scene, engine, contact, integrator, dt, segments): the scene and the
settings that fix what a job computes. A matched pair is comparable only when both rows have the
same `scene_hash` (canonical scene and impactval's version) and their reference values (ref_t_m,
ref_f_m, ref_delta_m) agree within REFERENCE_MOVE_LIMIT, so a changed scene file or a reference that
moved is never reported as an engine change (a reference whose code changed but whose values did not
leaves the rows comparable). The engine version is a separate axis: rows of different engine
versions are compared (that is what an upgrade check is for) and the report names both versions.

Errors are deterministic, so every change is real; a row is flagged when the |error| of a metric
grows past that metric's threshold (`parse_fail_on("f_m:+20%")`). Marks:

| mark | meaning |
|---|---|
| `x` | not comparable (no baseline row with this key, the scene changed, or the reference's values moved) |
| `!` | newly failing (the baseline row had a result, this one has none) |
| `*` | fixed (the baseline row failed, this one has a result) |
| `+` | worse: some metric's |error| grew past its threshold |
| `-` | better: some metric's |error| shrank past its threshold, none got worse |

Wall times are noisy and are never compared pairwise: `wall_time_steps` looks for a step in the
history of several nights (see there).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import pandas as pd

from impactval.errors import ImpactvalError

KEY = ("scene", "engine", "contact", "integrator", "dt", "segments")
#: error metrics compared pairwise: name -> results column (signed relative error; curve >= 0)
METRICS = {"t_m": "err_t_m", "f_m": "err_f_m", "delta_m": "err_delta_m", "curve": "err_curve"}
#: smallest absolute change of an |error| (as a fraction: 1e-5 = 0.001 percentage points) that can be flagged
ABS_FLOOR = 1e-5
#: largest relative move of the reference's t_m, f_m, delta_m between a row and its baseline that leaves them comparable:
#: half of ABS_FLOOR, so a move of the reference alone (an error moves with it by about as much) cannot flag a row.
#: Two honest references at the default tol 1e-6 differ by at most 2e-6; a reference that moved more has been changed
REFERENCE_MOVE_LIMIT = 0.5 * ABS_FLOOR
#: the reference's values in a results row
REFERENCE_COLUMNS = {"t_m": "ref_t_m", "f_m": "ref_f_m", "delta_m": "ref_delta_m"}
#: default relative growth of |error| that flags a row (0.2 = +20 %)
DEFAULT_THRESHOLD = 0.2
#: default relative step of the stepping wall time, persisting over WALL_WINDOW nights, that flags a row
DEFAULT_WALL_THRESHOLD = 0.5
#: nights a wall-time step must persist; the history needs 2x this many nights before it judges
WALL_WINDOW = 3


@dataclass(frozen=True)
class ThresholdCheck:
    """When is a metric worse: its |error| grew by more than `rel` (relative, 0.2 = +20 %) or by more
    than `abs_pp` percentage points (whichever is given), and by more than ABS_FLOOR in any case.
    `metric` is one of METRICS or "wall_time" (stepping wall time, judged from the history)."""

    metric: str
    rel: float | None = None
    abs_pp: float | None = None

    def describe(self) -> str:
        return f"{self.metric}:+{100 * self.rel:g}%" if self.rel is not None else f"{self.metric}:+{self.abs_pp:g}pp"

    def verdict(self, old: float, new: float) -> tuple[float, str]:
        """(relative change of |error|, "+" worse / "-" better / "" within) between two signed errors."""
        if not (math.isfinite(old) and math.isfinite(new)):
            return math.nan, ""
        a, b = abs(old), abs(new)
        change = (b - a) / a if a > 0 else (math.inf if b > 0 else 0.0)
        if abs(b - a) <= ABS_FLOOR:
            return change, ""
        if self.rel is not None:
            past = abs(change) > self.rel
        else:
            past = 100 * abs(b - a) > self.abs_pp
        return change, ("+" if b > a else "-") if past else ""


_FAIL_ON = re.compile(r"^\s*([a-z_]+)\s*:\s*\+?\s*([0-9.eE+-]+)\s*(%|pp)\s*$")


def parse_fail_on(text: str) -> ThresholdCheck:
    """'f_m:+20%' (|error| grows by 20 % of itself) or 'f_m:+0.5pp' (by 0.5 percentage points);
    metrics: t_m, f_m, delta_m, curve, wall_time (stepping wall time, from the history)."""
    m = _FAIL_ON.match(str(text))
    allowed = ", ".join([*METRICS, "wall_time"])
    if not m:
        raise ImpactvalError(f"--fail-on takes METRIC:+N% or METRIC:+Npp (e.g. 'f_m:+20%', 'curve:+0.5pp'; "
                             f"metrics: {allowed}), got {text!r}.")
    metric, number, unit = m.groups()
    if metric not in METRICS and metric != "wall_time":
        raise ImpactvalError(f"--fail-on: unknown metric {metric!r} in {text!r}; known: {allowed}.")
    try:
        value = float(number)
    except ValueError:
        raise ImpactvalError(f"--fail-on: {number!r} in {text!r} is not a number.") from None
    if not (math.isfinite(value) and value > 0):
        raise ImpactvalError(f"--fail-on: the threshold in {text!r} must be a positive number.")
    if metric == "wall_time" and unit == "pp":
        raise ImpactvalError(f"--fail-on: wall_time takes a relative step in % (e.g. 'wall_time:+50%'), got {text!r}.")
    return ThresholdCheck(metric, rel=value / 100 if unit == "%" else None, abs_pp=value if unit == "pp" else None)


def thresholds(fail_on: Iterable[str | ThresholdCheck] = (), default: float = DEFAULT_THRESHOLD) -> dict[str, ThresholdCheck]:
    """One check per metric: the given ones, the default (relative `default`) for the others."""
    if not (isinstance(default, (int, float)) and math.isfinite(default) and default > 0):
        raise ImpactvalError(f"threshold must be a positive fraction (0.2 = 20 %), got {default!r}.")
    out = {m: ThresholdCheck(m, rel=float(default)) for m in METRICS}
    out["wall_time"] = ThresholdCheck("wall_time", rel=DEFAULT_WALL_THRESHOLD)
    for item in fail_on:
        check = item if isinstance(item, ThresholdCheck) else parse_fail_on(item)
        out[check.metric] = check
    return out


def load_results(path: str | Path, schema_version: int) -> pd.DataFrame:
    """A results.csv written by `impactval run`; an older schema is refused with a message."""
    p = Path(path)
    if not p.is_file():
        raise ImpactvalError(f"--baseline {p}: file does not exist (give the results.csv of an earlier run).")
    try:
        df = pd.read_csv(p, keep_default_na=True)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as err:
        raise ImpactvalError(f"--baseline {p}: not a results.csv of impactval run ({err}); give the "
                             f"results.csv an earlier run wrote.") from None
    for col in ("err_t_m", "err_f_m", "err_delta_m", "err_curve"):     # schema 3 exports errors in % as NAME_pct
        if col not in df and f"{col}_pct" in df:
            df[col] = pd.to_numeric(df[f"{col}_pct"], errors="coerce") / 100.0
    missing = [c for c in (*KEY, "status", "schema_version", "err_t_m", "err_f_m", "err_delta_m") if c not in df]
    if missing:
        raise ImpactvalError(f"--baseline {p}: not a results.csv of impactval run (missing column {missing[0]!r}).")
    versions = set(pd.to_numeric(df["schema_version"], errors="coerce").dropna().astype(int))
    from impactval.store import COMPARABLE_SCHEMAS     # schema 4 only added columns to 3

    if not versions or not versions <= (set(COMPARABLE_SCHEMAS) if schema_version in COMPARABLE_SCHEMAS
                                        else {schema_version}):
        raise ImpactvalError(f"--baseline {p}: results schema {sorted(versions)} cannot be compared with schema "
                             f"{schema_version}; rerun the baseline with this impactval version.")
    # several runs appended to one file: the newest row per key is the baseline
    return df.drop_duplicates(list(KEY), keep="last")


def _num(x) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def reference_moved(old, new) -> str:
    """"" when two rows' reference values (REFERENCE_COLUMNS) agree within REFERENCE_MOVE_LIMIT (relative), or when
    either row has none (a failed job's reference may be missing); else the moves in words ('t_m +3.1e-05, f_m
    -1.2e-05')."""
    moves = []
    for m, col in REFERENCE_COLUMNS.items():
        a = _num(old.get(col)) if col in old else math.nan
        b = _num(new.get(col)) if col in new else math.nan
        if math.isfinite(a) and math.isfinite(b) and a != 0.0 and abs(b / a - 1.0) > REFERENCE_MOVE_LIMIT:
            moves.append(f"{m} {b / a - 1.0:+.2g}")
    return ", ".join(moves)


def score(row) -> float:
    """Largest |relative error| over t_m, f_m, delta_m (NaN when the row has no numbers)."""
    vals = [abs(_num(row[k])) for k in ("err_t_m", "err_f_m", "err_delta_m") if k in row]
    vals = [v for v in vals if math.isfinite(v)]
    return max(vals) if vals else math.nan


def _cell(k: str, v) -> object:
    if k == "dt":                   # a time step [s], or a word such as "auto"
        x = _num(v)
        return x if math.isfinite(x) else str(v)
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    v = str(v)
    if k == "segments" and v.endswith(".0"):
        v = v[:-2]
    return v


def row_key(row) -> tuple:
    """The comparison key of a row (KEY, normalised: dt as float, segments as text, NaN as '')."""
    return tuple(_cell(k, row[k]) for k in KEY)


def _ok(status) -> bool:
    return str(status) == "ok"


#: key fields a job without a result may not know (a timeout or a dead worker reports no integrator and no N)
UNREPORTED = ("integrator", "segments")


def _unreported_match(row, base: dict) -> pd.Series | None:
    """The one baseline row that matches when a row without a result (on either side) leaves the fields it
    could not report (UNREPORTED) empty: a job that newly times out or crashes is `!` newly failing, one that
    timed out before and runs now `*` fixed, not `x` not comparable (cc_short_heavy_ball at --timeout 1: six
    newly failing jobs passed a night with exit 0)."""
    key = row_key(row)
    found = []
    for k, o in base.items():
        # two results know their integrator; an empty N on a result is a target without a structure to size (a
        # rigid plate, a second ball), where older rows showed the asked --segments
        free = UNREPORTED if not (_ok(row["status"]) and _ok(o["status"])) else ("segments",)
        idx = [i for i, name in enumerate(KEY) if name in free]
        if all(a == b for i, (a, b) in enumerate(zip(key, k)) if i not in idx) and \
                all(key[i] == k[i] or "" in (key[i], k[i]) for i in idx):
            found.append(o)
    return found[0] if len(found) == 1 else None


def compare(new: pd.DataFrame, old: pd.DataFrame, checks: float | dict[str, ThresholdCheck] | None = None) -> pd.DataFrame:
    """One row per new row: KEY, versions, statuses, old and new error and relative change of |error|
    per metric (`old_err_f_m`, `err_f_m`, `change_f_m`, ...), the mark (see module doc), `why` (the
    reason for the mark in words, with numbers) and `changed` (any metric differs at all).

    `checks`: thresholds per metric (`thresholds(...)`), or one relative threshold for all."""
    if checks is None or isinstance(checks, (int, float)):
        checks = thresholds((), DEFAULT_THRESHOLD if checks is None else checks)
    base = {}
    for _, r in old.iterrows():
        base[row_key(r)] = r                         # the newest row per key wins
    rows = []
    for _, r in new.iterrows():
        o = base.get(row_key(r))
        if o is None:
            o = _unreported_match(r, base)
        out = {k: r[k] for k in KEY}
        out.update(version=str(r.get("version", "") or ""), old_version="" if o is None else str(o.get("version", "") or ""),
                   status=str(r["status"]), old_status="" if o is None else str(o["status"]),
                   old_score=math.nan if o is None else score(o), score=score(r))
        mark, why, changed = "", "", False
        for m, col in METRICS.items():
            a = _num(o.get(col)) if o is not None and col in o else math.nan
            b = _num(r.get(col)) if col in r else math.nan
            out[f"old_{col}"], out[col] = a, b
            out[f"change_{m}"] = math.nan
        if o is None:
            mark, why = "x", "no baseline row with this scene, engine and settings"
        elif str(o.get("scene_hash", "")) != str(r.get("scene_hash", "")):
            mark, why = "x", f"scene or reference changed (scene hash {o.get('scene_hash', '')} -> {r.get('scene_hash', '')})"
        elif moved := reference_moved(o, r):
            mark, why = "x", (f"reference changed: its values moved by {moved} (relative; comparable within "
                              f"{REFERENCE_MOVE_LIMIT:.0e})")
        elif _ok(o["status"]) and not _ok(r["status"]):
            msg = " ".join(str(r.get("message", "") or "").split())
            mark, why = "!", f"{o['status']} -> {r['status']}: {msg}".rstrip(": ")
        elif not _ok(o["status"]) and _ok(r["status"]):
            mark, why = "*", f"{o['status']} -> ok"
        elif _ok(r["status"]):
            worse, better = [], []
            for m, col in METRICS.items():
                a, b = out[f"old_{col}"], out[col]
                if math.isfinite(a) and math.isfinite(b) and a != b:
                    changed = True
                change, verdict = checks[m].verdict(a, b)
                out[f"change_{m}"] = change
                text = f"{m} {100 * a:+.4g} % -> {100 * b:+.4g} % ({100 * change:+.0f} % in size)"
                if verdict == "+":
                    worse.append(text)
                elif verdict == "-":
                    better.append(text)
            if worse:
                mark, why = "+", "; ".join(worse)
            elif better:
                mark, why = "-", "; ".join(better)
        if mark in ("+", "-", "!", "*") and out["old_version"] and out["version"] and out["old_version"] != out["version"]:
            # (a job without a result may report no version: that is no upgrade)
            why += f" (engine version {out['old_version'] or '?'} -> {out['version'] or '?'})"
        out.update(mark=mark, why=why, changed=changed)
        old_s, new_s = out["old_score"], out["score"]
        out["change"] = (new_s - old_s) / old_s if math.isfinite(old_s) and math.isfinite(new_s) and old_s > 0 else math.nan
        rows.append(out)
    return pd.DataFrame(rows)


def regressions(cmp: pd.DataFrame) -> bool:
    """True when a row is worse (`+`) or newly failing (`!`)."""
    return bool(cmp["mark"].isin(["+", "!"]).any()) if len(cmp) else False


def comparable(cmp: pd.DataFrame) -> int:
    """How many rows were compared (mark other than `x`)."""
    return int((cmp["mark"] != "x").sum()) if len(cmp) else 0


def _fmt(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _every_differing_key(new: pd.DataFrame, old: pd.DataFrame) -> list[str]:
    """For each KEY column (and the scene hash) whose values differ at all between the two runs, 'column:
    baseline A, B; now C' (values sorted, at most 4 each): `differing_keys`' wording and its last resort."""
    def values(df: pd.DataFrame, k: str) -> list[str]:
        vals = sorted({_fmt(_cell(k, v)) for v in df[k]}) if k in df else []
        return [v if v != "" else "(default)" for v in vals]

    out = []
    for k in (*KEY, "scene_hash"):
        a, b = values(old, k), values(new, k)
        if a != b:
            short = lambda vs: ", ".join(vs[:4]) + (f" (+{len(vs) - 4} more)" if len(vs) > 4 else "")  # noqa: E731
            out.append(f"{k}: baseline {short(a) or 'none'}; now {short(b) or 'none'}")
    return out


def differing_keys(new: pd.DataFrame, old: pd.DataFrame) -> list[str]:
    """Why no row of `new` has a comparable baseline row in `old`: the key columns (KEY and the scene hash)
    that actually differ, each as 'column: baseline A; now B'.

    A key differs when a row of this night has a value of it the baseline never had (its values are not a
    subset of the baseline's); for a row whose every value the baseline had (a new combination), the keys
    that alone keep it from a baseline row differ. The values shown are those of the rows concerned (and of
    the baseline rows they would match with that key ignored, when there are any). A key whose values this
    night are merely fewer than the baseline's (fewer scenes or engines tonight) is no difference and is left
    out. Only when no key is found so is every key with other values listed."""
    keys = (*KEY, "scene_hash")

    def cells(df: pd.DataFrame) -> list[tuple[tuple, bool]]:
        """(key cells, has a result) per row."""
        return [(tuple(_cell(k, r[k]) if k in df else "" for k in keys), str(r.get("status", "")) == "ok")
                for _, r in df.iterrows()]

    def free(results: bool) -> tuple[str, ...]:
        # an empty value matching any, as in history._unreported_match: a job without a result reports no
        # integrator or N; a target without a structure to size (rigid plate, second ball) has no N
        return UNREPORTED if not results else ("segments",)

    def same(a, b, i: int, results: bool) -> bool:
        return a == b or (keys[i] in free(results) and "" in (a, b))

    new_cells, old_cells = cells(new), cells(old)
    old_vals = [{c[i] for c, _ in old_cells} for i in range(len(keys))]
    found: dict[int, tuple[set, set]] = {}           # key index -> (new row positions, old row positions)
    hash_at = len(keys) - 1

    def near(c: tuple, ok: bool, i: int) -> list[int]:
        """The baseline rows the row `c` would match if key i alone were ignored (another scene has another hash)."""
        ignored = (i, hash_at) if keys[i] == "scene" else (i,)
        return [m for m, (o, o_ok) in enumerate(old_cells)
                if o[i] != c[i] and all(same(o[n], c[n], n, ok and o_ok) for n in range(len(keys)) if n not in ignored)]

    for j, (c, ok) in enumerate(new_cells):
        known = [i for i in range(len(keys)) if not (keys[i] in free(ok) and c[i] == "")]
        # a value the baseline never had is this row's difference (a new scene: not its hash as well); only without
        # one, a combination of known values is, and then the keys that alone keep the row from a baseline row differ
        new_values = [i for i in known if c[i] not in old_vals[i]]
        if keys.index("scene") in new_values and hash_at in new_values:
            new_values.remove(hash_at)
        for i in new_values or known:
            rows = near(c, ok, i) or (range(len(old_cells)) if new_values else [])
            if rows:
                rows_new, rows_old = found.setdefault(i, (set(), set()))
                rows_new.add(j)
                rows_old.update(rows)
    every = _every_differing_key(new, old)
    out = []
    for i in sorted(found):
        rows_new, rows_old = found[i]
        line = [d for d in _every_differing_key(new.iloc[sorted(rows_new)], old.iloc[sorted(rows_old)])
                if d.startswith(f"{keys[i]}: ")] or [d for d in every if d.startswith(f"{keys[i]}: ")]
        out += line
    return out or every


def require_comparable(cmp: pd.DataFrame, new: pd.DataFrame, old: pd.DataFrame, baseline: str) -> None:
    """Raise ImpactvalError (exit 2) when no row could be compared: a drifted setup is an error,
    never a pass. The message names the keys that differ."""
    if len(new) and comparable(cmp) == 0:
        diff = differing_keys(new, old)
        moved = [str(w) for w in cmp.get("why", ()) if str(w).startswith("reference changed")]
        raise ImpactvalError(f"nothing comparable with {baseline}: none of the {len(new)} rows has a baseline row "
                             f"with the same scene, engine, settings and scene hash"
                             + (f"; differing: {' | '.join(diff)}" if diff else "")
                             + (f"; {len(moved)} of them matched a baseline row but the {moved[0]}" if moved else "")
                             + (". Rerun the baseline with this version" if moved else
                                ". Rerun the baseline with these settings, or use the baseline's settings") + ".")


def wall_time_steps(history: pd.DataFrame, threshold: float = DEFAULT_WALL_THRESHOLD,
                    window: int = WALL_WINDOW) -> pd.DataFrame:
    """Speed regressions from the history of several nights (asv's idea: a step, not a noisy night).

    `history`: rows of successive runs with KEY, `run_index` (0 = oldest) and `wall_time_step_s` [s].
    For each key the ok rows are ordered by night; the last `window` nights are compared with the
    median of the (up to 3 x window) nights before them. A row is "slower" when every one of the last
    `window` nights is more than `threshold` (relative) above that median, "faster" when every one is
    that much below, "steady" otherwise, and "not enough history" with fewer than 2 x window nights.
    Returns one row per key: KEY, state, nights, before_s (median), after_s (median of the window),
    ratio (after / before).
    """
    cols = [*KEY, "state", "nights", "before_s", "after_s", "ratio"]
    if history is None or not len(history):
        return pd.DataFrame(columns=cols)
    h = history[history["status"].astype(str) == "ok"].copy()
    h["_key"] = [row_key(r) for _, r in h.iterrows()]
    h["_wall"] = pd.to_numeric(h["wall_time_step_s"], errors="coerce")
    out = []
    for key, g in h.groupby("_key", sort=False):
        s = g.sort_values("run_index")["_wall"].dropna().to_numpy()
        rec = dict(zip(KEY, key), nights=len(s), before_s=math.nan, after_s=math.nan, ratio=math.nan)
        if len(s) < 2 * window:
            rec["state"] = f"not enough history ({len(s)} of {2 * window} nights)"
        else:
            after = s[-window:]
            before = s[:-window][-3 * window:]
            med_b, med_a = float(pd.Series(before).median()), float(pd.Series(after).median())
            rec.update(before_s=med_b, after_s=med_a, ratio=med_a / med_b if med_b > 0 else math.nan)
            if med_b > 0 and (after > med_b * (1 + threshold)).all():
                rec["state"] = "slower"
            elif med_b > 0 and (after < med_b / (1 + threshold)).all():
                rec["state"] = "faster"
            else:
                rec["state"] = "steady"
        out.append(rec)
    return pd.DataFrame(out, columns=cols)


def markdown(cmp: pd.DataFrame, baseline: str | Path, threshold: float | dict[str, ThresholdCheck] | None = None) -> str:
    """The report section: flagged rows first (with the numbers), then every compared row."""
    from impactval.reports.run_report import comparison_section

    return comparison_section(cmp, str(baseline), threshold)


def flagged_lines(cmp: pd.DataFrame) -> list[str]:
    """One console line per marked row: 'MARK scene / engine (settings): why'."""
    order = {"!": 0, "+": 1, "*": 2, "-": 3, "x": 4}
    lines = []
    for _, r in cmp[cmp["mark"] != ""].sort_values("mark", key=lambda s: s.map(order), kind="stable").iterrows():
        lines.append(f"  {r['mark']} {r['scene']} / {r['engine']} ({r['contact']}, dt={_fmt(_cell('dt', r['dt']))}"
                     f"{', N=' + str(_cell('segments', r['segments'])) if _cell('segments', r['segments']) else ''}): "
                     f"{r['why']}")
    return lines


def summary_counts(cmp: pd.DataFrame) -> dict[str, int]:
    """How many rows got each mark, plus 'changed' (any metric differs, flagged or not)."""
    out = {m: int((cmp["mark"] == m).sum()) if len(cmp) else 0 for m in ("!", "+", "*", "-", "x")}
    out["changed"] = int(cmp["changed"].sum()) if len(cmp) else 0
    # compared rows that no engine stepped in either run (skipped both times: an unsupported scene): compared, but
    # nothing in them could change
    both = (cmp["mark"] != "x") & (cmp["status"].astype(str) == "skipped") & (cmp["old_status"].astype(str) == "skipped") \
        if len(cmp) and {"status", "old_status"} <= set(cmp) else pd.Series(dtype=bool)
    out["skipped_both"] = int(both.sum())
    return out


def check_names(checks: dict[str, ThresholdCheck] | Sequence | None) -> str:
    """'t_m:+20%, f_m:+20%, ...' for the report."""
    if checks is None or isinstance(checks, (int, float)):
        checks = thresholds((), DEFAULT_THRESHOLD if checks is None else checks)
    return ", ".join(c.describe() for c in (checks.values() if isinstance(checks, dict) else checks))
