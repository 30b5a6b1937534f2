"""Measure the unresolved-mode table of the error estimate (reference/solve.py UNRESOLVED_THETA / UNRESOLVED_C).

For one mode (s = (m0/m) phi^2, w = omega delta_m/v0) on the worked ball, at many base steps H = t_plate/n and at
tol 1e-5 and 1e-8, the excess of the real error over what the estimate already covers is measured exactly as
`kernel.solve_auto` computes it (the three runs of `kernel.solve_triple`, delta_max from the dense peak):

    excess = err(fine run vs the same mode at n = 3000, tol 1e-12) - Richardson estimate - the rigid plate's own error

relative (t_m, and 1.5x delta_m for f_m), divided by s w^-3.5, and binned by theta_c = omega_c H (omega_c: the mode's
frequency held by the contact's tangent stiffness, as in solve_auto). Two coupling classes (CLASSES): s <= 1 (row 0)
and s > 1 (row 1, strongly coupled modes). Prints, per bin, the largest excess of each class and the table that
solve.py holds: SAFETY x the largest excess of the bin and its two neighbours (a mode just past a bin edge, off the
(s, w) grid, showed up to 5x its own bin's largest excess: s 0.85, w 50 at theta_c 1.800), as a running maximum up to
theta_c = MONOTONE; above it row 0 (s <= 1) follows the measurements, which peak where one base step holds a whole
period of the mode (theta_c near 2 pi and 4 pi: all three runs of the estimate alias the mode alike, so their
differences miss its error) and fall between, floored at the bins of (MONOTONE, 5.5]; row 1 stays a running maximum.

Run: python benchmarks/unresolved_table.py [--quick]   (about 5 min on one core; --quick: a coarse grid)
"""
from __future__ import annotations

import math
import sys

import numpy as np

from impactval.reference import kernel
from impactval.reference import solve as rs
from impactval.reference.beams import Modes
from impactval.reference.hertz import plate_impact

M0, ALPHA, V0 = 0.0327, 1.5384e10, 1.0
PLATE = plate_impact(M0, ALPHA, V0)
#: bin edges (upper ends) = the table's theta points
THETA = np.array([0.35, 0.5, 0.6, 0.7, 0.8, 1.0, 1.2, 1.5, 1.65, 1.8, 2.0, 2.2, 2.45, 2.7, 3.0, 3.25, 3.5, 3.75, 4.0,
                  4.25, 4.5, 4.75, 5.0, 5.25, 5.5, 5.75, 6.0, 6.25, 6.5, 6.75, 7.0, 7.25, 7.5, 7.75, 8.0, 8.5, 9.0,
                  10.0, 11.0, 12.0, 13.0, 14.0, 15.0, 16.0, 18.0, 20.0])
#: below this theta_c the table is a running maximum (row 0 above it: the measured bins, see the module docstring)
MONOTONE = 3.5
#: row 0 above MONOTONE is at least the largest excess of the bins in (MONOTONE, BACKGROUND_TO]
BACKGROUND_TO = 5.5
#: the coupling classes (upper bounds of s; the last row holds every s above): the table's rows
CLASSES = (1.0,)
#: rows whose excess above MONOTONE follows the measurements (s <= 1); the strongly coupled row is a running maximum
RESONANT_ROWS = (0,)
#: the table is SAFETY x the running maximum of the measured excess (the grid in s and w is sparse: a single mode
#: between its points, s = 9.6 and w = 34 on a random target, needed 1.9x the largest excess measured in its bin)
SAFETY = 3.0


def triple(md: Modes, n: float, tol: float) -> tuple[np.ndarray, float]:
    """((t_m, delta_m) of the fine run, Richardson estimate (relative, max of t_m and 1.5 delta_m)) as solve_auto."""
    omega, g, ew = rs._select(md)
    J = kernel.levels(float(n), tol, rs.SMALLEST_STEP_FACTOR)
    out = kernel.solve_triple(omega, g, ew, M0, ALPHA, V0, md.residual_flexibility, PLATE.t_m / n, J,
                              rs.P_DEGREE, rs.GRADING_WINDOW * PLATE.t_m, int(20 * n + 60 * J + 500))
    x = np.array([[c[0, 1] - c[0, 0], c[0, 2]] for c in out[9:12]])
    rich = max(kernel.richardson(*x[:, 0], rs.ESTIMATE_ORDER) / x[0, 0],
               1.5 * kernel.richardson(*x[:, 1], rs.ESTIMATE_ORDER) / x[0, 1])
    return x[0], rich


def err(x: np.ndarray, truth: np.ndarray) -> float:
    return float(np.max(np.abs(x - truth) / truth * [1.0, 1.5]))


