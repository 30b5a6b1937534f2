"""MuJoCo Warp adapter: the MuJoCo adapter's model (same MJCF, same solref/solimp, built by
`MujocoAdapter.build`) put on Warp with `mujoco_warp.put_model` and stepped with `mjw.step` on the
CPU in float32, one step captured as a Warp CPU graph and replayed.

Contact modes:

- "hertz": collision off; a `mjw.Callback(passive=...)` Warp kernel adds alpha*max(delta,0)^1.5 to
  `qfrc_passive` (J^T f at the ball's tip and, opposite, at the target's hit point, from the
  current kinematics, so RK4 stages see their own state). MuJoCo C's `mjcb_passive` is ignored by
  `mjw.step`, hence the kernel;
- "native": the MuJoCo adapter's linear, undamped contact pair of stiffness k0 (direct solref,
  impedance 1e-4, see engines/mujoco_.py);
- "native-hertz": the MuJoCo adapter's fitted solimp shape (the fit runs in MuJoCo C).

Model differences forced by float32 (measured, docs/mujoco-warp.md): the chain's tree is rooted at its
middle segment (option chain_root; supports become constraints, the same beam), it uses the section rotary
inertia by default, and its N (the MuJoCo C chain's) is capped at MAX_SEGMENTS; `diagexact` is off (unsupported),
the contact's direct solref rescaled to keep k0; connect anchors re-rounded to float32 kinematics. On a Timoshenko
beam the chain is the Timoshenko chain (engines.chain.hencky_chain(shear=True): a transverse slide of kappa G A / l at
every node, 2 kappa G A / l at a supported end; MuJoCo C's model, built by the same `build_xml`, here rooted in the
middle), at MuJoCo C's Timoshenko sizing, capped the same way.
The C comparison uses the same model. Modal targets are not offered.

Sampling: after each step a kernel stores the sample at the step's start (kinematics, constraint
force and energy that `mjw.step` computed for it) and the new qpos/qvel, so no extra forward pass
runs (RK4: an extra `mjw.forward` after the step, whose state is sampled, since RK4's last
evaluation is its fourth stage). The series ends by the base's window rule. Kinetic energy uses the velocities around a sample with the mass matrix of the
initial configuration: Euler/implicitfast get 1/2 v_before' M v_after + V, the quantity semi-implicit Euler
conserves (as the MuJoCo adapter; the chain moves by micrometres, so M(q) is constant to ~1e-7); RK4 uses the
engine's own energy. The slide-x joints' kinetic energy (float32 rounding noise along the beam) is kept out of the
checked energy and reported apart (`_check_axial_noise`); delta is formed from the hit point's and the ball's
displacements (`_mjw_kernels.approach`), not from the sites' world z; steps are recorded in chunks the host empties
(engines/_warp.py ChunkedRecord). docs/mujoco-warp.md "Small impacts in float32".

"C vs Warp": unless option `compare_c` is false, the identical MuJoCo model also runs in MuJoCo C
(float64) with the same settings, and `diagnostics["vs_mujoco_c"]` holds the signed relative
differences (Warp - C)/C of t_m, f_m and delta_m (plus the C values), so float32 and the Warp
solver are told apart from the physics error.

Timing: `wall_time_build_s` includes building the model and the first step, which compiles the
Warp kernels (14-18 s cold on an idle machine, 0.02-2 s from the cache, see engines/_warp.py);
`diagnostics["compile_s"]` holds that first step alone. `wall_time_step_s` is the captured stepping.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, fields, replace
from functools import lru_cache

import numpy as np

from impactval.engines.base import WINDOW_CAP, EngineAdapter, EngineSettings, Plan, Simulation, plate_times
from impactval.engines.mujoco_ import INTEGRATORS, MujocoAdapter, MujocoOptions, default_segments
from impactval.engines.options import boolean, one_of, option
from impactval.errors import EngineError

#: most chain segments the automatic sizing may choose, per rotary inertia (measured, docs/mujoco-warp.md).
#: The chain is rooted at its middle segment (option chain_root), which halves the tree depth and cuts
#: float32's error in M^-1 f by 6-10x (N = 93: 7 % -> 1 %); then the "section" chain (rotary inertia
#: m (l^2 + h^2)/12) runs and matches MuJoCo C within 0.04 % up to N = 121 and grows energy at 161; the
#: "none" chain (m l^2/12, worse conditioned) runs to N = 81 (NaN at 93) with solver-iteration overflows
#: and float32 differences to C up to 0.7 % from N ~ 76. A larger settings.segments is built as asked.
MAX_SEGMENTS = {"section": 121, "none": 81}
#: largest diagonally scaled condition number of the chain's mass matrix the sizing accepts for float32
#: (measured, scaled cond of M(q0) -> outcome in float32: <= 1.8e7 every chain ran and matched MuJoCo C within
#: 0.04 %; 2.8e7 ("none", heavy_wc_slender N = 76) 0.7 % off C; >= 5.6e7 NaN or energy growth)
COND_LIMIT = 2e7
#: steps replayed between host checks of the contact state (after a first chunk sized to the contact)
CHUNK = 64
#: largest number of contacts / constraint rows the Warp data holds (one contact pair, supports)
NCONMAX, NJMAX = 8, 32


@dataclass(frozen=True)
class MujocoWarpOptions(MujocoOptions):
    """`--option mujoco-warp.KEY=VALUE`: the MuJoCo adapter's options (same model) plus these."""

    rotary_inertia: str = option("section", "segment rotary inertia: 'section' = m (l^2 + h^2)/12 (default here: the "
                                 "better-conditioned chain float32 can solve), 'none' = m l^2/12 (MuJoCo's default; "
                                 "in float32 +1.7 % f_m vs C and 3.5 % energy error at N = 51)",
                                 one_of("none", "section"))
    chain_root: str = option("middle", "segment the chain's kinematic tree starts from: 'middle' (default here: two "
                             "branches of ~N/2, supports as constraints), 'hit', or 'end' (MuJoCo's serial chain; in "
                             "float32 N <= 51 only)", one_of("end", "hit", "middle"))
    compare_c: bool = option(True, "also run the identical model in MuJoCo C and report diagnostics['vs_mujoco_c'] "
                             "(default true)", boolean)
    graph_capture: bool = option(True, "replay one captured step as a Warp CPU graph (default true; false = plain "
                                 "kernel launches, ~100x slower)", boolean)


