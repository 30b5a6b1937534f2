"""Newton adapter (NVIDIA Newton on Warp, CPU, float32): the ball and the target built with
`newton.ModelBuilder`, stepped by one of Newton's rigid-body solvers, one step (collision + solver
+ a recording kernel) captured as a Warp CPU graph and replayed (see engines/_warp.py).

Model (SI, z up, no gravity, no friction, no damping: `angular_damping = 0`, contact kd = 0):

- ball: a free body (sphere shape of the scene's radius, mass and inertia set explicitly) touching
  the target at t = 0 with velocity -v0;
- rigid plate: Newton's ground plane;
- beam: the Hencky chain of the MuJoCo adapter (N rigid segments of length l = L/N, mass rho*A*l,
  in-plane rotary inertia m(l^2 + h^2)/12, revolute joints about y of stiffness EI/l, a box shape
  on the hit segment only). Supports: simply supported = revolute joints to the world at x = 0
  and x = L (the second closes a loop: SemiImplicit's penalty joints allow the axial give a real
  beam has); clamped = a 2EI/l revolute spring to the world; cantilever = free end.
  Out-of-plane rotary inertias are set to the in-plane one's order: they are never excited, and the
  penalty joints (one `joint_attach_ke` for position and angle) would otherwise limit the step.

Contact: Newton's penalty contact, normal force ke*d with ke = the scene's k0 on both shapes
(Newton averages the two) and kd = 0: a linear spring, compared with the linear theory
(`contact_law` linear k0). The force series is ke*max(delta, 0) from the kinematics after each step.

Integrators (`--integrator`): "semi-implicit" (default; SolverSemiImplicit, explicit penalty joints
with joint_attach_ke = ATTACH_KE), "featherstone" (reduced coordinates; no loop closures, so only the
plate and the cantilever), "xpbd" (SolverXPBD: positional contacts that ignore ke: a result, see
docs/newton.md). Contact "hertz" (injected force) is not offered.
"""
from __future__ import annotations

import math
import time

import numpy as np

from impactval.engines.base import EngineAdapter, EngineSettings, Simulation
from impactval.errors import EngineError

INTEGRATORS = ("semi-implicit", "featherstone", "xpbd")
#: default chain segment count (SemiImplicit is stable at dt = 1e-6 with it, see docs/newton.md)
DEFAULT_SEGMENTS = 41
#: penalty stiffness of SemiImplicit's joint attachment [N/m and N m/rad]; stable at dt = 1e-6
#: with the segment masses of the worked beam, and stiff enough that joint give is < 0.1 % of the
#: beam's compliance
ATTACH_KE = 1e9
#: steps replayed between host checks of the contact state
CHUNK = 256
#: simulated time limit as a multiple of the rigid-plate contact time (plus the tail)
MAX_TIME_FACTOR = 200.0
OPTIONS = {
    "attach_ke": (float, f"SemiImplicit joint attachment stiffness (default {ATTACH_KE:g})"),
    "xpbd_iterations": (int, "XPBD solver iterations (default 2, Newton's)"),
    "max_time": (float, "simulated time limit [s]"),
    "graph_capture": (bool, "replay one captured step as a Warp CPU graph (default true)"),
}


def _option(settings: EngineSettings, key: str, default):
    value = settings.option(key, default)
    kind = OPTIONS[key][0]
    try:
        if kind is bool and isinstance(value, str):
            if value.lower() not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError
            return value.lower() in ("true", "1", "yes")
        out = kind(value)
    except (TypeError, ValueError):
        raise EngineError(f"newton: option {key} must be {kind.__name__}, got {value!r}.") from None
    if kind in (float, int) and not out > 0:
        raise EngineError(f"newton: option {key} must be positive, got {value!r}.")
    return out


