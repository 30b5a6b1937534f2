"""The report of a run (`impactval run`, `impactval nightly`, `impactval report`): markdown first.

Order follows what a reader needs in a minute: a header (what ran where, how it ended), a summary
per engine (worst error, status counts, regressions), the comparison marks, figures (force curves,
trends), then the full table (empty columns dropped), the reference values with their provenance,
and the messages of rows without a result. `reports.html.render_html` turns the same markdown into
one self-contained HTML page, so both always say the same thing.
"""
from __future__ import annotations

import json
import math
from typing import Any, Iterable, Mapping

import pandas as pd

from impactval.compare import NO_REFERENCE
from impactval.reports.style import MARKS


def _num(x: Any) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def _pct(x: Any) -> str:
    x = _num(x)
    return "" if not math.isfinite(x) else f"{100 * x:+.3f}"


def _pct_abs(x: Any) -> str:
    x = _num(x)
    return "" if not math.isfinite(x) else f"{100 * x:.3f}"


def _ms(x: Any) -> str:
    x = _num(x)
    return "" if not math.isfinite(x) else f"{1e3 * x:.1f}"


def _int(x: Any) -> str:
    x = _num(x)
    return "" if not math.isfinite(x) else str(int(x))


def _seg(x: Any) -> str:
    if x in ("", None) or (isinstance(x, float) and math.isnan(x)):
        return ""
    s = str(x)
    return s[:-2] if s.endswith(".0") else s


def _dt(x: Any) -> str:
    """A time step [s] as text ("auto" and other words stay as they are)."""
    v = _num(x)
    return f"{v:g}" if math.isfinite(v) else ("" if x is None or (isinstance(x, float)) else str(x))


def _col(r, key: str) -> Any:
    return r[key] if key in r else math.nan


def _ran(r) -> bool:
    """False for a row that never built or stepped (skipped, not installed, refused before stepping): its wall
    times and steps are not measurements (they showed as 0.0 ms, 0 steps)."""
    if str(r["status"]) in ("skipped", "not-installed"):
        return False
    return not (_num(_col(r, "n_steps")) == 0 and _num(_col(r, "wall_time_build_s")) == 0)


def _contact_cell(r) -> str:
    """The row's contact mode, and the law that ran when an option changed a "hertz" contact's law (an Exudyn row with
    law=linear said "hertz": user test s20 fuzz2, finding 7)."""
    contact, law = str(r["contact"]), _col(r, "contact_law")
    law = "" if law is None or (isinstance(law, float) and pd.isna(law)) else str(law)
    return f"{contact} (law {law})" if contact == "hertz" and law and law != "hertz" else contact


#: (header, cell function, right-aligned) of the results table, in order
_COLUMNS = (
    ("scene", lambda r: str(r["scene"]), False),
    ("engine", lambda r: str(r["engine"]), False),
    ("contact", lambda r: _contact_cell(r), False),
    ("integrator", lambda r: "" if pd.isna(r["integrator"]) else str(r["integrator"]), False),
    ("dt [s]", lambda r: _dt(r["dt"]), False),
    ("N", lambda r: _seg(r["segments"]), False),
    ("status", lambda r: str(r["status"]), False),
    ("contacts", lambda r: _int(_col(r, "n_contacts")) if str(r["status"]) == "ok" else "", True),
    ("t_m %", lambda r: _pct(r["err_t_m"]), True),
    ("f_m %", lambda r: _pct(r["err_f_m"]), True),
    ("delta_m %", lambda r: _pct(r["err_delta_m"]), True),
    ("curve %", lambda r: _pct_abs(_col(r, "err_curve")), True),
    ("lin t_m %", lambda r: _pct(_col(r, "lin_err_t_m")), True),
    ("lin f_m %", lambda r: _pct(_col(r, "lin_err_f_m")), True),
    ("lin delta_m %", lambda r: _pct(_col(r, "lin_err_delta_m")), True),
    ("C vs Warp t_m %", lambda r: _pct(_col(r, "vs_mujoco_c_t_m")), True),
    ("C vs Warp f_m %", lambda r: _pct(_col(r, "vs_mujoco_c_f_m")), True),
    ("C vs Warp delta_m %", lambda r: _pct(_col(r, "vs_mujoco_c_delta_m")), True),
    ("build ms", lambda r: _ms(_col(r, "wall_time_build_s")) if _ran(r) else "", True),
    ("step ms", lambda r: _ms(_col(r, "wall_time_step_s")) if _ran(r) else "", True),
    ("steps", lambda r: _int(_col(r, "n_steps")) if _ran(r) else "", True),
)


