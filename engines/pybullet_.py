"""PyBullet adapter: the ball on a rigid plate or on a chain beam, in PyBullet 3.2 (DIRECT mode).

A stepping adapter (engines/base.py): `build` makes the scene, `step` applies the spring torques and
contact forces from the current state and calls `stepSimulation` (timed), `observe` reads the new state
back and computes the sample and its energy (not timed); the base owns the loop, the window,
dt = "auto", the stability limit (refused before stepping when dt is above it) and the status.

Scene in Bullet (SI units; z is up, the ball moves down along -z with v0 and touches at t = 0):
- ball: a sphere multibody of mass m0, no gravity, no damping, no friction, no restitution;
- rigid plate: a static box whose top face is z = 0;
- second ball (target kind "ball"): a free sphere multibody (centre at z = -R2, moving at +v2 toward the
  first ball); injected Hertz acts on both balls, native contact is Bullet's sphere-sphere pair with the
  two-ball k0 (reduced mass);
- beam: the Hencky chain of `engines.chain.hencky_chain` (rotary inertia m l^2/12 of a rigid bar: the
  reference is Euler-Bernoulli) as N box links along x joined by revolute joints about y; the spring
  torques -K q (EI/l per hinge, 2EI/l per clamped end) are applied every step with TORQUE_CONTROL
  after the default velocity motors are disabled. Supports: simply supported = a roller at x = 0 (a
  massless prismatic link along x before the first revolute) plus a JOINT_POINT2POINT pin at x = L;
  clamped-clamped = the same roller and pin plus clamp springs at both ends (the right clamp acts on
  the absolute angle of the last bar = the sum of all hinge angles); cantilever = a clamp spring at
  x = 0, free at x = L. N is sized from the scene (`engines.chain.segments_for` at option chain_tol,
  the impact point centred on a link), at most MAX_SIZED_LINKS = 115 (Bullet misbehaves near its
  127-link limit, see there); when the scene needs more, N is capped and the diagnostics' `validity`
  says so (its `model_error` is the chain's own error at that N). A Timoshenko scene builds the shear chain
  (`hencky_chain(..., shear=True)`, `_build_shear_chain`): a transverse slide link before every hinge link, so
  two links per segment and at most `sized_cap` = 56 segments (57 on a cantilever).

Always set (engines.md, PyBullet): numSubSteps = 0, contactSlop = 0, zero restitution, friction
and damping. Measured pitfalls handled here: a link's collision shape sits in its *link* frame
(at the hinge), not its inertial frame, so the box is shifted by h/2 (else sphere-box depths are
off by microns); `getLinkState` without computeForwardKinematics returns the previous step's
frame (a one-step lag in the contact point: +0.3 % in f_m at N = 51); createMultiBody silently
keeps at most 127 links; a JOINT_POINT2POINT pivot is given in the link's inertial frame; the
link inertia diagonal must be strictly inside the triangle inequality (i_x + i_y > i_z): Bullet's
mass-matrix check fails on the boundary depending on rounding (issue 11: ~1 in 5 beam geometries
crashed with [i_x, i_y, i_x + i_y]), so i_z = (1 - INERTIA_MARGIN)(i_x + i_y); Bullet clamps every joint rate of a multibody to 100 rad/s
by default (btMultiBody maxCoordinateVelocity): a steel ball at 10 m/s on a titanium beam turns the
hinges near it faster than that and the clamp made the energy grow 936 % at any dt, so the chain gets
maxJointVelocity = MAX_JOINT_VELOCITY.
The penetration is measured from body positions before each step (Bullet's contactDistance is
the pre-step value too), and the force of the step is paired with it: `contact(model)` and
`energy(model)` report the sample at the start of the last step.

Contact modes
- "hertz": the ball's collisions are filtered out; f = alpha * max(delta, 0)^1.5 from the current
  positions is applied with applyExternalForce on the ball and on the beam link every step.
- "native": Bullet's own contact as a linear spring of the paper's k0 = 0.8 alpha sqrt(delta_m)
  (rigid-plate delta_m). Route "global" (default, option native_route): contactERP = E (option
  contact_erp, default 1e3) and globalCFM = E / (k0 dt) with no per-body stiffness: nearly
  elastic. Route "per-body": changeDynamics(contactStiffness = k0, contactDamping = 0) on the
  ball: implicit Euler, dissipative (restitution ~ exp(-pi omega0 dt / 2)). Tuning options:
  contact_stiffness [N/m] and contact_damping [N s/m] (per-body route with those values), or erp and
  cfm (the global route with those values: a spring of erp/(cfm dt)). The result's contact law is
  the linear spring the run used (damping 0), so every native row gets its linear-theory comparison.
  The force is the sum of Bullet's reported normal forces (cross-checked against the ball's
  momentum change in diagnostics["force_report_mismatch"]).
- "native-hertz": the global route with globalCFM = E / (alpha sqrt(delta) dt) updated from the
  current penetration every step: the secant stiffness alpha sqrt(delta), so f = alpha delta^1.5.

Stability: Bullet steps multibodies with semi-implicit Euler, stable while omega_max dt < 2 with
omega_max of chain + ball + contact spring (tangent stiffness at the rigid-plate delta_m),
`engines.chain.omega_max`; the chain's own linearisation from Bullet's mass matrix gives the
reported structure frequencies.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from impactval.engines.base import EngineSettings, Plan, SteppingAdapter, plate_times
from impactval.engines.chain import (DEFAULT_CHAIN_TOL, HenckyChain, centring, chain_notes, hencky_chain, omega_max,
                                     segments_for)
from impactval.engines.options import inapplicable_notes, in_range, non_negative, one_of, option, positive
from impactval.errors import EngineError

NATIVE_ROUTES = ("global", "per-body")
#: how many chain frequencies go into the diagnostics
N_FREQUENCIES_REPORTED = 10
#: constraint solver: set explicitly so the iterations never stop on the default residual threshold
#: (1e-7) while the contact and pin impulses (~1e-8 N s at dt = 1e-7) are that small
SOLVER_RESIDUAL = 1e-30
SOLVER_ITERATIONS = 50
#: PyBullet's createMultiBody silently keeps at most this many links (measured with 3.2.7)
MAX_LINKS = 127
#: most links the automatic sizing chooses (measured, heavy WC ball on a slender steel beam: 105-119 links ran
#: within 0.4-1.3 %, 121 links grew in energy at every dt from 2e-7 to 5e-8 s although the linear limit was
#: 7.9e-7 s, and 125 links split the first contact (t_m -15 %): Bullet misbehaves near its link limit)
MAX_SIZED_LINKS = 115
#: least half-length [m] of the hit link's collision box, centred on the impact point (see _build_chain)
HIT_BOX_HALF = 5e-3
#: the third principal moment sits this far inside the triangle inequality (see the module docstring)
INERTIA_MARGIN = 1e-6
#: joint-rate clamp [rad/s] of the chain (Bullet's default 100 rad/s broke fast impacts, see the docstring)
MAX_JOINT_VELOCITY = 1e9


@dataclass(frozen=True)
class PybulletOptions:
    """`--option pybullet.KEY=VALUE`."""

    native_route: str = option("global", "native linear contact route: 'global' (ERP/CFM, nearly elastic, default) "
                               "or 'per-body' (contactStiffness, implicit, dissipative)", one_of(*NATIVE_ROUTES), contacts=("native",))
    contact_erp: float = option(1e3, "contactERP of the global route (default 1e3)", positive)
    contact_stiffness: float | None = option(None, "per-body contactStiffness [N/m] (native; default k0)", positive, contacts=("native",))
    contact_damping: float | None = option(None, "per-body contactDamping [N s/m] (native; default 0)", non_negative, contacts=("native",))
    erp: float | None = option(None, "global contactERP (native; with cfm: a spring of erp/(cfm dt))", positive)
    cfm: float | None = option(None, "globalCFM (native; with erp)", positive)
    chain_tol: float = option(DEFAULT_CHAIN_TOL, f"relative tolerance the chain is sized for (default "
                              f"{DEFAULT_CHAIN_TOL:g})", in_range(1e-4, 0.2))


def most_links(beam) -> int:
    return MAX_LINKS - (1 if beam.support in ("simply-supported", "clamped-clamped") else 0)


def is_shear(scene) -> bool:
    """True when the job builds the Timoshenko chain (a slide and a hinge link per node): theory = timoshenko."""
    return getattr(scene.target, "theory", "euler-bernoulli") == "timoshenko"


def most_segments(beam, shear: bool, links: int = MAX_LINKS) -> int:
    """Most chain segments within `links` Bullet links: one link per segment (plus the roller) for the
    Euler-Bernoulli chain; two per segment (slide + hinge) plus the roller and the far end's slide link on a
    supported beam for the Timoshenko chain."""
    if not shear:
        return links - (1 if beam.support in ("simply-supported", "clamped-clamped") else 0)
    return (links - (2 if beam.support in ("simply-supported", "clamped-clamped") else 0)) // 2


def sized_cap(scene) -> int:
    """Most segments the automatic sizing chooses (within MAX_SIZED_LINKS links)."""
    shear = is_shear(scene)
    if not shear:
        return min(most_links(scene.target), MAX_SIZED_LINKS)
    return most_segments(scene.target, True, MAX_SIZED_LINKS)


def default_segments(scene, settings: EngineSettings | None = None) -> int:
    """Chain links for a beam scene when settings.segments is None (0 for other targets):
    `engines.chain.segments_for` at option chain_tol, centred impact point, at most `most_links`
    (the Timoshenko chain: at most `sized_cap` segments, two links each)."""
    target = scene.target
    if getattr(target, "kind", "") != "beam":
        return 0
    tol = settings.option("chain_tol", DEFAULT_CHAIN_TOL) if settings is not None else DEFAULT_CHAIN_TOL
    if is_shear(scene):
        return _sized_shear(scene, float(tol)).n
    return _sized(scene, float(tol)).n


@lru_cache(maxsize=16)
def _sized(scene, tol: float):
    most = min(most_links(scene.target), MAX_SIZED_LINKS)
    return segments_for(scene, tol, "none", most, centring(scene.target.impact_at, most))


@lru_cache(maxsize=16)
def _sized_shear(scene, tol: float):
    most = sized_cap(scene)
    return segments_for(scene, tol, "none", most, centring(scene.target.impact_at, most), shear=True)


@dataclass(frozen=True)
class ChainLinear:
    """Bullet's linearised chain about the straight configuration: mass matrix `mass` and stiffness
    `stiffness` over the joint coordinates, constraint rows `constraints` (pin: x and z of the far
    end), null-space basis `basis` of the constraints."""

    mass: np.ndarray
    stiffness: np.ndarray
    constraints: np.ndarray
    basis: np.ndarray

    def frequencies(self) -> np.ndarray:
        """Natural frequencies [rad/s] of the constrained chain, ascending."""
        from scipy import linalg

        z = self.basis
        w2 = linalg.eigh(z.T @ self.stiffness @ z, z.T @ self.mass @ z, eigvals_only=True)
        return np.sqrt(np.clip(w2, 0.0, None))


class _Client:
    """One PyBullet DIRECT client; every call goes to it (one client per job)."""

    def __init__(self) -> None:
        import pybullet

        self.p = pybullet
        self.cid = pybullet.connect(pybullet.DIRECT)
        if self.cid < 0:
            raise RuntimeError("pybullet.connect(DIRECT) failed")

    def __getattr__(self, name):
        fn = getattr(self.p, name)
        cid = self.cid
        bound = functools.partial(fn, physicsClientId=cid)
        setattr(self, name, bound)          # made once: the stepping loop calls these every step
        return bound

    def close(self) -> None:
        try:
            self.p.disconnect(physicsClientId=self.cid)
        except Exception:  # noqa: BLE001 - already gone
            pass


class PybulletAdapter(SteppingAdapter):
    """PyBullet 3.2: rigid plate and chain beams (all three supports); see the module docstring."""

    name = "pybullet"
    module = "pybullet"
    contacts = ("hertz", "native", "native-hertz")
    integrators = ("semi-implicit-euler",)
    integrator_methods = {"semi-implicit-euler": "symplectic-euler"}
    Options = PybulletOptions
    expected_failures: dict[str, str] = {}
    sample_lag = 1          # a step's reported force belongs to the penetration at its start

    def version(self) -> str:
        from importlib.metadata import version

        return version("pybullet")

    def check_settings(self, settings: EngineSettings) -> EngineSettings:
        settings = super().check_settings(settings)
        if (settings.option("erp") is None) != (settings.option("cfm") is None):
            raise EngineError("pybullet: options erp and cfm go together (the spring is erp/(cfm dt)); give both.")
        return settings

    # ------------------------------------------------------------------ planning
    def segments(self, scene, settings: EngineSettings) -> int:
        """Chain links used for `scene` under `settings`."""
        return settings.segments if settings.segments is not None else default_segments(scene, settings)

    def chain(self, scene, settings: EngineSettings) -> HenckyChain | None:
        if scene.target.kind != "beam":
            return None
        n = self.segments(scene, settings)
        shear = is_shear(scene)
        most = most_segments(scene.target, shear)
        if n < 2:
            raise EngineError(f"pybullet: segments must be at least 2 for a beam, got {n}.")
        if n > most:
            raise EngineError(f"pybullet: segments must be at most {most} for a {scene.target.support} beam (PyBullet "
                              f"keeps at most {MAX_LINKS} links per multibody, the roller takes one"
                              + (", the Timoshenko chain two per segment" if shear else "") + f"), got {n}.")
        if shear:
            return hencky_chain(scene.target, n, "none", shear=True)
        return hencky_chain(scene.target, n, "none")

    def contact_law(self, scene, settings: EngineSettings):
        from impactval.reference.hertz import ContactLaw

        if settings.contact == "native":
            k, c = settings.option("contact_stiffness"), settings.option("contact_damping")
            if settings.option("erp") is not None:
                if isinstance(settings.dt, (int, float)):
                    return ContactLaw.linear(settings.option("erp") / (settings.option("cfm") * settings.dt))
                return None
            if k is not None or c is not None:
                return ContactLaw.linear(k or plate_times_k0(scene)) if not c else None
        return super().contact_law(scene, settings)

    def plan(self, scene, settings: EngineSettings) -> Plan:
        from impactval.engines.chain import model_error, model_error_diagnostics
        from impactval.reference.hertz import ContactLaw

        kind = scene.target.kind
        if kind not in ("rigid-plate", "beam", "ball"):
            raise EngineError(f"pybullet: target kind {kind!r} is not supported; use a rigid-plate, beam or ball scene.")
        chain = self.chain(scene, settings)
        law = self.contact_law(scene, settings) or ContactLaw.linear(plate_times_k0(scene))
        if settings.contact == "native-hertz":
            law = ContactLaw.hertz(scene.alpha)
        om, what = omega_max(scene, law, chain)
        diag: dict = {"omega_max": om, "integrator": self.integrators[0]}
        notes: list[str] = []
        err = 0.0
        if chain is not None:
            hertz = model_error(scene, chain)      # the sizing's (and its notes') measure
            # the row's: under its own contact law (a native linear spring k: the chain's linear theory vs the
            # continuum's, what the runner compares it with; a damped or erp/cfm law unknown here: Hertz's)
            me, me_diag = model_error_diagnostics(scene, chain, self.contact_law(scene, settings) and law, hertz)
            err = me.largest
            diag.update(segments=chain.n, **me_diag)
            tol = float(settings.option("chain_tol", DEFAULT_CHAIN_TOL))
            cap = sized_cap(scene)
            notes = chain_notes(scene, chain, hertz, tol, cap if settings.segments is None else None)
            if chain.shear and settings.segments is None and any(v.startswith("chain capped") for v in notes):
                notes.append(f"Timoshenko chain: a slide and a hinge link per segment, so at most {cap} segments "
                             f"({MAX_SIZED_LINKS} of Bullet's {MAX_LINKS} links per multibody)")
        return Plan(2.0 / om, f"semi-implicit Euler, {what}", err, diag,
                    (*inapplicable_notes(settings, self.name), *notes))

    # ------------------------------------------------------------------ the job
    def build(self, scene, settings: EngineSettings) -> "_Run":
        client = _Client()
        try:
            return _build(client, scene, settings, self.chain(scene, settings))
        except BaseException:
            client.close()
            raise

    def stepper(self, run: "_Run"):
        """The run's own step (specialised at build time for the rigid plate with injected Hertz)."""
        return run.step

    def step(self, run: "_Run") -> None:
        run.step()

    def observe(self, run: "_Run") -> None:
        run.observe()

    def contact(self, run: "_Run") -> tuple[float, float]:
        return run.sample[0], run.sample[1]

    def energy(self, run: "_Run") -> float:
        return run.sample[5]

    def kinematics(self, run: "_Run") -> tuple[float, float, float]:
        return run.sample[2], run.sample[3], run.sample[4]

    def frequencies(self, run: "_Run") -> np.ndarray:
        if run.chain is None:
            return np.zeros(0)
        w = run.linear.frequencies()
        return w[w > 1e-6 * max(float(w.max()), 1.0)][:N_FREQUENCIES_REPORTED]

    def describe(self, run: "_Run") -> str:
        what = f"chain N={run.chain.n}" if run.chain is not None else getattr(run, "target_name", "rigid plate")
        return (what + f", contact {run.mode}"
                + (f" ({run.route})" if run.mode == "native" else ""))

    def close(self, run: "_Run") -> None:
        if run.mode != "hertz":
            run.diagnostics["force_report_mismatch"] = run.mismatch / max(run.f_max, 1e-300)
        run.client.close()

    def simulate(self, scene, settings: EngineSettings):
        from impactval.engines.base import add_validity, modes_not_applied

        sim = super().simulate(scene, settings)
        n_modes, note = modes_not_applied(scene, settings, "pybullet")
        add_validity(sim.diagnostics, note)
        sim.settings = {"segments": sim.diagnostics.get("segments"), "integrator": "semi-implicit-euler",
                        "native_route": sim.diagnostics.get("native_route"), "modes": n_modes}
        if settings.contact == "native":
            from impactval.reference.hertz import ContactLaw

            k, c = sim.diagnostics.get("native_k"), sim.diagnostics.get("native_damping", 0.0)
            sim.contact_law = ContactLaw.linear(k) if k and not c else None
            chain = self.chain(scene, settings)
            if sim.contact_law is not None and chain is not None:
                # the spring as built (erp/cfm with dt "auto" is known only now): the chain's model error under it
                # replaces the plan's in the row's diagnostics (cached: the plan's when the plan knew the spring;
                # otherwise `result.model_error` keeps the plan's Hertz one)
                from impactval.engines.chain import model_error_diagnostics

                sim.diagnostics.update(model_error_diagnostics(scene, chain, sim.contact_law)[1])
        if scene.target.kind == "beam":
            from impactval.engines.chain import continuum_frequencies

            sim.diagnostics["continuum_frequencies"] = [float(w) for w in continuum_frequencies(scene.target,
                                                                                                N_FREQUENCIES_REPORTED)]
        return sim

    def structure_frequencies(self, scene, settings: EngineSettings) -> np.ndarray:
        """Natural frequencies [rad/s] of the chain beam built for `scene` (empty for a plate)."""
        if scene.target.kind != "beam":
            return np.zeros(0)
        settings = self.check_settings(settings)
        client = _Client()
        try:
            _set_common(client, 1e-6)
            chain, lin, *_ = _build_chain(client, scene.target, self.chain(scene, settings))
            return lin.frequencies()
        finally:
            client.close()


