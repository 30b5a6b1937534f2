"""The same impact as a system of ODEs, integrated by scipy (the independent check, physics.md sec. 3).

State: ball displacement x1 and velocity, modal coordinates q_i and velocities, in scaled units
(time delta_m/v0, length delta_m of the rigid-plate impact) so that a single tolerance suits all
components. m0 x1'' = -f, m_i q_i'' + m_i omega_i^2 q_i = phi_i f, f = alpha max(x1 - sum phi_i q_i, 0)^1.5.
The contact end is an event, located by the dense output.
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from impactval.reference.beams import Modes
from impactval.reference.hertz import plate_impact
from impactval.reference.result import Metrics


def solve_ode(modes: Modes, mass: float, alpha: float, v0: float, rtol: float = 1e-12,
              atol: float = 1e-14, method: str = "DOP853", t_max_factor: float = 20.0,
              window: float = 0.0) -> tuple[Metrics, dict]:
    """First-contact metrics (t_m [s], f_m [N], delta_m [m]) from the ODE form.

    With `window` > 0 [s], integration continues that long after the first contact and the
    returned dict lists the later contacts' (start, end) times [s] under "contacts".
    Residual flexibility is not supported here (pure n-mode model).
    """
    plate = plate_impact(mass, alpha, v0)
    ts, ls = plate.delta_m / v0, plate.delta_m            # time and length scales
    keep = np.abs(modes.phi) > 1e-12
    w = modes.omega[keep] * ts                            # scaled frequencies
    phi = modes.phi[keep]
    mu = modes.modal_mass[keep] / mass
    n = len(w)
    k = 1.25                                              # alpha delta_m^2.5 / (m0 v0^2)

    w2 = w**2
    phi_mu = phi / mu
    out = np.empty(2 + 2 * n)

    def rhs(_t, y):
        d = y[0] - phi @ y[2:2 + n]
        f = k * d * np.sqrt(d) if d > 0 else 0.0
        out[0] = y[1]
        out[1] = -f
        out[2:2 + n] = y[2 + n:]
        np.multiply(phi_mu, f, out=out[2 + n:])
        out[2 + n:] -= w2 * y[2:2 + n]
        return out.copy()

    def ev_end(_t, y):
        return y[0] - phi @ y[2:2 + n]

    def ev_peak(_t, y):
        return y[1] - phi @ y[2 + n:]

    def ev_start(_t, y):
        return y[0] - phi @ y[2:2 + n]

    ev_end.terminal = window <= 0
    ev_end.direction = -1
    ev_start.direction = 1
    ev_peak.direction = -1
    y0 = np.zeros(2 + 2 * n)
    y0[1] = 1.0
    t_max = t_max_factor * 2.943 + window / ts
    sol = solve_ivp(rhs, (0.0, t_max), y0, method=method, rtol=rtol, atol=atol, events=[ev_end, ev_peak, ev_start],
                    dense_output=False)
    ends = sol.t_events[0]
    if window > 0:
        stop = ends[0] + window / ts
        ends = ends[ends <= stop]
    starts = sol.t_events[2]
    starts = starts[(starts > 1e-9) & (starts < (ends[-1] if len(ends) else 0.0))]
    peaks_t, peaks_y = sol.t_events[1], sol.y_events[1]
    t_end = ends[0]
    d_peak = max(y[0] - phi @ y[2:2 + n] for t, y in zip(peaks_t, peaks_y) if t < t_end)
    info = {"nfev": sol.nfev, "ends": ends * ts, "starts": np.concatenate(([0.0], starts)) * ts}
    return Metrics(t_end * ts, alpha * (d_peak * ls) ** 1.5, d_peak * ls), info