def table_rows(df: pd.DataFrame, marks: Mapping[tuple, str] | None = None,
               keep_empty: bool = False) -> tuple[list[str], list[list[str]], list[bool]]:
    """Header, text cells and right-alignment of the results table (errors in %, wall times in ms).
    Columns that are empty in every row are dropped (unless `keep_empty`); `marks` (row key ->
    mark, see impactval.history.row_key) adds a first column "mark"."""
    cols = list(_COLUMNS)
    cells = [[fn(r) for _, fn, _ in cols] for _, r in df.iterrows()]
    keep = [keep_empty or not cells or any(c[i] for c in cells) or i < 2 for i in range(len(cols))]
    header = [h for (h, _, _), k in zip(cols, keep) if k]
    right = [a for (_, _, a), k in zip(cols, keep) if k]
    cells = [[x for x, k in zip(c, keep) if k] for c in cells]
    if marks is not None:
        from impactval.history import row_key

        keys = [row_key(r) for _, r in df.iterrows()]
        header, right = ["mark", *header], [False, *right]
        cells = [[marks.get(k, ""), *c] for k, c in zip(keys, cells)]
    return header, cells, right


def _noted(df: pd.DataFrame) -> list[tuple[str, str, str]]:
    """(scene, engine, note) of the rows with a result whose message holds validity notes (runner.row_notes)."""
    if "message" not in df or "status" not in df:
        return []
    out = []
    for _, r in df.iterrows():
        msg = r["message"]
        if str(r["status"]) == "ok" and isinstance(msg, str) and msg.strip():
            out.append((str(r["scene"]), str(r["engine"]), " ".join(msg.split())))
    return out


def notes_section(df: pd.DataFrame) -> list[str]:
    """'Notes on rows with a result': each ok row's validity notes (why its error may exceed the bar)."""
    noted = _noted(df)
    if not noted:
        return []
    return ["## Notes on rows with a result", "",
            *(f"- {scene} / {engine}: {note}" for scene, engine, note in noted), ""]


def text_table(df: pd.DataFrame) -> str:
    """The results table as aligned plain text (empty columns dropped), then a `! scene / engine: note` line
    per row with a result that carries validity notes."""
    header, cells, right = table_rows(df)
    widths = [max(len(h), *(len(c[i]) for c in cells)) if cells else len(h) for i, h in enumerate(header)]

    def line(items):
        return "  ".join(x.rjust(w) if r else x.ljust(w) for x, w, r in zip(items, widths, right)).rstrip()

    notes = [f"  ! {scene} / {engine}: {note}" for scene, engine, note in _noted(df)]
    return "\n".join([line(header), *(line(c) for c in cells), *notes, *_unresolved(df)])


def _unresolved(df: pd.DataFrame) -> list[str]:
    """`  - scene / engine: status: message` per row without a result (skipped, unstable, ...) or without a reference
    to compare it with (an ok row whose scene's reference was refused): the terminal names the reason, the limit and
    the fix, as the report's "Rows without a result" does."""
    if "message" not in df or "status" not in df:
        return []
    out = []
    for _, r in df.iterrows():
        msg = r["message"]
        unchecked = str(r["status"]) == "ok" and isinstance(msg, str) and msg.startswith(NO_REFERENCE)
        if (str(r["status"]) != "ok" or unchecked) and isinstance(msg, str) and msg.strip():
            out.append(f"  - {r['scene']} / {r['engine']}: {r['status']}: {' '.join(msg.split())}")
    return out


def _md_table(header: list[str], cells: Iterable[list[str]], right: list[bool] | None = None) -> list[str]:
    right = right or [False] * len(header)
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---:" if r else "---" for r in right) + "|"]
    for c in cells:
        out.append("| " + " | ".join(str(x).replace("|", "\\|") for x in c) + " |")
    return out


def _score(r) -> tuple[float, str]:
    best, name = math.nan, ""
    for m in ("t_m", "f_m", "delta_m"):
        v = abs(_num(r[f"err_{m}"]))
        if math.isfinite(v) and not (v <= best):
            best, name = v, m
    return best, name


