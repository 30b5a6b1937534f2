"""Measure the PyBullet bars of issue 5 and a few sweeps around them; prints the numbers.

    python benchmarks/pybullet_bars.py            # ~1-2 min on 2 shared cores

Each engine number is compared with an independent answer: the Hertz closed form (plate), the
linear closed form (plate, native linear), `impactval.solve` (beam, Hertz) and the exact linear
multi-mode solution (beam, native linear; eigen-decomposition of ball + modes + spring k0, below).
"""
from __future__ import annotations

import math
import time

import numpy as np
from scipy import linalg, optimize

import impactval
from impactval.engines.base import EngineSettings
from impactval.engines.pybullet_ import PybulletAdapter, default_segments
from impactval.reference.beams import beam_modes
from impactval.reference.hertz import plate_impact


def linear_modal_impact(scene, k0: float, n_modes: int = 200) -> tuple[float, float, float]:
    """Exact first contact of the ball on a modal beam with a linear spring k0: (t_m, f_m, delta_m).

    Coordinates x = (ball displacement, modal q_i); M = diag(m0, m_i), K from k0 (delta = x_b -
    sum phi_i q_i) and m_i omega_i^2; x(t) = V diag(sin(p t)/p) V^T M x'(0) with M-normalised V.
    """
    modes = beam_modes(scene.target, n_modes)
    m0, v0 = scene.ball.mass, scene.ball.velocity
    n = modes.n + 1
    mass = np.diag(np.concatenate([[m0], modes.modal_mass]))
    c = np.concatenate([[1.0], -modes.phi])
    stiff = k0 * np.outer(c, c) + np.diag(np.concatenate([[0.0], modes.modal_mass * modes.omega**2]))
    w2, vecs = linalg.eigh(stiff, mass)
    p = np.sqrt(w2)
    amp = (c @ vecs) * (vecs.T @ mass @ np.eye(n)[:, 0] * v0) / p       # delta(t) = sum amp_k sin(p_k t)

    def delta(t):
        return np.sin(np.outer(np.atleast_1d(t), p)) @ amp

    t_guess = math.pi * math.sqrt(m0 / k0)
    ts = np.linspace(1e-3 * t_guess, 3 * t_guess, 30001)
    d = delta(ts)
    k = int(np.argmax(d < 0))
    t_m = optimize.brentq(lambda t: delta(t)[0], ts[k - 1], ts[k], xtol=1e-16)
    kp = int(np.argmax(d[:k]))
    res = optimize.minimize_scalar(lambda t: -delta(t)[0], bounds=(ts[max(kp - 1, 0)], ts[kp + 1]), method="bounded",
                                   options={"xatol": 1e-15})
    delta_m = -res.fun
    return t_m, k0 * delta_m, delta_m


def line(label, res, ref, extra=""):
    if res.status != "ok":
        print(f"{label:58s} {res.status}: {res.message}")
        return
    e = [res.t_m / ref[0] - 1, res.f_m / ref[1] - 1, res.delta_m / ref[2] - 1]
    us = res.wall_time_step_s / max(res.n_steps, 1) * 1e6
    print(f"{label:58s} t_m {e[0]:+.4%}  f_m {e[1]:+.4%}  delta_m {e[2]:+.4%}  "
          f"{res.n_steps} steps {us:.0f} us/step {extra}")


