"""Presentation of a tuning result (`impactval tune`): tables, ready-to-paste snippets, the f(t) plot.

Input is the dict of DIR/tuned.json (`impactval.tune.Tuned.as_json()`), so a report can be redrawn
from the file alone. Snippets carry absolute SI values a user's own model accepts. matplotlib is
imported only when the plot is drawn.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

#: restitution coefficients the conversion table shows besides the user's own
DEFAULT_RESTITUTIONS = (1.0, 0.9, 0.7, 0.5)


def _g(x: Any, digits: int = 6) -> str:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return str(x)
    return "" if not math.isfinite(x) else f"{x:.{digits}g}"


def _pct(x: Any) -> str:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return ""
    return "" if not math.isfinite(x) else f"{100 * x:+.3f}"


def middle(speeds: Sequence[float]) -> float:
    from impactval.tune import middle_speed

    return middle_speed(speeds)


def residual_table(residuals: list[dict[str, Any]], title: str) -> list[str]:
    """Markdown rows: speed, engine t_m/f_m/delta_m and their signed errors [%] against the reference."""
    out = [f"### {title}", "", "| v0 [m/s] | status | t_m [us] | f_m [N] | delta_m [um] | t_m error % | f_m error % | "
           "delta_m error % |", "|---:|---|---:|---:|---:|---:|---:|---:|"]
    for r in residuals:
        out.append(f"| {r['speed']:.4g} | {r.get('status', '')} | {_g(1e6 * r['t_m'] if r['t_m'] is not None else None)} | "
                   f"{_g(r['f_m'])} | {_g(1e6 * r['delta_m'] if r['delta_m'] is not None else None)} | "
                   f"{_pct(r['err_t_m'])} | {_pct(r['err_f_m'])} | {_pct(r['err_delta_m'])} |")
    return out + [""]


def restitution_rows(tuned: dict[str, Any], restitutions: Sequence[float]) -> list[dict[str, Any]]:
    """Per restitution e: damping ratio zeta (linear spring-dashpot model), dashpot c [N s/m] for the tuned
    (or, for a Hertz law, the middle speed's energy-equivalent) spring, and each engine's knob values."""
    from impactval.tune import damping_ratio, k0_energy, mujoco_direct_solref, mujoco_timeconst_solref

    cf, p = tuned["closed_form"], tuned["parameters"]
    mass = cf["mass"]
    k = p.get("k")
    if k is None:    # a Hertz-like law: the linear spring of the same energy at the middle speed
        k = k0_energy(mass, cf["alpha"], middle(tuned["speeds"]))
    m_eff = p.get("m_eff", mass)
    rows = []
    for e in restitutions:
        z = damping_ratio(e)
        c = 2.0 * z * math.sqrt(k * mass)
        row = {"e": e, "zeta": z, "k": k, "c": c, "solref_direct": mujoco_direct_solref(k, c, m_eff)}
        row["solref_timeconst"] = mujoco_timeconst_solref(k, z, m_eff) if z > 0 else None
        rows.append(row)
    return rows


#: the ready-to-paste snippet of each engine: (language, template); the template's fields are the
#: tuned.json "parameters" plus scene, contact, dt and the MuJoCo vectors as words (solref_words, solimp_words)
SNIPPETS: dict[str, tuple[str, str]] = {
    "mujoco": ("xml", """\
<!-- impactval tune {scene} ({contact}): effective mass m_eff = {m_eff:.9g} kg (1/efc_diagA of the contact row at \
first touch); solref is stiffness per unit m_eff [1/s^2] -->
<option timestep="{dt:g}"><flag diagexact="enable"/></option>
<contact>
  <pair geom1="BALL" geom2="TARGET" condim="1" margin="0" gap="0"
        solref="{solref_words}" solimp="{solimp_words}"/>
</contact>"""),
    "pybullet": ("python", """\
# impactval tune {scene}: linear contact k = {k:.6g} N/m
# global route (nearly elastic; CFM holds for this dt only: globalCFM = ERP / (k dt)):
p.setPhysicsEngineParameter(fixedTimeStep={dt:g}, numSubSteps=0, contactSlop=0,
                            contactERP={erp:g}, globalCFM={cfm:.9g})
# per-body route (solved implicitly: loses energy, restitution ~ exp(-pi omega dt / 2)):
p.changeDynamics(ball, -1, contactStiffness={k:.9g}, contactDamping=0.0, restitution=0,
                 lateralFriction=0, linearDamping=0, angularDamping=0)"""),
    "exudyn": ("python", """\
# impactval tune {scene}: f = {contact_stiffness:.9g} * pen^{contact_exponent:g}
mbs.AddObject(exu.itemInterface.ObjectContactSphereSphere(
    markerNumbers=[mTarget, mBall], nodeNumber=nData, spheresRadii=[R_target, R_ball],
    contactStiffness={contact_stiffness:.9g}, contactStiffnessExponent={contact_exponent:g},
    contactDamping=0.0, impactModel=0, dynamicFriction=0.0))"""),
}


def snippet(tuned: dict[str, Any]) -> tuple[str, str]:
    """(language, text) of the ready-to-paste snippet for the tuned engine (see `SNIPPETS`)."""
    lang, template = SNIPPETS[tuned["engine"]]
    p = tuned["parameters"]
    words = {f"{k}_words": " ".join(str(p[k]).split(",")) for k in ("solref", "solimp") if k in p}
    return lang, template.format_map({**p, **words, "scene": tuned["scene"], "contact": tuned["contact"],
                                      "dt": tuned["dt"]})


def mujoco_snippet(tuned: dict[str, Any]) -> str:
    """The MJCF snippet of a MuJoCo tuning (`snippet` for engine "mujoco")."""
    return snippet({**tuned, "engine": "mujoco"})[1]


def markdown(tuned: dict[str, Any], restitutions: Sequence[float] = DEFAULT_RESTITUTIONS,
             plot: str | None = None) -> str:
    """The tuning report (markdown): fitted options, residuals per speed before and after, the
    speed-dependent springs, restitution conversions, the snippet, notes."""
    cf, p = tuned["closed_form"], tuned["parameters"]
    out = [f"# Contact tuning: {tuned['engine']} on {tuned['scene']} ({tuned['contact']})", "",
           f"Speeds {', '.join(f'{v:.4g}' for v in tuned['speeds'])} m/s; engine dt = {tuned['dt']:g} s; "
           f"{tuned['engine_runs']} engine runs ({tuned['evaluations']} least-squares evaluations, "
           f"{tuned['jobs_reused']} stored jobs reused). Errors are signed (engine - reference)/reference in %.",
           "", "## Fitted options (`impactval run --contact native --option KEY=VALUE`)", "",
           "| option | value |", "|---|---|"]
    out += [f"| `{k}` | `{v}` |" for k, v in tuned["options"].items()]
    out += ["", "| parameter | value |", "|---|---|"]
    units = {"m_eff": "kg (1/efc_diagA at first touch)", "m_invweight": "kg (1/body_invweight0 of the ball)",
             "k": "N/m", "k_scale": "N/m (solref * m_eff)", "stiffness_per_mass": "1/s^2",
             "contact_stiffness": "N/m^exponent", "cfm": "", "erp": "", "alpha_fit_rel_error": "(fit/alpha - 1)"}
    out += [f"| {k} | {_g(v, 9)} {units.get(k, '')} |" for k, v in p.items()]
    out += ["", f"Material: alpha = {cf['alpha']:.6g} N/m^1.5 (E* = {cf['e_star']:.4g} Pa), ball mass "
            f"{cf['mass']:.6g} kg.", ""]
    out += residual_table(tuned["residuals"], "After tuning")
    before = tuned.get("before", {})
    if before.get("residuals"):
        opts = ", ".join(f"`{k}={v}`" for k, v in before["options"].items())
        out += residual_table(before["residuals"], f"Before ({opts})")
    if tuned.get("scan"):
        out += ["### Stiffness scan before the fit (flexible target: the closed form is the rigid plate's)", "",
                "Least squares starts from the best of these; the fitted options are the best point of every "
                "evaluation. Errors over the fitted quantities and speeds.", "",
                "| options | largest error % | sum of squared errors |", "|---|---:|---:|"]
        for r in tuned["scan"]:
            opts = ", ".join(f"`{k}={v}`" for k, v in r["options"].items())
            out.append(f"| {opts} | {100 * r['largest']:.3g} | {r['sum_sq']:.4g} |")
        out.append("")
    out += ["## Springs by speed (closed form, rigid plate)", "",
            f"A linear spring gives t_m * f_m = pi m v, Hertz 3.679 m v: the ratio {cf['linear_product_ratio']:.4f} "
            "means no k matches both. Single best k over the range (log least squares): "
            f"{cf['k_compromise']:.6g} N/m.", "",
            "| v0 [m/s] | k0 energy-equivalent [N/m] | k matching t_m [N/m] | k matching f_m [N/m] | "
            "k equal errors [N/m] | MuJoCo solref of k equal (flat solimp) |", "|---:|---:|---:|---:|---:|---|"]
    m_eff = cf.get("m_eff", cf["mass"])
    for r in cf["k_by_speed"]:
        out.append(f"| {r['speed']:.4g} | {r['k0_energy']:.6g} | {r['k_t_m']:.6g} | {r['k_f_m']:.6g} | "
                   f"{r['k_equal']:.6g} | `{-r['k_equal'] / m_eff:.6g} 0` |")
    out += ["", "## Restitution", "",
            "The reference is elastic; its rebound speed over approach speed (the elastic truth, < 1 on a flexible "
            "target where energy stays in vibration; for two balls their separation speed over approach speed):", "", "| v0 [m/s] | reference rebound [m/s] | e |", "|---:|---:|---:|"]
    reference = tuned.get("reference", [])
    for t in reference:
        out.append(f"| {t['speed']:.4g} | {_g(t['rebound_velocity'])} | {_g(t['restitution'], 5)} |")
    following = [t["speed"] for t in reference if not float(t["restitution"]) > 0]
    at = ", ".join(f"{v:.4g}" for v in following)
    if following:
        out += ["", f"**e <= 0 at v0 = {at} m/s: the ball still moves toward the structure when the first contact "
                f"ends (it follows the structure), so re-contacts follow and this e is not the impact's rebound**; "
                f"see them with `impactval reference SCENE --window S`."]
    out += ["", "To add dissipation, model: linear spring-dashpot (Kelvin-Voigt), contact ending when the approach "
            "returns to zero: e = exp(-pi zeta / sqrt(1 - zeta^2)), c = 2 zeta sqrt(k m). For a Hertz law k is the "
            "energy-equivalent k0 of the middle speed (an approximation); the MuJoCo columns assume a flat solimp "
            "(d0 = dwidth), where dampratio is exactly zeta."]
    if following and len(following) == len(reference):
        out += ["", "No conversion table for this scene: the model needs a single contact that ends with the ball "
                "moving away (e > 0), and at every speed here the first contact ends with the ball still approaching "
                "and re-contacts follow, so a damping chosen for an e would not give that e here. (For the contact "
                "spring alone, a ball on an immovable surface: c = `impactval.tune.damping_for(e, k, m)`.)"]
    else:
        if following:
            out += ["", f"The table does not describe v0 = {at} m/s, where the first contact ends with the ball "
                    f"still approaching (e <= 0 above) and re-contacts follow."]
        out += ["", "| e | zeta | k [N/m] | c [N s/m] | MuJoCo solref direct | MuJoCo solref time constant |",
                "|---:|---:|---:|---:|---|---|"]
    for r in ([] if following and len(following) == len(reference) else restitution_rows(tuned, restitutions)):
        tc = r["solref_timeconst"]
        tc_s = f"`{tc[0]:.6g} {tc[1]:.6g}`" if tc else "none (dampratio 0 is refused)"
        out.append(f"| {r['e']:g} | {r['zeta']:.5g} | {r['k']:.6g} | {r['c']:.6g} | "
                   f"`{r['solref_direct'][0]:.6g} {r['solref_direct'][1]:.6g}` | {tc_s} |")
    lang, text = snippet(tuned)
    out += ["", "## Snippet (absolute units)", "", f"```{lang}", text, "```", ""]
    if plot:
        out += [f"![engine vs reference f(t), before and after]({plot})", ""]
    if tuned.get("notes"):
        out += ["## Notes", ""] + [f"- {n}" for n in tuned["notes"]] + [""]
    return "\n".join(out)


def force_plot(tuned: dict[str, Any], series: dict[str, dict[float, dict]], reference: dict[float, tuple],
               path: str | Path) -> Path | None:
    """f(t) of the reference and the engine before and after tuning, one panel per speed.
    `series` = {"before"|"after": {speed: {"t": ..., "f": ...}}}, `reference` = {speed: (t, f)}.
    Returns the PNG path, or None without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    speeds = tuned["speeds"]
    fig, axes = plt.subplots(1, len(speeds), figsize=(3.2 * len(speeds), 3.2), squeeze=False)
    from impactval.reports.style import REFERENCE_COLOUR, engine_colour

    colour = engine_colour(tuned["engine"])
    for ax, v in zip(axes[0], speeds):
        t, f = reference[v]
        ax.plot(1e6 * t, f, color=REFERENCE_COLOUR, lw=1.5, label="reference (Hertz)")
        for which, style in (("before", ":"), ("after", "--")):
            s = series.get(which, {}).get(v)
            if s is not None:
                ax.plot(1e6 * s["t"], s["f"], color=colour, ls=style, lw=1.3, label=f"{tuned['engine']} {which}")
        ax.set_title(f"v0 = {v:.3g} m/s", fontsize=9)
        ax.set_xlabel("t [us]")
        ax.set_xlim(left=0)
    axes[0][0].set_ylabel("f [N]")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