def summary_section(df: pd.DataFrame, cmp: pd.DataFrame | None = None, trend: pd.DataFrame | None = None) -> list[str]:
    """Per engine: jobs, status counts, worst |error| (metric, scene, value in %), regressions."""
    from impactval.reference.result import FAILED

    failed = {str(s) for s in FAILED}
    out = ["## Summary", ""]
    header = ["engine", "version", "jobs", "ok", "failed", "other", "worst error", "where"]
    if cmp is not None:
        header += ["regressions", "fixed/better"]
    if trend is not None and len(trend):
        header += ["slower"]
    cells = []
    for engine, g in df.groupby("engine", sort=False):
        st = g["status"].astype(str)
        worst, where = math.nan, ""
        for _, r in g[st == "ok"].iterrows():
            s, m = _score(r)
            if math.isfinite(s) and not (s <= worst):
                worst, where = s, f"{m}, {r['scene']}"
        others = st[(st != "ok") & ~st.isin(failed)]
        other = ", ".join(f"{n} {k}" for k, n in others.value_counts().items())
        bad = st[st.isin(failed)]
        failed_txt = ", ".join(f"{n} {k}" for k, n in bad.value_counts().items()) or "0"
        versions = ", ".join(sorted({str(v) for v in g.get("version", pd.Series(dtype=str)).dropna() if str(v)}))
        row = [str(engine), versions, str(len(g)), str(int((st == "ok").sum())), failed_txt, other or "0",
               "" if not math.isfinite(worst) else f"{100 * worst:.3f} %", where]
        if cmp is not None:
            c = cmp[cmp["engine"] == engine]
            reg = c[c["mark"].isin(["+", "!"])]
            row.append("; ".join(f"{r['mark']} {r['scene']}: {_short_why(r)}" for _, r in reg.iterrows()) or "none")
            good = c[c["mark"].isin(["*", "-"])]
            row.append(str(len(good)))
        if trend is not None and len(trend):
            t = trend[(trend["engine"] == engine) & (trend["state"] == "slower")]
            row.append(", ".join(f"{r['scene']} x{r['ratio']:.2f}" for _, r in t.iterrows()) or "none")
        cells.append(row)
    out += _md_table(header, cells)
    out += _incomplete_line(df)
    out += ["", "Errors are signed relative differences (engine - reference) / reference in %; the worst error "
            "is the largest |error| of t_m, f_m, delta_m over the engine's rows. Failed: crashed, timeout, "
            "unstable, no-contact (`impactval run` exits 1; a sweep or a map, whose grids step past limits on "
            "purpose, does not); other: not-installed, skipped, interrupted (informative).", ""]
    return out


def _incomplete_line(df: pd.DataFrame) -> list[str]:
    """Under the summary table of a run stopped before some jobs finished (rows of status `interrupted`): that the
    run is incomplete, and which engines lost how many jobs (an engine that never ran shows "none ran")."""
    from impactval.reference.result import Status

    stopped = df[df["status"].astype(str) == Status.INTERRUPTED.value]
    if not len(stopped):
        return []
    per = []
    for engine, g in df.groupby("engine", sort=False):
        n_stopped = int((g["status"].astype(str) == Status.INTERRUPTED.value).sum())
        if n_stopped:
            per.append(f"{engine} ({'none' if n_stopped == len(g) else len(g) - n_stopped} of its {len(g)} "
                       f"job{'s' if len(g) != 1 else ''} ran)")
    return ["", f"**Incomplete**: {len(stopped)} of {len(df)} jobs did not run (status `interrupted`: the run was "
                f"stopped before they finished): {', '.join(per)}. The counts and worst errors above cover only the "
                f"jobs that ran."]


