"""required_modes on the whole catalogue: do the reduced models meet the tolerance? (issue 3, bar 4)

For each scene and tolerance: the chosen count with the residual static flexibility, and the count
without it, are solved exactly and compared with the automatic reference at tol 1e-7.
Prints errors in units of the tolerance (must be <= 1). Run: python benchmarks/theory_modechoice.py [tol ...]
"""
import sys
import time


import impactval
from impactval.reference.hertz import plate_impact
from impactval.reference.modechoice import required_modes
from impactval.reference.solve import solve_modes, structure_modes
from impactval.scenarios.scene import catalogue_names


def main(tols):
    print(f"{'scene':24s} {'tol':>6s} {'n':>5s} {'err/tol':>8s} {'n_plain':>7s} {'err/tol':>8s} {'rigid ok':>8s} "
          f"{'plate err/tol':>13s} {'t_choice':>8s}")
    for name in catalogue_names():
        sc = impactval.load_scene(name)
        m, a, v = sc.ball.mass, sc.alpha, sc.ball.velocity
        truth = impactval.solve(sc, tol=1e-7)
        pe = plate_impact(m, a, v)
        rig = max(abs(pe.t_m / truth.t_m - 1), abs(pe.f_m / truth.f_m - 1), abs(pe.delta_m / truth.delta_m - 1))
        for tol in tols:
            t0 = time.perf_counter()
            ch = required_modes(sc, tol)
            tc = time.perf_counter() - t0
            errs = []
            for n, res in ((ch.count, True), (ch.count_without_residual, False)):
                if sc.target.kind == "rigid-plate":
                    errs.append(0.0)
                    continue
                run, _ = solve_modes(structure_modes(sc, n, res), m, a, v, tol=min(tol / 50, 1e-7))
                e = run.metrics.relative_to(truth.metrics)
                errs.append(max(abs(e.t_m), abs(e.f_m), abs(e.delta_m)))
            print(f"{name:24s} {tol:6.0e} {ch.count:5d} {errs[0] / tol:8.3f} {ch.count_without_residual:7d} "
                  f"{errs[1] / tol:8.3f} {str(ch.rigid_plate_enough):>8s} {rig / tol:13.3g} {tc:7.2f}s")


if __name__ == "__main__":
    main([float(x) for x in sys.argv[1:]] or [1e-1, 1e-2, 1e-3, 1e-4, 1e-5])
