"""One bar for a float32 engine's Timoshenko-chain row (MuJoCo Warp and Newton tests share it)."""
from __future__ import annotations

import impactval
from impactval.engines.base import EngineSettings


def timoshenko_row_meets_the_bar(adapter, name, contact: str, to_prediction: float):
    """Run `name` at every default with `contact`; injected Hertz within 1.5 % of the Timoshenko reference and within
    `to_prediction` of the row's predicted model_error, native within 1.5 % of the linear theory for the engine's own
    spring. Returns the row for the engine's own further checks."""
    from impactval.reference.linear import solve_linear

    sc = impactval.load_scene(name)
    r = adapter.run(sc, EngineSettings(contact=contact))
    assert r.status == "ok", r.message
    if contact == "hertz":
        ref = impactval.solve(sc, tol=1e-6)
    else:
        ref = solve_linear(sc, stiffness=r.diagnostics["contact_stiffness"])
    for m in ("t_m", "f_m", "delta_m"):
        err = getattr(r, m) / getattr(ref, m) - 1.0
        assert abs(err) <= 0.015, (m, err)
        if contact == "hertz":
            assert abs(err - r.diagnostics[f"model_error_{m}"]) <= to_prediction, (m, err, r.diagnostics[f"model_error_{m}"])
    return r