def comparison_section(cmp: pd.DataFrame, baseline: str, checks=None, trend: pd.DataFrame | None = None) -> str:
    """The comparison with the baseline: thresholds, counts, flagged rows with numbers, then every row."""
    from impactval.history import check_names, summary_counts

    counts = summary_counts(cmp)
    out = ["", "## Against the baseline", "",
           f"Baseline: {baseline}. Thresholds (growth of |error| that flags a row): {check_names(checks)}. "
           f"Rows are compared only with the same scene, engine, contact, integrator, dt and N and the same scene "
           f"hash (scene + reference version); the engine version is a separate axis and named where it changed.",
           "",
           "Marks: " + "; ".join(f"`{m}` {text}" for m, text in MARKS.items()) + ".", "",
           f"Counts: {counts['!']} newly failing, {counts['+']} worse, {counts['*']} fixed, {counts['-']} better, "
           f"{counts['x']} not comparable, {counts['changed']} of {len(cmp)} rows changed at all.", ""]
    flagged = cmp[cmp["mark"] != ""]
    order = {"!": 0, "+": 1, "*": 2, "-": 3, "x": 4}
    if len(flagged):
        for _, r in flagged.sort_values("mark", key=lambda s: s.map(order), kind="stable").iterrows():
            out.append(f"- `{r['mark']}` {r['scene']} / {r['engine']} ({r['contact']}, dt = {_dt(r['dt'])} s"
                       f"{', N = ' + _seg(r['segments']) if _seg(r['segments']) else ''}): {r['why']}")
        out.append("")
    header = ["mark", "scene", "engine", "contact", "dt [s]", "N", "version", "baseline %", "now %", "change"]
    cells = []
    for _, r in cmp.sort_values("mark", key=lambda s: s.map(lambda m: order.get(m, 5)), kind="stable").iterrows():
        ch = _num(r["change"])
        version = r["version"] if r["old_version"] == r["version"] else f"{r['old_version']} -> {r['version']}"
        cells.append([r["mark"], r["scene"], r["engine"], r["contact"], _dt(r["dt"]), _seg(r["segments"]),
                      version, _pct_abs(r["old_score"]), _pct_abs(r["score"]),
                      "" if not math.isfinite(ch) else f"{100 * ch:+.1f} %"])
    out += ["Largest |error| of t_m, f_m, delta_m per row, in %:", ""]
    out += _md_table(header, cells, [False] * 4 + [True, True, False, True, True, True])
    if trend is not None and len(trend) and trend["state"].astype(str).str.startswith("not enough history").all():
        out += ["", "### Stepping wall time over the history", "",
                f"Not enough history yet: wall-time steps are judged from {2 * _window()} nights on "
                f"(now at most {int(pd.to_numeric(trend['nights']).max())})."]
    elif trend is not None and len(trend):
        out += ["", "### Stepping wall time over the history", "",
                "Wall times are noisy: a row is flagged only when each of the last nights is past the threshold "
                "against the median of the nights before (a step that persists).", ""]
        tcells = [[r["scene"], r["engine"], r["contact"], _dt(r["dt"]), _seg(r["segments"]), r["state"],
                   str(r["nights"]), _ms(r["before_s"]), _ms(r["after_s"]),
                   "" if not math.isfinite(_num(r["ratio"])) else f"{_num(r['ratio']):.2f}"]
                  for _, r in trend.iterrows()]
        out += _md_table(["scene", "engine", "contact", "dt [s]", "N", "state", "nights", "before ms", "last ms",
                          "ratio"], tcells, [False] * 6 + [True] * 4)
    return "\n".join(out) + "\n"


def _window() -> int:
    from impactval.history import WALL_WINDOW

    return WALL_WINDOW


def _short_why(r) -> str:
    """The regressed row's worst metric with its numbers (the full reason is in the comparison)."""
    if r["mark"] != "+":
        return str(r["why"])
    parts = [p.strip() for p in str(r["why"]).split(";")]
    changes = [(abs(_num(r.get(f"change_{p.split()[0]}"))), p) for p in parts if p.split() and
               math.isfinite(_num(r.get(f"change_{p.split()[0]}")))]
    return max(changes)[1] if changes else str(r["why"])


def reference_section(references: pd.DataFrame) -> list[str]:
    """Reference values per scene with their provenance (closed form / Volterra solver with its
    uncertainty / literature), as code_aster tags its reference values."""
    out = ["## Reference values", "",
           "What every error above is measured against. Provenance: *closed form* (exact formula), *Volterra "
           "solver* (impactval's Hertz/modal solver; ± is its checked uncertainty bound), *literature* (published "
           "value).", ""]
    cells = []
    for _, r in references.iterrows():
        def pm(v, u, k, digits):
            v, u = _num(v), _num(u)
            if not math.isfinite(v):
                return ""
            return f"{v * k:.{digits}g}" + (f" ± {u * k:.1g}" if math.isfinite(u) and u > 0 else "")

        cells.append([r["scene"], pm(r["t_m"], r.get("u_t_m"), 1e6, 9), pm(r["f_m"], r.get("u_f_m"), 1, 9),
                      pm(r["delta_m"], r.get("u_delta_m"), 1e6, 9), _int(r.get("n_contacts")),
                      _int(r.get("modes")), str(r.get("provenance", ""))])
    out += _md_table(["scene", "t_m [us]", "f_m [N]", "delta_m [um]", "contacts", "modes", "provenance"], cells,
                     [False, True, True, True, True, True, False])
    warnings = [f"- {r['scene']}: {w}" for _, r in references.iterrows()
                for w in (r.get("validity") if isinstance(r.get("validity"), (tuple, list)) else ())]
    if warnings:
        out += ["", "Where a reference stretches its own assumptions (the engines are compared with it all the same; "
                "an engine that models what the reference leaves out may differ by that much):", "", *warnings]
    return out + [""]