def plate_times_k0(scene) -> float:
    """The paper's k0 [N/m] of the scene's contact (a second ball: of the two-ball contact, reduced mass)."""
    return plate_times(scene).k0


# ---------------------------------------------------------------------------- building

def world_point(pos, orn, local) -> tuple[float, float, float]:
    """pos + R(orn) local [m] in double precision (orn a quaternion x, y, z, w): a link's contact point from its frame.
    PyBullet's multiplyTransforms rounds its arguments to float32: the top face h/2 = 18.8595 mm above a WC beam's
    axis came out 6.5e-11 m high, so the ball started that far inside the beam; against a slow impact's approach
    (0.83 um for a 7 mm glass ball at 3.3 cm/s) that biased f_m by +6e-4 at every dt and N, and by +2.4e-3 for a
    1 mm steel ball at 4 mm/s (v' = v + w t + q x t, t = 2 q x v)."""
    qx, qy, qz, qw = orn
    vx, vy, vz = local
    tx = 2.0 * (qy * vz - qz * vy)
    ty = 2.0 * (qz * vx - qx * vz)
    tz = 2.0 * (qx * vy - qy * vx)
    return (pos[0] + vx + qw * tx + (qy * tz - qz * ty),
            pos[1] + vy + qw * ty + (qz * tx - qx * tz),
            pos[2] + vz + qw * tz + (qx * ty - qy * tx))


