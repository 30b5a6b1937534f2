"""MuJoCo adapter: the ball and the target built as an MJCF model, stepped with `mj_step`.

Model (SI units, z up, the ball falls along -z, no gravity, no friction, no damping):

- ball: a sphere of the scene's mass and radius on one slide joint along z, touching the target
  at t = 0 with velocity -v0;
- rigid plate: the world (a plane geom at z = 0);
- beam: a Hencky chain of N rigid segments of length l = L/N along x (neutral axis at z = 0, top
  face at z = h/2). Each segment carries the mass m = rho*A*l and the rotary inertia
  m*(l^2 + h^2)/12 of a real beam piece (option rotary_inertia = "section", the default) or
  m*l^2/12 (rotary_inertia = "none": pure Euler-Bernoulli, like the reference). The section's
  rotary inertia lowers the chain's highest frequency, so N = 81 runs at dt = 1e-6 with Euler
  (without it Euler needs dt < ~0.6 us), at the price of a model difference (Rayleigh beam:
  first three frequencies -0.02/-0.07/-0.15 % on the worked case; up to ~1.3 % in t_m on a long
  contact, see docs/mujoco.md). Neighbouring segments are joined by hinges (axis y) of
  stiffness EI/l; a clamped end is a hinge to the ground of stiffness 2EI/l
  (the end curvature is lumped over half a segment). Supports: simply supported = a roller at
  x = 0 (slide x + free hinge) and a `<connect>` pin at x = L (a pin at both ends locks the
  chain); clamped-clamped = a roller with a 2EI/l hinge at x = 0 and, at x = L, a `<connect>`
  pin plus a fixed tendon over all hinge angles (= the last segment's absolute rotation) of
  stiffness 2EI/l; cantilever = a 2EI/l hinge to the ground at x = 0, free end.
  The ball hits the segment that contains x = impact_at*L, at that point;
- modal target (contact "hertz" only): one oscillator per mode, mass m_i/phi_i^2 on a slide
  joint with stiffness (m_i/phi_i^2)*omega_i^2; the contact point moves by the sum of their
  displacements.

Contact modes:

- "hertz": collision off; `alpha*max(delta, 0)^1.5` is computed in `mjcb_passive` from the
  current state (so every Runge-Kutta stage sees its own state) and applied with `mj_applyFT`
  to the ball and, opposite, to the target at the contact point;
- "native": one explicit contact pair (condim 1) set to a linear, undamped spring of the paper's
  k0 = 0.8*alpha*sqrt(delta_m) (rigid-plate delta_m): direct solref = (-k0/m_eff, 0) with
  m_eff = 1/efc_diagA of the contact row (exact diagonal, `diagexact`) and a flat solimp of
  small impedance (d0 = dwidth = NATIVE_IMPEDANCE = 1e-4, see there why not MuJoCo's 0.9);
- "native-hertz": the same pair with solref and the solimp shape fitted (least squares on the
  static force law MuJoCo itself produces, on a plate with the scene's ball) to alpha*delta^1.5
  over 0..1.2 delta_m, impedance <= 1e-3; the fit's RMS error is reported in diagnostics["native_hertz_fit_rms"].

Series are sampled after every step at the new state (an extra `mj_forward`, not counted in the
stepping wall time). Diagnostics of a beam: the chain's own first natural frequencies
(`structure_frequencies`, from MuJoCo's linearised transition matrix, so supports and soft
constraints are as simulated) next to the continuum's (`continuum_frequencies`). Energy for
Euler/implicitfast uses the mean of the half-step velocities around a sample (second order).
The support constraints use solref = (2 dt, 1) (MuJoCo's default 0.02 s makes them springs).
"""
from __future__ import annotations

import math
import time
from functools import lru_cache

import numpy as np

from impactval.engines.base import EngineAdapter, EngineDiverged, EngineSettings, Simulation
from impactval.errors import EngineError