def header_section(info: Mapping[str, Any] | None, settings=None, df: pd.DataFrame | None = None) -> list[str]:
    """Title and one line per fact: run, date, how it ended, versions, machine, settings."""
    info = dict(info or {})
    # the title names the command that made the rows ("impactval sweep" for a re-rendered sweep), "impactval run"
    # when nothing says (reports.build.run_info gives the stored command in backticks)
    words = str(info.get("command") or "").strip("`").split()
    made_by = f"impactval {words[1]}" if len(words) > 1 and words[0] == "impactval" else "impactval run"
    out = [f"# {info.pop('title', None) or made_by}", ""]
    labels = (("verdict", "verdict"), ("run_id", "run"), ("command", "command"), ("started", "started"),
              ("finished", "finished"),
              ("ended", "how it ended"), ("versions", "versions"), ("machine", "machine"), ("suite", "suite"))
    for key, label in labels:
        v = info.get(key)
        if v in (None, "", {}):
            continue
        if isinstance(v, Mapping):
            v = ", ".join(f"{k} {x}" for k, x in v.items())
        out.append(f"- **{label}**: {v}")
    if settings is not None:
        asked = _dt(settings.dt)
        auto = not math.isfinite(_num(settings.dt))      # "auto": each engine chose its own step
        used = ""
        if df is not None and len(df) and "dt" in df:
            used = ", ".join(f"{x:g}" for x in sorted(set(pd.to_numeric(df["dt"], errors="coerce").dropna()),
                                                       reverse=True))
        # the steps the rows carry first, then (at --dt auto) that the engines chose them, not the user
        steps = (f"{used} s" if used else f"{asked} (no row stepped)" if auto else f"{asked} s")
        chosen = f" (--dt {asked}: the engines chose these steps)" if auto and used else ""
        out.append(f"- **settings**: dt = {steps}, contact = {settings.contact}, integrator = "
                   f"{settings.integrator or 'engine default'}, segments = {settings.segments or 'engine default'}, "
                   f"timeout = {settings.timeout_s:g} s{chosen}")
    return out + [""] if len(out) > 2 else out


def markdown_report(df: pd.DataFrame, settings=None, *, info: Mapping[str, Any] | None = None,
                    cmp: pd.DataFrame | None = None, baseline: str | None = None, checks=None,
                    trend: pd.DataFrame | None = None, references: pd.DataFrame | None = None,
                    figures: Iterable[tuple[str, str]] = ()) -> str:
    """report.md of a run.

    Parameters
    ----------
    df : the run's rows (impactval.runner.COLUMNS)
    settings : EngineSettings of the run, optional (shown in the header)
    info : header facts (run_id, command, started, finished, ended, versions, machine, suite), optional
    cmp, baseline, checks : comparison with a baseline (impactval.history.compare), its name and thresholds
    trend : wall-time steps over the history (impactval.history.wall_time_steps)
    references : one row per scene: t_m [s], f_m [N], delta_m [m], u_* (absolute), n_contacts, modes, provenance
    figures : (caption, relative path of a PNG) pairs, shown after the summary
    """
    out = header_section(info, settings, df)
    out += summary_section(df, cmp, trend)
    if cmp is not None:
        out += comparison_section(cmp, baseline or "the baseline", checks, trend).splitlines()
        out.append("")
    figures = list(figures)
    if figures:
        out += ["## Figures", ""]
        for caption, path in figures:
            out += [f"![{caption}]({path})", "", f"*{caption}*", ""]
    marks = None
    if cmp is not None and len(cmp):
        from impactval.history import row_key

        marks = {row_key(r): r["mark"] for _, r in cmp.iterrows()}
    header, cells, right = table_rows(df, marks)
    out += ["## Results", "",
            "Errors in % (engine - reference) / reference; `curve` is the RMS of f(t) - f_ref(t) over the first "
            "contact divided by the reference f_m; `lin` columns compare a native (linear) contact with the "
            "linear-theory reference for the same spring; `C vs Warp` columns (MuJoCo Warp rows) are "
            "(Warp - C) / C on the identical model run in MuJoCo C; `contacts` counts contact phases in the "
            "simulated window; wall times in ms. Columns empty in every row are left out.", ""]
    out += _md_table(header, cells, right)
    out.append("")
    out += error_source_section(df)
    if references is not None and len(references):
        out += reference_section(references)
    out += notes_section(df)
    bad = df[df["status"].astype(str) != "ok"]
    if len(bad):
        out += ["## Rows without a result", ""]
        for _, r in bad.iterrows():
            out.append(f"- {r['scene']} / {r['engine']}: **{r['status']}**: {' '.join(str(r['message']).split())}")
        out.append("")
    out += frequency_section(df)
    return "\n".join(out).rstrip() + "\n"