def _set_common(c: _Client, dt: float) -> None:
    c.setGravity(0, 0, 0)
    c.setPhysicsEngineParameter(fixedTimeStep=dt, numSubSteps=0, contactSlop=0.0, restitutionVelocityThreshold=0.0,
                                solverResidualThreshold=SOLVER_RESIDUAL, numSolverIterations=SOLVER_ITERATIONS)


def _no_losses(c: _Client, body: int, links) -> None:
    for link in links:
        c.changeDynamics(body, link, restitution=0.0, lateralFriction=0.0, spinningFriction=0.0,
                         rollingFriction=0.0, linearDamping=0.0, angularDamping=0.0, jointDamping=0.0)


def link_inertia(mass: float, length: float, width: float, height: float) -> list[float]:
    """Principal moments [kg m^2] of a chain link for Bullet: about y the rigid bar's m l^2/12 (the
    Euler-Bernoulli chain), about x the section's m (w^2 + h^2)/12, about z strictly inside the triangle
    inequality (never excited; on the boundary Bullet's mass-matrix check fails by rounding)."""
    i_y = mass * length * length / 12.0
    i_x = mass * (width**2 + height**2) / 12.0
    return [i_x, i_y, (1.0 - INERTIA_MARGIN) * (i_x + i_y)]


