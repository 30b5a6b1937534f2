"""MuJoCo Warp and Newton next to MuJoCo C, in one process, side by side (issue 19).

Prints for the plate and the worked beam: errors vs the exact theory (closed-form sine / linear
theory for native contact, the Hertz reference for injected Hertz), the C-vs-Warp differences,
build time (model + first step = kernel compile or cache load) apart from stepping time, and per-step
cost with Warp CPU graph capture against plain kernel launches (ratios taken in the same run; the
machine may be loaded, so compare within a run). Also the float32 caveat: plate native at dt down
to 5e-8 for C and Warp; the worked and two unseen beams (MuJoCo C's own chain, the Warp chain with C on the
identical model, Newton); the chain's tree root and size limits in float32; the first unstable dt on the
plate (the energy measure). Several minutes; not a test.

Run: python benchmarks/bench_warp_engines.py   (Newton's beams only: ... newton; the Timoshenko scenes: ... timoshenko)
"""
from __future__ import annotations

from pathlib import Path

import impactval
from impactval.engines.base import EngineSettings, load_adapter
from impactval.reference.linear import solve_linear

UNSEEN = Path(__file__).resolve().parent.parent / "tests" / "unseen"


def line(engine: str, scene_name: str, **kw) -> None:
    sc = impactval.load_scene(scene_name)
    s = EngineSettings(**kw)
    r = load_adapter(engine).run(sc, s)
    label = f"{engine:12s} {Path(scene_name).stem:20s} {s.contact:7s} {s.integrator or '-':13s} dt={s.dt!s:<7} " \
            f"{dict(s.options) or ''}"
    if not r.success:
        print(f"{label} {r.status}: {r.message}", flush=True)
        return
    ref = impactval.solve(sc) if s.contact == "hertz" else solve_linear(sc, stiffness=r.diagnostics["contact_stiffness"])
    err = [100 * (a / b - 1) for a, b in ((r.t_m, ref.t_m), (r.f_m, ref.f_m), (r.delta_m, ref.delta_m))]
    vs = r.diagnostics.get("vs_mujoco_c", {})
    vs_txt = " vs C %+.4f/%+.4f/%+.4f %%" % tuple(100 * vs[k] for k in ("t_m", "f_m", "delta_m")) if "t_m" in vs else ""
    label += f" N={r.diagnostics['segments']} dt={r.dt:.3g}" if r.diagnostics.get("segments") else ""
    print(f"{label} {r.model}: err {err[0]:+.3f}/{err[1]:+.3f}/{err[2]:+.3f} % (t_m/f_m/delta_m vs "
          f"{'Hertz' if s.contact == 'hertz' else 'linear'} theory), energy {100 * r.energy_error:.2f} %, "
          f"build {r.wall_time_build_s:.2f} s (compile/load {r.diagnostics.get('compile_s', 0):.2f} s), "
          f"step {1e6 * r.wall_time_step_s / max(r.n_steps, 1):.1f} us x {r.n_steps}{vs_txt}"
          f"{' [' + r.diagnostics['validity'] + ']' if r.diagnostics.get('validity') else ''}", flush=True)