#: modes listed per row in the frequency section
N_MODES_SHOWN = 4


def _freqs(r, key: str) -> list[float]:
    text = r.get(key, "") if hasattr(r, "get") else ""
    return json.loads(text) if isinstance(text, str) and text else []


def frequency_section(df: pd.DataFrame) -> list[str]:
    """Each engine structure model's lowest frequencies next to the continuum's: Euler-Bernoulli
    (what the adapters report as continuum) and, for beams, Timoshenko."""
    if "structure_frequencies" not in df:
        return []
    freq = df[df["structure_frequencies"].fillna("").astype(str).str.len() > 0]
    if not len(freq):
        return []
    out = ["## Structure model frequencies [rad/s] (engine model vs continuum)", "",
           "Each mode: the engine model's frequency, then its signed difference to the Euler-Bernoulli continuum "
           "(EB; for a modal target the scene's given frequencies) and, for beams, to the Timoshenko beam (both "
           "spectra in frequency order).", ""]
    for _, r in freq.drop_duplicates(["scene", "engine", "segments"]).iterrows():
        s, c, t = (_freqs(r, k) for k in ("structure_frequencies", "continuum_frequencies", "timoshenko_frequencies"))
        # a beam's continuum is Euler-Bernoulli's; a modal target's is the scene's own list ("EB" there named a beam
        # that does not exist: user test s20)
        theory = str(r["beam_theory"]) if "beam_theory" in r and isinstance(r["beam_theory"], str) else None
        beam = theory is None or bool(theory.strip()) or bool(t)    # an older store (no column): as before
        items = []
        for i, a in enumerate(s[:N_MODES_SHOWN]):
            diffs = [f"{label} {100 * (a / ref[i] - 1):+.2f} %" for label, ref in
                     (("EB" if beam else "given", c), ("Timoshenko", t)) if i < len(ref) and ref[i] > 0]
            items.append(f"{a:.1f}" + (f" ({', '.join(diffs)})" if diffs else ""))
        out.append(f"- {r['scene']} / {r['engine']} (N = {_seg(r['segments'])}): {'; '.join(items)}")
    return out + [""]


#: a theory gap smaller than this (fraction, every metric) does not tell the two theories apart
GAP_RESOLVED = 1e-3
#: a structure error within this fraction of |gap| of a theory counts as "like" that theory
GAP_LIKE = 0.25
_THEORY = {"euler-bernoulli": "Euler-Bernoulli", "timoshenko": "Timoshenko"}
_METRICS = ("t_m", "f_m", "delta_m")