#: default Hencky chain segment count (see `default_segments`)
DEFAULT_SEGMENTS = 81
#: MuJoCo integrators offered (first = default); "discrete" damps contacts and is left out
INTEGRATORS = ("Euler", "implicitfast", "RK4")
#: impedance of the native contact pair. MuJoCo's soft contact gives f = (d/A)*(k*delta - a0): the
#: a0 term (the target's own acceleration at the contact) turns a contact on a flexible target into
#: a stiff constraint for the usual d ~ 0.9-0.95 (worked-case beam: f up to 12x k0*delta); a small
#: constant d with solref scaled to match keeps it a spring (d = 1e-4: within 0.05 % of k0*delta)
NATIVE_IMPEDANCE = 1e-4
#: largest impedance of the fitted native-hertz shape (same reason)
NATIVE_HERTZ_DMAX = 1e-3
#: simulated time limit as a multiple of the rigid-plate contact time (plus the tail)
MAX_TIME_FACTOR = 200.0
#: how many chain frequencies to report
N_FREQUENCIES = 6
#: engine-specific options (settings.options): name -> (allowed values or a type, meaning)
OPTIONS = {
    "max_time": (float, "simulated time limit [s] (default: 200 rigid-plate contact times + tail)"),
    "equality_timeconst": (float, "solref time constant [s] of the support constraints (default 2*dt)"),
    "native_impedance": (float, f"constant solimp impedance d of the native linear contact "
                         f"(default {NATIVE_IMPEDANCE:g}; MuJoCo's usual 0.9-0.95 stiffens it on flexible targets)"),
    "rotary_inertia": (("section", "none"), "segment rotary inertia: 'section' = m(l^2+h^2)/12 (a real "
                       "beam's, default), 'none' = m l^2/12 (pure Euler-Bernoulli; needs dt < ~0.5 us at N = 81)"),
}


def default_segments(scene) -> int:
    """Hencky chain segment count when settings.segments is None.

    81 segments: on the worked case (simply supported, mid-span) the chain's impact errors are
    at most 1.0 % and its first three frequencies within 0.2 % of the continuum, and Euler is
    stable at dt = 1e-6 (with the default section rotary inertia).
    One function so a mode-based criterion can replace it.
    """
    return DEFAULT_SEGMENTS


def _fmt(x: float) -> str:
    return f"{x:.17g}"


def _vec(*xs: float) -> str:
    return " ".join(_fmt(x) for x in xs)


class _Layout:
    """Geometry of the built model: where the contact point is and how to read it."""

    def __init__(self) -> None:
        self.kind = ""
        self.n_segments = 0
        self.segment_length = math.nan
        self.hinge_stiffness = math.nan
        self.clamp_stiffness = math.nan
        self.hit_segment = -1
        self.top = 0.0               # z of the target's contact point at rest [m]
        self.impact_x = 0.0
        self.n_modes = 0


