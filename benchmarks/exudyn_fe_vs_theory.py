"""What sets the Exudyn solid FE beam's error on a scene (docs/exudyn.md, heavy WC ball on a slender beam).

The reference solver on the FE body's own modes (the adapter's `model_error` route) against the Euler-Bernoulli
and the Timoshenko reference of the same scene: FE modes as built, with the residual flexibility of the dropped
FE modes (FE static solve), with the load at the top-centre node instead of the section mean, and fewer modes.
Prints frequencies of the FE model against both theories. Slow (one FE build per mesh; not cached here).

    python benchmarks/exudyn_fe_vs_theory.py tests/unseen/heavy_wc_slender.toml --modes 60 --elements 122,1,1
"""
import argparse
import dataclasses
import time

import numpy as np

import impactval
from impactval.engines.exudyn_fem import _fixed_dofs, fe_beam
from impactval.reference.beams import Modes, beam_modes
from impactval.reference.solve import solve_modes
from impactval.reference.structure import structure_modes


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scene")
    ap.add_argument("--modes", type=int, default=60)
    ap.add_argument("--elements", default="", help="nx,ny,nz (default: the adapter's)")
    ap.add_argument("--tol", type=float, default=1e-5)
    a = ap.parse_args()
    sc = impactval.load_scene(a.scene)
    beam, ball = sc.target, sc.ball
    sct = dataclasses.replace(sc, target=dataclasses.replace(beam, theory="timoshenko"))

    def metrics(md):
        run, _ = solve_modes(md, ball.mass, sc.alpha, ball.velocity, a.tol)
        m = run.metrics
        return np.array([m.t_m, m.f_m, m.delta_m])

    def pc(x, ref):
        return " / ".join(f"{100 * (u / r - 1):+.2f}" for u, r in zip(x, ref))

    eb, tm = impactval.solve(sc, tol=a.tol), impactval.solve(sct, tol=a.tol)
    EB, TM = (np.array([r.t_m, r.f_m, r.delta_m]) for r in (eb, tm))
    print(f"Euler-Bernoulli {EB}, Timoshenko {TM}: Timoshenko vs EB {pc(TM, EB)} %")
    n = a.modes
    elements = tuple(int(x) for x in a.elements.split(",")) if a.elements else None
    t0 = time.perf_counter()
    fe = fe_beam(beam, n, elements, use_cache=False)
    print(f"FE {fe.elements} hex27, {fe.n_dof} DOF, {n} modes: build {time.perf_counter() - t0:.1f} s")
    w_eb, w_t = beam_modes(beam, n).omega, structure_modes(sct, n).omega
    for k in sorted({0, 9, 29, n - 1} & set(range(n))):
        print(f"  mode {k + 1}: FE vs EB {100 * (fe.omega[k] / w_eb[k] - 1):+.3f} %, vs Timoshenko "
              f"{100 * (fe.omega[k] / w_t[k] - 1):+.3f} %")
    from scipy.sparse.linalg import spsolve
    free = np.setdiff1d(np.arange(fe.n_dof), _fixed_dofs(beam, fe.nodes))
    f = np.zeros(fe.n_dof)
    f[3 * fe.contact_nodes + 1] = fe.contact_weights
    u = np.zeros(fe.n_dof)
    u[free] = spsolve(fe.stiffness.tocsr()[free][:, free].tocsc(), f[free])
    static = float(fe.contact_weights @ u[3 * fe.contact_nodes + 1])
    resid = max(static - float(np.sum(fe.phi_contact**2 / fe.omega**2)), 0.0)
    top = np.flatnonzero((np.abs(fe.nodes[:, 0] - beam.impact_x) < 1e-9) & (np.abs(fe.nodes[:, 1] - beam.height / 2) < 1e-9)
                         & (np.abs(fe.nodes[:, 2]) < 1e-9))
    cases = [("section mean, plain", Modes(fe.omega, np.ones(n), fe.phi_contact, 0.0)),
             ("section mean + residual flexibility", Modes(fe.omega, np.ones(n), fe.phi_contact, resid))]
    if top.size:
        cases.append(("top-centre node, plain", Modes(fe.omega, np.ones(n), fe.mode_basis[3 * top[0] + 1], 0.0)))
    for k in (n // 3, n // 2, 2 * n // 3):
        if k >= 4:
            cases.append((f"first {k} modes", Modes(fe.omega[:k], np.ones(k), fe.phi_contact[:k], 0.0)))
    print(f"static flexibility FE {static:.5e} m/N")
    for label, md in cases:
        m = metrics(md)
        print(f"  {label}: vs EB {pc(m, EB)} % | vs Timoshenko {pc(m, TM)} %")


if __name__ == "__main__":
    main()
