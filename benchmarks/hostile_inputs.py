"""Hostile inputs (issue 18): try what an adversarial user would, count the clean outcomes.

Every case runs in its own process (the CLI, or a `python -c` snippet for the Python API) with a
90 s limit; its peak memory comes from os.wait4. A case is *clean* when
- the exit code is 0 or 2 (1 only for `run`, which flags failing engine rows with it),
- no traceback appears,
- stdout holds no nan/inf where an answer is printed,
- it ends within 90 s and stays under 4 GB,
- a case that must be refused exits 2 with one `impactval: error:` line naming the field or option.

    python benchmarks/hostile_inputs.py [--only SUBSTRING] [--json out.json] [--jobs 1]

Prints one line per case that is not clean and the counts (total, by owner). Owners name who in
the team owns the fix (issue 18 was split); "hardening" is this branch.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import textwrap
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

LIMIT_S = 90.0
LIMIT_RSS_KB = 4 * 1024 * 1024
NONFINITE = re.compile(r"(?<![A-Za-z_/])(nan|NaN|-?inf|-?Infinity)(?![A-Za-z_])")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from hostile_cases import (API_EDGE, API_REFUSED_CASES, BAD_RANGE_CASES, BEAM, MODAL,  # noqa: E402
                           PLATE, named)  # the scene fixtures, range texts and API calls the tests use

GOOD_BEAM, GOOD_MODAL, GOOD_PLATE = named(BEAM, "hostile"), named(MODAL, "hostile_modal"), named(PLATE, "hostile_plate")


@dataclass
class Case:
    id: str
    argv: list[str] | None = None          # CLI arguments (after `impactval`)
    expect: str = "either"                  # "refuse" | "ok" | "either"
    names: str = ""                         # a refusal must mention this (field or option)
    owner: str = "hardening"
    files: dict[str, str] = field(default_factory=dict)   # files to write first (name -> text)
    code: str | None = None                 # Python API snippet (its value is printed), instead of argv


API_PRELUDE = """
import math, sys
import impactval
from impactval.errors import ImpactvalError
def _show(r):
    if hasattr(r, "t_m"):
        u = getattr(r, "uncertainty", None)
        print("t_m", r.t_m, "f_m", r.f_m, "delta_m", r.delta_m)
        if u is not None:
            print("uncertainty", u.t_m, u.f_m, u.delta_m)
    else:
        print(type(r).__name__)
try:
    _show(eval(compile(CODE, "<case>", "eval")))
except ImpactvalError as err:
    print(f"impactval: error: {err}", file=sys.stderr)
    sys.exit(2)