def _segment_box(c, p, h: float, width: float, height: float) -> int:
    """A segment's collision box [m]. A link's collision shape sits in its link frame (the hinge at the bar's left
    end), not in its inertial frame: the box is shifted by h/2 so it covers the bar (else sphere-box depths err by um)."""
    return c.createCollisionShape(p.GEOM_BOX, halfExtents=[h / 2, width / 2, height / 2],
                                  collisionFramePosition=[h / 2, 0, 0])


def _hit_box(c, p, hc, h: float, width: float, height: float) -> int:
    """The hit link's collision box: centred on the impact point, at least HIT_BOX_HALF [m] each way along x."""
    hit_half = max(h / 2, HIT_BOX_HALF)
    return c.createCollisionShape(p.GEOM_BOX, halfExtents=[hit_half, width / 2, height / 2],
                                  collisionFramePosition=[hc.hit_offset, 0, 0])


def _multibody(c, masses, shapes, positions, inertial, parents, joint_types, axes) -> int:
    """One multibody on a fixed massless base from per-link lists (positions [m], masses [kg]); all built or raise."""
    nl = len(masses)
    body = c.createMultiBody(
        baseMass=0.0, baseCollisionShapeIndex=-1, basePosition=[0, 0, 0],
        linkMasses=masses, linkCollisionShapeIndices=shapes, linkVisualShapeIndices=[-1] * nl,
        linkPositions=positions, linkOrientations=[[0, 0, 0, 1]] * nl,
        linkInertialFramePositions=inertial, linkInertialFrameOrientations=[[0, 0, 0, 1]] * nl,
        linkParentIndices=parents, linkJointTypes=joint_types, linkJointAxis=axes)
    if c.getNumJoints(body) != nl:
        raise RuntimeError(f"pybullet built {c.getNumJoints(body)} of {nl} links")
    return body