def _beam_xml(beam, n: int, lay: _Layout, contact_geom: bool, rotary: str = "section") -> tuple[str, str]:
    """Worldbody chain and extra sections (equality, tendon) for a Hencky chain beam."""
    mat = beam.material
    length, w, h = beam.length, beam.width, beam.height
    l = length / n
    ei = mat.young * beam.second_moment
    k_hinge, k_clamp = ei / l, 2.0 * ei / l
    m_seg = mat.density * beam.area * l
    iyy = m_seg * (l * l + (h * h if rotary == "section" else 0.0)) / 12.0
    ixx = izz = m_seg * (l * l + w * w + h * h) / 12.0     # out of plane: never excited
    x_c = beam.impact_x
    hit = min(int(x_c / l), n - 1)
    lay.kind, lay.n_segments, lay.segment_length = "beam", n, l
    lay.hinge_stiffness, lay.clamp_stiffness, lay.hit_segment = k_hinge, k_clamp, hit
    lay.top, lay.impact_x = h / 2.0, x_c
    support = beam.support
    parts, closes = [], []
    for i in range(n):
        pos = _vec(0.0, 0.0, 0.0) if i == 0 else _vec(l, 0.0, 0.0)
        s = [f'<body name="seg{i}" pos="{pos}">']
        if i == 0:
            if support in ("simply-supported", "clamped-clamped"):
                s.append('<joint name="root_x" type="slide" axis="1 0 0"/>')
            k_root = 0.0 if support == "simply-supported" else k_clamp
            s.append(f'<joint name="h0" type="hinge" axis="0 1 0" stiffness="{_fmt(k_root)}"/>')
        else:
            s.append(f'<joint name="h{i}" type="hinge" axis="0 1 0" stiffness="{_fmt(k_hinge)}"/>')
        s.append(f'<inertial pos="{_vec(l / 2, 0, 0)}" mass="{_fmt(m_seg)}" diaginertia="{_vec(ixx, iyy, izz)}"/>')
        if i == hit:
            off = x_c - i * l
            s.append(f'<site name="hit" pos="{_vec(off, 0, h / 2)}" size="0.001"/>')
            if contact_geom:
                s.append(f'<geom name="target" type="box" pos="{_vec(off, 0, 0)}" '
                         f'size="{_vec(l / 2, w / 2, h / 2)}" contype="0" conaffinity="0" mass="0"/>')
        parts.append("".join(s))
        closes.append("</body>")
    chain = "".join(parts) + "".join(closes)
    extra = ""
    if support in ("simply-supported", "clamped-clamped"):
        extra += f'<equality><connect name="pin" body1="seg{n - 1}" anchor="{_vec(l, 0, 0)}"/></equality>'
    if support == "clamped-clamped":
        joints = "".join(f'<joint joint="h{i}" coef="1"/>' for i in range(n))
        extra += f'<tendon><fixed name="clamp_end" stiffness="{_fmt(k_clamp)}" springlength="0">{joints}</fixed></tendon>'
    return chain, extra


def _modal_xml(target, lay: _Layout) -> str:
    parts = []
    for i, (om, mm, ph) in enumerate(zip(target.omega, target.modal_mass, target.phi)):
        if abs(ph) < 1e-12:
            continue       # a mode with phi = 0 at the contact point is never excited
        m_i = mm / ph**2
        parts.append(f'<body name="mode{i}" pos="0 0 -1"><joint name="q{i}" type="slide" axis="0 0 1" '
                     f'stiffness="{_fmt(m_i * om * om)}"/><inertial pos="0 0 0" mass="{_fmt(m_i)}" '
                     f'diaginertia="1e-6 1e-6 1e-6"/></body>')
        lay.n_modes += 1
    lay.kind = "modal"
    return "".join(parts)


def build_xml(scene, settings: EngineSettings, n_segments: int | None = None,
              solref: tuple[float, float] = (-1.0, 0.0),
              solimp=(NATIVE_IMPEDANCE, NATIVE_IMPEDANCE, 0.001, 0.5, 2.0)) -> tuple[str, _Layout]:
    """MJCF text of the scene and its layout. `solref`/`solimp` are those of the contact pair
    (used only for native contact modes)."""
    target = scene.target
    ball = scene.ball
    lay = _Layout()
    native = settings.contact != "hertz"
    extra = ""
    if target.kind == "rigid-plate":
        lay.kind, lay.top = "plate", 0.0
        world = ('<geom name="target" type="plane" size="1 1 0.1" contype="0" conaffinity="0"/>'
                 '<site name="hit" pos="0 0 0" size="0.001"/>')
    elif target.kind == "beam":
        world, extra = _beam_xml(target, n_segments or default_segments(scene), lay, native,
                                 settings.option("rotary_inertia", "section"))
    else:
        world = _modal_xml(target, lay)
    z_ball = lay.top + ball.radius
    ib = 0.4 * ball.mass * ball.radius**2
    ball_xml = (f'<body name="ball" pos="{_vec(lay.impact_x, 0, z_ball)}"><joint name="ball_z" type="slide" '
                f'axis="0 0 1"/><inertial pos="0 0 0" mass="{_fmt(ball.mass)}" diaginertia="{_vec(ib, ib, ib)}"/>'
                f'<geom name="ball" type="sphere" size="{_fmt(ball.radius)}" contype="0" conaffinity="0" mass="0"/>'
                f'<site name="tip" pos="{_vec(0, 0, -ball.radius)}" size="0.001"/></body>')
    integ = settings.integrator or INTEGRATORS[0]
    flags = '<flag energy="enable" gravity="disable"' + (' diagexact="enable"/>' if native else ' contact="disable"/>')
    pair = ""
    if native:
        pair = (f'<contact><pair geom1="ball" geom2="target" condim="1" margin="0" gap="0" '
                f'solref="{_vec(*solref)}" solimp="{_vec(*solimp)}"/></contact>')
    xml = (f'<mujoco model="{scene.name}"><option timestep="{_fmt(settings.dt)}" integrator="{integ}" '
           f'gravity="0 0 0">{flags}</option>'
           f'<worldbody>{world}{ball_xml}</worldbody>{extra}{pair}</mujoco>')
    return xml, lay