def main() -> None:
    for contact in ("native", "hertz"):
        line("mujoco", "plate_steel", dt=1e-6, contact=contact)
        line("mujoco-warp", "plate_steel", dt=1e-6, contact=contact)
        line("mujoco-warp", "plate_steel", dt=1e-6, contact=contact, options=(("graph_capture", False),))
        line("newton", "plate_steel", dt=1e-6, contact=contact)
        line("newton", "plate_steel", dt=1e-6, contact=contact, options=(("graph_capture", False),))
    for integ in ("featherstone", "xpbd"):
        line("newton", "plate_steel", dt=1e-6, contact="native", integrator=integ)
    for dt in (2.5e-7, 1e-7, 5e-8):          # float32: the step's displacement nears the position's rounding
        line("mujoco", "plate_steel", dt=dt, contact="native")
        line("mujoco-warp", "plate_steel", dt=dt, contact="native", options=(("compare_c", False),))
        line("newton", "plate_steel", dt=dt, contact="native")
    beams = ("beam_ss_midspan", str(UNSEEN / "cantilever_titanium.toml"), str(UNSEEN / "cc_aluminium_0p3.toml"))
    for beam in beams:
        for contact in ("native", "hertz"):
            line("mujoco", beam, dt="auto", contact=contact)                       # MuJoCo C's own chain
            line("mujoco-warp", beam, dt="auto", contact=contact)                  # + C on the identical model
    for contact in ("native", "hertz"):
        line("mujoco-warp", "beam_ss_midspan", dt=1e-6, contact=contact)
    line("newton", "beam_ss_midspan", dt=1e-6, contact="native", integrator="xpbd")
    newton_beams()
    for root in ("end", "middle"):           # float32: the serial chain vs the tree rooted at its middle
        line("mujoco-warp", "beam_ss_midspan", dt=1e-6, contact="hertz", segments=81, options=(("chain_root", root),))
    for n in (121, 161):                     # the section chain's float32 limit
        line("mujoco-warp", "beam_ss_midspan", dt="auto", contact="hertz", segments=n)
    line("mujoco-warp", "beam_ss_midspan", dt="auto", contact="hertz", options=(("rotary_inertia", "none"),))
    line("mujoco-warp", "beam_ss_midspan", dt="auto", contact="hertz", segments=93,
         options=(("rotary_inertia", "none"),))
    for engine in ("mujoco", "mujoco-warp", "newton"):   # the energy measure: first unstable dt on the plate
        onset(engine)


def newton_beams() -> None:
    """Newton SemiImplicit, every default, on the worked and every unseen beam, native (vs the linear theory) and
    injected Hertz (vs the Hertz reference): status, N, attach_ke, retries, errors, the predicted model_error
    (rigid-jointed chain + give, exact linear theory), in-plane energy and axial noise (docs/newton.md's table); then
    the float32 findings: axial noise against the origin's distance (ulp of x) and the ball's integrated point
    (centre vs lowest point) at dt 4e-8 (python benchmarks/bench_warp_engines.py newton)."""
    from impactval.engines.newton_ import NewtonAdapter
    from impactval.reference.linear import solve_linear

    def row(adapter, beam, **kw):
        sc = impactval.load_scene(beam)
        r = adapter.run(sc, EngineSettings(**kw))
        d = r.diagnostics
        label = f"{Path(beam).stem:28s} {kw.get('contact', 'hertz'):6s} {kw.get('dt', 'auto')!s:6s}"
        if r.status != "ok":
            print(f"{label} {r.status}: {r.message}", flush=True)
            return
        ref = impactval.solve(sc) if kw.get("contact") != "native" else solve_linear(sc, stiffness=d["contact_stiffness"])
        err = [100 * (a / b - 1) for a, b in ((r.t_m, ref.t_m), (r.f_m, ref.f_m), (r.delta_m, ref.delta_m))]
        print(f"{label} N {d['segments']:3d} attach_ke {d['attach_ke']:.3g} retries {d.get('retries', 0)}: "
              f"{err[0]:+.2f} / {err[1]:+.2f} / {err[2]:+.2f} %, predicted {100 * d['model_error_t_m']:+.2f} / "
              f"{100 * d['model_error_f_m']:+.2f} % (model_error {100 * r.model_error:.2f} %), in-plane energy "
              f"{100 * r.energy_error:.2f} %, axial noise {100 * d['axial_noise_energy']:.0f} %, dt {r.dt:.2g} s"
              f"{' [' + '; '.join(r.validity) + ']' if r.validity else ''}", flush=True)

    adapter = NewtonAdapter()
    for beam in ["beam_ss_midspan"] + sorted(str(p) for p in UNSEEN.glob("*.toml")):
        for contact in ("native", "hertz"):
            row(adapter, beam, contact=contact)
    heavy = str(UNSEEN / "ti_ss_steel_heavy.toml")
    for shift in (0.0, 0.5, 1.5):            # the ulp of the joints' x: axial noise ~ulp^2, metrics unchanged
        far = NewtonAdapter()
        far.origin_shift = shift * impactval.load_scene(heavy).target.length
        print(f"origin {shift:g} L away:", end=" ")
        row(far, heavy, contact="native", segments=90, dt=1e-7, options=(("attach_ke", 6e9),))
    for at_bottom in (True, False):          # the ball's integrated point: float32 rounding of its z per step
        ball = NewtonAdapter()
        ball.ball_at_contact_point = at_bottom
        print(f"ball point at its {'lowest point' if at_bottom else 'centre'}:", end=" ")
        row(ball, heavy, contact="hertz", dt=4e-8)


