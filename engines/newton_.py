"""Newton adapter (NVIDIA Newton on Warp, CPU, float32): the ball and the target built with
`newton.ModelBuilder`, stepped by one of Newton's rigid-body solvers, one step (collision + solver
+ a recording kernel) captured as a Warp CPU graph and replayed (see engines/_warp.py).

Model (SI, z up, no gravity, no friction, no damping: `angular_damping = 0`, contact kd = 0):

- ball: a free body (sphere shape of the scene's radius, mass and inertia set explicitly) touching
  the target at t = 0 with velocity -v0;
- rigid plate: Newton's ground plane;
- beam: the shared Hencky chain (`engines.chain.hencky_chain`: N rigid segments, mass rho*A*l, rotary
  inertia m(l^2 + h^2)/12 by default (option rotary_inertia), revolute joints about y with passive
  stiffness EI/l, 2EI/l at a clamp), a box shape on the hit segment only. N from the shared sizing
  capped at MAX_SEGMENTS = 41 (SemiImplicit's penalty joints soften finer chains). Supports: simply
  supported = revolute joints to the world at x = 0 and x = L (the second closes a loop:
  SemiImplicit's penalty joints give the axial freedom a roller would); clamped ends add 2EI/l;
  cantilever = free end. Out-of-plane inertias are the box's (never excited: the problem is planar).
  Modal targets are not built.

Contact "native": Newton's penalty contact, normal force ke*d with ke = the scene's k0 on both shapes
(Newton averages the two) and kd = 0: a linear spring, compared with the linear theory (`contact_law`
linear k0); the force series is ke*max(delta, 0) from the kinematics after each step. Contact
"hertz": no shapes; a Warp kernel adds alpha*max(delta,0)^1.5 to `body_f` from the current poses.

Integrators (`--integrator`): "semi-implicit" (default; SolverSemiImplicit, explicit penalty joints
with joint_attach_ke = ATTACH_KE, attach kd = 0), "featherstone" (reduced coordinates; no loop
closures, so only the plate and the cantilever), "xpbd" (SolverXPBD: positional contacts that ignore
ke: a result, see docs/newton.md). Build time (Newton's finalize + the first captured step, which
compiles or loads kernels: `diagnostics["compile_s"]`) and stepping time are reported apart.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from impactval.engines.base import WINDOW_CAP, EngineAdapter, EngineSettings, Plan, Simulation, plate_times
from impactval.engines.chain import DEFAULT_CHAIN_TOL, HenckyChain, centring, hencky_chain, omega_max, segments_for
from impactval.engines.options import boolean, in_range, one_of, option, positive
from impactval.errors import EngineError

INTEGRATORS = ("semi-implicit", "featherstone", "xpbd")
#: most segments the automatic chain sizing may choose: SemiImplicit's penalty joints add a give per
#: joint, so more segments are not more accurate (worked beam, native: N = 41 f_m +0.53 %, N = 81 -2.1 %)
MAX_SEGMENTS = 41
#: penalty stiffness of SemiImplicit's joint attachment [N/m and N m/rad]; stable at dt = 1e-6
#: with the segment masses of the worked beam (3e9 grows energy, 1e10 diverges)
ATTACH_KE = 1e9
#: steps replayed between host checks of the contact state (after a first chunk sized to the contact)
CHUNK = 64


def _whole(value) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"must be a positive whole number, got {value!r}")
    return value


@dataclass(frozen=True)
class NewtonOptions:
    """`--option newton.KEY=VALUE`."""

    attach_ke: float = option(ATTACH_KE, f"SemiImplicit joint attachment stiffness [N/m, N m/rad] (default "
                              f"{ATTACH_KE:g})", positive)
    xpbd_iterations: int = option(2, "XPBD solver iterations (default 2, Newton's)", _whole)
    rotary_inertia: str = option("section", "segment rotary inertia: 'section' = m (l^2 + h^2)/12 (default), "
                                 "'none' = m l^2/12", one_of("none", "section"))
    chain_tol: float = option(DEFAULT_CHAIN_TOL, "relative tolerance the chain is sized for (capped at "
                              f"{MAX_SEGMENTS} segments)", in_range(1e-4, 0.2))
    graph_capture: bool = option(True, "replay one captured step as a Warp CPU graph (default true)", boolean)


class NewtonAdapter(EngineAdapter):
    """Newton (`pip install 'impactval[newton]'`); see the module docstring."""

    name = "newton"
    module = "newton"
    contacts = ("hertz", "native")
    integrators = INTEGRATORS
    min_segments = 2
    Options = NewtonOptions
    expected_failures = {
        "check_beam_model": "the chain is capped at 41 segments (SemiImplicit's penalty joints soften finer chains: "
                            "worked beam N = 41 f_m +0.5 %, N = 81 -2.1 %; a stiffer attach_ke is unstable or "
                            "drowned by float32 rounding), and a 41-segment chain's own model_error (2.8 %) is above "
                            "the suite's 2 % bound",
    }

    def version(self) -> str:
        from importlib.metadata import version

        return f"{version('newton')} (warp {version('warp-lang')}, float32, cpu)"


    def chain(self, scene, settings: EngineSettings) -> HenckyChain | None:
        """The Hencky chain this job builds (engines.chain; None for a plate)."""
        if scene.target.kind != "beam":
            return None
        rotary = settings.option("rotary_inertia", "section")
        n = settings.segments
        if n is None:
            tol = float(settings.option("chain_tol", DEFAULT_CHAIN_TOL))
            n = segments_for(scene, tol, rotary, MAX_SEGMENTS, centring(scene.target.impact_at, MAX_SEGMENTS)).n
        return hencky_chain(scene.target, n, rotary)

    def explicit(self, settings: EngineSettings) -> bool:
        return (settings.integrator or INTEGRATORS[0]) != "xpbd"

    def plan(self, scene, settings: EngineSettings) -> Plan:
        """Stability limit 2/omega_max of chain + ball + contact spring; for SemiImplicit, of the chain as it
        integrates it: free planar segments held by the penalty attachments (`penalty_chain_omega_max`)."""
        from impactval.engines.chain import model_error
        from impactval.reference.hertz import ContactLaw

        if scene.target.kind not in ("rigid-plate", "beam"):
            raise EngineError(f"newton builds a rigid plate or a chain beam, not a {scene.target.kind!r} target.")
        chain = self.chain(scene, settings)
        law = self.contact_law(scene, settings) or ContactLaw.hertz(scene.alpha)
        om, what = omega_max(scene, law, chain)
        integ = settings.integrator or INTEGRATORS[0]
        diag: dict = {}
        err = 0.0 if chain is None else math.nan
        if chain is not None:
            me = model_error(scene, chain)
            err = me.largest
            diag.update(segments=chain.n, model_error_t_m=me.t_m, model_error_f_m=me.f_m,
                        model_error_delta_m=me.delta_m, rotary_inertia=chain.rotary)
            if integ == "semi-implicit":
                law_k = law.stiffness(_plate_delta_m(scene))
                om_pen = penalty_chain_omega_max(chain, float(settings.option("attach_ke", ATTACH_KE)),
                                                 scene.ball.mass, law_k)
                if om_pen > om:
                    om, what = om_pen, (f"SemiImplicit penalty-joint chain N = {chain.n} (attach_ke in x and z at "
                                        f"each joint) + ball + contact spring {law_k:.3g} N/m")
        if integ == "xpbd":
            return Plan(math.inf, "XPBD (positional, no explicit limit)", err, diag)
        return Plan(2.0 / om, f"{integ}, {what}", err, diag)

    def structure_frequencies(self, scene, settings: EngineSettings) -> np.ndarray:
        """The chain's natural frequencies [rad/s] from its linear model (engines.chain; rigid joints:
        SemiImplicit's penalty joints lower them slightly)."""
        chain = self.chain(scene, self.check_settings(settings))
        return np.zeros(0) if chain is None else np.asarray(chain.frequencies()[:6], float)

    # ------------------------------------------------------------------ model
    def build(self, scene, settings: EngineSettings, wp, newton):
        """(model, layout dict) of the scene."""
        from impactval.reference.hertz import plate_impact

        integ = settings.integrator or INTEGRATORS[0]
        ball = scene.ball
        plate = plate_impact(ball.mass, scene.alpha, ball.velocity)
        ke = plate.k0
        b = newton.ModelBuilder(gravity=(0.0, 0.0, 0.0))
        cfg = newton.ModelBuilder.ShapeConfig(ke=ke, kd=0.0, kf=0.0, mu=0.0, restitution=0.0, density=0.0,
                                              margin=0.0, gap=0.0)
        lay = {"kind": scene.target.kind, "hit_body": -1, "hit_local": (0.0, 0.0, 0.0), "top": 0.0,
               "segments": 0, "contact_stiffness": ke}
        target = scene.target
        if target.kind == "rigid-plate":
            if settings.contact == "native":
                b.add_ground_plane(cfg=cfg)
            x_hit = 0.0
        elif target.kind == "beam":
            if integ == "featherstone" and target.support != "cantilever":
                raise EngineError(f"newton: featherstone has no loop closures, so a {target.support} beam "
                                  f"(supports at both ends) cannot be built; use semi-implicit or xpbd.")
            x_hit = target.impact_x
            self._chain(b, target, self.chain(scene, settings), cfg if settings.contact == "native" else None, lay,
                        wp, newton)
        else:
            raise EngineError("newton: modal targets are not built (only rigid bodies and the chain beam); use "
                              "mujoco or exudyn.")
        r = ball.radius
        ib = 0.4 * ball.mass * r * r
        z0 = lay["top"] + r
        body = b.add_body(xform=wp.transform((x_hit, 0.0, z0), wp.quat_identity()), mass=ball.mass,
                          inertia=wp.mat33(ib, 0, 0, 0, ib, 0, 0, 0, ib), label="ball")
        if settings.contact == "native":           # injected Hertz: no shapes, no collisions
            b.add_shape_sphere(body, radius=r, cfg=cfg)
        lay.update(ball=body, z0=z0)
        model = b.finalize(device="cpu")
        return model, lay

    @staticmethod
    def _chain(b, beam, chain: HenckyChain, cfg, lay: dict, wp, newton) -> None:
        n, length, w, h = chain.n, chain.length, chain.width, chain.height
        l, m_seg = chain.segment_length, chain.segment_mass
        iyy = chain.rotary_inertia
        ixx = izz = m_seg * (l * l + w * w + h * h) / 12.0      # out of plane: never excited
        hit = chain.hit_segment
        y_axis = (0.0, 1.0, 0.0)
        links = []
        for i in range(n):
            body = b.add_link(xform=wp.transform((i * l, 0.0, 0.0), wp.quat_identity()), com=(l / 2, 0.0, 0.0),
                              mass=m_seg, inertia=wp.mat33(ixx, 0, 0, 0, iyy, 0, 0, 0, izz), label=f"seg{i}")
            links.append(body)
            if i == hit:
                off = chain.hit_offset
                if cfg is not None:
                    b.add_shape_box(body, xform=wp.transform((off, 0.0, 0.0), wp.quat_identity()),
                                    hx=l / 2, hy=w / 2, hz=h / 2, cfg=cfg)
                lay.update(hit_body=body, hit_local=(off, 0.0, h / 2), top=h / 2)
        joints = []
        k_root = 0.0 if beam.support == "simply-supported" else chain.clamp_stiffness
        joints.append(b.add_joint_revolute(-1, links[0], axis=y_axis, stiffness=k_root, damping=0.0,
                                           target_ke=0.0, target_kd=0.0, label="h0"))
        for i in range(1, n):
            joints.append(b.add_joint_revolute(
                links[i - 1], links[i], parent_xform=wp.transform((l, 0.0, 0.0), wp.quat_identity()),
                axis=y_axis, stiffness=chain.hinge_stiffness, damping=0.0, target_ke=0.0, target_kd=0.0, label=f"h{i}"))
        b.add_articulation(joints, label="beam")
        if beam.support in ("simply-supported", "clamped-clamped"):
            k_end = 0.0 if beam.support == "simply-supported" else chain.clamp_stiffness
            b.add_joint_revolute(-1, links[-1], parent_xform=wp.transform((length, 0.0, 0.0), wp.quat_identity()),
                                 child_xform=wp.transform((l, 0.0, 0.0), wp.quat_identity()),
                                 axis=y_axis, stiffness=k_end, damping=0.0, target_ke=0.0, target_kd=0.0,
                                 label="pin")
        lay.update(segments=n, segment_length=l, length=length,
                   pinned_end=beam.support in ("simply-supported", "clamped-clamped"))
        lay["hinge_stiffness"] = [k_root] + [chain.hinge_stiffness] * (n - 1)
        if beam.support in ("simply-supported", "clamped-clamped"):
            lay["hinge_stiffness"].append(k_end)      # the end pin: the last segment's absolute angle

    # ------------------------------------------------------------------ stepping
    def simulate(self, scene, settings: EngineSettings) -> Simulation:
        from impactval.engines._warp import CapturedStep, import_warp, window_end

        t0 = time.perf_counter()
        wp = import_warp()
        import newton

        from impactval.engines import _newton_kernels as K

        integ = settings.integrator or INTEGRATORS[0]
        model, lay = self.build(scene, settings, wp, newton)
        if integ == "semi-implicit":
            lay["attach_ke"] = float(settings.options.attach_ke)
            solver = newton.solvers.SolverSemiImplicit(model, angular_damping=0.0, joint_attach_ke=lay["attach_ke"],
                                                       joint_attach_kd=0.0)
        elif integ == "featherstone":
            solver = newton.solvers.SolverFeatherstone(model, angular_damping=0.0)
        else:
            solver = newton.solvers.SolverXPBD(model, iterations=settings.options.xpbd_iterations)
        s0, s1 = model.state(), model.state()
        control = model.control()
        ball = lay["ball"]
        jqd = model.joint_qd.numpy()
        j_ball = int(np.flatnonzero(model.joint_child.numpy() == ball)[0])
        qd0 = int(model.joint_qd_start.numpy()[j_ball])
        jqd[qd0 + 2] = -scene.ball.velocity
        s0.joint_qd.assign(jqd)
        newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
        pipeline = newton.CollisionPipeline(model)
        contacts = pipeline.contacts() if hasattr(pipeline, "contacts") else model.contacts(pipeline)
        nb = model.body_count
        plate = plate_times(scene)
        n_max = int(math.ceil((WINDOW_CAP * plate.t_m + settings.tail) / float(settings.dt))) + 1
        states = wp.zeros((n_max + 2, 13 * nb), dtype=float, device="cpu")
        counter = wp.zeros(1, dtype=int, device="cpu")
        bq, bqd = s0.body_q.numpy(), s0.body_qd.numpy()
        first = np.concatenate([bq.ravel(), bqd.ravel()])
        dt = float(settings.dt)
        pair = [s0, s1]

        # an even number of solver steps per replay keeps the captured state buffers in place
        hertz = settings.contact == "hertz"
        hertz_args = [model.body_com, ball, float(scene.ball.radius), lay["hit_body"], wp.vec3(*lay["hit_local"]),
                      float(lay["top"]), float(scene.alpha)]

        def two_steps():
            for a, b in ((pair[0], pair[1]), (pair[1], pair[0])):
                a.clear_forces()
                if hertz:
                    wp.launch(K.hertz_force, dim=1, inputs=[a.body_q, *hertz_args, a.body_f], device="cpu")
                else:
                    pipeline.collide(a, contacts)
                solver.step(a, b, control, contacts, dt)
                wp.launch(K.record, dim=1, inputs=[b.body_q, b.body_qd, counter, states], device="cpu")

        stepper = CapturedStep(wp, two_steps, capture=settings.options.graph_capture)
        stepper.warm_up()
        build_s = time.perf_counter() - t0
        step_s, n_steps = 0.0, 2
        chunk = max(CHUNK, int(1.1 * plate.t_m / dt))       # the first chunk covers a rigid-plate contact
        end = None
        while n_steps < n_max and end is None:
            n = max(1, min(chunk, n_max - n_steps) // 2)
            ts = time.perf_counter()
            stepper.run(n)
            step_s += time.perf_counter() - ts
            n_steps += 2 * n
            chunk = CHUNK
            delta, f = self._series(states.numpy()[:n_steps + 1], first, lay, scene, nb)[:2]
            end = window_end(np.column_stack([delta, f]), settings, scene)
        n_stepped = int(counter.numpy()[0])        # steps run (stepping wall time covers all of them)
        n_rec = n_stepped
        if end is not None:
            n_rec = min(n_rec, end)                  # the window rule: samples 0..end
        delta, f, xs, xb, vb = self._series(states.numpy()[:n_rec + 1], first, lay, scene, nb)
        # one state past the last sample (when stepped) gives the last sample's velocity after its step
        energy = self._energy(states.numpy()[:min(n_rec + 2, n_stepped + 1)], first, lay, scene, model, nb, delta)
        if hertz:
            f = scene.alpha * np.maximum(delta, 0.0) ** 1.5
            energy += 0.4 * scene.alpha * np.maximum(delta, 0.0) ** 2.5 - 0.5 * lay["contact_stiffness"] * np.maximum(delta, 0.0) ** 2
        t = np.arange(n_rec + 1) * dt
        diagnostics = {"compile_s": stepper.compile_s, "graph_capture": stepper.graph is not None,
                       "float": "float32", "contact_stiffness": lay["contact_stiffness"],
                       "contact_law": "hertz, injected into body_f" if hertz else "linear penalty ke = k0, kd = 0"}
        if integ == "semi-implicit":
            diagnostics["attach_ke"] = lay["attach_ke"]
        if lay["segments"]:
            diagnostics["segments"] = lay["segments"]
        kind = "rigid-plate" if lay["kind"] == "rigid-plate" else f"hencky-chain-{lay['segments']}"
        return Simulation(t=t, delta=delta, f=f, x_ball=xb, x_structure=xs, v_ball=vb, energy=energy,
                          build_s=build_s, step_s=step_s, n_steps=n_stepped,
                          model=f"newton-{kind}-{integ}-{settings.contact}-float32", diagnostics=diagnostics,
                          settings={"integrator": integ, "segments": lay["segments"] or None},
                          contact_law=self.contact_law(scene, settings))

    @staticmethod
    def _series(st: np.ndarray, first: np.ndarray, lay: dict, scene, nb: int):
        """(delta, force, hit-point displacement, ball displacement, ball velocity toward the target)."""
        st = st.astype(float)
        st[0] = first
        ball = lay["ball"]
        zb = st[:, 7 * ball + 2]
        if lay["hit_body"] >= 0:
            hb = lay["hit_body"]
            pos, quat = st[:, 7 * hb:7 * hb + 3], st[:, 7 * hb + 3:7 * hb + 7]
            zh = pos[:, 2] + _rotate(quat, np.asarray(lay["hit_local"]))[:, 2]
        else:
            zh = np.zeros(len(st))
        delta = zh - (zb - scene.ball.radius)
        f = lay["contact_stiffness"] * np.maximum(delta, 0.0)
        vb = -st[:, 7 * nb + 6 * ball + 2]
        return delta, f, lay["top"] - zh, lay["z0"] - zb, vb

    @staticmethod
    def _energy(st, first, lay, scene, model, nb, delta) -> np.ndarray:
        """Energy [J] per sample k (len(delta) samples; `st` may hold one state more): kinetic
        1/2 v_k' M v_(k+1) with the twists before (v_k) and after (v_(k+1)) step k, the quantity semi-implicit
        Euler conserves on a linear system (as the MuJoCo adapters measure it; the last sample without a next
        state uses its own twist) + hinge springs + contact spring + the penalty joints' stretch."""
        st = st.astype(float)
        st[0] = first
        n_s = len(delta)
        qd = st[:, 7 * nb:].reshape(len(st), nb, 6)
        q = st[:n_s, :7 * nb].reshape(n_s, nb, 7)
        mass = model.body_mass.numpy().astype(float)
        inertia = model.body_inertia.numpy().astype(float)
        before = qd[:n_s]
        after = np.concatenate([qd[1:n_s + 1], qd[len(qd) - 1:][:max(0, n_s + 1 - len(qd))]])
        ke = 0.5 * np.einsum("b,kbi,kbi->k", mass, before[..., :3], after[..., :3])
        ke += 0.5 * np.einsum("kbi,bij,kbj->k", before[..., 3:], inertia, after[..., 3:])   # planar: I ~ world frame
        pe = 0.5 * lay["contact_stiffness"] * np.maximum(delta, 0.0) ** 2
        if lay["segments"]:
            n = lay["segments"]
            chain = q[:, :n]                  # the segments are bodies 0..n-1
            theta = 2.0 * np.arctan2(chain[..., 4], chain[..., 6])     # rotation about y
            rel = np.diff(np.concatenate([np.zeros((n_s, 1)), theta], axis=1), axis=1)
            k = np.asarray(lay["hinge_stiffness"])
            pe += 0.5 * rel**2 @ k[:n]
            if len(k) > n:
                pe += 0.5 * k[n] * theta[:, -1] ** 2
            if lay.get("attach_ke"):
                pe += 0.5 * lay["attach_ke"] * _joint_gaps_squared(chain, lay)
        return pe + ke


def _plate_delta_m(scene) -> float:
    from impactval.reference.hertz import plate_impact

    return plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity).delta_m