class _Probe:
    """Reads delta [m] (approach of the contact points) and the contact force [N] of a model."""

    def __init__(self, mujoco, model, lay: _Layout, scene, contact: str):
        self.mj, self.m, self.lay, self.contact = mujoco, model, lay, contact
        self.alpha = scene.alpha
        self.ball_body = model.body("ball").id
        self.ball_dof = model.jnt_dofadr[model.joint("ball_z").id]
        self.ball_qpos = model.jnt_qposadr[model.joint("ball_z").id]
        self.tip = model.site("tip").id
        self.hit = model.site("hit").id if lay.kind != "modal" else -1
        self.hit_body = model.site_bodyid[self.hit] if self.hit >= 0 else -1
        if lay.kind == "modal":
            names = [model.joint(j).name for j in range(model.njnt)]
            self.mode_qpos = np.array([model.jnt_qposadr[j] for j, nm in enumerate(names) if nm.startswith("q")])
            self.mode_dofs = np.array([model.jnt_dofadr[j] for j, nm in enumerate(names) if nm.startswith("q")])
        self.ball_geom = model.geom("ball").id
        self.force6 = np.zeros(6)

    def delta_points(self, d) -> tuple[float, float]:
        """(delta [m], downward displacement of the target's contact point [m]) for d's kinematics."""
        z_tip = d.site_xpos[self.tip, 2]
        if self.lay.kind == "modal":
            z_hit = float(np.sum(d.qpos[self.mode_qpos]))     # each oscillator's upward displacement
        else:
            z_hit = d.site_xpos[self.hit, 2] - self.lay.top
        return float(z_hit + self.lay.top - z_tip), float(-z_hit)

    def native_force(self, d) -> float:
        f = 0.0
        for i in range(d.ncon):
            c = d.contact[i]
            if c.geom1 == self.ball_geom or c.geom2 == self.ball_geom:
                self.mj.mj_contactForce(self.m, d, i, self.force6)
                f += self.force6[0]
        return float(f)

    def hertz_callback(self):
        """The mjcb_passive callback adding alpha*max(delta,0)^1.5 at the current state."""
        mj, alpha = self.mj, self.alpha
        fvec, zero = np.zeros(3), np.zeros(3)
        ball_body, hit_body, tip, hit = self.ball_body, self.hit_body, self.tip, self.hit
        lay = self.lay
        modal = lay.kind == "modal"
        mode_dofs = self.mode_dofs if modal else None

        def cb(m, d):
            delta, _ = self.delta_points(d)
            if delta <= 0.0:
                return
            f = alpha * delta**1.5
            fvec[2] = f
            mj.mj_applyFT(m, d, fvec, zero, d.site_xpos[tip], ball_body, d.qfrc_passive)
            if modal:
                d.qfrc_passive[mode_dofs] -= f      # the same force pushes every oscillator down
            elif hit_body > 0:
                fvec[2] = -f
                mj.mj_applyFT(m, d, fvec, zero, d.site_xpos[hit], hit_body, d.qfrc_passive)
        return cb


def _check_options(settings: EngineSettings) -> None:
    for key, value in settings.options:
        if key not in OPTIONS:
            raise EngineError(f"mujoco: unknown option {key!r}; known: {', '.join(OPTIONS)}.")
        allowed = OPTIONS[key][0]
        if allowed is float:
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not value > 0:
                raise EngineError(f"mujoco: option {key} must be a positive number, got {value!r}.")
        elif value not in allowed:
            raise EngineError(f"mujoco: option {key} must be one of {', '.join(allowed)}, got {value!r}.")


