"""Theory pages: nonlinear (Hertz) vs linear-contact vs first-order perturbation results for a scene.

`compare_models(scene)` returns the comparison as a DataFrame; `theory_page(scene, out_dir)` writes a
markdown page with it, the model-form error of a linear contact, the modes that matter and a PNG plot of
the force curves (matplotlib, imported only when a plot is drawn); `theory_index(pages, out_dir)` writes
a summary over scenes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from impactval.reference.result import Metrics

#: rows of the comparison, in order: (key, label)
MODELS = (
    ("nonlinear", "Hertz contact, elastic structure (reference, exact)"),
    ("linear", "linear contact k0, elastic structure (exact)"),
    ("perturbation", "Hertz, first order in s (exact zero order)"),
    ("perturbation-sine", "Hertz, first order, paper's sine approximation"),
    ("perturbation-linear", "linear contact, first order in s"),
    ("plate", "Hertz contact, rigid plate (closed form)"),
    ("plate-linear", "linear contact, rigid plate (closed form)"),
)


@dataclass(frozen=True)
class TheoryComparison:
    """All models of one scene: `table` (DataFrame, one row per model, SI units and relative differences
    to the nonlinear reference), the linear contact's `model_form_error` (relative, linear - Hertz), the
    first-order `s_total` (sum of s_j), the mode choice, the force curves per model (t [s], f [N]) and the exact
    solutions' own warnings (`warnings`: (model, text) pairs: Hertz assumptions, an uncertainty above tol, ...) and,
    on a beam, the beam-theory gap sentence (`beam_theory`, the one `reference --explain` prints; "" otherwise)."""

    scene: str
    table: object
    model_form_error: Metrics
    s_total: float
    choice: object
    curves: dict
    k0: float
    tol: float
    warnings: tuple = ()
    beam_theory: str = ""


def compare_models(scene, tol: float = 1e-6, choice_tol: float = 1e-3) -> TheoryComparison:
    """Solve `scene` with every model (see MODELS); `tol` for the exact solvers, `choice_tol` for the mode choice."""
    import pandas as pd

    import impactval
    from impactval.reference.hertz import plate_impact
    from impactval.reference.linear import solve_linear
    from impactval.reference.modechoice import required_modes
    from impactval.reference.perturbation import perturbation, perturbation_curve

    from impactval.reference.structure import contact_scene

    beam_theory = beam_theory_line(scene) if scene.target.kind == "beam" else ""
    two_balls = scene.target.kind == "ball"
    scene = contact_scene(scene)          # a second ball: the equivalent ball on a rigid plate
    ball = scene.ball
    plate = plate_impact(ball.mass, scene.alpha, ball.velocity)
    ref = impactval.solve(scene, tol=tol)
    lin = solve_linear(scene, tol=tol)
    metrics: dict[str, Metrics] = {"nonlinear": ref.metrics, "linear": lin.metrics}
    curves = {"nonlinear": (ref.t, ref.f), "linear": (lin.t, lin.f)}
    s_total = 0.0
    if scene.target.kind != "rigid-plate":
        for key, model in (("perturbation", "hertz"), ("perturbation-sine", "hertz-sine"),
                           ("perturbation-linear", "linear")):
            p = perturbation(scene, model)
            metrics[key] = p.metrics
            t, _, f = perturbation_curve(scene, model)
            curves[key] = (t, f)
            s_total = float(np.sum(p.weights.s))
    metrics["plate"] = Metrics(plate.t_m, plate.f_m, plate.delta_m)
    metrics["plate-linear"] = Metrics(math.pi * plate.delta_m / ball.velocity, 0.8 * plate.f_m, plate.delta_m)
    tp = np.linspace(0.0, plate.t_m, 400)
    curves["plate"] = (tp, plate.force(tp))
    labels = dict(MODELS)
    if scene.target.kind == "rigid-plate":      # no elastic structure: the exact solutions are the rigid face's
        face = "two balls' relative motion" if two_balls else "rigid plate"
        labels["nonlinear"] = f"Hertz contact, {face} (reference, exact)"
        labels["linear"] = f"linear contact k0, {face} (exact)"
        if two_balls:
            labels["plate"] = "Hertz contact, reduced mass on a rigid face (closed form)"
            labels["plate-linear"] = "linear contact, reduced mass on a rigid face (closed form)"
    rows = []
    for key, _ in MODELS:
        if key not in metrics:
            continue
        m = metrics[key]
        d = m.relative_to(ref.metrics)
        rows.append({"model": key, "description": labels[key], "t_m_s": m.t_m, "f_m_N": m.f_m,
                     "delta_m_m": m.delta_m, "rel_t_m": d.t_m, "rel_f_m": d.f_m, "rel_delta_m": d.delta_m})
    table = pd.DataFrame(rows)
    warnings = tuple(("nonlinear", w) for w in ref.validity) + tuple(("linear", w) for w in lin.validity)
    return TheoryComparison(scene.name, table, lin.metrics.relative_to(ref.metrics), s_total,
                            required_modes(scene, choice_tol), curves, plate.k0, tol, warnings, beam_theory)


#: above this beam-theory gap (relative, any metric) an Euler-Bernoulli scene's explanation recommends Timoshenko
THEORY_NOTE = 0.01


def beam_theory_line(scene) -> str:
    """How much the beam theory alone moves a beam scene's answer, as one sentence (`reference --explain` and the
    theory page): the reference with the other theory (the run report's theory gap, `runner.theory_gap`, both
    theories solved at THEORY_GAP_TOL whatever the page's tol: the gap is shown to 0.01 %), and a recommendation when
    an Euler-Bernoulli beam is off Timoshenko's by more than THEORY_NOTE (shear and rotary inertia: short beams, and
    slender ones whose contact excites high modes)."""
    import impactval
    from impactval.runner import THEORY_GAP_TOL, theory_gap

    ref = impactval.solve(scene, tol=THEORY_GAP_TOL)
    g = theory_gap(scene, ref, THEORY_GAP_TOL)
    if not all(math.isfinite(v) for v in g.gap.values()):
        return f"beam theory: the reference with theory = \"{g.other}\" did not solve; no theory gap"
    line = (f"beam theory: with theory = \"{g.other}\" the reference moves by t_m {100 * g.gap['t_m']:+.2f} %, "
            f"f_m {100 * g.gap['f_m']:+.2f} %, delta_m {100 * g.gap['delta_m']:+.2f} %")
    if g.other == "timoshenko" and max(abs(v) for v in g.gap.values()) > THEORY_NOTE:
        line += (f" (above {100 * THEORY_NOTE:g} %: shear and rotary inertia matter here; a real beam of these "
                 "proportions behaves like Timoshenko's, set theory = \"timoshenko\" in the scene)")
    return line


def _pct(x: float) -> str:
    return f"{100 * x:+.3f} %" if math.isfinite(x) else "n/a"


def _num(x: float, scale: float = 1.0) -> str:
    """A metric in the table's unit, or n/a where the model gives no answer (a first-order shift <= -100 %)."""
    return f"{x * scale:.6g}" if math.isfinite(x) else "n/a"