def _chain_parts(c, beam, hc: HenckyChain):
    """What both chain builders start from: (pybullet module, length, height, width [m], segments n, segment
    length h [m], segment mass [kg], support, roller at x = 0 (a supported far end), the segment's box shape)."""
    p = c.p
    roller = beam.support in ("simply-supported", "clamped-clamped")
    box = _segment_box(c, p, hc.segment_length, beam.width, beam.height)
    return (p, beam.length, beam.height, beam.width, hc.n, hc.segment_length, hc.segment_mass, beam.support, roller,
            box)


def _build_chain(c: _Client, beam, hc: HenckyChain):
    """The beam as the chain `hc` of box links (see the module docstring); returns (body, ChainLinear,
    revolute joint indices, all joints, K over the revolute coordinates, contact link, local point).
    A shear chain (`hc.shear`): see `_build_shear_chain`."""
    if hc.shear:
        return _build_shear_chain(c, beam, hc)
    p, length, height, width, n, h, m_bar, support, roller, box = _chain_parts(c, beam, hc)
    masses, shapes, positions, joint_types, axes, inertial, parents = [], [], [], [], [], [], []
    if roller:      # massless slider along x at x = 0
        masses.append(0.0)
        shapes.append(-1)
        positions.append([0, 0, 0])
        joint_types.append(p.JOINT_PRISMATIC)
        axes.append([1, 0, 0])
        inertial.append([0, 0, 0])
        parents.append(0)
    first = len(masses)
    # the hit link's box is centred on the impact point and at least HIT_BOX_HALF long each way: Bullet rounds a
    # box's edges by its collision margin (~1 mm measured), so a ball landing within ~1 mm of a link's end, or on
    # a link shorter than 2 mm, met the rounded edge first (cantilever hit at 0.97 L: Bullet's gap was 29.6 um at
    # touch, the ball went 30 um in without force; 1 mm ball on 1.8 mm links: 0.64 um) and the energy "grew" by
    # 265-900 %. Links of one multibody do not collide with each other, so the longer box overlaps nothing.
    hit_box = _hit_box(c, p, hc, h, width, height)
    for i in range(n):
        masses.append(m_bar)
        shapes.append(hit_box if i == hc.hit_segment else box)
        positions.append([0, 0, 0] if i == 0 else [h, 0, 0])
        joint_types.append(p.JOINT_REVOLUTE)
        axes.append([0, 1, 0])
        inertial.append([h / 2, 0, 0])
        parents.append(len(masses) - 1)     # 1-based parent index = previous link (0 = base)
    nl = len(masses)
    body = _multibody(c, masses, shapes, positions, inertial, parents, joint_types, axes)
    all_joints = list(range(nl))
    revolute = list(range(first, nl))
    inertia = link_inertia(m_bar, h, width, height)
    for j in revolute:
        c.changeDynamics(body, j, mass=m_bar, localInertiaDiagonal=inertia)
    _no_losses(c, body, [-1] + all_joints)
    c.changeDynamics(body, -1, maxJointVelocity=MAX_JOINT_VELOCITY)
    c.setJointMotorControlArray(body, all_joints, p.VELOCITY_CONTROL, forces=[0.0] * nl)

    # Hencky springs over the revolute coordinates q (relative angles; bar k's angle = sum q_0..k)
    k_rev = np.zeros((n, n))
    for j in range(1, n):
        k_rev[j, j] += hc.hinge_stiffness
    if support in ("clamped-clamped", "cantilever"):
        k_rev[0, 0] += hc.clamp_stiffness
    if support == "clamped-clamped":
        k_rev += hc.clamp_stiffness * np.ones((n, n))

    q0 = [0.0] * nl
    mass = np.asarray(c.calculateMassMatrix(body, q0), float)
    stiff = np.zeros((nl, nl))
    stiff[first:, first:] = k_rev
    end_lin, _ = c.calculateJacobian(body, nl - 1, [h, 0, 0], q0, q0, q0)
    end_lin = np.asarray(end_lin, float)
    contact_link = first + hc.hit_segment
    local = (hc.hit_offset, 0.0, height / 2)
    if roller:
        constraints = end_lin[[0, 2]]
        # the pivot is given in the link's inertial (centre-of-mass) frame: the far end is h/2 beyond it
        c.createConstraint(body, nl - 1, -1, -1, p.JOINT_POINT2POINT, [0, 0, 0], [h / 2, 0, 0], [length, 0, 0])
    else:
        constraints = np.zeros((0, nl))
    from scipy import linalg

    basis = linalg.null_space(constraints) if constraints.size else np.eye(nl)
    return body, ChainLinear(mass, stiff, constraints, basis), revolute, all_joints, k_rev, contact_link, local