class MujocoWarpAdapter(EngineAdapter):
    """MuJoCo Warp (`pip install 'impactval[mujoco-warp]'`); see the module docstring."""

    name = "mujoco-warp"
    module = "mujoco_warp"
    contacts = ("hertz", "native", "native-hertz")
    integrators = INTEGRATORS
    integrator_methods = MujocoAdapter.integrator_methods
    min_segments = 2
    Options = MujocoWarpOptions

    def version(self) -> str:
        from importlib.metadata import version

        return f"{version('mujoco-warp')} (warp {version('warp-lang')}, float32, cpu)"


    # ------------------------------------------------------------------ the identical model in C
    def c_settings(self, scene, settings: EngineSettings) -> EngineSettings:
        """The settings MuJoCo C gets for the identical model: the MuJoCo options only, the chain's
        segment count fixed (see `segments`)."""
        opts = settings.options
        if isinstance(opts, tuple):
            opts = self.parse(settings).options
        c_opts = MujocoOptions(**{f.name: getattr(opts, f.name) for f in fields(MujocoOptions)})
        segments = settings.segments
        if segments is None and scene.target.kind == "beam":
            segments = sized_segments(scene, c_opts.chain_tol, c_opts.rotary_inertia, c_opts.chain_root)
        return replace(settings, options=c_opts, segments=segments)

    def plan(self, scene, settings: EngineSettings) -> Plan:
        """MuJoCo's plan for the identical model (chain, stability limit, model error)."""
        _check_target(scene)
        return _SameModelInC().plan(scene, self.c_settings(scene, settings))

    def contact_law(self, scene, settings: EngineSettings):
        return MujocoAdapter().contact_law(scene, self.c_settings(scene, settings))

    def structure_frequencies(self, scene, settings: EngineSettings) -> np.ndarray:
        """The chain's natural frequencies [rad/s] from MuJoCo C's linearisation of the identical model."""
        return _SameModelInC().structure_frequencies(scene, self.c_settings(scene, self.check_settings(settings)))

    def simulate(self, scene, settings: EngineSettings) -> Simulation:
        from impactval.engines._warp import CapturedStep, ChunkedRecord, WindowTracker, float32_contact_note, import_warp

        _check_target(scene)
        t0 = time.perf_counter()
        wp = import_warp()
        import mujoco
        import mujoco_warp as mjw

        from impactval.engines import _mjw_kernels as K

        c_settings = self.c_settings(scene, settings)
        c_model = _SameModelInC()
        run = c_model.build(scene, c_settings)
        c_model.close(run)                  # restores MuJoCo C's callbacks; the model and data stay
        mjm, mjd, lay, probe, info = run.model, run.data, run.lay, run.probe, dict(run.diagnostics)
        # native contact: MuJoCo's own collision of the geoms' world z, at the ball's centre height top + r (refused
        # here when float32 cannot resolve the approach; injected Hertz forms it from displacements)
        contact_note = "" if settings.contact == "hertz" else float32_contact_note(
            "mujoco-warp", float(lay.top) + scene.ball.radius, plate_times(scene).delta_m)
        mujoco.mj_forward(mjm, mjd)
        m = mjw.put_model(mjm)
        # the constraint solver's iteration overflows are reported in the row (diagnostics), not printed
        quiet = int(mjw.OverflowType.ITERATIONS) | int(mjw.OverflowType.LS_ITERATIONS)
        m.opt.warn_overflow = int(m.opt.warn_overflow) & ~quiet
        d = mjw.put_data(mjm, mjd, nconmax=NCONMAX, njmax=NJMAX)
        if mjm.neq:
            info["pin_anchor_shift"] = _reanchor_connects(wp, mjw, mujoco, mjm, m, d)
        contact = settings.contact
        native = contact != "hertz"
        # delta from the displacements of the hit point and the ball (`_mjw_kernels.approach`), their rest values
        # from the Warp kinematics itself, so delta is 0 at t = 0 to the last bit
        mjw.forward(m, d)
        hit_body = max(int(probe.hit_body), 0)
        ball_joint = mjm.joint("ball_z").id
        disp_args = [d.xpos, d.xquat, d.qpos, hit_body, wp.vec3(*mjm.site_pos[probe.hit]),
                     float(d.xpos.numpy()[0, hit_body, 2]), int(probe.ball_qpos), float(mjm.jnt_axis[ball_joint][2]),
                     float(d.qpos.numpy()[0, probe.ball_qpos])]
        if contact == "hertz":
            args = [m.body_rootid, m.body_isdofancestor, d.subtree_com, d.cdof, d.site_xpos, probe.tip,
                    probe.hit, probe.ball_body, hit_body, float(scene.alpha), *disp_args[:3], *disp_args[4:],
                    d.qfrc_passive]
            nv = mjm.nv

            def passive(m_, d_):
                wp.launch(K.hertz_passive, dim=nv, inputs=args, device="cpu")

            m.callback = mjw.Callback(passive=passive)
        plate = plate_times(scene)
        dt = float(settings.dt)
        n_max = int(math.ceil((WINDOW_CAP * plate.t_m + settings.tail) / dt)) + 1
        nq, nv = mjm.nq, mjm.nv
        chunk = max(CHUNK, int(1.1 * plate.t_m / dt))       # the first chunk covers a rigid-plate contact
        # one row per step in chunks the host empties (ChunkedRecord): row 0, the warm-up step, a chunk, spares
        rows = min(n_max, chunk) + 4
        st_rec = ChunkedRecord(wp, rows, nq + nv, "mujoco-warp", dt)
        sm_rec = ChunkedRecord(wp, rows, 5, "mujoco-warp", dt, base=st_rec.base)
        samples, states = sm_rec.buffer, st_rec.buffer
        counter = wp.zeros(1, dtype=int, device="cpu")
        states0 = np.concatenate([mjd.qpos, mjd.qvel]).astype(np.float32)
        rk4 = (settings.integrator or INTEGRATORS[0]) == "RK4"
        offset = 1 if rk4 else 0
        rec_args = [d.energy, d.qpos, d.qvel, d.nacon, d.contact.efc_address, d.efc.force, float(scene.alpha),
                    int(native), nv, nq, *disp_args[:2], *disp_args[3:], wp.array([disp_args[-1]], dtype=float, device="cpu"),
                    offset]
        if rk4:                              # sample 0 from a forward pass at t = 0
            mjw.forward(m, d)
            first = wp.array([-1], dtype=int, device="cpu")
            wp.launch(K.record, dim=1, inputs=[*rec_args[:-1], 1, first, st_rec.base, samples, states], device="cpu")
        rec_args += [counter, st_rec.base, samples, states]

        def one_step():
            mjw.step(m, d)
            if rk4:
                mjw.forward(m, d)
            wp.launch(K.record, dim=1, inputs=rec_args, device="cpu")

        stepper = CapturedStep(wp, one_step, capture=settings.options.graph_capture)
        stepper.warm_up()                  # the first real step: compiles or loads the kernels
        build_s = time.perf_counter() - t0

        step_s, n_steps = 0.0, 1
        ball_q = probe.ball_qpos
        end = None
        window = WindowTracker(settings, scene)      # the window rule, each sample looked at once
        while n_steps < n_max and end is None:
            n = min(chunk, n_max - n_steps)
            ts = time.perf_counter()
            stepper.run(n)
            step_s += time.perf_counter() - ts
            n_steps += n
            chunk = CHUNK
            count, done = int(counter.numpy()[0]), st_rec.done
            # samples of global index done + offset .. count - 1 + offset (RK4's sample 0 with the first chunk)
            block = sm_rec.copy(0 if (offset == 0 or done == 0) else 1, count - done + offset, count)
            st_rec.take(count)
            end = window.feed(block)
        n_steps = int(counter.numpy()[0])
        n_rec = n_steps + offset                       # samples: one per step start (+ the end for RK4)
        if end is not None:
            n_rec = min(n_rec, end + 1)                # the window rule: stop at the contact's end + tail
        s = sm_rec.all()[:n_rec].astype(float)
        st = st_rec.all(states0)[:n_steps + 1].astype(float)
        t = np.arange(n_rec) * dt
        qpos, qvel = st[:, :nq], st[:, nq:]
        x_ball = mjm.qpos0[ball_q] - qpos[:n_rec, ball_q]
        v_ball = -qvel[:n_rec, probe.ball_dof]
        energy, axial = self._energy(mujoco, mjm, settings, s, qvel, n_rec, info, scene)
        diagnostics = dict(info)
        diagnostics["compile_s"] = stepper.compile_s
        diagnostics["graph_capture"] = stepper.graph is not None
        diagnostics["float"] = "float32"
        overflow = int(d.overflow.numpy()[0])
        notes = []
        if overflow & quiet:
            names = [t.name for t in (mjw.OverflowType.ITERATIONS, mjw.OverflowType.LS_ITERATIONS) if overflow & int(t)]
            diagnostics["solver_overflow"] = names
            notes.append(f"mujoco_warp's constraint solver hit its iteration limit ({', '.join(names)}) in float32: "
                         f"compare with the C run (vs_mujoco_c)")
        if axial.size and energy.size and energy[0] > 0:
            _check_axial_noise(scene, dt, mjm, axial, energy[0], diagnostics, notes)
        if contact_note:
            notes.append(contact_note.removeprefix("mujoco-warp: "))
        if lay.kind == "beam":
            diagnostics["segments"] = lay.n_segments
            diagnostics["chain_root"] = settings.option("chain_root", "middle")
            diagnostics["mass_condition"] = mass_condition(scene, lay.n_segments, settings.options.rotary_inertia,
                                                           settings.options.chain_root)
            if settings.segments is None:
                c_n = default_segments(scene, EngineSettings(options=(("chain_tol", settings.options.chain_tol),)))
                if c_n > lay.n_segments:
                    from impactval.engines.chain import hencky_chain, law_model_error
                    from impactval.reference.hertz import ContactLaw

                    k_lin = info.get("contact_stiffness") if contact == "native" else None
                    me, kind = law_model_error(scene, hencky_chain(scene.target, lay.n_segments,
                                                                   settings.options.rotary_inertia,
                                                                   shear=timoshenko(scene)),
                                               ContactLaw.linear(k_lin) if k_lin else None)
                    spring = f" under the native spring {k_lin:.3g} N/m" if kind == "linear" else ""
                    notes.append(f"chain capped at {lay.n_segments} segments for float32 (MAX_SEGMENTS, COND_LIMIT; "
                                 f"rotary inertia {settings.options.rotary_inertia!r}); MuJoCo C's sizing asks for {c_n}; "
                                 f"predicted model error{spring} t_m {100 * me.t_m:+.2g} / f_m {100 * me.f_m:+.2g} % (the capped "
                                 f"chain's own: its f_m swings with where the hit falls in a segment, and the sizing takes "
                                 f"the N near the cap with the smallest)")
        sim = Simulation(t=t, delta=s[:, 0], f=s[:, 1], x_ball=x_ball, x_structure=s[:, 2], v_ball=v_ball,
                         energy=energy, build_s=build_s, step_s=step_s, n_steps=n_steps,
                         model=f"mujoco-warp-{_model_kind(lay)}-{contact}-float32", diagnostics=diagnostics,
                         validity=tuple(f"mujoco-warp: {n}" for n in notes),
                         settings={"integrator": settings.integrator or INTEGRATORS[0],
                                   "segments": lay.n_segments or None})
        if contact == "native" and info.get("contact_stiffness"):
            from impactval.reference.hertz import ContactLaw

            sim.contact_law = ContactLaw.linear(info["contact_stiffness"])
        if settings.options.compare_c:
            diagnostics["vs_mujoco_c"] = self._vs_c(scene, c_settings, sim)
        return sim

    @staticmethod
    def _energy(mujoco, mjm, settings, s, qvel, n_rec, info, scene) -> tuple[np.ndarray, np.ndarray]:
        """(energy, axial) [J] per sample: ball + structure + contact energy without the chain's motion along the beam
        (see the module docstring), and that axial part (the kinetic energy of the slide-x joints: the floating
        root's and a roller's), float32 rounding noise (`_check_axial_noise`). Both empty for native-hertz."""
        delta = np.maximum(s[:, 0], 0.0)
        if settings.contact == "hertz":
            contact_pe = 0.4 * scene.alpha * delta**2.5
        elif settings.contact == "native":
            contact_pe = 0.5 * info["contact_stiffness"] * delta**2
        else:
            return np.zeros(0), np.zeros(0)     # the fitted law's potential is tabulated only by the C adapter
        d0 = mujoco.MjData(mjm)
        mujoco.mj_forward(mjm, d0)
        mass, unit, col = np.zeros((mjm.nv, mjm.nv)), np.zeros(mjm.nv), np.zeros(mjm.nv)
        for i in range(mjm.nv):            # columns of M(q0) via mj_mulM
            unit[:] = 0.0
            unit[i] = 1.0
            mujoco.mj_mulM(mjm, d0, col, unit)
            mass[:, i] = col
        axial_dofs = [int(mjm.jnt_dofadr[j]) for j in range(mjm.njnt)
                      if mjm.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE and abs(mjm.jnt_axis[j][0]) > 0.5]
        rk4 = (settings.integrator or INTEGRATORS[0]) == "RK4"
        # sample k = the state at step k's start; qvel[k] the velocity before that step, qvel[k+1] after it:
        # 1/2 v_k' M v_(k+1) + V(q_k) is what semi-implicit Euler conserves on a linear system (as MuJoCo C's
        # adapter measures it); the mean velocity adds a ripple of (omega dt)^2/4 of the energy. RK4: the engine's own
        before, after = qvel[:n_rec], qvel[:n_rec] if rk4 else qvel[1:n_rec + 1]
        ke = s[:, 4] if rk4 else 0.5 * np.einsum("ki,ij,kj->k", before, mass, after)
        axial = np.zeros(0)
        if axial_dofs:
            rest_b, rest_a = before.copy(), after.copy()
            rest_b[:, axial_dofs] = 0.0
            rest_a[:, axial_dofs] = 0.0
            axial = 0.5 * (np.einsum("ki,ij,kj->k", before, mass, after) - np.einsum("ki,ij,kj->k", rest_b, mass, rest_a))
        energy = s[:, 3] + contact_pe + ke
        return (energy - axial if axial.size else energy), axial

    def _vs_c(self, scene, c_settings: EngineSettings, sim: Simulation) -> dict:
        """Run MuJoCo C on the identical model; signed relative differences (Warp - C)/C."""
        c = _SameModelInC().run(scene, c_settings)
        if not c.success:
            return {"status": str(c.status), "message": c.message}
        warp = self.result_from(scene, c_settings, sim)
        if not warp.success:
            return {"status": "warp-" + str(warp.status), "c_t_m": c.t_m, "c_f_m": c.f_m, "c_delta_m": c.delta_m}
        return {"t_m": warp.t_m / c.t_m - 1.0, "f_m": warp.f_m / c.f_m - 1.0,
                "delta_m": warp.delta_m / c.delta_m - 1.0,
                "c_t_m": c.t_m, "c_f_m": c.f_m, "c_delta_m": c.delta_m, "c_version": c.version}