def _theory_verdict(r, scene_theory: str, other: str) -> str:
    """Which beam theory the engine's structure model behaves like, when the numbers say so."""
    s = [_num(_col(r, f"structure_err_{m}")) for m in _METRICS]
    g = [_num(_col(r, f"theory_gap_{m}")) for m in _METRICS]
    if not all(math.isfinite(x) for x in s + g):
        return ""
    if max(abs(x) for x in g) < GAP_RESOLVED:
        return "; the two theories agree here, so the structure part is the model's own discretisation"
    if all(abs(a - b) <= GAP_LIKE * abs(b) for a, b in zip(s, g)):
        return f"; its structure model behaves like {_THEORY[other]}'s"
    if all(abs(a) <= GAP_LIKE * abs(b) for a, b in zip(s, g)):
        return f"; its structure model behaves like {_THEORY[scene_theory]}'s"
    rest = " (the rest: the model's own discretisation or mode count)"
    own = _spectrum_follows(r, scene_theory, other)
    if own is not None and all(abs(a - b) < abs(a) for a, b in zip(s, g)):
        # the answer moved toward the other theory, but the spectrum is the scene theory's: a stiffer (or softer)
        # discretisation of the right theory, not the other theory (Exudyn's solid on a Timoshenko cantilever)
        return (f"; its structure model follows {_THEORY[scene_theory]}'s spectrum (first frequencies within "
                f"{100 * own:.2g} %), so its structure error is the model's own discretisation, not "
                f"{_THEORY[other]}'s theory")
    gap = _first_mode_gap(r, scene_theory)
    if gap:
        # the model's own first modes are off the scene theory's: that is a cause more modes cannot remove (Exudyn's
        # solid on a wide clamped PMMA beam, fz3002: 3.6-5.0 % stiffer, and the text blamed "discretisation or mode
        # count"; 20 -> 36 modes moved f_m by 0.11 points of its 1.06 %)
        return gap
    if all(abs(a - b) < abs(a) for a, b in zip(s, g)):
        return f"; its structure model is closer to {_THEORY[other]}'s than to {_THEORY[scene_theory]}'s" + rest
    if all(abs(a - b) > abs(a) for a, b in zip(s, g)):
        return f"; its structure model is closer to {_THEORY[scene_theory]}'s than to {_THEORY[other]}'s" + rest
    return ("; neither theory alone explains its structure error (the model's own discretisation or mode count "
            "is part of it)")


#: the first-mode gap the split names as a cause: engines.base FREQ_GAP, the threshold of the Exudyn adapter's note too
from impactval.engines.base import FREQ_GAP, FREQ_GAP_MODES  # noqa: E402


def _first_mode_gap(r, scene_theory: str) -> str:
    """The split's text when the model's first frequencies all sit more than FREQ_GAP on one side of the scene
    theory's ("" otherwise, or when the frequencies are unknown)."""
    s, c, t = (_freqs(r, k) for k in ("structure_frequencies", "continuum_frequencies", "timoshenko_frequencies"))
    ref = t if scene_theory == "timoshenko" else c
    n = min(len(s), len(ref), FREQ_GAP_MODES)
    if n == 0 or any(x <= 0 for x in ref[:n]):
        return ""
    gaps = [s[i] / ref[i] - 1.0 for i in range(n)]
    lo, hi = min(gaps), max(gaps)
    if max(abs(lo), abs(hi)) <= FREQ_GAP or lo * hi <= 0:
        return ""
    alt = c if scene_theory == "timoshenko" else t
    if len(alt) >= n and all(x > 0 for x in alt[:n]) and max(abs(s[i] / alt[i] - 1.0) for i in range(n)) <= FREQ_GAP:
        return ""           # it follows the other theory's spectrum: a theory question, not discretisation
    way = "stiffer" if lo > 0 else "softer"
    return (f"; its first {n} modes are {100 * min(abs(lo), abs(hi)):.1f}-{100 * max(abs(lo), abs(hi)):.1f} % {way} "
            f"than {_THEORY[scene_theory]}'s: the model's own structure (3-D elasticity, its mesh) is in its structure "
            f"error, and more modes will not remove that part (the row's notes split it from the truncation where the "
            f"engine estimates it)")


#: a model "follows" a theory's spectrum when its worst frequency difference to it is this many times smaller
SPECTRUM_CLEAR = 3.0


def _spectrum_follows(r, scene_theory: str, other: str) -> float | None:
    """The model's worst relative frequency difference to the scene theory's spectrum when that is
    SPECTRUM_CLEAR times smaller than to the other theory's (None: unknown or not clear)."""
    s, c, t = (_freqs(r, k) for k in ("structure_frequencies", "continuum_frequencies", "timoshenko_frequencies"))
    n = min(len(s), len(c), len(t), N_MODES_SHOWN)
    if n == 0:
        return None
    worst = {th: max(abs(s[i] / ref[i] - 1.0) for i in range(n))
             for th, ref in (("euler-bernoulli", c), ("timoshenko", t))}
    if worst[scene_theory] * SPECTRUM_CLEAR < worst[other]:
        return worst[scene_theory]
    return None