class MujocoAdapter(EngineAdapter):
    """MuJoCo (`pip install 'impactval[mujoco]'`); see the module docstring for the model."""

    name = "mujoco"
    module = "mujoco"
    contacts = ("hertz", "native", "native-hertz")
    integrators = INTEGRATORS

    def check_settings(self, settings: EngineSettings) -> None:
        super().check_settings(settings)
        _check_options(settings)

    # ------------------------------------------------------------------ model
    def build(self, scene, settings: EngineSettings):
        """(model, data, layout, probe, contact info) of the scene, ready to step."""
        import mujoco

        if scene.target.kind == "modal" and settings.contact != "hertz":
            raise EngineError(f"mujoco: a modal target has no surface to collide with; use contact 'hertz' "
                              f"(got {settings.contact!r}).")
        n = None
        if scene.target.kind == "beam":
            n = settings.segments or default_segments(scene)
            if n < 2:
                raise EngineError(f"segments must be at least 2 for a Hencky chain, got {n}.")
        info: dict = {}
        xml, lay = build_xml(scene, settings, n)
        model = mujoco.MjModel.from_xml_string(xml)
        if lay.kind == "beam":
            # MuJoCo's default equality solref (0.02 s) makes the supports springs of ~20 rad/s
            # (first frequency -96 %); 2*dt is the stiffest time constant refsafe allows
            tc = settings.option("equality_timeconst", 2.0 * settings.dt)
            model.eq_solref[:, 0] = tc
            model.eq_solref[:, 1] = 1.0
            info["equality_solref"] = (float(tc), 1.0)
        if settings.contact != "hertz":
            from impactval.reference.hertz import plate_impact

            plate = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
            a_inv_mass = _contact_diag_a(mujoco, model, scene)
            info["contact_inverse_mass"] = a_inv_mass
            if settings.contact == "native":
                k0 = plate.k0
                model.pair_solref[0] = (-k0 * a_inv_mass, 0.0)
                imp = float(settings.option("native_impedance", NATIVE_IMPEDANCE))
                if not imp < 1.0:
                    raise EngineError(f"mujoco: option native_impedance must be below 1, got {imp!r}.")
                model.pair_solimp[0] = (imp, imp, 0.001, 0.5, 2.0)
                info["native_impedance"] = imp
                info["contact_stiffness"] = k0
                info["contact_law"] = "linear k0 = 0.8*alpha*sqrt(delta_m)"
            else:
                k_scale, solimp, rms = fit_native_hertz(scene)
                solref = (-k_scale * a_inv_mass, 0.0)
                model.pair_solref[0] = solref
                model.pair_solimp[0] = solimp
                info.update(native_hertz_solref=tuple(solref), native_hertz_solimp=tuple(solimp),
                            native_hertz_fit_rms=rms,
                            contact_law="fitted solimp shape toward alpha*delta^1.5")
        data = mujoco.MjData(model)
        probe = _Probe(mujoco, model, lay, scene, settings.contact)
        data.qvel[probe.ball_dof] = -scene.ball.velocity
        return model, data, lay, probe, info

    # ------------------------------------------------------------------ stepping
    def _simulate(self, scene, settings: EngineSettings) -> Simulation:
        import mujoco

        from impactval.reference.hertz import plate_impact

        t0 = time.perf_counter()
        model, d, lay, probe, info = self.build(scene, settings)
        diagnostics: dict = dict(info)
        if lay.kind == "beam":
            diagnostics.update(self.structure_frequencies(scene, settings, model))
            diagnostics["segments"] = lay.n_segments
            diagnostics["rotary_inertia"] = settings.option("rotary_inertia", "section")
        build_s = time.perf_counter() - t0

        plate = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
        t_max = MAX_TIME_FACTOR * plate.t_m + settings.tail
        t_max = float(settings.option("max_time", t_max))
        n_max = int(math.ceil(t_max / settings.dt)) + 1
        alpha = scene.alpha
        contact = settings.contact
        if contact == "native":
            k_lin = info["contact_stiffness"]
            potential = (lambda dl: 0.5 * k_lin * dl * dl)
        elif contact == "native-hertz":
            potential = _tabulated_potential(mujoco, model, scene, plate)
        else:
            potential = (lambda dl: 0.4 * alpha * dl**2.5)

        cols = {k: [] for k in ("t", "delta", "f", "xb", "xs", "v", "pe", "ke", "ke_sync")}
        # Euler and implicitfast update the velocity first and move with it: the stored qvel is a
        # half-step velocity, and 1/2 v'Mv with it swings by O(omega*dt) (2.5 % on the plate at
        # 1 us) though nothing is lost. Kinetic energy at a sample is taken with the mean of the
        # velocities before and after it (second order, as for leapfrog); RK4 uses its own qvel.
        sync = (settings.integrator or INTEGRATORS[0]) in ("Euler", "implicitfast")
        v_mean, mv = np.zeros(model.nv), np.zeros(model.nv)
        x_ball0 = d.qpos[probe.ball_qpos]
        bad = mujoco.mjtWarning.mjWARN_BADQACC

        def record() -> tuple[float, float]:
            delta, xs = probe.delta_points(d)
            if contact == "hertz":
                f = alpha * delta**1.5 if delta > 0 else 0.0
            else:
                f = probe.native_force(d)
            pot = potential(delta) if delta > 0 else 0.0
            cols["t"].append(d.time)
            cols["delta"].append(delta)
            cols["f"].append(f)
            cols["xb"].append(x_ball0 - d.qpos[probe.ball_qpos])
            cols["xs"].append(xs)
            cols["v"].append(-d.qvel[probe.ball_dof])
            cols["pe"].append(d.energy[0] + pot)
            cols["ke"].append(d.energy[1])
            return delta, f

        old_cb, old_warn = mujoco.get_mjcb_passive(), mujoco.get_mju_user_warning()
        warnings: list[str] = []
        # MuJoCo would print warnings and append them to ./MUJOCO_LOG.TXT; they become the status instead
        mujoco.set_mju_user_warning(warnings.append)
        if contact == "hertz":
            mujoco.set_mjcb_passive(probe.hertz_callback())
        step_s = 0.0
        n_steps = 0
        try:
            mujoco.mj_forward(model, d)
            record()
            touched, t_end = False, math.inf
            for _ in range(n_max):
                v_mean[:] = d.qvel
                ts = time.perf_counter()
                mujoco.mj_step(model, d)
                step_s += time.perf_counter() - ts
                if sync:                  # d.qM is still the mass matrix of the sample before the step
                    v_mean += d.qvel
                    v_mean *= 0.5
                    mujoco.mj_mulM(model, d, mv, v_mean)
                    cols["ke_sync"].append(0.5 * float(v_mean @ mv))
                n_steps += 1
                if d.warning[bad].number > 0:
                    raise EngineDiverged(f"MuJoCo reported NaN/huge accelerations after {n_steps} steps "
                                         f"(t = {n_steps * settings.dt:.3g} s, dt = {settings.dt:g} s): "
                                         f"{warnings[0].strip() if warnings else ''}")
                mujoco.mj_forward(model, d)
                delta, f = record()
                if not math.isfinite(delta) or abs(delta) > 10 * scene.ball.radius:
                    break          # the base class classifies NaN/blow-up from the series
                if f > 0:
                    touched = True
                elif touched and delta < 0 and t_end == math.inf:
                    t_end = d.time
                if d.time >= t_end + settings.tail:
                    break
        finally:
            mujoco.set_mjcb_passive(old_cb)
            mujoco.set_mju_user_warning(old_warn)
        if warnings:
            diagnostics["mujoco_warnings"] = warnings[:5]
        ke = np.asarray(cols["ke"])
        if sync:
            ke[:len(cols["ke_sync"])] = cols["ke_sync"]
        energy = np.asarray(cols["pe"]) + ke
        if lay.kind == "beam":
            diagnostics["equality_violation_max"] = _equality_violation(d)
        model_name = {"plate": "rigid-plate", "modal": f"modal-{lay.n_modes}"}.get(
            lay.kind, f"hencky-chain-{lay.n_segments}")
        return Simulation(t=np.asarray(cols["t"]), delta=np.asarray(cols["delta"]), f=np.asarray(cols["f"]),
                          x_ball=np.asarray(cols["xb"]), x_structure=np.asarray(cols["xs"]),
                          v_ball=np.asarray(cols["v"]), energy=energy, build_s=build_s,
                          step_s=step_s, n_steps=n_steps, model=f"mujoco-{model_name}-{contact}",
                          diagnostics=diagnostics,
                          settings={"integrator": settings.integrator or INTEGRATORS[0],
                                    "segments": lay.n_segments or None})

    # ------------------------------------------------------------------ diagnostics
    def structure_frequencies(self, scene, settings: EngineSettings, model=None) -> dict:
        """The chain's first natural frequencies [rad/s] from MuJoCo's linearised transition
        (no contact, undeformed chain) and the continuum's (Euler-Bernoulli)."""
        import mujoco

        from impactval.reference.beams import beam_frequencies

        beam = scene.target
        if model is None:
            model, *_ = self.build(scene, settings)
        mat = beam.material
        cont = beam_frequencies(beam.support, N_FREQUENCIES, beam.length, mat.young, beam.second_moment,
                                mat.density, beam.area)
        freqs = chain_frequencies(mujoco, model)
        return {"structure_frequencies": [float(x) for x in freqs[:N_FREQUENCIES]],
                "continuum_frequencies": [float(x) for x in cont]}