def _check_axial_noise(scene, dt: float, mjm, axial: np.ndarray, impact_energy: float, diagnostics: dict,
                       notes: list) -> None:
    """The chain's motion along the beam (`axial` [J] per sample: the slide-x joints' kinetic energy) is float32
    rounding: the root's and the pins' x positions round at ulp(L) and the constraints' correction over ~2 dt turns
    that into a velocity ~ulp/dt flipping sign every step (fz2203, 2.2e-6 J impact: 680x it in x while the rest stayed
    within 0.18 % and f_m within 0.08 % of MuJoCo C). Kept out of the energy check, reported as axial_noise_energy
    (relative to the impact energy) with a note beyond AXIAL_NOISE_NOTE; a run beyond both AXIAL_NOISE_STOP x the
    impact energy and AXIAL_FLOOR_STOP x the float32 floor 1/2 m_beam (ulp(L)/dt)^2 is unstable (a blow-up)."""
    from impactval.engines._warp import (AXIAL_FLOOR_STOP, AXIAL_NOISE_NOTE, AXIAL_NOISE_STOP, axial_noise_blows_up,
                                         floor_text, share_text)
    from impactval.engines.base import EngineDiverged

    target = scene.target
    m_beam = target.material.density * target.length * target.width * target.height
    ulp = float(np.spacing(np.float32(target.length)))
    floor = 0.5 * m_beam * (ulp / dt) ** 2
    noise_j = float(np.max(axial))
    noise = noise_j / impact_energy
    diagnostics["axial_noise_energy"] = noise
    diagnostics["axial_noise_floor_J"] = floor
    if axial_noise_blows_up(noise_j, impact_energy, floor):
        raise EngineDiverged(f"float32 axial noise: the chain's motion along the beam reached {noise:.3g}x the impact "
                             f"energy and {noise_j / floor:.3g}x its float32 floor 1/2 m (ulp(L)/dt)^2 (limits "
                             f"{AXIAL_NOISE_STOP:g}x and {AXIAL_FLOOR_STOP:g}x)", diagnostics)
    if noise > AXIAL_NOISE_NOTE:
        notes.append(f"float32 rounding of the chain's x positions put {share_text(noise)} of the impact energy into "
                     f"its motion along the beam, {floor_text(noise_j, floor)}; the contact does not see it and the "
                     f"energy check uses the rest; unstable only beyond {AXIAL_NOISE_STOP:g}x the impact energy and "
                     f"{AXIAL_FLOOR_STOP:g}x the floor (docs/mujoco-warp.md)")