def main() -> None:
    a = PybulletAdapter()
    print(f"pybullet {a.version()}")
    plate = impactval.load_scene("plate_steel")
    pr = plate_impact(plate.ball.mass, plate.alpha, plate.ball.velocity)
    hertz_plate = (pr.t_m, pr.f_m, pr.delta_m)
    omega0 = math.sqrt(pr.k0 / plate.ball.mass)
    linear_plate = (math.pi / omega0, pr.k0 * pr.delta_m, pr.delta_m)

    print("\n== rigid plate ==")
    line("bar: injected Hertz dt=1e-6 (<= 0.05 %)", a.run(plate, EngineSettings(dt=1e-6)), hertz_plate)
    line("bar: native linear, global route dt=1e-7 (<= 0.1 %)",
         a.run(plate, EngineSettings(dt=1e-7, contact="native")), linear_plate)
    line("native linear, global route dt=1e-6", a.run(plate, EngineSettings(dt=1e-6, contact="native")), linear_plate)
    for dt in (1e-6, 1e-7):
        r = a.run(plate, EngineSettings(dt=dt, contact="native", options=(("native_route", "per-body"),)))
        line(f"native linear, per-body route dt={dt:g}", r, linear_plate,
             f"restitution {r.rebound_velocity / plate.ball.velocity:.5f} "
             f"(exp(-pi w0 dt/2) = {math.exp(-math.pi * omega0 * dt / 2):.5f})")
    line("native-hertz (CFM per step) dt=1e-6", a.run(plate, EngineSettings(dt=1e-6, contact="native-hertz")),
         hertz_plate)
    for dt in (1e-5, 3e-5, 1e-4):
        r = a.run(plate, EngineSettings(dt=dt))
        line(f"injected Hertz dt={dt:g} (limit {2 / math.sqrt(1.5 * plate.alpha * math.sqrt(pr.delta_m) / plate.ball.mass):.3g} s)",
             r, hertz_plate)

    print("\n== simply supported beam, mid-span ==")
    beam = impactval.load_scene("beam_ss_midspan")
    t0 = time.perf_counter()
    ref = impactval.solve(beam)
    print(f"reference: t_m {ref.t_m * 1e6:.3f} us, f_m {ref.f_m:.2f} N, delta_m {ref.delta_m * 1e6:.4f} um "
          f"({time.perf_counter() - t0:.1f} s)")
    hertz_beam = (ref.t_m, ref.f_m, ref.delta_m)
    lin_beam = linear_modal_impact(beam, pr.k0)
    print(f"linear reference (k0, 200 modes, exact): t_m {lin_beam[0] * 1e6:.3f} us, f_m {lin_beam[1]:.2f} N, "
          f"delta_m {lin_beam[2] * 1e6:.4f} um")
    r = a.run(beam, EngineSettings(dt=1e-7, segments=101))
    line("bar: injected Hertz N=101 dt=1e-7 (<= 1.5 %)", r, hertz_beam)
    d = r.diagnostics
    fr = np.array(d["structure_frequencies"][:5]) / np.array(d["continuum_frequencies"][:5]) - 1
    print(f"   chain N=101 frequencies vs continuum (modes 1-5): {', '.join(f'{x:+.2e}' for x in fr)}; "
          f"stability limit {d['stability_limit_dt']:.3g} s (chain alone {d['structure_stability_limit_dt']:.3g} s)")
    line("native-hertz N=101 dt=1e-7", a.run(beam, EngineSettings(dt=1e-7, segments=101, contact="native-hertz")),
         hertz_beam)
    line("native linear (global) N=101 dt=1e-7 vs linear reference",
         a.run(beam, EngineSettings(dt=1e-7, segments=101, contact="native")), lin_beam)
    for n in (21, 51, 81, 100, 125):
        line(f"injected Hertz N={n} dt=1e-7", a.run(beam, EngineSettings(dt=1e-7, segments=n)), hertz_beam)
    line("injected Hertz N=101 dt=2e-7", a.run(beam, EngineSettings(dt=2e-7, segments=101)), hertz_beam)

    print("\n== stability limit (N=51, injected Hertz) ==")
    probe = a.run(beam, EngineSettings(dt=1e-7, segments=51))
    limit = probe.diagnostics["stability_limit_dt"]
    for fac in (0.9, 0.99, 1.01, 1.1, 2.0):
        r = a.run(beam, EngineSettings(dt=fac * limit, segments=51))
        print(f"   dt = {fac:.2f} x limit ({fac * limit:.3g} s): {r.status} {r.message}")

    print("\n== other catalogue beams (injected Hertz, default segments) ==")
    for name, dt in (("beam_ss_quarter", 1e-7), ("beam_cc_midspan", 1e-7), ("beam_cantilever_tip", 1e-7),
                     ("light_ball_heavy_beam", 1e-7), ("light_ball_heavy_beam", 5e-8), ("heavy_ball_slender_beam", 1e-7)):
        s = impactval.load_scene(name)
        rs = impactval.solve(s)
        n = default_segments(s)
        line(f"{name} N={n} dt={dt:g}", a.run(s, EngineSettings(dt=dt)), (rs.t_m, rs.f_m, rs.delta_m))

if __name__ == "__main__":
    main()