def onset(engine: str) -> None:
    """First unstable dt on the plate (injected Hertz) on a 2^(1/4) grid from 0.35 dt_limit, as a fraction of it."""
    sc = impactval.load_scene("plate_steel")
    adapter = load_adapter(engine)
    opts = (("compare_c", False),) if engine == "mujoco-warp" else ()
    lim = adapter.plan(sc, adapter.check_settings(EngineSettings(dt=1e-6, options=opts))).dt_limit
    for k in range(-6, 4):
        frac = 2 ** (k / 4)
        r = adapter.run(sc, EngineSettings(dt=float(f"{frac * lim:.4g}"), options=opts))
        if not r.success:
            print(f"{engine:12s} plate onset: first unstable dt = {frac:.3f} dt_limit ({r.message})", flush=True)
            return
    print(f"{engine:12s} plate onset: none up to {frac:.3f} dt_limit", flush=True)

def timoshenko() -> None:
    """MuJoCo Warp and Newton, every default, on the five Timoshenko scenes, injected Hertz (vs the Timoshenko Hertz
    reference) and native (vs its linear theory): N, errors, the predicted model_error, energy, Warp vs MuJoCo C, and for
    native the chain's own linear-theory prediction (solve_linear_modes on its modes) (docs/mujoco-warp.md and
    docs/newton.md, "Timoshenko beams"; python benchmarks/bench_warp_engines.py timoshenko; the clamped-clamped linear
    reference takes ~5 min)."""
    from impactval.engines.base import execute_job
    from impactval.engines.chain import hencky_chain
    from impactval.reference.linear import solve_linear_modes

    scenes = ["beam_ss_stubby_timoshenko", str(UNSEEN / "stubby_steel_timoshenko.toml"),
              str(UNSEEN.parent / "unseen2" / "cantilever_al_tip_timoshenko.toml"),
              str(UNSEEN.parent / "unseen2" / "cc_soft_polymer_timoshenko.toml"), str(UNSEEN / "heavy_wc_slender_timoshenko.toml")]
    for name in scenes:
        sc = impactval.load_scene(name)
        hertz_ref = impactval.solve(sc, tol=1e-6)
        linear_refs: dict = {}
        for engine in ("mujoco-warp", "newton"):
            for contact in ("hertz", "native"):
                r = execute_job(engine, sc, EngineSettings(contact=contact))
                label = f"{engine:12s} {Path(name).stem:30s} {contact:6s}"
                if r.status != "ok":
                    print(f"{label} {r.status}: {r.message}", flush=True)
                    continue
                d = r.diagnostics
                if contact == "hertz":
                    ref, pred = hertz_ref, [d[f"model_error_{m}"] for m in ("t_m", "f_m", "delta_m")]
                else:
                    k = d["contact_stiffness"]
                    ref = linear_refs.setdefault(k, solve_linear(sc, stiffness=k))
                    chain = hencky_chain(sc.target, d["segments"], shear=True)
                    own = solve_linear_modes(chain.modes(), sc.ball.mass, k, sc.ball.velocity).metrics
                    pred = [getattr(own, m) / getattr(ref, m) - 1 for m in ("t_m", "f_m", "delta_m")]
                err = [getattr(r, m) / getattr(ref, m) - 1 for m in ("t_m", "f_m", "delta_m")]
                vs = d.get("vs_mujoco_c", {})
                vs_txt = " vs C %+.4f/%+.4f/%+.4f %%" % tuple(100 * vs[k] for k in ("t_m", "f_m", "delta_m")) if "t_m" in vs else ""
                print(f"{label} N {d['segments']:3d} dt {r.dt:.2g}: {100 * err[0]:+.3f} / {100 * err[1]:+.3f} / "
                      f"{100 * err[2]:+.3f} %, predicted {100 * pred[0]:+.3f} / {100 * pred[1]:+.3f} / {100 * pred[2]:+.3f} %, "
                      f"energy {100 * r.energy_error:.3f} %{vs_txt}{' [' + '; '.join(r.validity) + ']' if r.validity else ''}",
                      flush=True)


if __name__ == "__main__":
    import sys

    {"newton": newton_beams, "timoshenko": timoshenko}.get(" ".join(sys.argv[1:]), main)()