def penalty_chain_omega_max(chain: HenckyChain, attach_ke: float, ball_mass: float, contact_k: float) -> float:
    """Highest frequency [rad/s] of the chain SemiImplicit integrates, linearised in the plane: each segment
    a free body (x, z of its centre of mass, rotation theta; mass m, rotary inertia J), every joint's anchors
    held together by attach_ke in x and z (a world joint: the anchor to its world point), the hinge springs
    on the relative rotations, the ball on the contact spring at the hit point. (The segment-on-two-springs
    estimate 2 sqrt(attach_ke/m) misses the rotation: the anchors' z coupling with lever l/2 on J gives
    omega^2 ~ 12 attach_ke l^2 / (m (l^2 + h^2)), 1.2-1.4x higher on the worked beam, where it blew up.)"""
    from scipy import linalg

    n, l = chain.n, chain.segment_length
    nd = 3 * n + 1                                     # per segment x, z, theta; then the ball's z
    mass = np.zeros(nd)
    mass[0:3 * n:3] = mass[1:3 * n:3] = chain.segment_mass
    mass[2:3 * n:3] = chain.rotary_inertia
    mass[-1] = ball_mass
    k = np.zeros((nd, nd))

    def anchor_rows(i: int, end: int) -> tuple[np.ndarray, np.ndarray]:
        """x and z rows of segment i's anchor at its left (end = -1) or right (+1) end, linearised."""
        rx, rz = np.zeros(nd), np.zeros(nd)
        rx[3 * i] = 1.0
        rz[3 * i + 1] = 1.0
        rz[3 * i + 2] = -end * l / 2.0                 # rotation theta about y moves (end*l/2, 0) by -theta*end*l/2 in z
        return rx, rz

    def spring(row: np.ndarray, stiffness: float) -> None:
        k[:] += stiffness * np.outer(row, row)

    for i in range(n - 1):                             # joint i+1: right end of i to left end of i+1
        (ax, az), (bx, bz) = anchor_rows(i, 1), anchor_rows(i + 1, -1)
        spring(bx - ax, attach_ke)
        spring(bz - az, attach_ke)
        rot = np.zeros(nd)
        rot[3 * (i + 1) + 2], rot[3 * i + 2] = 1.0, -1.0
        spring(rot, chain.hinge_stiffness)
    ends = [(0, -1, 0.0 if chain.support == "simply-supported" else chain.clamp_stiffness)]
    if chain.support in ("simply-supported", "clamped-clamped"):
        ends.append((n - 1, 1, 0.0 if chain.support == "simply-supported" else chain.clamp_stiffness))
    for i, end, k_rot in ends:                         # world joints
        ax, az = anchor_rows(i, end)
        spring(ax, attach_ke)
        spring(az, attach_ke)
        rot = np.zeros(nd)
        rot[3 * i + 2] = 1.0
        spring(rot, k_rot)
    hit = np.zeros(nd)                                 # contact: ball z minus the hit point's z
    hit[3 * chain.hit_segment + 1] = 1.0
    hit[3 * chain.hit_segment + 2] = -(chain.hit_offset - l / 2.0)
    hit[-1] = -1.0
    spring(hit, contact_k)
    scale = 1.0 / np.sqrt(mass)
    w2 = linalg.eigvalsh(k * scale[:, None] * scale[None, :])
    return float(math.sqrt(max(float(w2[-1]), 0.0)))


def _joint_gaps_squared(chain: np.ndarray, lay: dict) -> np.ndarray:
    """Sum over the chain's joints of |child anchor - parent anchor|^2 [m^2] per sample: the
    stretch of SemiImplicit's penalty attachments (their energy is attach_ke/2 times this)."""
    ns, n = chain.shape[:2]
    l = lay["segment_length"]
    pos, quat = chain[..., :3], chain[..., 3:]
    tail = pos + _rotate(quat.reshape(-1, 4), np.array([l, 0.0, 0.0])).reshape(ns, n, 3)   # x = l end
    gaps = np.sum((pos[:, 1:] - tail[:, :-1]) ** 2, axis=(1, 2)) + np.sum(pos[:, 0] ** 2, axis=1)
    if lay["pinned_end"]:
        gaps += np.sum((tail[:, -1] - np.array([lay["length"], 0.0, 0.0])) ** 2, axis=1)
    return gaps


def _rotate(quat: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vector v by unit quaternions (x, y, z, w), row-wise."""
    xyz, w = quat[:, :3], quat[:, 3:4]
    t = 2.0 * np.cross(xyz, v)
    return v + w * t + np.cross(xyz, t)