class _SameModelInC(MujocoAdapter):
    """MuJoCo C on the model MuJoCo Warp runs: the MuJoCo adapter's model without `diagexact`
    (unsupported by mujoco_warp), the contact pair's direct solref rescaled to keep the stiffness k:
    solref = (-k*A, 0) with A = efc_diagA without diagexact (body_invweight0 sums), the diagonal both engines then use;
    on a Timoshenko beam the Timoshenko chain in any tree root (MuJoCo C's own adapter builds it serially only)."""

    def chain(self, scene, settings: EngineSettings):
        chain = super().chain(scene, settings)
        if chain is None or chain.shear or not timoshenko(scene):
            return chain
        from impactval.engines.chain import hencky_chain

        return hencky_chain(scene.target, chain.n, chain.rotary, shear=True)

    def build(self, scene, settings: EngineSettings):
        import mujoco

        run = super().build(scene, settings)
        if settings.contact == "hertz":
            return run
        model, info = run.model, run.diagnostics
        model.opt.enableflags &= ~int(mujoco.mjtEnableBit.mjENBL_DIAGEXACT)
        a_exact = info["contact_inverse_mass"]
        a_approx = _contact_diag_approx(mujoco, model)
        model.pair_solref[0, 0] *= a_approx / a_exact
        info["contact_inverse_mass"] = a_approx
        info["contact_inverse_mass_exact"] = a_exact
        mujoco.mj_forward(model, run.data)
        return run