def chain_frequencies(mujoco, model) -> np.ndarray:
    """Natural frequencies [rad/s], ascending, from the eigenvalues of MuJoCo's finite-differenced
    one-step transition matrix A (lambda = exp(s dt), omega = |Im log(lambda)| / dt), with contact
    and callbacks off and the Euler integrator (the structure's frequencies, not an integrator's). Overdamped/constraint modes (|Re s| > |Im s|) are left out."""
    m = model
    saved_flags, saved_integrator = m.opt.disableflags, m.opt.integrator
    old_cb = mujoco.get_mjcb_passive()
    mujoco.set_mjcb_passive(None)
    try:
        m.opt.disableflags = saved_flags | mujoco.mjtDisableBit.mjDSBL_CONTACT
        m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER     # mjd_transitionFD refuses RK4
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        nx = 2 * m.nv + m.na
        a = np.zeros((nx, nx))
        mujoco.mjd_transitionFD(m, d, 1e-8, True, a, None, None, None)
    finally:
        m.opt.disableflags, m.opt.integrator = saved_flags, saved_integrator
        mujoco.set_mjcb_passive(old_cb)
    lam = np.linalg.eigvals(a)
    s = np.log(lam.astype(complex)) / m.opt.timestep
    osc = (s.imag > 1e-6) & (np.abs(s.real) < s.imag)
    return np.sort(s.imag[osc])