def _build_shear_chain(c: _Client, beam, hc: HenckyChain):
    """The Timoshenko chain `hc` (engines.chain, shear=True): at every node a massless link on a transverse
    (z) prismatic joint, its child the segment's box link on the revolute joint about y, so node j's slide
    opens along the previous segment's transverse axis (kappa G A / l; 2 kappa G A / l at x = 0) and its hinge
    turns by the relative angle (EI/l). The segment link's rotary inertia is the section's m (l^2 + h^2)/12.
    A supported beam ends in a small body (half a segment's mass, pinned, so it hardly moves) on a transverse
    slide of 2 kappa G A / l at x = L, pinned by JOINT_POINT2POINT; the roller at x = 0 is as for the
    Euler-Bernoulli chain. Spring forces/torques -K q over the slide and hinge coordinates are applied every
    step, as for the hinges of the Euler-Bernoulli chain. Returns what `_build_chain` returns, with the
    sprung (slide + hinge) joints in place of the revolute ones."""
    p, length, height, width, n, h, m_bar, support, roller, box = _chain_parts(c, beam, hc)
    masses, shapes, positions, joint_types, axes, inertial, parents = [], [], [], [], [], [], []

    def add(mass, shape, pos, joint, axis, com):
        masses.append(mass)
        shapes.append(shape)
        positions.append(pos)
        joint_types.append(joint)
        axes.append(axis)
        inertial.append(com)
        parents.append(len(masses) - 1)     # 1-based parent index = previous link (0 = base)

    if roller:      # massless slider along x at x = 0
        add(0.0, -1, [0, 0, 0], p.JOINT_PRISMATIC, [1, 0, 0], [0, 0, 0])
    first = len(masses)
    hit_box = _hit_box(c, p, hc, h, width, height)     # see _build_chain
    for i in range(n):
        add(0.0, -1, [0, 0, 0] if i == 0 else [h, 0, 0], p.JOINT_PRISMATIC, [0, 0, 1], [0, 0, 0])
        add(m_bar, hit_box if i == hc.hit_segment else box, [0, 0, 0], p.JOINT_REVOLUTE, [0, 1, 0], [h / 2, 0, 0])
    if roller:      # the far end's slide: a small pinned body at x = L
        add(m_bar / 2, -1, [h, 0, 0], p.JOINT_PRISMATIC, [0, 0, 1], [0, 0, 0])
    nl = len(masses)
    body = _multibody(c, masses, shapes, positions, inertial, parents, joint_types, axes)
    all_joints = list(range(nl))
    sprung = list(range(first, nl))         # slide 0, hinge 0, slide 1, ..., hinge n-1 (, far-end slide)
    i_x = m_bar * (width**2 + height**2) / 12.0
    inertia = [i_x, hc.rotary_inertia, (1.0 - INERTIA_MARGIN) * (i_x + hc.rotary_inertia)]
    for i in range(n):
        c.changeDynamics(body, first + 2 * i + 1, mass=m_bar, localInertiaDiagonal=inertia)
    if roller:
        tiny = 1e-6 * hc.rotary_inertia
        c.changeDynamics(body, nl - 1, mass=m_bar / 2, localInertiaDiagonal=[tiny, tiny, tiny])
    _no_losses(c, body, [-1] + all_joints)
    c.changeDynamics(body, -1, maxJointVelocity=MAX_JOINT_VELOCITY)
    c.setJointMotorControlArray(body, all_joints, p.VELOCITY_CONTROL, forces=[0.0] * nl)

    # springs over the sprung coordinates: slides (relative transverse offsets) and hinges (relative angles)
    ns = len(sprung)
    k_spr = np.zeros((ns, ns))
    hinges = [2 * i + 1 for i in range(n)]
    k_spr[0, 0] = hc.support_shear_stiffness
    for i in range(1, n):
        k_spr[2 * i, 2 * i] = hc.shear_stiffness
        k_spr[2 * i + 1, 2 * i + 1] = hc.hinge_stiffness
    if support in ("clamped-clamped", "cantilever"):
        k_spr[1, 1] += hc.clamp_stiffness
    if support == "clamped-clamped":
        k_spr[np.ix_(hinges, hinges)] += hc.clamp_stiffness
    if roller:
        k_spr[ns - 1, ns - 1] = hc.support_shear_stiffness

    q0 = [0.0] * nl
    mass = np.asarray(c.calculateMassMatrix(body, q0), float)
    stiff = np.zeros((nl, nl))
    stiff[first:, first:] = k_spr
    contact_link = first + 2 * hc.hit_segment + 1
    local = (hc.hit_offset, 0.0, height / 2)
    if roller:
        end_lin, _ = c.calculateJacobian(body, nl - 1, [0, 0, 0], q0, q0, q0)
        constraints = np.asarray(end_lin, float)[[0, 2]]
        c.createConstraint(body, nl - 1, -1, -1, p.JOINT_POINT2POINT, [0, 0, 0], [0, 0, 0], [length, 0, 0])
    else:
        constraints = np.zeros((0, nl))
    from scipy import linalg

    basis = linalg.null_space(constraints) if constraints.size else np.eye(nl)
    return body, ChainLinear(mass, stiff, constraints, basis), sprung, all_joints, k_spr, contact_link, local