def _reanchor_connects(wp, mjw, mujoco, mjm, m, d) -> float:
    """Move each `<connect>`'s world anchor to where float32 kinematics put the body anchor at qpos0.

    The compiler stores the world anchor in float64; mujoco_warp's forward kinematics sums 81 float32
    segment offsets and lands ~2e-7 m away, which a support constraint of time constant 2 dt turns
    into a 7 kN kick at t = 0. Returns the largest shift [m] (reported as diagnostics["pin_anchor_shift"])."""
    mjw.kinematics(m, d)
    xpos, xmat = d.xpos.numpy()[0].astype(float), d.xmat.numpy()[0].astype(float)
    eq = m.eq_data.numpy()
    shift = 0.0
    for i in range(mjm.neq):
        if mjm.eq_type[i] != mujoco.mjtEq.mjEQ_CONNECT or mjm.eq_obj2id[i] > 0:
            continue
        b = mjm.eq_obj1id[i]
        world = xpos[b] + xmat[b].reshape(3, 3) @ mjm.eq_data[i, :3]
        shift = max(shift, float(np.max(np.abs(world - mjm.eq_data[i, 3:6]))))
        eq[..., i, 3:6] = world
    m.eq_data.assign(eq)
    return shift


def _contact_diag_approx(mujoco, model) -> float:
    """MuJoCo's approximate inverse effective mass [1/kg] of the contact row (efc_diagA without diagexact) at first touch."""
    d = mujoco.MjData(model)
    jq = model.jnt_qposadr[model.joint("ball_z").id]
    d.qpos[jq] = model.qpos0[jq] - 1e-9
    mujoco.mj_forward(model, d)
    rows = np.flatnonzero(np.asarray(d.efc_type) == mujoco.mjtConstraint.mjCNSTR_CONTACT_FRICTIONLESS)
    if rows.size != 1:
        raise EngineError(f"mujoco-warp: expected one contact row at first touch, found {rows.size}.")
    return float(d.efc_diagA[rows[0]])