class NewtonAdapter(EngineAdapter):
    """Newton (`pip install 'impactval[newton]'`); see the module docstring."""

    name = "newton"
    module = "newton"
    contacts = ("native", "hertz")
    integrators = INTEGRATORS

    def version(self) -> str:
        from importlib.metadata import version

        return f"{version('newton')} (warp {version('warp-lang')}, float32, cpu)"

    def check_settings(self, settings: EngineSettings) -> None:
        super().check_settings(settings)
        for key, _ in settings.options:
            if key not in OPTIONS:
                raise EngineError(f"newton: unknown option {key!r}; known: {', '.join(OPTIONS)}.")
            _option(settings, key, None)

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
            n = settings.segments or DEFAULT_SEGMENTS
            if n < 2:
                raise EngineError(f"segments must be at least 2 for a Hencky chain, got {n}.")
            if integ == "featherstone" and target.support != "cantilever":
                raise EngineError(f"newton: featherstone has no loop closures, so a {target.support} beam "
                                  f"(supports at both ends) cannot be built; use semi-implicit or xpbd.")
            x_hit = target.impact_x
            self._chain(b, target, n, cfg if settings.contact == "native" else None, lay, wp, newton)
        else:
            raise EngineError("newton: a modal target has no surface to collide with (contact is native only).")
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
    def _chain(b, beam, n: int, cfg, lay: dict, wp, newton) -> None:
        mat = beam.material
        length, w, h = beam.length, beam.width, beam.height
        l = length / n
        ei = mat.young * beam.second_moment
        m_seg = mat.density * beam.area * l
        iyy = m_seg * (l * l + h * h) / 12.0
        ixx = izz = m_seg * (l * l + w * w + h * h) / 12.0
        hit = min(int(beam.impact_x / l), n - 1)
        y_axis = (0.0, 1.0, 0.0)
        links = []
        for i in range(n):
            body = b.add_link(xform=wp.transform((i * l, 0.0, 0.0), wp.quat_identity()), com=(l / 2, 0.0, 0.0),
                              mass=m_seg, inertia=wp.mat33(ixx, 0, 0, 0, iyy, 0, 0, 0, izz), label=f"seg{i}")
            links.append(body)
            if i == hit:
                off = beam.impact_x - i * l
                if cfg is not None:
                    b.add_shape_box(body, xform=wp.transform((off, 0.0, 0.0), wp.quat_identity()),
                                    hx=l / 2, hy=w / 2, hz=h / 2, cfg=cfg)
                lay.update(hit_body=body, hit_local=(off, 0.0, h / 2), top=h / 2)
        joints = []
        k_root = 0.0 if beam.support == "simply-supported" else 2.0 * ei / l
        joints.append(b.add_joint_revolute(-1, links[0], axis=y_axis, stiffness=k_root, damping=0.0,
                                           target_ke=0.0, target_kd=0.0, label="h0"))
        for i in range(1, n):
            joints.append(b.add_joint_revolute(
                links[i - 1], links[i], parent_xform=wp.transform((l, 0.0, 0.0), wp.quat_identity()),
                axis=y_axis, stiffness=ei / l, damping=0.0, target_ke=0.0, target_kd=0.0, label=f"h{i}"))
        b.add_articulation(joints, label="beam")
        if beam.support in ("simply-supported", "clamped-clamped"):
            k_end = 0.0 if beam.support == "simply-supported" else 2.0 * ei / l
            b.add_joint_revolute(-1, links[-1], parent_xform=wp.transform((length, 0.0, 0.0), wp.quat_identity()),
                                 child_xform=wp.transform((l, 0.0, 0.0), wp.quat_identity()),
                                 axis=y_axis, stiffness=k_end, damping=0.0, target_ke=0.0, target_kd=0.0,
                                 label="pin")
        lay.update(segments=n, segment_length=l, length=length,
                   pinned_end=beam.support in ("simply-supported", "clamped-clamped"))
        lay["hinge_stiffness"] = [k_root] + [ei / l] * (n - 1)
        if beam.support in ("simply-supported", "clamped-clamped"):
            lay["hinge_stiffness"].append(k_end)      # the end pin: the last segment's absolute angle

    # ------------------------------------------------------------------ stepping
    def _simulate(self, scene, settings: EngineSettings) -> Simulation:
        from impactval.engines._warp import CapturedStep, import_warp
        from impactval.reference.hertz import plate_impact

        t0 = time.perf_counter()
        wp = import_warp()
        import newton

        from impactval.engines import _newton_kernels as K

        integ = settings.integrator or INTEGRATORS[0]
        model, lay = self.build(scene, settings, wp, newton)
        if integ == "semi-implicit":
            lay["attach_ke"] = _option(settings, "attach_ke", ATTACH_KE)
            solver = newton.solvers.SolverSemiImplicit(model, angular_damping=0.0, joint_attach_ke=lay["attach_ke"],
                                                       joint_attach_kd=0.0)
        elif integ == "featherstone":
            solver = newton.solvers.SolverFeatherstone(model, angular_damping=0.0)
        else:
            solver = newton.solvers.SolverXPBD(model, iterations=_option(settings, "xpbd_iterations", 2))
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
        plate = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
        t_max = float(settings.option("max_time", MAX_TIME_FACTOR * plate.t_m + settings.tail))
        n_max = int(math.ceil(t_max / settings.dt)) + 1
        states = wp.zeros((n_max + 2, 13 * nb), dtype=float, device="cpu")
        counter = wp.zeros(1, dtype=int, device="cpu")
        bq, bqd = s0.body_q.numpy(), s0.body_qd.numpy()
        first = np.concatenate([bq.ravel(), bqd.ravel()])
        dt = settings.dt
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

        stepper = CapturedStep(wp, two_steps, capture=_option(settings, "graph_capture", True))
        stepper.warm_up()
        build_s = time.perf_counter() - t0
        step_s, n_steps = 0.0, 2
        while n_steps < n_max:
            n = min(CHUNK // 2, (n_max - n_steps + 1) // 2)
            ts = time.perf_counter()
            stepper.run(n)
            step_s += time.perf_counter() - ts
            n_steps += 2 * n
            if _window_done(self._series(states.numpy()[:n_steps + 1], first, lay, scene, nb)[:2], settings, scene):
                break
        n_rec = int(counter.numpy()[0])
        delta, f, xs, xb, vb = self._series(states.numpy()[:n_rec + 1], first, lay, scene, nb)
        energy = self._energy(states.numpy()[:n_rec + 1], first, lay, scene, model, nb, delta)
        if hertz:
            f = scene.alpha * np.maximum(delta, 0.0) ** 1.5
            energy += 0.4 * scene.alpha * np.maximum(delta, 0.0) ** 2.5 - 0.5 * lay["contact_stiffness"] * np.maximum(delta, 0.0) ** 2
        t = np.arange(n_rec + 1) * dt
        diagnostics = {"compile_s": stepper.compile_s, "graph_capture": stepper.graph is not None,
                       "float": "float32", "contact_stiffness": lay["contact_stiffness"],
                       "contact_law": "hertz, injected into body_f" if hertz else "linear penalty ke = k0, kd = 0"}
        if integ == "semi-implicit":
            diagnostics["attach_ke"] = _option(settings, "attach_ke", ATTACH_KE)
        if lay["segments"]:
            diagnostics["segments"] = lay["segments"]
        kind = "rigid-plate" if lay["kind"] == "rigid-plate" else f"hencky-chain-{lay['segments']}"
        return Simulation(t=t, delta=delta, f=f, x_ball=xb, x_structure=xs, v_ball=vb, energy=energy,
                          build_s=build_s, step_s=step_s, n_steps=n_rec,
                          model=f"newton-{kind}-{integ}-{settings.contact}-float32", diagnostics=diagnostics,
                          settings={"integrator": integ, "segments": lay["segments"] or None})

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
        """Kinetic (mean of the velocities around a sample: SemiImplicit moves with the new velocity)
        + hinge springs + contact spring [J]."""
        st = st.astype(float)
        st[0] = first
        qd = st[:, 7 * nb:].reshape(len(st), nb, 6)
        q = st[:, :7 * nb].reshape(len(st), nb, 7)
        mass = model.body_mass.numpy().astype(float)
        inertia = model.body_inertia.numpy().astype(float)
        v = qd.copy()
        v[:-1] = 0.5 * (qd[:-1] + qd[1:])
        ke = 0.5 * np.einsum("b,kbi,kbi->k", mass, v[..., :3], v[..., :3])
        ke += 0.5 * np.einsum("kbi,bij,kbj->k", v[..., 3:], inertia, v[..., 3:])   # planar: I ~ world frame
        pe = 0.5 * lay["contact_stiffness"] * np.maximum(delta, 0.0) ** 2
        if lay["segments"]:
            n = lay["segments"]
            chain = q[:, :n]                  # the segments are bodies 0..n-1
            theta = 2.0 * np.arctan2(chain[..., 4], chain[..., 6])     # rotation about y
            rel = np.diff(np.concatenate([np.zeros((len(st), 1)), theta], axis=1), axis=1)
            k = np.asarray(lay["hinge_stiffness"])
            pe += 0.5 * rel**2 @ k[:n]
            if len(k) > n:
                pe += 0.5 * k[n] * theta[:, -1] ** 2
            if lay.get("attach_ke"):
                pe += 0.5 * lay["attach_ke"] * _joint_gaps_squared(chain, lay)
        return pe + ke


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


def _window_done(series, settings: EngineSettings, scene) -> bool:
    """True once the series blew up or the first contact ended `settings.tail` ago."""
    delta, f = series
    if not np.all(np.isfinite(delta)) or np.any(np.abs(delta) > 10 * scene.ball.radius):
        return True
    on = f > 0
    if not on.any():
        return False
    first = int(np.argmax(on))
    ends = np.flatnonzero(~on[first:] & (delta[first:] < 0))
    return bool(ends.size) and (len(delta) - first - ends[0]) * settings.dt >= settings.tail