class _Run:
    """A live PyBullet job. `sample` = (delta, f, x_ball, x_structure, v_ball, energy) of the state at the
    start of the last step, with the force Bullet applied in that step."""

    def __init__(self, **kw: Any) -> None:
        self.__dict__.update(kw)

    def read(self) -> None:
        """Current state: ball position and rate, chain angles and rates, contact point."""
        c = self.client
        self.pos = self.getpos(self.ball_body)[0]
        self.vz = self.getvel(self.ball_body)[0][2]
        if self.chain is not None:
            states = c.getJointStates(self.body, self.all_j)
            self.q_all = np.fromiter((s[0] for s in states), float, len(states))
            self.qd_all = np.fromiter((s[1] for s in states), float, len(states))
            # computeForwardKinematics: without it getLinkState returns the previous step's frame
            st = c.getLinkState(self.body, self.link, computeForwardKinematics=1)
            self.point = world_point(st[4], st[5], self.local)
            self.z_point = self.point[2]
        else:
            self.z_point, self.point = self.surface_z, None
            self.q_all = self.qd_all = None
        self.d = self.z_point - (self.pos[2] - self.radius)

    def other_energy(self) -> float:
        """Kinetic energy [J] of bodies other than the ball and the chain (none here; see _TwoBallRun)."""
        return 0.0

    def target_point(self) -> tuple[Any, float]:
        """(contact point on a moving target or None, its height [m]) for a target without a chain."""
        return None, self.surface_z

    def contact_potential(self, d: float, d_new: float) -> float:
        if d <= 0 or d_new <= 0:
            return 0.0
        if self.mode == "native":
            return 0.5 * self.k_native * d * d_new
        return 0.4 * self.alpha * (d * d_new) ** 1.25

    def energy_of(self, d: float, q_all) -> float:
        """Energy [J] of the previous sample in the form semi-implicit Euler conserves exactly for linear
        systems: rates after the step, potentials as the product of the positions before and after
        (k/2 x_n x_n+1; Hertz (2/5) alpha (d_n d_n+1)^1.25). No O((omega dt)^2) ripple."""
        e = 0.5 * self.m0 * self.vz * self.vz + self.contact_potential(d, self.d) + self.other_energy()
        if self.chain is not None:
            n = self.n_rev
            q, qn, qd = q_all[-n:], self.q_all[-n:], self.qd_all
            e += 0.5 * float(qd @ self.m_full @ qd) + 0.5 * float(q @ self.k_rev @ qn)
        return e

    def step(self) -> None:
        """The physics of one step (timed): read the positions the forces need, apply the spring torques
        and the contact force, stepSimulation. `observe` then builds the sample."""
        c, p = self.client, self.p
        pos = self.getpos(self.ball_body)[0]
        if self.chain is not None:
            q = np.fromiter((s[0] for s in c.getJointStates(self.body, self.rev)), float, self.n_rev)
            # computeForwardKinematics: without it getLinkState returns the previous step's frame
            st = c.getLinkState(self.body, self.link, computeForwardKinematics=1)
            point = world_point(st[4], st[5], self.local)
            z_point = point[2]
            c.setJointMotorControlArray(self.body, self.rev, p.TORQUE_CONTROL, forces=(-(self.k_rev @ q)).tolist())
        else:
            point, z_point = self.target_point()
        d = z_point - (pos[2] - self.radius)
        f = 0.0
        if self.mode == "hertz":
            f = self.alpha * d**1.5 if d > 0 else 0.0
            if f > 0:
                c.applyExternalForce(self.ball_body, -1, [0, 0, f], pos, p.WORLD_FRAME)
                if point is not None:      # a chain link or a second ball takes the reaction
                    c.applyExternalForce(self.body, self.link, [0, 0, -f], point, p.WORLD_FRAME)
        elif self.mode == "native-hertz":
            dd = d if d > self.delta_floor else self.delta_floor
            c.setPhysicsEngineParameter(globalCFM=self.erp / (self.alpha * math.sqrt(dd) * self.dt))
        c.stepSimulation()
        self.stepped = (d, f, pos, z_point)

    def plate_hertz_stepper(self):
        """`step` specialised for injected Hertz on the rigid plate: the same statements with everything it
        reads bound as locals of a closure (no branches on the target or the mode, no attribute lookups), so
        the timed step stays within a few % of a bare loop (benchmarks/bench_sweep_overhead.py)."""
        getpos, ball, surface, radius, alpha = self.getpos, self.ball_body, self.surface_z, self.radius, self.alpha
        apply_force, step_simulation, world = self.client.applyExternalForce, self.client.stepSimulation, \
            self.p.WORLD_FRAME
        run = self

        def step() -> None:
            pos = getpos(ball)[0]
            d = surface - (pos[2] - radius)
            f = alpha * d**1.5 if d > 0 else 0.0
            if f > 0:
                apply_force(ball, -1, [0, 0, f], pos, world)
            step_simulation()
            run.stepped = (d, f, pos, surface)
        return step

    def observe(self) -> None:
        """The sample of the last step (not timed): Bullet's contact force (native modes), the new state, the
        energy of the step's start."""
        c = self.client
        d, f, pos, z_point = self.stepped
        q_prev, vz = self.q_all, self.vz
        if self.mode != "hertz":
            f = sum(cp[9] for cp in c.getContactPoints(self.ball_body, self.target_body))
            f_mom = self.m0 * (self.getvel(self.ball_body)[0][2] - vz) / self.dt
            if f > 0 or f_mom != 0:
                self.mismatch = max(self.mismatch, abs(f - f_mom))
            self.f_max = max(self.f_max, f)
        self.read()
        e = self.energy_of(d, q_prev)
        self.sample = (d, f, self.z_ball0 - pos[2], self.z_point0 - z_point, -vz, e)


def _add_second_ball(c: _Client, target) -> int:
    """A second free sphere (target kind "ball") of the target's mass and radius, centre at z = -R2 (top at
    z = 0, where the first ball touches), moving toward the first ball (+z) at the target's velocity, no
    gravity, damping, friction or restitution. Returns its body id."""
    sphere = c.createCollisionShape(c.p.GEOM_SPHERE, radius=target.radius)
    body = c.createMultiBody(baseMass=target.mass, baseCollisionShapeIndex=sphere, basePosition=[0, 0, -target.radius])
    _no_losses(c, body, [-1])
    c.resetBaseVelocity(body, [0, 0, target.velocity], [0, 0, 0])
    return body