@lru_cache(maxsize=32)
def sized_segments(scene, chain_tol: float, rotary: str, root: str = "middle") -> int:
    """Segments of the Warp chain: the MuJoCo C chain's (its sizing, `engines.mujoco_.default_segments`, with
    the C default rotary inertia "none", at `chain_tol`), capped at MAX_SEGMENTS[rotary], then lowered in ~10 %
    steps while the chain's joint-space mass matrix is beyond what float32 factorises (`mass_condition` above
    COND_LIMIT); when capped, the N within 12 below the cap with the smallest model error, the shared sizing's
    rule at its cap (engines.chain.segments_for). (Sizing the "section" chain itself would not
    converge: its rotary inertia keeps its frequencies off the Euler-Bernoulli ones, so it runs to any cap.)"""
    from impactval.engines.chain import MIN_SEGMENTS, centred

    from impactval.engines.chain import hencky_chain, model_error

    shear = timoshenko(scene)      # C's default_segments sizes its (serial) Timoshenko chain there: the same chain model
    c_n = n = default_segments(scene, EngineSettings(options=(("chain_tol", chain_tol), ("rotary_inertia", "none"))))
    cap = MAX_SEGMENTS[rotary]
    while n > MIN_SEGMENTS:
        if n > cap:
            n = centred(scene.target.impact_at, cap - max(2, cap // 10), cap, cap)
        if mass_condition(scene, n, rotary, root) <= COND_LIMIT:
            break
        cap = max(MIN_SEGMENTS, int(0.9 * n))
    if n < c_n:     # capped: as the shared sizing at its cap, the N near the cap with the smallest model error
        n = min(range(max(MIN_SEGMENTS, n - 12), n + 1),
                key=lambda m: (model_error(scene, hencky_chain(scene.target, m, rotary, shear=shear)).largest, -m))
    return n


@lru_cache(maxsize=64)
def mass_condition(scene, n: int, rotary: str, root: str) -> float:
    """Condition number of the chain model's joint-space mass matrix M(q0), diagonally scaled (the part a
    Cholesky factorisation feels), from MuJoCo C in float64."""
    import mujoco

    from impactval.engines.chain import hencky_chain
    from impactval.engines.mujoco_ import build_xml

    xml, _ = build_xml(scene, EngineSettings(dt=1e-6, options=(("chain_root", root),)),
                       hencky_chain(scene.target, n, rotary, shear=timoshenko(scene)))
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    mass = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, mass)
    scale = 1.0 / np.sqrt(np.diag(mass))
    return float(np.linalg.cond(mass * scale[:, None] * scale[None, :]))


def timoshenko(scene) -> bool:
    """True on a Timoshenko beam: MuJoCo Warp builds the Timoshenko chain there (engines.chain.hencky_chain(shear=True):
    a transverse slide of kappa G A / l at every node, 2 kappa G A / l at a supported end, the section's rotary
    inertia; MuJoCo C's model, built by the same `build_xml`) in whichever tree root (chain_root) is asked."""
    return getattr(scene.target, "theory", "euler-bernoulli") == "timoshenko"


def _check_target(scene) -> None:
    if scene.target.kind not in ("rigid-plate", "beam"):
        raise EngineError(f"mujoco-warp builds a rigid plate or a chain beam, not a {scene.target.kind!r} target "
                          f"(the Warp sampling reads the hit site of a plate or chain); use mujoco or the reference.")


def _model_kind(lay) -> str:
    return {"plate": "rigid-plate", "modal": f"modal-{lay.n_modes}"}.get(lay.kind, f"hencky-chain-{lay.n_segments}")