"""


def scene_cases(d: Path) -> list[Case]:
    """Scene-file cases: a good scene with one thing changed, run through `reference --json`."""
    out: list[Case] = []

    def sc(cid, base, old, new, expect="refuse", names="", owner="hardening", extra_args=()):
        text = base.replace(old, new, 1) if old else base + new
        assert text != base or not old, cid
        fname = f"{cid}.toml"
        out.append(Case(cid, ["reference", str(d / fname), "--tol", "1e-4", "--json", *extra_args], expect=expect,
                        names=names, owner=owner, files={fname: text}))

    B, M, P = GOOD_BEAM, GOOD_MODAL, GOOD_PLATE
    # --- ball numbers
    for v, e in (("1e300", "refuse"), ("1e-300", "refuse"), ("0", "refuse"), ("-0.01", "refuse"), ("nan", "refuse"),
                 ("inf", "refuse"), ("1" + "0" * 400, "refuse"), ('"0.01"', "refuse"), ("true", "refuse"),
                 ("1e-9", "refuse"), ("1e3", "refuse"), ("5e-5", "either"), ("[0.01]", "refuse"), ("{}", "refuse")):
        sc(f"radius={v[:12]}", P, "radius = 0.01", f"radius = {v}", e, "radius")
    for v, e in (("1e300", "refuse"), ("1e-300", "refuse"), ("1e5", "refuse"), ("1e-12", "refuse"), ("-0.0", "refuse"),
                 ("3e8", "refuse"), ("0.001", "either"), ("100.0", "either")):
        sc(f"velocity={v}", P, "velocity = 1.0", f"velocity = {v}", e, "velocity")
    for v, e in (("1e300", "refuse"), ("1e-300", "refuse"), ("0", "refuse"), ('"heavy"', "refuse"), ("[1.0]", "refuse"),
                 ("1e9", "refuse"), ("2.0", "either")):
        sc(f"mass={v}", P, 'material = "steel"\n[target]', f'material = "steel"\nmass = {v}\n[target]', e, "mass")
    sc("mass=1e300-beam", B, 'material = "steel"\n[target]', 'material = "steel"\nmass = 1e300\n[target]', "refuse", "mass")
    # --- materials
    mat = '\n[materials.x]\nyoung = {y}\npoisson = {p}\ndensity = {r}\n'
    for (y, p, r), key in (((1e300, 0.3, 7800), "young"), ((1e-300, 0.3, 7800), "young"), ((1.0, 0.3, 7800), "young"),
                           ((2e11, 0.5, 7800), "poisson"), ((2e11, -1.0, 7800), "poisson"), ((2e11, "nan", 7800), "poisson"),
                           ((2e11, 0.3, 1e300), "density"), ((2e11, 0.3, 1e-300), "density"), ((2e11, 0.3, 0), "density")):
        sc(f"material-{key}={y:g},{p},{r:g}", P.replace('material = "steel"', 'material = "x"'), None,
           mat.format(y=y, p=p, r=r), "refuse", key)
    sc("material-ok-rubber", P.replace('material = "steel"', 'material = "x"'), None,
       mat.format(y=1e7, p=0.49, r=1100), "either")
    out.append(Case("materials-not-table", ["reference", str(d / "mnt.toml"), "--json"], expect="refuse", names="materials",
                    files={"mnt.toml": "materials = 5\n" + P}))
    sc("material-name-quote", P.replace('material = "steel"', 'material = "a\\"b"', 1), None,
       '\n[materials."a\\"b"]\nyoung = 2e11\npoisson = 0.3\ndensity = 7800\n', "refuse", "materials")
    sc("material-name-newline", P.replace('material = "steel"', 'material = "a\\nb"', 1), None,
       '\n[materials."a\\nb"]\nyoung = 2e11\npoisson = 0.3\ndensity = 7800\n', "refuse", "materials")
    sc("material-wrong-type", P, 'material = "steel"', "material = 7", "refuse", "material")
    # --- beam numbers
    for key, old in (("length", "length = 0.5"), ("width", "width = 0.01"), ("height", "height = 0.01")):
        for v in ("1e300", "1e-300", "1e5", "1e-9"):
            sc(f"{key}={v}", B, old, f"{key} = {v}", "refuse", key)
    for v, e in (("1e-300", "refuse"), ("0.9999999999", "either"), ("0", "refuse"), ("-0.5", "refuse"),
                 ("nan", "refuse"), ('"mid"', "refuse")):
        sc(f"impact_at={v}", B, "impact_at = 0.5", f"impact_at = {v}", e, "impact_at")
    for v, e in (("10" + "0" * 30, "refuse"), ("2.5", "refuse"), ("-3", "refuse"), ("true", "refuse"), ("3", "either")):
        sc(f"modes={v[:10]}", B, "impact_at = 0.5", f"impact_at = 0.5\nmodes = {v}", e, "modes")
    sc("modes=100000", B, "impact_at = 0.5", "impact_at = 0.5\nmodes = 100000", "either", owner="ref-core")
    sc("support=5", B, 'support = "simply-supported"', "support = 5", "refuse", "support")
    sc("support=list", B, 'support = "simply-supported"', 'support = ["a"]', "refuse", "support")
    sc("kind=table", B, 'kind = "beam"', "kind = {a = 1}", "refuse", "kind")
    sc("slender-aspect", B, "height = 0.01", "height = 2.0", "either")
    # --- modal numbers
    for key, val in (("omega", "[1e-300, 120000.0]"), ("omega", "[1e300, 120000.0]"), ("omega", "[0.0, 1.0]"),
                     ("modal_mass", "[1e-300, 0.8]"), ("modal_mass", "[1e300, 0.8]"), ("phi", "[1e300, 0.7]"),
                     ("phi", "[nan, 0.7]"), ("omega", "[]"), ("omega", "[[1.0], [2.0]]"), ("omega", '["a", "b"]'),
                     ("phi", "[5.0, 0.7]")):
        old = {"omega": "omega = [30000.0, 120000.0]", "modal_mass": "modal_mass = [0.5, 0.8]",
               "phi": "phi = [1.0, 0.7]"}[key]
        sc(f"{key}={val[:14]}", M, old, f"{key} = {val}", "refuse", key)
    sc("phi=[1e-300,1e-300]", M, "phi = [1.0, 0.7]", "phi = [1e-300, 1e-300]", "either")
    sc("phi=[0,0]", M, "phi = [1.0, 0.7]", "phi = [0.0, 0.0]", "either")
    sc("phi=[-1,0.7]", M, "phi = [1.0, 0.7]", "phi = [-1.0, 0.7]", "either")
    many = ", ".join(["30000.0"] * 100001)
    out.append(Case("modal-100001-modes", ["reference", str(d / "m100001.toml"), "--json", "--tol", "1e-3"],
                    expect="refuse", names="omega",
                    files={"m100001.toml": M.replace("omega = [30000.0, 120000.0]", f"omega = [{many}]")
                    .replace("modal_mass = [0.5, 0.8]", f"modal_mass = [{', '.join(['0.5'] * 100001)}]")
                    .replace("phi = [1.0, 0.7]", f"phi = [{', '.join(['0.5'] * 100001)}]")}))
    sc("modal-light-structure", M, "modal_mass = [0.5, 0.8]", "modal_mass = [1e-9, 1e-9]", "either")
    sc("modal-low-omega", M, "omega = [30000.0, 120000.0]", "omega = [0.01, 0.02]", "either")
    sc("modal-high-omega", M, "omega = [30000.0, 120000.0]", "omega = [1e9, 2e9]", "either")
    # --- names, tags, descriptions reaching MJCF / CSV / markdown / file names
    for label, v in (("quote", '"a\\"b"'), ("newline", '"a\\nb"'), ("slash", '"../../tmp/evil"'), ("empty", '""'),
                     ("space", '" "'), ("long", '"' + "x" * 5000 + '"'), ("html", '"<script>alert(1)</script>"'),
                     ("pipe", '"a|b"'), ("ansi", '"\\u001b[31mred"'), ("nul", '"a\\u0000b"'), ("int", "5"),
                     ("xml-amp", '"a&b"'), ("dash-start", '"-rf"')):
        sc(f"name-{label}", P, 'name = "hostile_plate"', f"name = {v}", "refuse", "name")
    sc("name-ok-unicode", P, 'name = "hostile_plate"', 'name = "Stahl_3"', "either")
    for label, v in (("newline", '["a\\nb"]'), ("string", '"nightly"'), ("empty", '[""]'), ("int", "[1]"),
                     ("html", '["<b>x</b>"]')):
        out.append(Case(f"tags-{label}", ["reference", str(d / f"tags-{label}.toml"), "--json"], expect="refuse",
                        names="tags", files={f"tags-{label}.toml": f"tags = {v}\n" + P}))
    for label, v, e in (("newline", '"a\\nb"', "refuse"), ("ansi", '"\\u001b[2J"', "refuse"),
                        ("huge", '"' + "y" * 100000 + '"', "refuse"), ("int", "3", "refuse"), ("ok", '"fine | text"', "either")):
        out.append(Case(f"description-{label}", ["reference", str(d / f"desc-{label}.toml"), "--json"], expect=e,
                        names="description", files={f"desc-{label}.toml": f"description = {v}\n" + P}))
    # --- structure of the file
    for label, text, names in (
            ("empty-file", "", "missing"), ("target-int", P.replace('[target]\nkind = "rigid-plate"\nmaterial = "steel"\n', "") + "target = 5\n", "target"),
            ("ball-list", "ball = []\n" + P.split("[ball]")[1].split("[target]", 1)[0].replace("radius", "#") + "[target]\nkind = \"rigid-plate\"\nmaterial = \"steel\"\n", "ball"),
            ("unknown-top", "colour = 1\n" + P, "colour"), ("binary", "\x00\x01\x02\xff", ""),
            ("deep-nesting", "name = " + "[" * 5000 + "]" * 5000 + "\n" + P.replace('name = "hostile_plate"\n', ""), ""),
            ("malformed", "[ball\n", "TOML"),
            ("int-5000-digits", P.replace("radius = 0.01", "radius = 1" + "0" * 5000), "")):
        out.append(Case(f"file-{label}", ["reference", str(d / f"file-{label}.toml"), "--json"], expect="refuse",
                        names=names, files={f"file-{label}.toml": text}))
    out.append(Case("file-bom", ["reference", str(d / "file-bom.toml"), "--json"], expect="ok",
                    files={"file-bom.toml": "\ufeff" + P}))
    return out


def cli_cases(d: Path) -> list[Case]:
    f = d / "a_file"
    cases = [
        Case("scenes --tag nosuchtag", ["scenes", "--tag", "nosuchtag"], "refuse", "tag"),
        Case("scenes --tag ''", ["scenes", "--tag", ""], "refuse", "tag"),
        Case("scenes --tag nightly", ["scenes", "--tag", "nightly"], "ok"),
        Case("reference nosuch", ["reference", "nosuchscene"], "refuse", "nosuchscene"),
        Case("reference ''", ["reference", ""], "refuse", "scene"),
        Case("reference NUL", ["reference", "a\x01b"], "refuse", "scene"),
        Case("reference long name", ["reference", "x" * 5000], "refuse", "scene"),
        Case("reference dir", ["reference", str(d)], "refuse", ""),
        Case("reference dir.toml", ["reference", str(d / "dir.toml")], "refuse", ""),
        Case("reference /dev/null", ["reference", "/dev/null"], "refuse", ""),
        Case("reference plate_steel.toml missing", ["reference", "nosuch.toml"], "refuse", "nosuch"),
        Case("reference plate_steel ok", ["reference", "plate_steel", "--json"], "ok"),
        Case("reference modal ok", ["reference", "modal_two_mode", "--tol", "1e-4"], "ok"),
    ]
    for v, e in (("nan", "refuse"), ("inf", "refuse"), ("-1", "refuse"), ("0", "refuse"), ("1", "refuse"),
                 ("1e-13", "refuse"), ("abc", "refuse"), ("1e-300", "refuse"), ("1e-12", "either"), ("0.1", "either")):
        cases.append(Case(f"reference --tol {v}", ["reference", "plate_steel", "--tol", v, "--json"], e, "tol"))
    cases.append(Case("reference beam --tol 1e-12", ["reference", "beam_ss_midspan", "--tol", "1e-12", "--json"], "either"))
    for v, e, owner in (("-1", "refuse", "hardening"), ("nan", "refuse", "hardening"), ("inf", "refuse", "hardening"),
                        ("1e-300", "either", "hardening"), ("1e9", "refuse", "ref-core")):
        cases.append(Case(f"reference --window {v}", ["reference", "plate_steel", "--window", v, "--json"], e,
                          "window", owner))
    cases.append(Case("reference heavy --window 1000", ["reference", "heavy_ball_slender_beam", "--window", "1000",
                                                         "--tol", "1e-4"], "either", "window", "ref-core"))
    cases.append(Case("reference heavy --window 0.05", ["reference", "heavy_ball_slender_beam", "--window", "0.05",
                                                         "--tol", "1e-4", "--json"], "either", "window", "ref-core"))
    for label, path in (("under-file", f"{f}/x.csv"), ("unwritable", "/proc/nope/x.csv"), ("is-dir", str(d)),
                        ("empty", ""), ("missing-parent", str(d / "no" / "such" / "dir" / "x.csv"))):
        e = "either" if label == "missing-parent" else "refuse"
        cases.append(Case(f"reference --curve {label}", ["reference", "plate_steel", "--curve", path], e, "--curve"))
        cases.append(Case(f"reference --model linear --curve {label}",
                          ["reference", "plate_steel", "--model", "linear", "--curve", path], e, "--curve"))
    cases += [
        Case("reference --curve two scenes", ["reference", "plate_steel", "modal_two_mode", "--curve", str(d / "c.csv")],
             "refuse", "--curve"),
        Case("reference --model bad", ["reference", "plate_steel", "--model", "quadratic"], "refuse", "--model"),
        Case("reference --explain tol 0.1", ["reference", "modal_two_mode", "--explain", "--tol", "0.1"], "either"),
        Case("reference --model perturbation --json", ["reference", "modal_two_mode", "--model", "perturbation", "--json"], "ok"),
        Case("reference --model linear --window -1", ["reference", "plate_steel", "--model", "linear", "--window", "-1"],
             "refuse", "window"),
        Case("reference --model linear --tol nan", ["reference", "plate_steel", "--model", "linear", "--tol", "nan"],
             "refuse", "tol"),
        Case("reference --json --explain", ["reference", "plate_steel", "--json", "--explain"], "ok"),
        Case("reference unknown option", ["reference", "plate_steel", "--speed", "3"], "refuse", "--speed"),
    ]
    for label, path in (("under-file", f"{f}/rep"), ("unwritable", "/proc/nope/rep"), ("is-file", str(f)),
                        ("empty", "")):
        cases.append(Case(f"theory --out {label}", ["theory", "plate_steel", "--no-plot", "--out", path], "refuse", "--out"))
    cases += [
        Case("theory --tol nan", ["theory", "plate_steel", "--no-plot", "--tol", "nan", "--out", str(d / "th1")],
             "refuse", "tol"),
        Case("theory --tol 1", ["theory", "plate_steel", "--no-plot", "--tol", "1", "--out", str(d / "th2")],
             "refuse", "tol"),
        Case("theory ok", ["theory", "modal_two_mode", "--no-plot", "--out", str(d / "th3")], "ok"),
        Case("theory name-slash file", ["theory", str(d / "name-slash.toml"), "--no-plot", "--out", str(d / "th4")],
             "refuse", "name"),
    ]
    run = ["run", "plate_steel", "--out", str(d / "runs")]
    for label, args, e, names, owner in (
            ("--engines ''", ["--engines", ""], "refuse", "engine", "engines-v2"),
            ("--engines nosuch", ["--engines", "nosuch"], "refuse", "nosuch", "engines-v2"),
            ("--engines builtins:exit", ["--engines", "builtins:exit"], "refuse", "builtins:exit", "engines-v2"),
            ("--engines os:getcwd", ["--engines", "os:getcwd"], "refuse", "os:getcwd", "engines-v2"),
            ("--engines x:", ["--engines", "x:"], "refuse", "x:", "engines-v2"),
            ("--engines :", ["--engines", ":"], "refuse", "engine", "engines-v2"),
            ("--engines nosuch.mod:Cls", ["--engines", "nosuch.mod:Cls"], "refuse", "nosuch.mod", "engines-v2"),
            ("--option bullet.x=1", ["--option", "bullet.x=1"], "refuse", "bullet", "engines-v2"),
            ("--option x", ["--option", "x"], "refuse", "--option", "hardening"),
            ("--option =1", ["--option", "=1"], "refuse", "--option", "hardening"),
            ("--integrator nosuch", ["--integrator", "nosuch"], "refuse", "integrator", "engines-v2"),
            ("--dt nan", ["--dt", "nan"], "refuse", "--dt", "hardening"),
            ("--dt -1", ["--dt", "-1"], "refuse", "--dt", "hardening"),
            ("--dt 0", ["--dt", "0"], "refuse", "--dt", "hardening"),
            ("--dt inf", ["--dt", "inf"], "refuse", "--dt", "hardening"),
            ("--dt abc", ["--dt", "abc"], "refuse", "--dt", "hardening"),
            ("--dt 1e-6,abc", ["--dt", "1e-6,abc"], "refuse", "--dt", "hardening"),
            ("--dt ''", ["--dt", ""], "refuse", "--dt", "hardening"),
            ("--dt 1e-300", ["--dt", "1e-300"], "refuse", "--dt", "hardening"),
            ("--dt 10", ["--dt", "10"], "refuse", "--dt", "hardening"),
            ("--timeout nan", ["--timeout", "nan"], "refuse", "timeout", "hardening"),
            ("--timeout -1", ["--timeout", "-1"], "refuse", "timeout", "hardening"),
            ("--timeout 0", ["--timeout", "0"], "refuse", "timeout", "hardening"),
            ("--timeout inf", ["--timeout", "inf"], "refuse", "timeout", "hardening"),
            ("--tail -1", ["--tail", "-1"], "refuse", "tail", "hardening"),
            ("--tail nan", ["--tail", "nan"], "refuse", "tail", "hardening"),
            ("--tail inf", ["--tail", "inf"], "refuse", "tail", "hardening"),
            ("--tail 1e9", ["--tail", "1e9"], "refuse", "tail", "hardening"),
            ("--segments 0", ["--segments", "0"], "refuse", "--segments", "hardening"),
            ("--segments 10**12", ["--segments", "1000000000000"], "refuse", "--segments", "hardening"),
            ("--modes 10**9", ["--modes", "1000000000"], "refuse", "--modes", "hardening"),
            ("--threshold nan", ["--threshold", "nan"], "refuse", "threshold", "hardening"),
            ("--threshold -1", ["--threshold", "-1"], "refuse", "threshold", "hardening"),
            ("--tol nan", ["--tol", "nan"], "refuse", "tol", "hardening"),
            ("--tol 5", ["--tol", "5"], "refuse", "tol", "hardening"),
            ("--baseline missing", ["--baseline", str(d / "nope.csv")], "refuse", "baseline", "nightly"),
            ("--baseline dir", ["--baseline", str(d)], "refuse", "baseline", "nightly"),
            ("--baseline binary", ["--baseline", str(d / "binary.csv")], "refuse", "baseline", "nightly"),
            ("--baseline non-numeric", ["--baseline", str(d / "nonnum.csv")], "refuse", "baseline", "nightly"),
            ("--tol 1e-300", ["--tol", "1e-300"], "refuse", "tol", "hardening"),
    ):
        cases.append(Case(f"run {label}", run + args, e, names, owner))
    for label, path in (("under-file", f"{f}/runs"), ("unwritable", "/proc/nope/runs"), ("is-file", str(f)), ("empty", "")):
        cases.append(Case(f"run --out {label}", ["run", "plate_steel", "--out", path], "refuse", "--out"))
    for label, args, e, names, owner in (
            ("--store under-file", ["--store", f"{f}/x.sqlite"], "refuse", "--store", "hardening"),
            ("--store unwritable", ["--store", "/proc/nope/x.sqlite"], "refuse", "--store", "hardening"),
            ("--store empty", ["--store", ""], "refuse", "--store", "hardening"),
            ("--store dir", ["--store", str(d)], "refuse", "--store", "hardening"),
            ("--store postgres unreachable", ["--store", "postgresql://nobody@127.0.0.1:1/x"], "refuse", "store",
             "runs-at-scale"),
            ("--jobs 0", ["--jobs", "0"], "refuse", "--jobs", "runs-at-scale"),
            ("--tag nosuchtag", ["--tag", "nosuchtag"], "refuse", "tag", "runs-at-scale"),
    ):
        cases.append(Case(f"run {label}", ["run", "plate_steel", "--engines", "mujoco", "--out", str(d / "rs"),
                                           *args], e, names, owner))
    cases += [
        Case("no command", [], "either"),
        Case("--version", ["--version"], "ok"),
        Case("unknown command", ["frobnicate"], "refuse", "frobnicate"),
        Case("run bad scene name", ["run", "nosuchscene", "--out", str(d / "r2")], "refuse", "nosuchscene"),
        Case("run mujoco plate ok", ["run", "plate_steel", "--engines", "mujoco", "--dt", "1e-6", "--out", str(d / "r3")],
             "either"),
        Case("run mujoco dt 1e-3 (too coarse)", ["run", "plate_steel", "--engines", "mujoco", "--dt", "1e-3", "--out",
                                                 str(d / "r4")], "either"),
        Case("run results.csv other columns", ["run", "plate_steel", "--out", str(d / "r5")], "either", owner="runs-at-scale"),
        Case("run --dt 1e-10 plate (slow)", ["run", "plate_steel", "--engines", "mujoco", "--dt", "1e-10", "--out",
                                              str(d / "r6"), "--timeout", "600"], "either", owner="engines-v2"),
    ]
    # the one range grammar a:b:n of sweep --dt, tune --speeds and extremes --axis: every bad form refused there
    for text, _ in BAD_RANGE_CASES:
        for cmd, option, args in (
                ("sweep", "--dt", ["sweep", "plate_steel", "--dt", text, "--out", str(d / "sw")]),
                ("tune", "--speeds", ["tune", "mujoco", "plate_steel", "--speeds", text, "--out", str(d / "tu")]),
                ("extremes", "--axis", ["extremes", "plate_steel", "--axis", f"velocity={text}", "--out", str(d / "ex")])):
            cases.append(Case(f"{cmd} {option} {text}", args, "refuse", option))
    cases.append(Case("extremes --axis old LO..HI:N", ["extremes", "plate_steel", "--axis", "velocity=0.1..10:5", "--out",
                                                      str(d / "ex")], "refuse", "velocity=0.1:10:5"))
    return cases


def api_cases(d: Path) -> list[Case]:
    """The Python API calls of tests/hostile_cases.py, each in its own process (the tests run them in process)."""
    rows = [(code, "refuse", word) for code, word in API_REFUSED_CASES] + [(code, "either", "") for code in API_EDGE]
    cases = []
    for code, expect, word in rows:
        cid = "api " + re.sub(r"__import__\('[\w.]+'\)\.(?:\w+\.)*(?=\w+\()", "", code).replace("impactval.", "")
        cases.append(Case(cid, code=code, expect=expect, names=word,
                          owner="runs-at-scale" if cid.startswith("api run(") else "hardening"))
    return cases


def prepare(d: Path, cases: list[Case]) -> None:
    (d / "a_file").write_text("x")
    (d / "dir.toml").mkdir(exist_ok=True)
    (d / "binary.csv").write_bytes(b"\x00\xff\xfe" * 100)
    import csv
    from impactval.runner import COLUMNS
    with (d / "nonnum.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        w.writerow(["abc"] * len(COLUMNS))
    (d / "r5").mkdir(exist_ok=True)
    (d / "r5" / "results.csv").write_text("a,b\n1,2\n")
    (d / "name-slash.toml").write_text(GOOD_PLATE.replace('name = "hostile_plate"', 'name = "../escaped"'))
    for c in cases:
        for name, text in c.files.items():
            (d / name).write_text(text)


@dataclass
class Outcome:
    case: Case
    rc: int | None
    seconds: float
    rss_mb: float
    stdout: str
    stderr: str
    problems: list[str]


def run_case(c: Case, d: Path) -> Outcome:
    if c.code is not None:
        argv = [sys.executable, "-c", f"CODE = {c.code!r}\n" + API_PRELUDE]
    else:
        argv = [sys.executable, "-m", "impactval.cli", *c.argv]
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        p = subprocess.Popen(argv, stdout=out, stderr=err, cwd=d, start_new_session=True)
        rc, rss, timed_out = None, 0.0, False
        while True:
            pid, status, ru = os.wait4(p.pid, os.WNOHANG)
            if pid:
                rc = os.waitstatus_to_exitcode(status)
                rss = ru.ru_maxrss / 1024
                break
            if time.perf_counter() - t0 > LIMIT_S:
                os.killpg(p.pid, 9)
                _, status, ru = os.wait4(p.pid, 0)
                rss, timed_out = ru.ru_maxrss / 1024, True
                break
            time.sleep(0.05)
        p.returncode = rc
        secs = time.perf_counter() - t0
        out.seek(0), err.seek(0)
        stdout = out.read().decode(errors="replace")
        stderr = err.read().decode(errors="replace")
    problems = []
    is_run = bool(c.argv) and c.argv[0] == "run"
    if timed_out:
        problems.append(f"killed after {LIMIT_S:g} s")
    elif rc not in (0, 2) and not (is_run and rc == 1):
        problems.append(f"exit {rc}")
    if "Traceback" in stderr or "Traceback" in stdout:
        last = [l for l in stderr.strip().splitlines() if l.strip()][-1:] or ["?"]
        problems.append(f"traceback: {last[0][:160]}")
    if rss * 1024 > LIMIT_RSS_KB:
        problems.append(f"peak memory {rss:.0f} MB")
    if rc == 0 and NONFINITE.search(stdout):
        problems.append(f"non-finite answer: {NONFINITE.search(stdout).group(0)} in {stdout.strip()[:100]!r}")
    err_lines = [l for l in stderr.splitlines() if l.startswith("impactval: error:") or l.startswith("Error:")]
    if c.expect == "refuse":
        if rc != 2:
            problems.append(f"accepted (exit {rc}), should be refused")
        elif c.names and not any(c.names.lower() in l.lower() for l in stderr.splitlines()):
            problems.append(f"refusal does not name {c.names!r}: {(err_lines or stderr.splitlines() or ['?'])[-1][:160]}")
    if c.expect == "ok" and rc != 0:
        problems.append(f"should succeed, exit {rc}: {stderr.strip()[-160:]}")
    return Outcome(c, rc, secs, rss, stdout, stderr, problems)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="")
    ap.add_argument("--json", default=None)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args()
    d = Path(tempfile.mkdtemp(prefix="hostile-"))
    cases = scene_cases(d) + cli_cases(d) + api_cases(d)
    ids = [c.id for c in cases]
    assert len(ids) == len(set(ids)), [i for i in ids if ids.count(i) > 1]
    cases = [c for c in cases if args.only in c.id]
    prepare(d, cases)
    t0 = time.perf_counter()
    with ThreadPoolExecutor(args.jobs) as pool:
        outcomes = list(pool.map(lambda c: run_case(c, d), cases))
    by_owner: dict[str, list[int]] = {}
    for o in outcomes:
        ok = not o.problems
        tally = by_owner.setdefault(o.case.owner, [0, 0])
        tally[0] += ok
        tally[1] += 1
        if not ok or args.verbose:
            print(f"{'ok ' if ok else 'BAD'} [{o.case.owner}] {o.case.id[:60]!s:60s} rc={o.rc} {o.seconds:5.1f}s "
                  f"{o.rss_mb:6.0f}MB  {'; '.join(o.problems)}")
            if args.verbose:
                print("      ", (o.stderr.strip().splitlines() or [""])[-1][:200])
    clean = sum(not o.problems for o in outcomes)
    print(f"\n{clean} of {len(outcomes)} cases clean ({time.perf_counter() - t0:.0f} s; slowest "
          f"{max(o.seconds for o in outcomes):.1f} s, peak memory {max(o.rss_mb for o in outcomes):.0f} MB)")
    for owner, (good, n) in sorted(by_owner.items()):
        print(f"  {owner:14s} {good:4d} of {n:4d} clean")
    if args.json:
        Path(args.json).write_text(json.dumps([{"id": o.case.id, "owner": o.case.owner, "rc": o.rc,
                                                "seconds": o.seconds, "rss_mb": o.rss_mb, "problems": o.problems}
                                               for o in outcomes], indent=1))
    return 0 if clean == len(outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())