class _TwoBallRun(_Run):
    """A live two-ball job: the contact point is the second ball's top, which moves with it."""

    def read(self) -> None:
        self.pos = self.getpos(self.ball_body)[0]
        self.vz = self.getvel(self.ball_body)[0][2]
        pos2 = self.getpos(self.target_body)[0]
        self.vz2 = self.getvel(self.target_body)[0][2]
        self.point = (pos2[0], pos2[1], pos2[2] + self.r2)
        self.z_point = self.point[2]
        self.q_all = self.qd_all = None
        self.d = self.z_point - (self.pos[2] - self.radius)

    def other_energy(self) -> float:
        return 0.5 * self.m2 * self.vz2 * self.vz2

    def target_point(self) -> tuple[Any, float]:
        pos2 = self.getpos(self.target_body)[0]
        return (pos2[0], pos2[1], pos2[2] + self.r2), pos2[2] + self.r2


def _build(c: _Client, scene, settings: EngineSettings, chain: HenckyChain | None) -> _Run:
    p = c.p
    dt = float(settings.dt)
    ball = scene.ball
    m0, radius, v0, alpha = ball.mass, ball.radius, ball.velocity, scene.alpha
    plate = plate_times(scene)          # a second ball: the two-ball contact (reduced mass, approach speed)
    k0 = plate.k0
    mode = settings.contact
    opt = settings.option
    route = opt("native_route", "global") if mode == "native" else "global"
    if mode == "native" and (opt("contact_stiffness") is not None or opt("contact_damping") is not None):
        route = "per-body"
    if mode == "native" and opt("erp") is not None:
        route = "global"
    erp = opt("erp") or opt("contact_erp", 1e3)
    _set_common(c, dt)
    diagnostics: dict = {}
    target = scene.target
    body = link = None
    local = None
    lin = rev = all_j = k_rev = None
    second = None
    if target.kind == "ball":
        second = _add_second_ball(c, target)
        target_body, surface_z, ball_xy = second, 0.0, (0.0, 0.0)
        body, link = second, -1         # the reaction of the injected force goes to the second ball
    elif chain is not None:
        body, lin, rev, all_j, k_rev, link, local = _build_chain(c, target, chain)
        target_body = body
        surface_z = target.height / 2
        ball_xy = (target.impact_x, 0.0)
    else:
        half = max(10 * radius, 0.05)
        box = c.createCollisionShape(p.GEOM_BOX, halfExtents=[half, half, half])
        target_body = c.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=box, basePosition=[0, 0, -half])
        _no_losses(c, target_body, [-1])
        surface_z = 0.0
        ball_xy = (0.0, 0.0)

    sphere = c.createCollisionShape(p.GEOM_SPHERE, radius=radius)
    z_ball0 = surface_z + radius
    ball_body = c.createMultiBody(baseMass=m0, baseCollisionShapeIndex=sphere,
                                  basePosition=[ball_xy[0], ball_xy[1], z_ball0])
    _no_losses(c, ball_body, [-1])
    c.resetBaseVelocity(ball_body, [0, 0, -v0], [0, 0, 0])

    k_native, damping = k0, 0.0
    if mode == "hertz":
        c.setCollisionFilterGroupMask(ball_body, -1, 0, 0)
    elif route == "per-body":
        k_native = float(opt("contact_stiffness") or k0)
        damping = float(opt("contact_damping") or 0.0)
        c.changeDynamics(ball_body, -1, contactStiffness=k_native, contactDamping=damping)
        diagnostics["dissipative"] = ("per-body contactStiffness is solved implicitly: the contact loses energy "
                                      "(restitution ~ exp(-pi omega0 dt / 2))")
    elif mode == "native" and opt("cfm") is not None:
        k_native = erp / (float(opt("cfm")) * dt)
        c.setPhysicsEngineParameter(contactERP=erp, globalCFM=float(opt("cfm")))
    else:
        k_start = k0 if mode == "native" else alpha * math.sqrt(1e-3 * plate.delta_m)
        c.setPhysicsEngineParameter(contactERP=erp, globalCFM=erp / (k_start * dt))
    if mode == "native":
        diagnostics.update(native_route=route, native_k=k_native, native_damping=damping, contact_stiffness=k_native)
    if mode == "native-hertz":
        diagnostics["native_route"] = "global, CFM updated from the penetration each step"
    if chain is not None:
        diagnostics["segments"] = chain.n
    run = (_TwoBallRun if second is not None else _Run)(client=c, p=p, chain=chain, body=body, link=link, local=list(local) if local else None, lin=None,
               linear=lin, rev=rev, all_j=all_j, k_rev=k_rev, m_full=lin.mass if lin is not None else None,
               n_rev=len(rev) if rev else 0, ball_body=ball_body, target_body=target_body, surface_z=surface_z,
               radius=radius, m0=m0, alpha=alpha, mode=mode, route=route, erp=erp, dt=dt, k_native=k_native,
               delta_floor=1e-6 * plate.delta_m, mismatch=0.0, f_max=0.0, diagnostics=diagnostics, z_ball0=z_ball0,
               getpos=c.getBasePositionAndOrientation, getvel=c.getBaseVelocity)
    if second is not None:
        run.m2, run.r2 = target.mass, target.radius
        run.target_name = "two spheres"
    elif chain is None and mode == "hertz":
        run.step = run.plate_hertz_stepper()
    run.read()
    run.z_point0 = run.z_point
    e0 = 0.5 * m0 * run.vz**2 + (0.0 if run.d <= 0 else run.contact_potential(run.d, run.d)) + run.other_energy()
    f0 = alpha * run.d**1.5 if (mode == "hertz" and run.d > 0) else 0.0
    run.sample = (run.d, f0, 0.0, 0.0, -run.vz, e0)
    return run
