"""Where each reference value comes from (as code_aster tags its reference values).

Three kinds: *closed form* (the rigid plate: Hertz's exact formulas, paper eq. 31-33), *Volterra
solver* (impactval's Hertz/modal solver, with the uncertainty bound it checks), *literature* (a
published value for the same scene, with the relative difference of our value to it).
`reference_record(scene, ref)` returns one flat dict per scene for the report's reference table
and for the result store.
"""
from __future__ import annotations

import math
from typing import Any

#: published values: scene name -> (source, t_m [s], f_m [N], delta_m [m]); compared only when the
#: scene still has the published parameters (checked through the closed form below)
LITERATURE = {
    "plate_steel": ("Yau & Zhang worked case (steel ball R = 10 mm at 1 m/s on a rigid steel plate; 6 digits)",
                    68.934e-6, 1743.78, 23.4208e-6),
}


def reference_record(scene, ref) -> dict[str, Any]:
    """Reference values of `scene` (t_m [s], f_m [N], delta_m [m], u_* absolute uncertainties,
    n_contacts, modes, model), `provenance`: one sentence naming the source of the values, and `validity`: the
    reference's own warnings (where the scene stretches Hertz's or the structure theory's assumptions)."""
    from impactval.reference.hertz import plate_impact

    unc = ref.uncertainty
    rec: dict[str, Any] = {
        "scene": scene.name, "t_m": ref.t_m, "f_m": ref.f_m, "delta_m": ref.delta_m,
        "u_t_m": unc.t_m if unc is not None else math.nan, "u_f_m": unc.f_m if unc is not None else math.nan,
        "u_delta_m": unc.delta_m if unc is not None else math.nan, "n_contacts": len(ref.contacts),
        "modes": ref.modes, "model": ref.model,
    }
    parts = []
    if scene.target.kind in ("rigid-plate", "ball"):
        what = "Hertz, paper eq. 31-33"
        plate_scene = scene
        if scene.target.kind == "ball":        # two free spheres: a ball of the reduced mass on a rigid plate
            from impactval.reference.spheres import equivalent_plate_scene

            plate_scene, what = equivalent_plate_scene(scene), "Hertz, two spheres as the reduced mass on a plate"
        p = plate_impact(plate_scene.ball.mass, plate_scene.alpha, plate_scene.ball.velocity)
        worst = max(abs(a / b - 1) for a, b in ((ref.t_m, p.t_m), (ref.f_m, p.f_m), (ref.delta_m, p.delta_m)))
        parts.append(f"closed form ({what}); the Volterra solver agrees to {worst:.1e}")
        rec.update(t_m=p.t_m, f_m=p.f_m, delta_m=p.delta_m, u_t_m=0.0, u_f_m=0.0, u_delta_m=0.0)
    else:
        tol = (ref.settings or {}).get("tol")
        parts.append(f"Volterra solver ({ref.model}, {ref.modes} modes"
                     + (f", tol {tol:g}" if isinstance(tol, (int, float)) else "") + "), ± its checked uncertainty")
    lit = LITERATURE.get(scene.name)
    if lit is not None:
        source, t_m, f_m, delta_m = lit
        worst = max(abs(a / b - 1) for a, b in ((rec["t_m"], t_m), (rec["f_m"], f_m), (rec["delta_m"], delta_m)))
        if worst < 1e-4:
            parts.append(f"literature: {source}, agrees to {worst:.1e}")
        else:
            parts.append(f"literature: {source} differs by {100 * worst:.3g} % (scene changed since?)")
    rec["provenance"] = "; ".join(parts)
    rec["validity"] = tuple(str(v) for v in (ref.validity or ()))
    return rec