def _frequency_note(r) -> str:
    """How far the model's first frequencies are from each theory's (largest |difference|), when both are known."""
    s, c, t = (_freqs(r, k) for k in ("structure_frequencies", "continuum_frequencies", "timoshenko_frequencies"))
    n = min(len(s), len(c), len(t), N_MODES_SHOWN)
    if n == 0:
        return ""

    def worst(ref):
        return max((s[i] / ref[i] - 1.0 for i in range(n)), key=abs)

    return (f"; its first {n} frequencies differ by up to {100 * worst(t):+.2f} % from Timoshenko's, "
            f"{100 * worst(c):+.2f} % from EB's")


def error_source_section(df: pd.DataFrame) -> list[str]:
    """"Where the error comes from": per engine row on a beam (or with a structure model error), the
    error of each metric as structure (the engine's structure model vs the continuum) + numerics
    (what its integrator and contact numerics add), and the scene's theory gap (the other beam
    theory's reference vs this one)."""
    cols = [f"{p}_{m}" for p in ("structure_err", "theory_gap") for m in _METRICS]
    if not any(c in df for c in cols):
        return []
    ok = df[df["status"].astype(str) == "ok"]
    has = ok[[c for c in cols if c in ok]].apply(pd.to_numeric, errors="coerce").notna().any(axis=1)
    rows = ok[has]
    if not len(rows):
        return []
    out = ["## Where the error comes from", "",
           "Per metric, error = structure + numerics (signed, in % of the scene's reference): *structure* is the "
           "engine's structure model against the scene's continuum (the reference solved on the model's own "
           "modes), *numerics* what the engine's integrator and contact add (a linear contact law: its error against the "
           "linear theory for the same spring, the structure model measured under that spring). The *theory gap* is the reference "
           "solved with the other beam theory against the scene's: the size of the structure-theory question.", ""]
    for _, r in rows.iterrows():
        scene = str(r["scene"])
        theory = str(_col(r, "beam_theory") or "euler-bernoulli")
        theory = theory if theory in _THEORY else "euler-bernoulli"
        other = "timoshenko" if theory == "euler-bernoulli" else "euler-bernoulli"
        label = ", ".join(x for x in (str(r["contact"]), f"dt = {_dt(r['dt'])} s",
                                      f"N = {_seg(r['segments'])}" if _seg(r["segments"]) else "") if x)
        parts = []
        linear = str(_col(r, "contact_law")) == "linear"
        for m in _METRICS:
            e, s, n = (_num(_col(r, f"{p}_{m}")) for p in ("err", "structure_err", "numerics_err"))
            le = _num(_col(r, f"lin_err_{m}"))
            if linear and math.isfinite(s) and math.isfinite(n) and math.isfinite(le):
                # the runner splits a linear law's error against the linear theory (structure under that spring)
                parts.append(f"{m} {_pct(e)} % (against the linear theory {_pct(le)} % = structure {_pct(s)} % "
                             f"+ numerics {_pct(n)} %)")
            elif math.isfinite(s) and math.isfinite(n):
                parts.append(f"{m} {_pct(e)} % = structure {_pct(s)} % + numerics {_pct(n)} %")
            elif math.isfinite(s):
                why = "linear contact law: see the lin columns" if str(_col(r, "contact_law")) == "linear" \
                    else "not split"
                parts.append(f"{m} {_pct(e)} % (structure {_pct(s)} %; {why})")
            else:
                parts.append(f"{m} {_pct(e)} %")
        line = f"- {scene} / {r['engine']} ({label}): " + "; ".join(parts)
        if not any(math.isfinite(_num(_col(r, f"structure_err_{m}"))) for m in _METRICS):
            line += " (the adapter reports no structure model error)"
        gap = [_num(_col(r, f"theory_gap_{m}")) for m in _METRICS]
        if any(math.isfinite(x) for x in gap):
            line += (f". Theory gap {_short_theory(theory)} -> {_short_theory(other)}: "
                     + ", ".join(f"{m} {_pct(x)} %" for m, x in zip(_METRICS, gap)))
            line += _theory_verdict(r, theory, other) + _frequency_note(r)
        out.append(line + ".")
    return out + [""]


def _short_theory(theory: str) -> str:
    return "EB" if theory == "euler-bernoulli" else _THEORY.get(theory, theory)