def measure(ss, ws, ns, tols=(1e-5, 1e-8)) -> np.ndarray:
    """Rows (s, w, theta_c, excess / (s w^-3.5))."""
    empty = Modes(np.zeros(0), np.zeros(0), np.zeros(0))
    plate_truth = triple(empty, 3000, 1e-12)[0]
    plate_err = {(n, tol): err(triple(empty, n, tol)[0], plate_truth) for n in ns for tol in tols}
    k_t = 1.5 * ALPHA * math.sqrt(PLATE.delta_m)
    rows = []
    for s in ss:
        for w in ws:
            omega = w * V0 / PLATE.delta_m
            one = Modes(np.array([omega]), np.array([M0 / s]), np.array([1.0]))
            omega_c = math.sqrt(omega**2 + k_t * s / M0)        # g omega = phi^2/m = s/m0
            truth = triple(one, 3000, 1e-12)[0]
            for n in ns:
                for tol in tols:
                    x, rich = triple(one, n, tol)
                    excess = err(x, truth) - rich - plate_err[(n, tol)]
                    rows.append((s, w, omega_c * PLATE.t_m / n, excess / (s * max(w, 1.0) ** -3.5)))
    return np.array(rows)


def _classes(rows: np.ndarray) -> list[np.ndarray]:
    """Boolean masks of the rows of each coupling class (CLASSES)."""
    bounds = (0.0,) + CLASSES + (np.inf,)
    return [(rows[:, 0] > lo) & (rows[:, 0] <= hi) for lo, hi in zip(bounds[:-1], bounds[1:])]


def table(rows: np.ndarray) -> np.ndarray:
    """(2, len(THETA)): per class, SAFETY x the largest excess of each bin and its two neighbours; a running maximum
    over theta up to MONOTONE (row 1: everywhere); row 0 above MONOTONE at least its background (module docstring)."""
    out = np.zeros((len(CLASSES) + 1, len(THETA)))
    for c, sel_s in enumerate(_classes(rows)):
        raw = np.full(len(THETA), -np.inf)
        lo = 0.0
        for k, hi in enumerate(THETA):
            sel = sel_s & (rows[:, 2] > lo) & (rows[:, 2] <= hi)
            if sel.any():
                raw[k] = float(rows[sel, 3].max())
            lo = hi
        background = raw[(THETA > MONOTONE) & (THETA <= BACKGROUND_TO)].max()
        run = 1e-6
        for k in range(len(THETA)):
            near = raw[max(k - 1, 0):k + 2].max()
            run = max(run, near)
            if THETA[k] <= MONOTONE or c not in RESONANT_ROWS:
                out[c, k] = SAFETY * run
            else:
                out[c, k] = SAFETY * max(near, background, 1e-6)
    return out


def main(quick: bool = False) -> None:
    ss = (0.01, 0.1, 1.0, 3.0, 30.0) if quick else (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 0.7, 1.0, 1.3, 1.7, 2.0, 2.5, 3.0,
                                                    5.0, 10.0, 20.0, 30.0)
    ws = (3, 10, 30, 100, 300, 1000) if quick else (3, 4, 5, 6, 8, 9, 12, 15, 20, 25, 30, 38, 45, 60, 75, 90, 110, 130,
                                                     160, 200, 250, 300, 400, 500, 600, 800, 1000)
    ns = np.unique(np.round(np.logspace(1, 3, 40 if quick else 400)).astype(int))
    rows = measure(ss, ws, ns)
    lo = 0.0
    print("theta_c bin      largest excess / (s w^-3.5):  s <= 1   (at s, w)          s > 1   (at s, w)")
    for hi in THETA:
        line = f"({lo:5.2f}, {hi:5.2f}]"
        for sel_s in _classes(rows):
            sel = sel_s & (rows[:, 2] > lo) & (rows[:, 2] <= hi)
            if sel.any():
                r = rows[sel][np.argmax(rows[sel, 3])]
                line += f"   {r[3]:+9.2e} (s {r[0]:g}, w {r[1]:g})"
        print(line)
        lo = hi
    sel = rows[:, 2] > THETA[-1]
    for c, sel_s in enumerate(_classes(rows)):
        tail = rows[sel & sel_s]
        if len(tail):
            print(f"above {THETA[-1]:g}, class {c}: largest excess / sqrt(w) {np.max(tail[:, 3] / np.sqrt(tail[:, 1])):+.2e}")
    tab = table(rows)
    np.set_printoptions(precision=2, linewidth=150)
    print(f"table ({SAFETY:g} x the largest excess of a bin and its neighbours, see the docstring):")
    print(repr(tab))


if __name__ == "__main__":
    main("--quick" in sys.argv)