def _equality_violation(d) -> float:
    """Largest equality-constraint violation [m] at the end of the run (support softness)."""
    import mujoco

    rows = np.flatnonzero(np.asarray(d.efc_type) == mujoco.mjtConstraint.mjCNSTR_EQUALITY)
    return float(np.max(np.abs(d.efc_pos[rows]))) if rows.size else 0.0


def _static_contact_force(mujoco, model, d, probe_dof_qpos: int, z0: float, deltas: np.ndarray,
                          ball_geom: int) -> np.ndarray:
    """Static force law of the contact pair: force [N] at each penetration, ball at rest."""
    out = np.zeros(len(deltas))
    f6 = np.zeros(6)
    for k, dl in enumerate(deltas):
        d.qpos[:] = model.qpos0
        d.qvel[:] = 0.0
        d.qpos[probe_dof_qpos] = z0 - dl
        mujoco.mj_forward(model, d)
        for i in range(d.ncon):
            c = d.contact[i]
            if ball_geom in (c.geom1, c.geom2):
                mujoco.mj_contactForce(model, d, i, f6)
                out[k] += f6[0]
    return out


def _contact_diag_a(mujoco, model, scene) -> float:
    """Exact inverse effective mass [1/kg] of the contact row (efc_diagA) at first touch."""
    d = mujoco.MjData(model)
    jq = model.jnt_qposadr[model.joint("ball_z").id]
    d.qpos[jq] = model.qpos0[jq] - 1e-9
    mujoco.mj_forward(model, d)
    rows = np.flatnonzero(np.asarray(d.efc_type) == mujoco.mjtConstraint.mjCNSTR_CONTACT_FRICTIONLESS)
    if rows.size != 1:
        raise EngineError(f"mujoco: expected one contact row at first touch, found {rows.size}.")
    return float(d.efc_diagA[rows[0]])


