"""Newton adapter (NVIDIA Newton on Warp, CPU, float32): the ball and the target built with
`newton.ModelBuilder`, stepped by one of Newton's rigid-body solvers, one step (collision + solver
+ a recording kernel) captured as a Warp CPU graph and replayed (see engines/_warp.py).

Model (SI, z up, no gravity, no friction, no damping: `angular_damping = 0`, contact kd = 0):

- ball: a free body (sphere shape of the scene's radius, mass and inertia set explicitly) touching
  the target at t = 0 with velocity -v0;
- rigid plate: Newton's ground plane;
- beam: the shared Hencky chain (`engines.chain.hencky_chain`: N rigid segments, mass rho*A*l, rotary
  inertia m l^2/12 by default (option rotary_inertia; 'section' adds m h^2/12), revolute joints about y with passive
  stiffness EI/l, 2EI/l at a clamp), a box shape on the hit segment only, the origin at the beam's middle
  (float32 positions |x| <= L/2). SemiImplicit: attach_ke ATTACH_KE_AUTO (`attach_ke_for`) and N from the
  shared sizing lowered until the penalty joints' give is within GIVE_TOL (`penalty_segments`); model_error =
  the rigid chain's composed with that give (`penalty_give`). An automatic attach_ke whose run fails the energy
  check is retried at half, N re-sized, up to ATTACH_KE_RETRIES times (the base's `retry` hook,
  option attach_ke_scale; an explicit attach_ke never is); the row records the retries and a validity note. Other integrators: the shared sizing capped at
  MAX_SEGMENTS = 41. Supports: simply
  supported = revolute joints to the world at x = 0 and x = L (the second closes a loop, held by
  SemiImplicit's penalty joints, so the ends are pinned axially too); clamped ends add 2EI/l;
  cantilever = free end. Out-of-plane inertias are the box's (never excited: the problem is planar).
  A Timoshenko beam (semi-implicit, featherstone) builds the Timoshenko chain (hencky_chain(shear=True), the chain of
  MuJoCo C and PyBullet): every joint a D6 joint, a transverse slide of kappa G A / l (2 kappa G A / l at a supported
  end) and the hinge, the section's rotary inertia, sized against Timoshenko theory; SemiImplicit's attach_ke then
  holds only x, so the penalty give vanishes (the linear model decouples x) and N is the shared sizing's.
  Modal targets are not built.

Contact "native": Newton's penalty contact, normal force ke*d with ke = the scene's k0 on both shapes
(Newton averages the two) and kd = 0: a linear spring, compared with the linear theory (`contact_law`
linear k0); the force series is ke*max(delta, 0) from the kinematics after each step. Contact
"hertz": no shapes; a Warp kernel adds alpha*max(delta,0)^1.5 to `body_f` from the current poses.

Integrators (`--integrator`): "semi-implicit" (default; SolverSemiImplicit, explicit penalty joints
with joint_attach_ke = the option or attach_ke_for(scene), attach kd = 0), "featherstone" (reduced coordinates; no loop
closures, so only the plate and the cantilever), "xpbd" (SolverXPBD: positional contacts that ignore
ke: a result, see docs/newton.md). Build time (Newton's finalize + the first captured step, which
compiles or loads kernels: `diagnostics["compile_s"]`) and stepping time are reported apart.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from impactval.engines.base import WINDOW_CAP, EngineAdapter, EngineSettings, Plan, Simulation, plate_times
from impactval.engines.chain import DEFAULT_CHAIN_TOL, MIN_SEGMENTS, HenckyChain, centring, hencky_chain, omega_max, segments_for
from impactval.engines.options import boolean, in_range, one_of, option, positive
from impactval.errors import EngineError

INTEGRATORS = ("semi-implicit", "featherstone", "xpbd")
#: most segments the automatic sizing gives Featherstone / XPBD (Featherstone costs ~20 ms/step at 41)
MAX_SEGMENTS = 41
#: most segments the automatic sizing gives SemiImplicit (step cost and the explicit limit ~ 1/N^1.5)
MAX_SEGMENTS_SEMI_IMPLICIT = 121
#: SemiImplicit's automatic joint_attach_ke on a beam [N/m]. Its float32 limit is the axial noise (AXIAL_NOISE_STOP),
#: not the bending: with the energy check on the in-plane energy, 1.5e10 ran all 14 beams (worked + 13 unseen,
#: rotary_inertia none, native) ok with in-plane energy within 0.46 % and axial noise 0-100 % of the impact energy
#: (docs/newton.md). The rule before (ke ulp(L/2) <= 0.12 v0 sqrt(k0 m), at most 6e9: 5e8-6e9 N/m) was sized against
#: the total energy, whose growth is the axial noise: it forced N down for the give (heavy beams +6 / +16 % f_m)
ATTACH_KE_AUTO = 1.5e10
#: largest relative change of t_m / f_m / delta_m the penalty joints' give may cause (penalty chain vs the
#: rigid-jointed chain, exact linear theory on both): N is lowered until the give is within it
GIVE_TOL = 5e-3
#: an `auto` attach_ke run whose energy check fails (float32 growth; never a dt above the predicted limit) is
#: retried with attach_ke times this (N re-sized for the give at the softer ke, as the auto rule does) ...
ATTACH_KE_RETRY_FACTOR = 0.5
#: ... at most this many times; an explicit `--option newton.attach_ke=X` is never retried
ATTACH_KE_RETRIES = 3
#: the attach_ke used before (default until this sizing; kept for reference in docs/tests)
ATTACH_KE = 1e9
#: float32 axial noise (measured, docs/newton.md "float32 energy growth"): the energy that grew with a stiff attach_ke is
#: the chain's motion ALONG the beam (segments' x velocity + the joints' x stretch), made by the rounding of the joints'
#: x positions (ulp(|x|) up to ulp(L/2)): ti_ss_steel_heavy N 90, attach_ke 6e9: +18 % with the origin at the middle,
#: +365 % with it moved 1.5 L away (ulp 4x: ~ulp^2), while the rest of the energy stayed within 0.26 / 2.5 % and f_m
#: was identical to 5 digits. So the energy check uses the in-plane bending energy (`_energy`), the axial part is
#: reported (diagnostics axial_noise_energy, relative to the impact energy) with a validity note beyond
#: AXIAL_NOISE_NOTE, and a run is unstable beyond both AXIAL_NOISE_STOP x the impact energy and AXIAL_FLOOR_STOP x
#: its float32 floor N attach_ke ulp(L/2)^2 (`axial_noise_floor`; the limits shared with MuJoCo Warp, engines/_warp.py)
from impactval.engines._warp import (AXIAL_FLOOR_STOP, AXIAL_NOISE_NOTE, AXIAL_NOISE_STOP,  # noqa: E402
                                     axial_noise_blows_up, float32_contact_note, floor_text,
                                     share_text)
#: a predicted model_error beyond this (the beam bar of issue 19, the MuJoCo C chain's) heads the row's validity
MODEL_ERROR_BAR = 0.015
#: steps replayed between host checks of the contact state (after a first chunk sized to the contact)
CHUNK = 64


def _auto_or_positive(value):
    if value == "auto":
        return value
    return positive(value)


def _whole(value) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"must be a positive whole number, got {value!r}")
    return value


@dataclass(frozen=True)
class NewtonOptions:
    """`--option newton.KEY=VALUE`."""

    attach_ke: float | str = option("auto", "SemiImplicit joint attachment stiffness [N/m, N m/rad]; 'auto' "
                                    "(default) = ATTACH_KE_AUTO on a beam (attach_ke_for)", _auto_or_positive)
    xpbd_iterations: int = option(2, "XPBD solver iterations (default 2, Newton's)", _whole)
    rotary_inertia: str = option("none", "segment rotary inertia: 'none' = m l^2/12 (default: the Euler-Bernoulli "
                                 "chain, the scenes' theory), 'section' = m (l^2 + h^2)/12 (a Rayleigh beam)",
                                 one_of("none", "section"))
    attach_ke_scale: float = option(1.0, "factor on the automatic attach_ke (default 1; the retry after an energy "
                                    "failure halves it)", in_range(1e-3, 1.0))
    chain_tol: float = option(DEFAULT_CHAIN_TOL, "relative tolerance the chain is sized for (capped at "
                              f"{MAX_SEGMENTS} segments, {MAX_SEGMENTS_SEMI_IMPLICIT} semi-implicit)",
                              in_range(1e-4, 0.2))
    graph_capture: bool = option(True, "replay one captured step as a Warp CPU graph (default true)", boolean)


class NewtonAdapter(EngineAdapter):
    """Newton (`pip install 'impactval[newton]'`); see the module docstring."""

    name = "newton"
    module = "newton"
    contacts = ("hertz", "native")
    integrators = INTEGRATORS
    integrator_methods = {"semi-implicit": "symplectic-euler"}   # featherstone, xpbd: not declared
    min_segments = 2
    Options = NewtonOptions
    # check_beam_model passes since the penalty sizing (worked beam, Hertz: t_m -0.24 / f_m +0.33 / delta_m +0.22 %,
    # model_error 0.52 %); it was a strict xfail while the chain was capped at 41 segments (model_error 2.8 %)
    expected_failures: dict = {}

    def version(self) -> str:
        from importlib.metadata import version

        return f"{version('newton')} (warp {version('warp-lang')}, float32, cpu)"


    def chain(self, scene, settings: EngineSettings) -> HenckyChain | None:
        """The Hencky chain this job builds (engines.chain; None for a plate)."""
        if scene.target.kind != "beam":
            return None
        rotary = settings.option("rotary_inertia", "none")
        shear = timoshenko_chain(scene, settings)
        n = settings.segments
        if n is None:
            tol = float(settings.option("chain_tol", DEFAULT_CHAIN_TOL))
            if (settings.integrator or INTEGRATORS[0]) == "semi-implicit":
                n = penalty_segments(scene, tol, rotary, self.attach_ke(scene, settings), shear)
            else:
                n = segments_for(scene, tol, rotary, MAX_SEGMENTS, centring(scene.target.impact_at, MAX_SEGMENTS),
                                 shear=shear).n
        return hencky_chain(scene.target, n, rotary, shear=shear)

    max_retries = ATTACH_KE_RETRIES
    #: the ball's body point at its lowest point (True, default) or at its centre (False, the model before; a test knob)
    ball_at_contact_point: bool = True
    #: axial noise [x impact energy] beyond which a run is unstable (AXIAL_NOISE_STOP) when it is also beyond
    #: axial_floor_stop x its float32 floor (AXIAL_FLOOR_STOP)
    axial_noise_stop: float = AXIAL_NOISE_STOP
    axial_floor_stop: float = AXIAL_FLOOR_STOP
    #: x of the beam's middle [m] (0: the origin there, float32 positions |x| <= L/2; a test knob for the rounding)
    origin_shift: float = 0.0

    def attach_ke(self, scene, settings: EngineSettings) -> float:
        """SemiImplicit's joint_attach_ke [N/m]: the option, or 'auto' = attach_ke_for(scene) (on an Euler-Bernoulli
        chain sized automatically: `stiff_beam_attach_ke`, stiffer where the joints' give cannot meet GIVE_TOL) times
        the option attach_ke_scale (1 by default; the retry halves it)."""
        ke = settings.option("attach_ke", "auto")
        if ke != "auto":
            return float(ke)
        scale = float(settings.option("attach_ke_scale", 1.0))
        if (scene.target.kind != "beam" or settings.segments is not None or timoshenko_chain(scene, settings)
                or (settings.integrator or INTEGRATORS[0]) != "semi-implicit"):
            return attach_ke_for(scene) * scale
        return stiff_beam_attach_ke(scene, float(settings.option("chain_tol", DEFAULT_CHAIN_TOL)),
                                    settings.option("rotary_inertia", "none")) * scale

    def retry(self, scene, settings: EngineSettings, result):
        """The base's "softer model" hook: SemiImplicit on a beam with attach_ke 'auto' whose row failed the energy
        check (float32 rounding of the stiff penalty joints pumps energy, independent of dt) is rerun at
        attach_ke_scale * ATTACH_KE_RETRY_FACTOR (N re-sized for the give at the softer attach_ke); an explicit
        attach_ke, another integrator or another failure is kept as it is (None)."""
        from dataclasses import replace

        integ = settings.integrator or INTEGRATORS[0]
        if (scene.target.kind != "beam" or integ != "semi-implicit" or settings.option("attach_ke") != "auto"
                or not _energy_failure(result)):
            return None
        from impactval.engines.base import Softer

        scale = float(settings.option("attach_ke_scale", 1.0)) * ATTACH_KE_RETRY_FACTOR
        softer = replace(settings, options=replace(settings.options, attach_ke_scale=scale))
        n_old, n_new = self.chain(scene, settings).n, self.chain(scene, softer).n
        return Softer(softer, f"attach_ke {self.attach_ke(scene, settings):.3g} -> {self.attach_ke(scene, softer):.3g}"
                              f" N/m, N {n_old} -> {n_new}")

    def explicit(self, settings: EngineSettings) -> bool:
        return (settings.integrator or INTEGRATORS[0]) != "xpbd"

    def plan(self, scene, settings: EngineSettings) -> Plan:
        """Stability limit 2/omega_max of chain + ball + contact spring; for SemiImplicit, of the chain as it
        integrates it: free planar segments held by the penalty attachments (`penalty_chain_omega_max`)."""
        from impactval.engines.chain import model_error, model_error_diagnostics
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
            # under the row's contact law (native: the linear spring ke = k0, the chain's linear theory vs the
            # continuum's, what the runner compares it with; the Hertz one then under model_error_hertz_*)
            me, me_diag = model_error_diagnostics(scene, chain, law, model_error(scene, chain))
            err = me.largest
            diag.update(segments=chain.n, **me_diag, rotary_inertia=chain.rotary)
            if integ == "semi-implicit":
                ke = self.attach_ke(scene, settings)
                give = penalty_give(scene, chain, ke, law)       # under the row's contact law
                beam = scene.target
                # the joints' z give as a shear compliance (kappa G A / (attach_ke l)); 0 on the Timoshenko chain,
                # whose joints' z is the shear slide itself (no attach_ke in z)
                shear = 0.0 if chain.shear else (beam.shear_coefficient * beam.shear_modulus * beam.area * chain.n
                                                 / (ke * beam.length))
                # the chain SemiImplicit integrates = the rigid-jointed chain + the joints' give (exact linear
                # theory on both chains); model_error is that chain's error against the scene's theory
                total = _with_give(me, give)
                err = max(abs(x) for x in total)
                diag.update(model_error_rigid_t_m=me.t_m, model_error_rigid_f_m=me.f_m,
                            model_error_rigid_delta_m=me.delta_m, penalty_give_t_m=give[0], penalty_give_f_m=give[1],
                            penalty_give_delta_m=give[2], model_error_t_m=total[0], model_error_f_m=total[1],
                            model_error_delta_m=total[2], attach_ke=ke, penalty_shear_fraction=shear)
                law_k = law.stiffness(_plate_delta_m(scene))
                om_pen = penalty_chain_omega_max(chain, ke, scene.ball.mass, law_k)
                if om_pen > om:
                    joints = ("attach_ke in x, the shear slide in z" if chain.shear else "attach_ke in x and z")
                    om, what = om_pen, (f"SemiImplicit penalty-joint chain N = {chain.n} ({joints} at each joint) + "
                                        f"ball + contact spring {law_k:.3g} N/m")
        validity = ()
        if chain is not None and err > MODEL_ERROR_BAR:
            validity = (self._model_error_note(scene, settings, chain, err, diag),)
        if chain is not None and chain.shear:
            diag["timoshenko_chain"] = True
        if integ == "xpbd":
            return Plan(math.inf, "XPBD (positional, no explicit limit)", err, diag, validity)
        return Plan(2.0 / om, f"{integ}, {what}", err, diag, validity)

    @staticmethod
    def _model_error_note(scene, settings: EngineSettings, chain: HenckyChain, err: float, diag: dict) -> str:
        """One line heading the row: the predicted model error beyond MODEL_ERROR_BAR, its cause, and what to set."""
        theory = getattr(scene.target, "theory", "euler-bernoulli")
        rigid_f = diag.get("model_error_rigid_f_m", diag["model_error_f_m"])
        parts = [f"rigid chain N = {chain.n} ({chain.rotary} rotary inertia) {100 * rigid_f:+.2g} % in f_m"]
        if "penalty_give_f_m" in diag and not chain.shear:      # the Timoshenko chain's joints give nothing in z
            parts.append(f"the penalty joints' give at attach_ke {diag['attach_ke']:.3g} N/m {100 * diag['penalty_give_f_m']:+.2g} %")
        if theory != "euler-bernoulli" and not chain.shear:
            fix = (f"the chain is Euler-Bernoulli and the scene's theory {theory} (the Timoshenko chain is built for "
                   f"semi-implicit and featherstone); use --integrator semi-implicit or exudyn's beam models")
        elif chain.n >= (MAX_SEGMENTS_SEMI_IMPLICIT if (settings.integrator or INTEGRATORS[0]) == "semi-implicit"
                         else MAX_SEGMENTS):
            fix = "N is at the adapter's cap: --segments (slower, smaller dt) trades time for accuracy"
        elif (abs(diag.get("penalty_give_f_m", 0.0)) > GIVE_TOL and not chain.shear and settings.segments is None
              and settings.option("attach_ke", "auto") == "auto"):
            fix = _stiffer_joints_hint(scene, settings, chain, diag["attach_ke"])
        else:
            fix = "--segments or a smaller --option newton.chain_tol trades time for accuracy"
        return (f"newton: predicted model error {100 * err:.2g} % > {100 * MODEL_ERROR_BAR:g} % ({'; '.join(parts)}); "
                f"{fix}")

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
        # finalize's inertia check "corrects" any principal moment under 1e-10 kg m^2 by adding ~1e-6 kg m^2 to all three
        # (newton 1.8 defaults): a 3 mm PMMA segment (2e-11 kg m^2) got 5e4x its rotary inertia, f_m +5.6 % against a
        # predicted 0.42 %. The inertias here are set from the geometry (positive, triangle inequality held), so only
        # non-finite or negative values may be corrected
        b.inertia_relative_tolerance = 0.0
        b.inertia_absolute_tolerance = float(np.finfo(np.float32).tiny)
        b.inertia_correction = 0.0
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
            x_hit = target.impact_x - target.length / 2.0 + self.origin_shift   # origin at the beam's middle (below)
            self._chain(b, target, self.chain(scene, settings), cfg if settings.contact == "native" else None, lay,
                        wp, newton)
        else:
            raise EngineError("newton: modal targets are not built (only rigid bodies and the chain beam); use "
                              "mujoco or exudyn.")
        r = ball.radius
        ib = 0.4 * ball.mass * r * r
        # the ball's body point (its integrated centre of mass) at its lowest point (BALL_AT_CONTACT_POINT), the sphere
        # r above it: a frictionless central contact never turns the ball, so only the point's z matters. Injected Hertz
        # has no shapes and reads only the ball's and the hit point's displacements, so there the point rests at z = 0,
        # where float32 resolves its small steps finely (at z = h/2 a step of v0 dt = 2.9 ulp rounded to 3: the ball
        # approached 4 % too fast, t_m -1.9 % on a 95 mm thick beam)
        lift = 0.0 if self.ball_at_contact_point else r
        z0 = 0.0 if settings.contact == "hertz" and self.ball_at_contact_point else lay["top"] + lift
        body = b.add_body(xform=wp.transform((x_hit, 0.0, z0), wp.quat_identity()), mass=ball.mass,
                          inertia=wp.mat33(ib, 0, 0, 0, ib, 0, 0, 0, ib), label="ball")
        if settings.contact == "native":           # injected Hertz: no shapes, no collisions
            b.add_shape_sphere(body, xform=wp.transform((0.0, 0.0, r - lift), wp.quat_identity()), radius=r, cfg=cfg)
        lay.update(ball=body, z0=z0)
        model = b.finalize(device="cpu")
        return model, lay

    def _chain(self, b, beam, chain: HenckyChain, cfg, lay: dict, wp, newton) -> None:
        n, length, w, h = chain.n, chain.length, chain.width, chain.height
        l, m_seg = chain.segment_length, chain.segment_mass
        iyy = chain.rotary_inertia
        ixx = izz = m_seg * (l * l + w * w + h * h) / 12.0      # out of plane: never excited
        hit = chain.hit_segment
        y_axis = (0.0, 1.0, 0.0)
        x0 = -length / 2.0 + self.origin_shift     # origin at the middle: float32 positions |x| <= L/2 (ulp 3e-8 m at 0.5 m, 1.5e-8 at 0.25)
        links = []
        for i in range(n):
            body = b.add_link(xform=wp.transform((x0 + i * l, 0.0, 0.0), wp.quat_identity()), com=(l / 2, 0.0, 0.0),
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
        if chain.shear:
            # the Timoshenko chain: every joint a D6 joint, a transverse slide (z in the parent's frame) of kappa G A / l
            # (2 kappa G A / l at a supported end) and the hinge about y; SemiImplicit holds only x (and the out-of-plane
            # directions) by attach_ke, so the slide's z is the shear spring itself
            dof = newton.ModelBuilder.JointDofConfig

            def hinge(parent, child, parent_xform, k_hinge, k_slide, label, child_xform=None):
                return b.add_joint_d6(parent, child, parent_xform=parent_xform, child_xform=child_xform, label=label,
                                      linear_axes=[dof(axis=(0.0, 0.0, 1.0), stiffness=k_slide, damping=0.0,
                                                       target_ke=0.0, target_kd=0.0)],
                                      angular_axes=[dof(axis=y_axis, stiffness=k_hinge, damping=0.0, target_ke=0.0,
                                                        target_kd=0.0)])

            joints.append(hinge(-1, links[0], wp.transform((x0, 0.0, 0.0), wp.quat_identity()), k_root,
                                chain.support_shear_stiffness, "h0"))
            for i in range(1, n):
                joints.append(hinge(links[i - 1], links[i], wp.transform((l, 0.0, 0.0), wp.quat_identity()),
                                    chain.hinge_stiffness, chain.shear_stiffness, f"h{i}"))
        else:
            joints.append(b.add_joint_revolute(-1, links[0], parent_xform=wp.transform((x0, 0.0, 0.0), wp.quat_identity()),
                                               axis=y_axis, stiffness=k_root, damping=0.0,
                                               target_ke=0.0, target_kd=0.0, label="h0"))
            for i in range(1, n):
                joints.append(b.add_joint_revolute(
                    links[i - 1], links[i], parent_xform=wp.transform((l, 0.0, 0.0), wp.quat_identity()),
                    axis=y_axis, stiffness=chain.hinge_stiffness, damping=0.0, target_ke=0.0, target_kd=0.0, label=f"h{i}"))
        b.add_articulation(joints, label="beam")
        if beam.support in ("simply-supported", "clamped-clamped"):
            k_end = 0.0 if beam.support == "simply-supported" else chain.clamp_stiffness
            if chain.shear:
                hinge(-1, links[-1], wp.transform((x0 + length, 0.0, 0.0), wp.quat_identity()), k_end,
                      chain.support_shear_stiffness, "pin", child_xform=wp.transform((l, 0.0, 0.0), wp.quat_identity()))
            else:
                b.add_joint_revolute(-1, links[-1], parent_xform=wp.transform((x0 + length, 0.0, 0.0), wp.quat_identity()),
                                     child_xform=wp.transform((l, 0.0, 0.0), wp.quat_identity()),
                                     axis=y_axis, stiffness=k_end, damping=0.0, target_ke=0.0, target_kd=0.0,
                                     label="pin")
        lay.update(segments=n, segment_length=l, length=length, x0=x0,
                   pinned_end=beam.support in ("simply-supported", "clamped-clamped"))
        lay["hinge_stiffness"] = [k_root] + [chain.hinge_stiffness] * (n - 1)
        if beam.support in ("simply-supported", "clamped-clamped"):
            lay["hinge_stiffness"].append(k_end)      # the end pin: the last segment's absolute angle
        if chain.shear:                               # the joints' slides, in the order of _joint_gap_vectors
            lay["shear_stiffness"] = ([chain.support_shear_stiffness] + [chain.shear_stiffness] * (n - 1)
                                      + [chain.support_shear_stiffness] * int(lay["pinned_end"]))

    # ------------------------------------------------------------------ stepping
    def simulate(self, scene, settings: EngineSettings) -> Simulation:
        from impactval.engines._warp import CapturedStep, ChunkedRecord, WindowTracker, import_warp

        t0 = time.perf_counter()
        wp = import_warp()
        import newton

        from impactval.engines import _newton_kernels as K

        integ = settings.integrator or INTEGRATORS[0]
        model, lay = self.build(scene, settings, wp, newton)
        # native contact: Newton's shapes at their real height, the ball's position integrated there (refused here
        # when float32 cannot resolve it; injected Hertz reads displacements near z = 0)
        contact_note = "" if settings.contact == "hertz" else float32_contact_note(
            "newton", lay["z0"], _plate_delta_m(scene), scene.ball.velocity * float(settings.dt))
        if integ == "semi-implicit":
            lay["attach_ke"] = self.attach_ke(scene, settings)
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
        dt = float(settings.dt)
        n_max = int(math.ceil((WINDOW_CAP * plate.t_m + settings.tail) / dt)) + 1
        first_chunk = max(CHUNK, int(1.1 * plate.t_m / dt))       # the first chunk covers a rigid-plate contact
        # rows: row 0 unused, the warm-up's two steps, a chunk, one spare
        rec = ChunkedRecord(wp, min(n_max, first_chunk) + 4, 13 * nb, "newton", dt)
        counter = wp.zeros(1, dtype=int, device="cpu")
        bq, bqd = s0.body_q.numpy(), s0.body_qd.numpy()
        first = np.concatenate([bq.ravel(), bqd.ravel()])
        pair = [s0, s1]

        # an even number of solver steps per replay keeps the captured state buffers in place
        hertz = settings.contact == "hertz"
        hertz_args = [model.body_com, ball, float(lay["z0"]), lay["hit_body"], wp.vec3(*lay["hit_local"]),
                      float(scene.alpha)]

        def two_steps():
            for a, b in ((pair[0], pair[1]), (pair[1], pair[0])):
                a.clear_forces()
                if hertz:
                    wp.launch(K.hertz_force, dim=1, inputs=[a.body_q, *hertz_args, a.body_f], device="cpu")
                else:
                    pipeline.collide(a, contacts)
                solver.step(a, b, control, contacts, dt)
                wp.launch(K.record, dim=1, inputs=[b.body_q, b.body_qd, counter, rec.base, rec.buffer], device="cpu")

        stepper = CapturedStep(wp, two_steps, capture=settings.options.graph_capture)
        stepper.warm_up()
        build_s = time.perf_counter() - t0
        step_s, n_steps = 0.0, 2
        chunk = first_chunk
        end = None
        window = WindowTracker(settings, scene)     # the window rule on (delta, f) per step, each looked at once
        window.feed(np.column_stack(self._series(first[None, :], first, lay, scene, nb)[:2]))
        while n_steps < n_max and end is None:
            n = max(1, min(chunk, n_max - n_steps) // 2)
            ts = time.perf_counter()
            stepper.run(n)
            step_s += time.perf_counter() - ts
            n_steps += 2 * n
            chunk = CHUNK
            block = rec.take(int(counter.numpy()[0]))
            end = window.feed(np.column_stack(self._series(np.vstack([first[None, :], block]), first, lay, scene,
                                                           nb)[:2])[1:])
        n_stepped = int(counter.numpy()[0])        # steps run (stepping wall time covers all of them)
        n_rec = n_stepped
        if end is not None:
            n_rec = min(n_rec, end)                  # the window rule: samples 0..end
        states = rec.all(first)
        delta, f, xs, xb, vb = self._series(states[:n_rec + 1], first, lay, scene, nb)
        # one state past the last sample (when stepped) gives the last sample's velocity after its step
        energy, axial = self._energy(states[:min(n_rec + 2, n_stepped + 1)], first, lay, scene, model, nb, delta)
        if hertz:
            f = scene.alpha * np.maximum(delta, 0.0) ** 1.5
            energy += 0.4 * scene.alpha * np.maximum(delta, 0.0) ** 2.5 - 0.5 * lay["contact_stiffness"] * np.maximum(delta, 0.0) ** 2
        t = np.arange(n_rec + 1) * dt
        diagnostics = {"compile_s": stepper.compile_s, "graph_capture": stepper.graph is not None,
                       "float": "float32", "contact_stiffness": lay["contact_stiffness"],
                       "contact_law": "hertz, injected into body_f" if hertz else "linear penalty ke = k0, kd = 0"}
        if integ == "semi-implicit":
            diagnostics["attach_ke"] = lay["attach_ke"]
        validity = (contact_note,) if contact_note else ()
        if lay["segments"] and energy[0] > 0:
            # float32 rounding noise in the joints' axial springs, outside the checked energy (AXIAL_NOISE_STOP)
            noise = float(np.max(axial) / energy[0])
            ke = lay.get("attach_ke", 0.0)
            floor = axial_noise_floor(lay["segments"], ke, scene.target.length / 2.0 + abs(self.origin_shift))
            diagnostics["axial_noise_energy"] = noise
            diagnostics["axial_noise_floor_J"] = floor
            if axial_noise_blows_up(noise * energy[0], energy[0], floor, self.axial_noise_stop, self.axial_floor_stop):
                from impactval.engines.base import EngineDiverged

                raise EngineDiverged(f"float32 axial noise: the chain's motion along the beam reached {noise:.3g}x the "
                                     f"impact energy and {noise * energy[0] / floor if floor > 0 else math.inf:.3g}x its "
                                     f"float32 floor N attach_ke ulp(L/2)^2 (limits {self.axial_noise_stop:g}x and "
                                     f"{self.axial_floor_stop:g}x; attach_ke {ke:.3g} N/m)", diagnostics)
            if noise > AXIAL_NOISE_NOTE:
                validity += (f"newton: float32 rounding of the joints' x positions put {share_text(noise)} of the impact "
                            f"energy into the chain's axial vibration (attach_ke {ke:.3g} N/m), "
                            f"{floor_text(noise * energy[0], floor)}; the contact does not see it and the energy check "
                            f"uses the rest; unstable only beyond {self.axial_noise_stop:g}x the impact energy and "
                            f"{self.axial_floor_stop:g}x the floor (docs/newton.md)",)
        if lay["segments"]:
            diagnostics["segments"] = lay["segments"]
        kind = "rigid-plate" if lay["kind"] == "rigid-plate" else f"hencky-chain-{lay['segments']}"
        return Simulation(t=t, delta=delta, f=f, x_ball=xb, x_structure=xs, v_ball=vb, energy=energy,
                          build_s=build_s, step_s=step_s, n_steps=n_stepped,
                          model=f"newton-{kind}-{integ}-{settings.contact}-float32", diagnostics=diagnostics,
                          settings={"integrator": integ, "segments": lay["segments"] or None},
                          contact_law=self.contact_law(scene, settings), validity=validity)

    @staticmethod
    def _series(st: np.ndarray, first: np.ndarray, lay: dict, scene, nb: int):
        """(delta, force, hit-point displacement, ball displacement, ball velocity toward the target)."""
        st = st.astype(float)
        st[0] = first
        ball = lay["ball"]
        zb = st[:, 7 * ball + 2]
        if lay["hit_body"] >= 0:       # the hit point's z displacement from rest (the segment's frame rests at z = 0)
            hb = lay["hit_body"]
            pos, quat = st[:, 7 * hb:7 * hb + 3], st[:, 7 * hb + 3:7 * hb + 7]
            local = np.asarray(lay["hit_local"])
            w_hit = pos[:, 2] + (_rotate(quat, local) - local)[:, 2]
        else:
            w_hit = np.zeros(len(st))
        delta = w_hit - (zb - lay["z0"])
        f = lay["contact_stiffness"] * np.maximum(delta, 0.0)
        vb = -st[:, 7 * nb + 6 * ball + 2]
        return delta, f, -w_hit, lay["z0"] - zb, vb

    @staticmethod
    def _energy(st, first, lay, scene, model, nb, delta) -> tuple[np.ndarray, np.ndarray]:
        """(energy, axial) [J] per sample k (len(delta) samples; `st` may hold one state more). Kinetic
        1/2 v_k' M v_(k+1) with the twists before (v_k) and after (v_(k+1)) step k, the quantity semi-implicit
        Euler conserves on a linear system (as the MuJoCo adapters measure it; the last sample without a next
        state uses its own twist) + hinge springs + contact spring + the penalty joints' stretch, split in two:
        `axial` = the chain's motion along the beam (segments' x kinetic energy + the joints' x stretch), the
        float32 rounding noise of AXIAL_NOISE, and `energy` = everything else (ball, contact, the segments' z
        and rotation, hinges, the joints' z stretch: the in-plane bending model the metrics come from)."""
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
        n = lay["segments"]
        axial = 0.5 * np.einsum("b,kb,kb->k", mass[:n], before[:, :n, 0], after[:, :n, 0])
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
            if lay.get("shear_stiffness"):            # the Timoshenko chain's D6 joints
                joints, joints_axial = _shear_joint_energy(chain, lay, lay.get("attach_ke", 0.0))
                pe += joints
                axial += joints_axial
            elif lay.get("attach_ke"):
                gaps = 0.5 * lay["attach_ke"] * _joint_gaps_squared(chain, lay)
                pe += gaps.sum(axis=1)
                axial += gaps[:, 0]
        return pe + ke - axial, axial


def linearised_chain(adapter, scene, settings: EngineSettings, eps: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """(mass diagonal, stiffness) of the built chain in each segment's z and rotation about y (order z_0, theta_0,
    z_1, ...), from Newton itself: the model's body masses and inertias, and the stiffness column by column by
    central differences of the forces SemiImplicit's joint kernel applies (one step of dt from rest, with the
    segment moved by +-eps [m] in z or turned by +-eps [rad] about its centre of mass: force = m dv / dt). An
    independent check of the chain model (`penalty_chain_matrices`' z-theta block; chain.linear() on the Timoshenko
    chain), float32 to ~1e-6."""
    from impactval.engines._warp import import_warp

    wp = import_warp()
    import newton

    from dataclasses import replace

    settings = replace(settings, integrator="semi-implicit", contact="hertz")
    model, lay = adapter.build(scene, settings, wp, newton)
    solver = newton.solvers.SolverSemiImplicit(model, angular_damping=0.0, joint_attach_ke=adapter.attach_ke(scene, settings),
                                               joint_attach_kd=0.0)
    state, out = model.state(), model.state()
    newton.eval_fk(model, state.joint_q, state.joint_qd, state)
    q0 = state.body_q.numpy().astype(np.float64)
    n, l = lay["segments"], lay["segment_length"]
    mass = model.body_mass.numpy().astype(float)[:n]
    inertia = model.body_inertia.numpy().astype(float)[:n, 1, 1]
    dt = 1e-6
    control = model.control()

    def forces(q: np.ndarray) -> np.ndarray:
        state.body_q.assign(q.astype(np.float32))
        state.body_qd.zero_()
        state.clear_forces()
        solver.step(state, out, control, None, dt)
        qd = out.body_qd.numpy().astype(float)[:n]
        f = np.empty(2 * n)
        f[0::2] = mass * qd[:, 2] / dt           # linear z (spatial top), angular y (spatial bottom)
        f[1::2] = inertia * qd[:, 4] / dt
        return f

    def moved(i: int, kind: int, h: float) -> np.ndarray:
        q = q0.copy()
        if kind == 0:
            q[i, 2] += h
        else:                                     # turn about y through the centre of mass (l/2 along the body's x)
            c, s_ = math.cos(h / 2), math.sin(h / 2)
            q[i, 3:7] = (0.0, s_, 0.0, c)         # the straight chain: identity rotation before
            q[i, 0] += l / 2 - (l / 2) * math.cos(h)
            q[i, 2] += (l / 2) * math.sin(h)      # the origin (left end) moves so the centre stays put
        return q

    k = np.zeros((2 * n, 2 * n))
    for i in range(n):
        for kind in (0, 1):
            k[:, 2 * i + kind] = -(forces(moved(i, kind, eps)) - forces(moved(i, kind, -eps))) / (2 * eps)
    diag = np.empty(2 * n)
    diag[0::2], diag[1::2] = mass, inertia
    return diag, 0.5 * (k + k.T)


def _energy_failure(result) -> bool:
    """True for an `unstable` row from the energy check (not a dt above the limit, NaN or a crash)."""
    from impactval.reference.result import Status

    return result.status == Status.UNSTABLE and result.message.startswith(("energy grew", "float32 axial noise"))


def _plate_delta_m(scene) -> float:
    from impactval.reference.hertz import plate_impact

    return plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity).delta_m


def timoshenko_chain(scene, settings: EngineSettings) -> bool:
    """True when the job builds the Timoshenko chain (a Timoshenko beam, integrator semi-implicit or featherstone):
    each joint a D6 joint with a transverse slide of kappa G A / l (2 kappa G A / l at a supported end) and the hinge,
    the section's rotary inertia (engines.chain.hencky_chain(shear=True), MuJoCo C's and PyBullet's chain). XPBD keeps
    the Euler-Bernoulli chain (its positional joints ignore the passive stiffness; the row's note says so)."""
    return (getattr(scene.target, "theory", "euler-bernoulli") == "timoshenko"
            and (settings.integrator or INTEGRATORS[0]) in ("semi-implicit", "featherstone"))


def _with_give(me, give) -> tuple[float, float, float]:
    """(t_m, f_m, delta_m) relative errors of the chain SemiImplicit integrates: the rigid-jointed chain's `me` (a
    Metrics of relative errors) composed with the penalty joints' give (exact linear theory on both chains)."""
    return tuple((1.0 + a) * (1.0 + g) - 1.0 for a, g in zip((me.t_m, me.f_m, me.delta_m), give))


def _stiffer_joints(scene, tol: float, rotary: str, ke: float) -> tuple[float, int, float]:
    """(attach_ke [N/m], N, predicted model error) of the first of ke x 4^k (k = 1..5) whose penalty chain (N re-sized
    for its give) is predicted within MODEL_ERROR_BAR, or the best of them."""
    from impactval.engines.chain import model_error

    best = None
    for k in range(1, 6):
        ke_k = ke * 4.0**k
        n = penalty_segments(scene, tol, rotary, ke_k)
        total = _with_give(model_error(scene, hencky_chain(scene.target, n, rotary)), _give(scene, n, rotary, ke_k, False))
        err = max(abs(x) for x in total)
        if best is None or err < best[2]:
            best = (ke_k, n, err)
        if err <= MODEL_ERROR_BAR:
            break
    return best


@lru_cache(maxsize=32)
def stiff_beam_attach_ke(scene, tol: float, rotary: str) -> float:
    """The automatic attach_ke [N/m] of an Euler-Bernoulli chain: ATTACH_KE_AUTO, unless its give stays beyond GIVE_TOL
    even at the fewest segments (a stiff, stubby beam: the give grows ~N^2, so the sizing lowers N until the rigid
    chain's own error dominates); then the stiffer one of `_stiffer_joints` (N re-sized for its give). Measured, a
    40 mm WC ball at 10 m/s on a 271 x 24 x 18 mm clamped WC beam (unseen; 1 of 38 random Euler-Bernoulli beams and
    none of the tests' 11 needs it): 1.5e10 N/m N = 8, f_m -10.4 % as predicted; 9.6e11 N/m N = 70, predicted 0.52 %
    in size (Hertz give), measured t_m +0.45, f_m +0.49 % (the signed f_m prediction is -0.52 %: a miss unchanged at
    dt/2 and with the origin moved, docs/newton.md), dt 2e-8 s (25x shorter), in-plane energy within 5.1 %."""
    base = ATTACH_KE_AUTO
    n = penalty_segments(scene, tol, rotary, base)
    if max(abs(x) for x in _give(scene, n, rotary, base, False)) <= GIVE_TOL:
        return base
    return _stiffer_joints(scene, tol, rotary, base)[0]


def _stiffer_joints_hint(scene, settings: EngineSettings, chain: HenckyChain, ke: float) -> str:
    """Where the penalty joints' give is beyond GIVE_TOL even at the fewest segments (a stiff, stubby beam: the give
    grows ~N^2 and the sizing lowers N until the rigid chain's own error dominates), more segments would add give: the
    fix is a stiffer attach_ke. The first of ke x 4^k (k = 1..5) whose penalty chain (N re-sized for its give) is
    predicted within MODEL_ERROR_BAR, or the best of them, as a setting to paste: the automatic attach_ke does this
    (`stiff_beam_attach_ke`), so the note appears where it is held back (option attach_ke_scale, or a retry)."""
    ke_k, n, err = _stiffer_joints(scene, float(settings.option("chain_tol", DEFAULT_CHAIN_TOL)), chain.rotary, ke)
    return (f"the joints' give dominates and grows with N, so more segments would not help: --option "
            f"newton.attach_ke={ke_k:.2g} is predicted at {100 * err:.2g} % (N = {n}; a shorter automatic step)")


def attach_ke_for(scene) -> float:
    """SemiImplicit joint_attach_ke [N/m] for `scene`: ATTACH_KE_AUTO on a beam, 1e9 for a rigid plate (no joints)."""
    return ATTACH_KE_AUTO if scene.target.kind == "beam" else ATTACH_KE


def penalty_give(scene, chain: HenckyChain, attach_ke: float, law=None) -> tuple[float, float, float]:
    """Relative change of (t_m, f_m, delta_m) [-] the penalty joints' give makes: the linearised penalty-joint chain
    (`penalty_chain_matrices`) against the rigid-jointed chain, both under the row's contact law `law`
    (`reference.hertz.ContactLaw`; None or a Hertz law: the reference solver with Hertz, a linear law: the exact linear
    theory with its spring). Under Hertz the give is not the linear spring's: on a stubby Al cantilever hit by a
    48 mm Al ball (unseen) the k0 spring's give was -0.48 % in f_m and Hertz's -0.77 %, what Newton measured (-0.77 %
    beyond the rigid chain's own +0.03 %). (Linear, checked against Newton, worked beam, native: predicted f_m vs
    theory +0.50 % at N = 41, ke 1e9 and +1.49 % at 3e9, measured +0.53 / +1.53 %; +1.85 / +1.85 % at ke 1e10.)"""
    spring = float(law.coefficient) if law is not None and getattr(law, "kind", "") == "linear" else 0.0
    return _give(scene, chain.n, chain.rotary, float(attach_ke), chain.shear, spring)


@lru_cache(maxsize=64)
def _give(scene, n: int, rotary: str, attach_ke: float, shear: bool = False,
          spring: float = 0.0) -> tuple[float, float, float]:
    """`penalty_give` of the chain of n segments: under Hertz (`spring` 0) or the linear spring `spring` [N/m]."""
    from scipy import linalg

    from impactval.engines.chain import MODEL_ERROR_REF_TOL
    from impactval.reference.beams import Modes
    from impactval.reference.linear import solve_linear_modes
    from impactval.reference.solve import solve_modes

    chain = hencky_chain(scene.target, n, rotary, shear=shear)
    mass, k, row = penalty_chain_matrices(chain, attach_ke)
    w2, vecs = linalg.eigh(k, np.diag(mass))
    phi = row @ vecs
    keep = np.abs(phi) > 1e-9 * np.abs(phi).max()          # axial modes do not reach the contact point
    pen = Modes(np.sqrt(np.clip(w2[keep], 0.0, None)), np.ones(int(keep.sum())), phi[keep], 0.0)
    ball = scene.ball
    if spring > 0.0:
        a = solve_linear_modes(pen, ball.mass, spring, ball.velocity).metrics
        b = solve_linear_modes(chain.modes(), ball.mass, spring, ball.velocity).metrics
    else:
        a = solve_modes(pen, ball.mass, scene.alpha, ball.velocity, MODEL_ERROR_REF_TOL)[0].metrics
        b = solve_modes(chain.modes(), ball.mass, scene.alpha, ball.velocity, MODEL_ERROR_REF_TOL)[0].metrics
    return a.t_m / b.t_m - 1.0, a.f_m / b.f_m - 1.0, a.delta_m / b.delta_m - 1.0


def penalty_segments(scene, tol: float, rotary: str, attach_ke: float, shear: bool = False) -> int:
    """Segments for SemiImplicit: the shared sizing (`segments_for`, capped at MAX_SEGMENTS_SEMI_IMPLICIT), then
    fewer while the penalty joints' give at `attach_ke` exceeds GIVE_TOL (the give grows ~N^2 at a fixed ke:
    each joint adds a shear-like compliance 1/ke, kGA_equivalent = ke l). `shear`: the Timoshenko chain, sized
    against Timoshenko theory; its joints' z is the shear slide (no attach_ke there), so its give is the axial
    attachment's only, which the linear model decouples from the bending (0)."""
    return _penalty_segments(scene, float(tol), rotary, float(attach_ke), bool(shear))


@lru_cache(maxsize=32)
def _penalty_segments(scene, tol: float, rotary: str, attach_ke: float, shear: bool = False) -> int:
    cap = MAX_SEGMENTS_SEMI_IMPLICIT
    adjust = centring(scene.target.impact_at, cap)
    n = segments_for(scene, tol, rotary, cap, adjust, shear=shear).n

    def within(m: int) -> bool:
        return max(abs(x) for x in _give(scene, m, rotary, attach_ke, shear)) <= GIVE_TOL

    if within(n):
        return n
    lo, hi = MIN_SEGMENTS, n                     # the give grows with N: bisect for the largest N within GIVE_TOL
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if within(mid) else (lo, mid)
    def off_centre(m: int) -> float:              # a contact point at a hinge is softer (chain.centred)
        return round(abs((scene.target.impact_at * m) % 1.0 - 0.5), 6)

    for m in sorted(range(max(MIN_SEGMENTS, lo - max(2, lo // 10)), lo + 1), key=lambda m: (off_centre(m), -m)):
        if within(m):
            return m
    return lo


def penalty_chain_matrices(chain: HenckyChain, attach_ke: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mass diagonal, stiffness, contact row) of the chain SemiImplicit integrates, linearised in the plane:
    per segment x, z of its centre of mass and rotation theta (mass m, m, rotary inertia J); every joint's
    anchors held together by attach_ke in x and z (a world joint: the anchor to its world point), the hinge
    springs on the relative rotations; the row gives the contact point's z. The Timoshenko chain (chain.shear):
    each joint's z is its D6 joint's slide, kappa G A / l (a world joint 2 kappa G A / l), not attach_ke."""
    n, l = chain.n, chain.segment_length
    nd = 3 * n
    mass = np.zeros(nd)
    mass[0::3] = mass[1::3] = chain.segment_mass
    mass[2::3] = chain.rotary_inertia
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
        spring(bz - az, chain.shear_stiffness if chain.shear else attach_ke)
        rot = np.zeros(nd)
        rot[3 * (i + 1) + 2], rot[3 * i + 2] = 1.0, -1.0
        spring(rot, chain.hinge_stiffness)
    ends = [(0, -1, 0.0 if chain.support == "simply-supported" else chain.clamp_stiffness)]
    if chain.support in ("simply-supported", "clamped-clamped"):
        ends.append((n - 1, 1, 0.0 if chain.support == "simply-supported" else chain.clamp_stiffness))
    for i, end, k_rot in ends:                         # world joints
        ax, az = anchor_rows(i, end)
        spring(ax, attach_ke)
        spring(az, chain.support_shear_stiffness if chain.shear else attach_ke)
        rot = np.zeros(nd)
        rot[3 * i + 2] = 1.0
        spring(rot, k_rot)
    row = np.zeros(nd)
    row[3 * chain.hit_segment + 1] = 1.0
    row[3 * chain.hit_segment + 2] = -(chain.hit_offset - l / 2.0)
    return mass, k, row


def penalty_chain_omega_max(chain: HenckyChain, attach_ke: float, ball_mass: float, contact_k: float) -> float:
    """Highest frequency [rad/s] of the chain SemiImplicit integrates, linearised in the plane: each segment
    a free body (x, z of its centre of mass, rotation theta; mass m, rotary inertia J), every joint's anchors
    held together by attach_ke in x and z (a world joint: the anchor to its world point), the hinge springs
    on the relative rotations, the ball on the contact spring at the hit point. (The segment-on-two-springs
    estimate 2 sqrt(attach_ke/m) misses the rotation: the anchors' z coupling with lever l/2 on J gives
    omega^2 ~ 12 attach_ke l^2 / (m (l^2 + h^2)), 1.2-1.4x higher on the worked beam, where it blew up.)"""
    from scipy import linalg

    m_chain, k_chain, row = penalty_chain_matrices(chain, attach_ke)
    nd = len(m_chain) + 1                              # the chain, then the ball's z
    mass = np.append(m_chain, ball_mass)
    k = np.zeros((nd, nd))
    k[:-1, :-1] = k_chain
    hit = np.append(row, -1.0)                         # contact: ball z minus the hit point's z
    k += contact_k * np.outer(hit, hit)
    scale = 1.0 / np.sqrt(mass)
    w2 = linalg.eigvalsh(k * scale[:, None] * scale[None, :])
    return float(math.sqrt(max(float(w2[-1]), 0.0)))


def _joint_gaps_squared(chain: np.ndarray, lay: dict) -> np.ndarray:
    """Sum over the chain's joints of the squared (x, y, z) components of child anchor - parent anchor [m^2] per
    sample, shape (samples, 3): the stretch of SemiImplicit's penalty attachments (energy attach_ke/2 times it)."""
    ns, n = chain.shape[:2]
    l = lay["segment_length"]
    pos, quat = chain[..., :3], chain[..., 3:]
    tail = pos + _rotate(quat.reshape(-1, 4), np.array([l, 0.0, 0.0])).reshape(ns, n, 3)   # x = l end
    x0 = lay["x0"]
    gaps = np.sum((pos[:, 1:] - tail[:, :-1]) ** 2, axis=1) + (pos[:, 0] - np.array([x0, 0.0, 0.0])) ** 2
    if lay["pinned_end"]:
        gaps += (tail[:, -1] - np.array([x0 + lay["length"], 0.0, 0.0])) ** 2
    return gaps


def _joint_gap_vectors(chain: np.ndarray, lay: dict) -> tuple[np.ndarray, np.ndarray]:
    """(gaps, slide axes), each (samples, joints, 3): child anchor - parent anchor [m] of every joint of the chain
    (h0, h1 .. h(n-1), then the end pin when there is one) and the joint's slide axis, the parent's z in the world
    (a world joint: the world's z)."""
    ns, n = chain.shape[:2]
    l = lay["segment_length"]
    pos, quat = chain[..., :3], chain[..., 3:]
    tail = pos + _rotate(quat.reshape(-1, 4), np.array([l, 0.0, 0.0])).reshape(ns, n, 3)   # x = l end
    z = _rotate(quat.reshape(-1, 4), np.array([0.0, 0.0, 1.0])).reshape(ns, n, 3)
    x0 = lay["x0"]
    world_z = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (ns, 1, 3))
    gaps = [pos[:, :1] - np.array([x0, 0.0, 0.0]), pos[:, 1:] - tail[:, :-1]]
    axes = [world_z, z[:, :-1]]
    if lay["pinned_end"]:
        gaps.append(tail[:, -1:] - np.array([x0 + lay["length"], 0.0, 0.0]))
        axes.append(world_z)
    return np.concatenate(gaps, axis=1), np.concatenate(axes, axis=1)


def axial_noise_floor(n_segments: int, attach_ke: float, x_max: float) -> float:
    """The float32 floor of SemiImplicit's axial noise [J]: n_segments joints whose x gaps are rounded at the float32
    spacing of the largest |x| [m] on the chain (ulp(x_max), L/2 with the origin at the middle), each a spring
    attach_ke [N/m]: n attach_ke ulp^2 (0 without penalty joints)."""
    ulp = float(np.spacing(np.float32(x_max)))
    return n_segments * attach_ke * ulp * ulp


def _shear_joint_energy(chain: np.ndarray, lay: dict, attach_ke: float) -> tuple[np.ndarray, np.ndarray]:
    """(energy, axial) [J] per sample of the Timoshenko chain's D6 joints: each slide's spring k_s/2 q^2 (q = the gap
    along the slide axis) plus SemiImplicit's attachment attach_ke/2 |gap - q axis|^2 (0 for Featherstone's exact
    joints); `axial` = the attachment's x part (the float32 axial noise, as `_joint_gaps_squared`'s x)."""
    gaps, axes = _joint_gap_vectors(chain, lay)
    q = np.einsum("sji,sji->sj", gaps, axes)
    rest = gaps - q[..., None] * axes
    slide = 0.5 * (q**2) @ np.asarray(lay["shear_stiffness"], float)
    attach = 0.5 * attach_ke * np.sum(rest**2, axis=(1, 2))
    return slide + attach, 0.5 * attach_ke * np.sum(rest[..., 0] ** 2, axis=1)


def _rotate(quat: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vector v by unit quaternions (x, y, z, w), row-wise."""
    xyz, w = quat[:, :3], quat[:, 3:4]
    t = 2.0 * np.cross(xyz, v)
    return v + w * t + np.cross(xyz, t)