def plot_forces(cmp: TheoryComparison, path: Path) -> Path:
    """PNG of the force curves f(t) of every model (matplotlib, Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.2), dpi=110)
    styles = {"nonlinear": ("k", "-", 2.0), "linear": ("tab:blue", "-", 1.5), "perturbation": ("tab:red", "--", 1.3),
              "perturbation-sine": ("tab:orange", ":", 1.3), "perturbation-linear": ("tab:cyan", "--", 1.1),
              "plate": ("0.55", "-.", 1.0)}
    for key, (t, f) in cmp.curves.items():
        c, ls, lw = styles.get(key, ("0.3", "-", 1.0))
        ax.plot(np.asarray(t) * 1e6, f, color=c, ls=ls, lw=lw, label=key)
    ax.set_xlabel("t [us]")
    ax.set_ylabel("contact force f [N]")
    ax.set_title(f"{cmp.scene}: contact force by model")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def theory_markdown(cmp: TheoryComparison, plot_name: str | None = None) -> str:
    """The markdown text of a theory page."""
    t = cmp.table
    lines = [f"# {cmp.scene}: nonlinear, linear and perturbation theory", ""]
    e = cmp.model_form_error
    lines += ["## Model-form error of a linear contact", "",
              f"A linear contact spring k0 = {cmp.k0:.6g} N/m (energy-equivalent to Hertz on a rigid plate) "
              f"instead of Hertz changes this scene's impact by **t_m {_pct(e.t_m)}, f_m {_pct(e.f_m)}, "
              f"delta_m {_pct(e.delta_m)}** (exact linear solution vs exact Hertz solution). An engine with a "
              "linear contact tuned to k0 is off by this much even with a perfect integrator; the rest of its "
              "error is numerical (compare it with the exact linear solution, `impactval reference "
              f"{cmp.scene} --model linear`).", ""]
    lines += ["## Metrics by model", "",
              "| model | t_m [us] | f_m [N] | delta_m [um] | t_m vs ref. | f_m vs ref. | delta_m vs ref. |",
              "|---|---:|---:|---:|---:|---:|---:|"]
    for _, r in t.iterrows():
        lines.append(f"| {r['description']} | {_num(r['t_m_s'], 1e6)} | {_num(r['f_m_N'])} | {_num(r['delta_m_m'], 1e6)} | "
                     f"{_pct(r['rel_t_m'])} | {_pct(r['rel_f_m'])} | {_pct(r['rel_delta_m'])} |")
    lines.append("")
    if cmp.warnings:
        lines += ["Warnings of the exact solutions:", ""] + [f"- {model}: {text}" for model, text in cmp.warnings] + [""]
    if cmp.beam_theory:
        lines += ["## Beam theory", "", cmp.beam_theory[0].upper() + cmp.beam_theory[1:] + ".", ""]
    if plot_name:
        lines += [f"![contact force by model]({plot_name})", ""]
        if "perturbation" in set(t["model"]):
            lines += ["The perturbation curves are d0 + d1 over the zero-order contact; their peaks differ from the "
                      "first-order metrics (evaluated at the zero-order peak) by terms of second order, which are "
                      "visible when the structure's effect is large.", ""]
    c = cmp.choice
    if len(c.s):
        se = c.structure_effect
        size = max(abs(se.t_m), abs(se.f_m), abs(se.delta_m))
        valid = ("small: the first-order results are accurate (error ~ the square of the shifts)" if size < 0.05 else
                 "not small: the first-order results are only indicative (their error is ~ the square of the shifts)")
        lines += ["## Which modes matter", "",
                  f"First-order effect of the whole structure: t_m {_pct(se.t_m)}, f_m {_pct(se.f_m)}, "
                  f"delta_m {_pct(se.delta_m)} ({valid}). Sum of the small parameters s_j = (m0/m_j) phi_j0^2 "
                  f"over the modes used: {cmp.s_total:.4g} (modes far above the impact frequency count with "
                  "s_j/w_j^2 only).",
                  f"For a relative tolerance of {c.tol:g}: keep **{'at least ' if c.count_capped else ''}{c.count}** "
                  f"modes with the residual static "
                  f"flexibility of the rest ({'at least ' if c.plain_count_capped else ''}{c.count_without_residual} "
                  f"without it; highest kept frequency "
                  f"{c.omega_max / (2 * math.pi):.5g} Hz). A rigid plate is "
                  f"{'enough' if c.rigid_plate_enough else 'not enough'}.", "",
                  "| mode | omega [rad/s] | w | s | TH | MH | s*TH (t_m) | 1.5 s*MH (f_m) |", "|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for j in _top_modes(c, 10):
            lines.append(f"| {j + 1} | {c.omega[j]:.5g} | {c.w[j]:.4g} | {c.s[j]:.4g} | {c.TH[j]:+.4f} | {c.MH[j]:+.4f} | "
                         f"{c.d_t[j]:+.3e} | {c.d_f[j]:+.3e} |")
        lines += ["", "Modes far below the impact frequency (w << 1) act as free masses (TH = MH = -0.4): they do "
                  "not fade. Modes far above it (w >> 1) fade like 1/w^2 and are springs in series, captured by "
                  "the residual static flexibility.", ""]
    return "\n".join(lines)


def _top_modes(choice, n: int) -> list[int]:
    """Indices of the n modes with the largest |contribution| to any metric (frequency order)."""
    size = np.maximum(np.abs(choice.d_t), np.abs(choice.d_f))
    idx = np.argsort(-size)[:n]
    return sorted(int(i) for i in idx if size[i] > 0)


def theory_page(scene, out_dir: str | Path, tol: float = 1e-6, choice_tol: float = 1e-3,
                plot: bool = True) -> tuple[Path, TheoryComparison]:
    """Write `<out_dir>/theory_<scene>.md` (and `.png`); returns the page path and the comparison."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cmp = compare_models(scene, tol, choice_tol)
    png = None
    if plot:
        png = plot_forces(cmp, out / f"theory_{scene.name}.png").name
    page = out / f"theory_{scene.name}.md"
    page.write_text(theory_markdown(cmp, png))
    return page, cmp


def theory_index(comparisons: list[TheoryComparison], out_dir: str | Path) -> Path:
    """`<out_dir>/theory.md`: the model-form error of a linear contact on every scene, with links."""
    out = Path(out_dir)
    lines = ["# Model-form error of a linear contact, per scene", "",
             "Exact linear-contact solution (spring k0) vs exact Hertz solution, relative.", "",
             "| scene | t_m | f_m | delta_m | modes needed (tol 1e-3) | rigid plate enough |", "|---|---:|---:|---:|---:|---|"]
    for c in comparisons:
        e = c.model_form_error
        lines.append(f"| [{c.scene}](theory_{c.scene}.md) | {_pct(e.t_m)} | {_pct(e.f_m)} | {_pct(e.delta_m)} | "
                     f"{c.choice.count} | {'yes' if c.choice.rigid_plate_enough else 'no'} |")
    path = out / "theory.md"
    path.write_text("\n".join(lines) + "\n")
    return path