@lru_cache(maxsize=16)
def fit_native_hertz(scene) -> tuple[float, tuple[float, ...], float]:
    """Fit the contact pair's direct solref stiffness and solimp shape so MuJoCo's static force law
    matches alpha*delta^1.5 on 0..1.2 delta_m (rigid-plate delta_m), on a plate with the scene's
    ball (the law scales with the effective mass, so it carries over to any target).

    Returns (stiffness scale k [N/m]: solref = (-k*A, 0) with A = efc_diagA of the contact row,
    solimp, RMS misfit of the force law over f_m). The impedance is kept <= NATIVE_HERTZ_DMAX (see there).
    """
    import mujoco
    from scipy import optimize

    from impactval.reference.hertz import plate_impact
    from impactval.scenarios.scene import RigidPlate, Scene

    plate_scene = Scene(scene.name + "-fit", scene.ball, RigidPlate(scene.target.material))
    xml, _ = build_xml(plate_scene, EngineSettings(contact="native"))
    model = mujoco.MjModel.from_xml_string(xml)
    plate = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
    a_inv_mass = _contact_diag_a(mujoco, model, plate_scene)
    d = mujoco.MjData(model)
    jq = model.jnt_qposadr[model.joint("ball_z").id]
    z0 = model.qpos0[jq]
    ball_geom = model.geom("ball").id
    deltas = np.linspace(0.02, 1.2, 30) * plate.delta_m
    target = scene.alpha * deltas**1.5
    width0 = 1.2 * plate.delta_m

    def unpack(p):
        k = math.exp(p[0]) * plate.k0 * a_inv_mass
        dw = NATIVE_HERTZ_DMAX
        return k, (max(p[1] * dw, 1e-4), dw, math.exp(p[2]) * width0, p[3], p[4])

    def resid(p):
        k, solimp = unpack(p)
        model.pair_solref[0] = (-k, 0.0)
        model.pair_solimp[0] = solimp
        f = _static_contact_force(mujoco, model, d, jq, z0, deltas, ball_geom)
        return (f - target) / plate.f_m

    lo = np.array([-3.0, 0.1, -3.0, 0.01, 1.0])
    hi = np.array([3.0, 1.0, 3.0, 0.99, 6.0])
    best = None
    for start in ([0.0, 0.5, 0.0, 0.5, 1.5], [0.5, 0.2, 0.3, 0.3, 1.0], [0.2, 0.7, -0.5, 0.1, 3.0]):
        try:
            sol = optimize.least_squares(resid, np.array(start), bounds=(lo, hi), xtol=1e-10, ftol=1e-10,
                                         max_nfev=300)
        except Exception:  # noqa: BLE001 - a failed start is just a worse fit
            continue
        if best is None or sol.cost < best.cost:
            best = sol
    if best is None:
        raise EngineError("mujoco: the native-hertz solimp fit failed from every start.")
    k, solimp = unpack(best.x)
    rms = float(np.sqrt(np.mean(resid(best.x) ** 2)))
    return k / a_inv_mass, tuple(float(x) for x in solimp), rms


def _tabulated_potential(mujoco, model, scene, plate):
    """Contact potential [J] of the model's static force law (cumulative trapezoid on a fine table)."""
    d = mujoco.MjData(model)
    jq = model.jnt_qposadr[model.joint("ball_z").id]
    deltas = np.linspace(0.0, 3.0 * plate.delta_m, 601)
    f = _static_contact_force(mujoco, model, d, jq, model.qpos0[jq], deltas, model.geom("ball").id)
    pot = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(deltas))])
    return lambda dl: float(np.interp(dl, deltas, pot))
