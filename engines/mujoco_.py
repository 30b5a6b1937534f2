"""MuJoCo adapter: the ball and the target built as an MJCF model, stepped with `mj_step`.

A stepping adapter (engines/base.py): `build` makes the model, `step` calls `mj_step`, `contact`,
`energy`, `kinematics` read the state; the base owns the loop, the window, dt = "auto", the
stability limit and the status.

Model (SI units, z up, the ball falls along -z, no gravity, no friction, no damping):

- ball: a sphere of the scene's mass and radius on one slide joint along z, touching the target
  at t = 0 with velocity -v0;
- rigid plate: the world (a plane geom at z = 0);
- beam: the Hencky chain of `engines.chain.hencky_chain` (N rigid segments along x, neutral axis at
  z = 0, top face at z = h/2, hinges of EI/l, clamped ends 2EI/l, rotary inertia m l^2/12: option
  rotary_inertia = "none", the default, the Euler-Bernoulli chain (a Timoshenko beam with the serial chain:
  the shear-deformable chain, transverse slides kappa G A / l at the nodes, docs/mujoco.md); "section" adds the section's
  m h^2/12, a Rayleigh beam, which lowers the chain's highest frequency (a larger stable dt) at the
  price of a model difference that grows with h/L). N is sized from the scene
  (`engines.chain.segments_for`: the modes that matter within `chain_tol` in frequency and the
  chain's own error on t_m, f_m, delta_m within `chain_tol`), reported as `model_error` (a native row's measured
  under its linear spring: `engines.chain.linear_model_error`, the Hertz one as `model_error_hertz_*`).
  Supports: simply supported = a roller at x = 0 (slide x + free hinge) and a `<connect>` pin at
  x = L (a pin at both ends locks the chain); clamped-clamped = a roller with a 2EI/l hinge at x = 0
  and, at x = L, a `<connect>` pin plus a fixed tendon over all hinge angles (= the last segment's
  absolute rotation) of stiffness 2EI/l; cantilever = a 2EI/l hinge to the ground at x = 0, free end.
  The ball hits the segment that contains x = impact_at*L, at that point;
- second ball (target kind "ball"): a free sphere of the target's mass and radius on its own slide joint
  along z (centre at z = -R2, moving at +v2 toward the first ball); the contact spring acts on the
  reduced mass (k0, dt auto and dt_limit from `engines.base.plate_times` / the two-ball contact);
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
  small impedance (d0 = dwidth = NATIVE_IMPEDANCE = 1e-4, see there why not MuJoCo's 0.9).
  Options `solref` ("a,b": positive = MuJoCo's standard time constant and damping ratio, negative =
  direct -stiffness, -damping per unit effective mass) and `solimp` (5 numbers) replace them (for
  tuning); the result's contact law is then linear only for a direct undamped solref with a flat solimp;
- "native-hertz": the same pair with solref and the solimp shape fitted (least squares on the
  static force law MuJoCo itself produces, on a plate with the scene's ball) to alpha*delta^1.5
  over 0..1.2 delta_m, impedance <= 1e-3; the fit's RMS error is reported in diagnostics["native_hertz_fit_rms"].

Stability: Euler and implicitfast treat the hinge springs and the contact explicitly (semi-implicit
Euler, stable while omega_max dt < 2), RK4 while omega_max dt < 2.83; omega_max is that of chain + ball
+ contact spring at its tangent stiffness at the rigid-plate f_m (`engines.chain.omega_max`).
After `mj_step` the positions-derived data describe the state at the start of the step, so the adapter
samples that state (`sample_lag = 1`, no extra `mj_forward`); energy for Euler/implicitfast is
1/2 v_before' M v_after + V (exactly conserved by the scheme on a linear system). The support constraints use
solref = (2 dt, 1) (MuJoCo's default 0.02 s makes them springs).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from impactval.engines.base import EngineDiverged, EngineSettings, Plan, SteppingAdapter, contact_scene, plate_times
from impactval.engines.chain import DEFAULT_CHAIN_TOL, HenckyChain, centring, hencky_chain, omega_max, segments_for
from impactval.engines.options import in_range, numbers, one_of, option, positive
from impactval.errors import EngineError, ImpactvalError

#: MuJoCo integrators offered (first = default); "discrete" damps contacts and is left out
INTEGRATORS = ("Euler", "implicitfast", "RK4")
#: explicit stability limit dt_limit = STABILITY[integrator] / omega_max (imaginary-axis bound of the scheme)
STABILITY = {"Euler": 2.0, "implicitfast": 2.0, "RK4": 2.0 * math.sqrt(2.0)}
#: impedance of the native contact pair. MuJoCo's soft contact gives f = (d/A)*(k*delta - a0): the
#: a0 term (the target's own acceleration at the contact) turns a contact on a flexible target into
#: a stiff constraint for the usual d ~ 0.9-0.95 (worked-case beam: f up to 12x k0*delta); a small
#: constant d with solref scaled to match keeps it a spring (d = 1e-4: within 0.05 % of k0*delta)
NATIVE_IMPEDANCE = 1e-4
#: largest impedance of the fitted native-hertz shape (same reason)
NATIVE_HERTZ_DMAX = 1e-3
#: most chain segments the sizing may choose (cost per step ~ N, steps ~ N^2 at the auto dt)
MAX_SEGMENTS = 400
#: how many chain frequencies to report
N_FREQUENCIES = 6
#: chains with more degrees of freedom than this report the frequencies of their chain model (engines.chain's Hencky
#: chain, which MuJoCo builds: its linearised chain matched it to 1e-7 on Euler-Bernoulli chains of 43-243 DOF and
#: 2e-4 to 4e-4 on Timoshenko chains of 165-325, the support constraints' softness) instead of MuJoCo's own
#: (`chain_frequencies`: finite differences of 2 x DOF steps, each ~DOF^3 on a serial chain's dense mass matrix:
#: 0.33 s at 163 DOF, 1.35 s at 243, 3.4 s at 325, ~140 s at 750)
FD_FREQUENCIES_MAX_DOF = 256


def _positive_below_one(value: Any) -> float:
    v = positive(value)
    if not v < 1.0:
        raise ValueError(f"must be a number in (0, 1), got {value!r}")
    return v


@dataclass(frozen=True)
class MujocoOptions:
    """`--option mujoco.KEY=VALUE`."""

    rotary_inertia: str = option("none", "segment rotary inertia: 'none' = m l^2/12 (Euler-Bernoulli chain, default), "
                                 "'section' = m (l^2 + h^2)/12 (Rayleigh beam)", one_of("none", "section"))
    chain_tol: float = option(DEFAULT_CHAIN_TOL, f"relative tolerance the chain is sized for (default "
                              f"{DEFAULT_CHAIN_TOL:g})", in_range(1e-4, 0.2))
    equality_timeconst: float | None = option(None, "solref time constant [s] of the support constraints (default 2*dt)",
                                              positive)
    native_impedance: float = option(NATIVE_IMPEDANCE, f"constant solimp impedance d of the native linear contact "
                                     f"(default {NATIVE_IMPEDANCE:g})", _positive_below_one)
    solref: tuple[float, float] | None = option(None, "contact pair solref 'a,b' (positive: timeconst [s], dampratio; "
                                                "negative: -stiffness, -damping per unit effective mass)", numbers(2))
    solimp: tuple[float, ...] | None = option(None, "contact pair solimp 'd0,dwidth,width,midpoint,power'", numbers(5))
    chain_root: str = option("auto", "segment the chain's kinematic tree starts from: 'end' (segment 0 on the support "
                             "joints, a serial chain), 'middle' (a floating middle segment with two branches, supports as "
                             "constraints: half the tree depth, a better-conditioned mass matrix, ~3x faster steps on "
                             "long chains), 'auto' (default: 'end' up to 256 degrees of freedom, else 'middle') or 'hit' "
                             "(rooted at the hit segment; the Euler-Bernoulli chain even on a Timoshenko scene)",
                             one_of("auto", "end", "hit", "middle"))


def default_segments(scene, settings: EngineSettings | None = None) -> int:
    """Chain segments for `scene` when settings.segments is None: `engines.chain.segments_for` at the
    option chain_tol, with the impact point centred on a segment."""
    tol = settings.option("chain_tol", DEFAULT_CHAIN_TOL) if settings is not None else DEFAULT_CHAIN_TOL
    rotary = settings.option("rotary_inertia", "none") if settings is not None else "none"
    return _sized(scene, float(tol), rotary, _shear(scene, settings)).n


def _shear(scene, settings: EngineSettings | None) -> bool:
    """True when the job builds the Timoshenko chain: a Timoshenko beam, rooted at its end or middle (chain_root
    'auto', 'end', 'middle'); chain_root 'hit' builds the Euler-Bernoulli chain (the row notes it)."""
    root = settings.option("chain_root", "auto") if settings is not None else "auto"
    return getattr(scene.target, "theory", "euler-bernoulli") == "timoshenko" and root != "hit"


#: chain_root 'auto' roots a chain of more degrees of freedom than this at its middle segment: a serial chain's mass
#: matrix is dense and its factorisation costs ~DOF^3 per step (a user's 385-segment Timoshenko chain, 770 DOF: 119 s
#: serial, 40 s from the middle, the metrics equal to 5e-6)
AUTO_ROOT_DOF = 256


def chain_root_of(root: str, chain: HenckyChain) -> str:
    """The tree root a chain is built with: `root` as asked, 'auto' resolved by the chain's size (AUTO_ROOT_DOF)."""
    if root != "auto":
        return root
    return "end" if chain.n * (2 if chain.shear else 1) <= AUTO_ROOT_DOF else "middle"


def _chain_for(scene, settings: EngineSettings) -> HenckyChain:
    n = settings.segments or default_segments(scene, settings)
    return hencky_chain(scene.target, n, settings.option("rotary_inertia", "none"), shear=_shear(scene, settings))


@lru_cache(maxsize=16)
def _sized(scene, tol: float, rotary: str, shear: bool = False):
    return segments_for(scene, tol, rotary, MAX_SEGMENTS, centring(scene.target.impact_at, MAX_SEGMENTS), shear=shear)
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
        self.root_segment = 0        # the chain segment the kinematic tree starts from



def _beam_xml(beam, chain: HenckyChain, lay: _Layout, contact_geom: bool, root: str = "end") -> tuple[str, str]:
    """Worldbody chain and extra sections (equality, tendon) for the Hencky chain of a beam.

    root = "end": a serial tree from segment 0 (the supports as in the module docstring). root = "hit" or
    "middle": the tree is rooted at the hit segment or the middle one (planar joints root_x, root_z, root_r
    at its centre of mass) with two branches to the ends, so the tree depth is ~N/2 (a serial chain's
    joint-space mass matrix gets ill-conditioned with its depth, see docs/mujoco-warp.md); the supports
    become constraints: a `<connect>` pin at each supported end, the roller at x = 0 a small body on a
    slide-x joint pinned to the world, a clamp's 2EI/l a fixed tendon over the joints whose sum is that
    end segment's absolute rotation. The same beam model either way (node hinges EI/l, same masses). A Timoshenko
    chain (chain.shear; MuJoCo Warp builds it rooted in the middle) adds a transverse slide of kappa G A / l at every
    node and, at each supported end, a small body on a slide of 2 kappa G A / l that carries the end's constraint."""
    n, l = chain.n, chain.segment_length
    w, h = beam.width, beam.height
    k_hinge, k_clamp = chain.hinge_stiffness, chain.clamp_stiffness
    m_seg = chain.segment_mass
    iyy = chain.rotary_inertia
    ixx = izz = m_seg * (l * l + w * w + h * h) / 12.0     # out of plane: never excited
    x_c = beam.impact_x
    hit = chain.hit_segment
    lay.kind, lay.n_segments, lay.segment_length = "beam", n, l
    lay.hinge_stiffness, lay.clamp_stiffness, lay.hit_segment = k_hinge, k_clamp, hit
    lay.top, lay.impact_x = h / 2.0, x_c
    support = beam.support
    if root == "end":
        return _serial_beam_xml(chain, lay, contact_geom, support, ixx, izz)
    r = hit if root == "hit" else (n - 1) // 2
    lay.root_segment = r

    # the small bodies at the supports (roller or clamp slide at x = 0, the shear slide at x = L) turn with segment 0
    # and n-1: their point rotary inertia is taken off those segments' (the same totals)
    tiny = _point_inertia(chain) if support in ("simply-supported", "clamped-clamped") or chain.shear else 0.0
    carries = {0: tiny}
    if chain.shear and support in ("simply-supported", "clamped-clamped"):
        carries[n - 1] = carries.get(n - 1, 0.0) + tiny

    def segment(i: int, left: bool) -> str:
        """Body i's inertial (and hit site); its frame is at its left end (root, right branch) or right end."""
        x0 = -l if left else 0.0          # the segment spans [x0, x0 + l] in its frame
        iyy_i = iyy - carries.get(i, 0.0)
        s = f'<inertial pos="{_vec(x0 + l / 2, 0, 0)}" mass="{_fmt(m_seg)}" diaginertia="{_vec(ixx, iyy_i, izz)}"/>'
        if i == hit:
            off = chain.hit_offset
            s += f'<site name="hit" pos="{_vec(x0 + off, 0, h / 2)}" size="0.001"/>'
            if contact_geom:
                s += (f'<geom name="target" type="box" pos="{_vec(x0 + off, 0, 0)}" '
                      f'size="{_vec(l / 2, w / 2, h / 2)}" contype="0" conaffinity="0" mass="0"/>')
        return s

    # the roller at x = 0 (simply supported, clamped-clamped): a body on a slide-x joint at node 0, pinned
    # to the world below; its mass never moves (pinned), its rotary inertia is negligible
    roller = ""
    if support in ("simply-supported", "clamped-clamped"):
        shear0 = (f'<joint name="s0" type="slide" axis="0 0 1" stiffness="{_fmt(chain.support_shear_stiffness)}"/>'
                  if chain.shear else "")
        roller = (f'<body name="roller0" pos="{_vec(-l if r > 0 else 0.0, 0, 0)}"><joint name="roller_x" type="slide" '
                  f'axis="1 0 0"/>{shear0}<inertial pos="0 0 0" mass="{_fmt(m_seg)}" diaginertia="{_vec(tiny, tiny, tiny)}"/>'
                  f'</body>')
    elif chain.shear:          # cantilever: the clamped end's shear slide, a small body the clamp pins
        roller = (f'<body name="clamp0" pos="{_vec(-l if r > 0 else 0.0, 0, 0)}"><joint name="s0" type="slide" '
                  f'axis="0 0 1" stiffness="{_fmt(chain.support_shear_stiffness)}"/><inertial pos="0 0 0" '
                  f'mass="{_fmt(m_seg / 2)}" diaginertia="{_vec(tiny, tiny, tiny)}"/></body>')

    def slide(j: int) -> str:
        """Node j's shear slide (a Timoshenko chain), before its hinge."""
        return (f'<joint name="s{j}" type="slide" axis="0 0 1" stiffness="{_fmt(chain.shear_stiffness)}"/>'
                if chain.shear else "")

    far_end = ""
    if chain.shear and support in ("simply-supported", "clamped-clamped"):   # x = L: the end's slide, pinned below
        far_end = (f'<body name="end" pos="{_vec(l, 0, 0)}"><joint name="s{n}" type="slide" axis="0 0 1" '
                   f'stiffness="{_fmt(chain.support_shear_stiffness)}"/><inertial pos="0 0 0" '
                   f'mass="{_fmt(m_seg / 2)}" diaginertia="{_vec(tiny, tiny, tiny)}"/></body>')
    # left branch: segments r-1 .. 0, each framed at its right end (node i+1), hinge h{i+1} there
    left = ""
    for i in range(r - 1, -1, -1):
        pos = _vec(0.0, 0.0, 0.0) if i == r - 1 else _vec(-l, 0.0, 0.0)
        left += (f'<body name="seg{i}" pos="{pos}">{slide(i + 1)}<joint name="h{i + 1}" type="hinge" axis="0 1 0" '
                 f'stiffness="{_fmt(k_hinge)}"/>' + segment(i, True))
        if i == 0:
            left += roller
    left += "</body>" * r
    # right branch: segments r+1 .. n-1, each framed at its left end (node i), hinge h{i} there
    right = ""
    for i in range(r + 1, n):
        right += (f'<body name="seg{i}" pos="{_vec(l, 0.0, 0.0)}">{slide(i)}<joint name="h{i}" type="hinge" axis="0 1 0" '
                  f'stiffness="{_fmt(k_hinge)}"/>' + segment(i, False) + (far_end if i == n - 1 else ""))
    right += "</body>" * (n - 1 - r)
    c = _vec(l / 2, 0, 0)
    chain_xml = (f'<body name="seg{r}" pos="{_vec(r * l, 0, 0)}">'
                 f'<joint name="root_x" type="slide" axis="1 0 0" pos="{c}"/>'
                 f'<joint name="root_z" type="slide" axis="0 0 1" pos="{c}"/>'
                 f'<joint name="root_r" type="hinge" axis="0 1 0" pos="{c}"/>'
                 + segment(r, False) + (roller if r == 0 else "") + (far_end if r == n - 1 else "") + left + right
                 + "</body>")
    eq, tendons = [], []
    if support in ("simply-supported", "clamped-clamped"):
        eq.append('<connect name="roller" body1="roller0" anchor="0 0 0"/>')
    if support == "cantilever":
        eq.append('<connect name="clamp" body1="clamp0" anchor="0 0 0"/>' if chain.shear else
                  f'<connect name="clamp" body1="seg0" anchor="{_vec(-l if r > 0 else 0.0, 0, 0)}"/>')
    if support in ("simply-supported", "clamped-clamped"):
        eq.append('<connect name="pin" body1="end" anchor="0 0 0"/>' if chain.shear else
                  f'<connect name="pin" body1="seg{n - 1}" anchor="{_vec(l, 0, 0)}"/>')
    if support in ("clamped-clamped", "cantilever"):      # segment 0's absolute rotation: root_r + left hinges
        joints = '<joint joint="root_r" coef="1"/>' + "".join(f'<joint joint="h{j}" coef="1"/>' for j in range(1, r + 1))
        tendons.append(f'<fixed name="clamp_start" stiffness="{_fmt(k_clamp)}" springlength="0">{joints}</fixed>')
    if support == "clamped-clamped":                      # segment n-1's: root_r + right hinges
        joints = '<joint joint="root_r" coef="1"/>' + "".join(f'<joint joint="h{j}" coef="1"/>' for j in range(r + 1, n))
        tendons.append(f'<fixed name="clamp_end" stiffness="{_fmt(k_clamp)}" springlength="0">{joints}</fixed>')
    extra = (f'<equality>{"".join(eq)}</equality>' if eq else "") + (f'<tendon>{"".join(tendons)}</tendon>' if tendons else "")
    return chain_xml, extra


#: the smallest rotary inertia [kg m^2] given to a body: 2x MuJoCo's mjMINVAL (1e-15), below which it refuses a
#: moving body ("mass and inertia of moving bodies must be larger than mjMINVAL")
MIN_INERTIA = 2e-15


def _point_inertia(chain: HenckyChain) -> float:
    """Rotary inertia [kg m^2] of the small bodies at a chain's supports (a roller, a clamp's or an end's shear
    slide): a point's, 1e-6 of a segment's, but at least MIN_INERTIA (a user's 158 x 2.5 x 1.2 mm PMMA Timoshenko beam
    in 182 segments: 1e-6 x 3.4e-13 kg m^2 was below what MuJoCo accepts, and the job crashed). The segment each turns
    with gives up as much, so the chain's inertia is unchanged; a segment too light for that is refused."""
    tiny = max(1e-6 * chain.rotary_inertia, MIN_INERTIA)
    if chain.rotary_inertia - 2.0 * tiny < MIN_INERTIA or chain.segment_mass / 2.0 < MIN_INERTIA:
        raise EngineError(f"mujoco: the chain's segments are too light for MuJoCo (mass {chain.segment_mass:.2g} kg, "
                          f"rotary inertia {chain.rotary_inertia:.2g} kg m^2; it refuses moving bodies below 1e-15): "
                          f"use fewer segments (--segments) or a larger beam.")
    return tiny


def _serial_beam_xml(chain: HenckyChain, lay: _Layout, contact_geom: bool, support: str, ixx: float,
                     izz: float) -> tuple[str, str]:
    """root = "end": segment 0 on the supports' joints, the others in series (see the module docstring)."""
    n, l = chain.n, chain.segment_length
    w, h = chain.width, chain.height
    k_hinge, k_clamp = chain.hinge_stiffness, chain.clamp_stiffness
    m_seg, iyy, hit = chain.segment_mass, chain.rotary_inertia, chain.hit_segment
    has_end = chain.shear and support != "cantilever"
    tiny = _point_inertia(chain) if has_end else 0.0
    parts, closes = [], []
    for i in range(n):
        pos = _vec(0.0, 0.0, 0.0) if i == 0 else _vec(l, 0.0, 0.0)
        s = [f'<body name="seg{i}" pos="{pos}">']
        if i == 0:
            if support in ("simply-supported", "clamped-clamped"):
                s.append('<joint name="root_x" type="slide" axis="1 0 0"/>')
            if chain.shear:      # the supported end's shear: a transverse slide of 2 kappa G A / l
                s.append(f'<joint name="s0" type="slide" axis="0 0 1" stiffness="{_fmt(chain.support_shear_stiffness)}"/>')
            k_root = 0.0 if support == "simply-supported" else k_clamp
            s.append(f'<joint name="h0" type="hinge" axis="0 1 0" stiffness="{_fmt(k_root)}"/>')
        else:
            if chain.shear:      # node i's shear: a slide along the previous segment's transverse axis
                s.append(f'<joint name="s{i}" type="slide" axis="0 0 1" stiffness="{_fmt(chain.shear_stiffness)}"/>')
            s.append(f'<joint name="h{i}" type="hinge" axis="0 1 0" stiffness="{_fmt(k_hinge)}"/>')
        # the end body's rotary inertia (it turns with segment n-1) is taken off that segment's: the same total
        iyy_i = iyy - tiny if i == n - 1 else iyy
        s.append(f'<inertial pos="{_vec(l / 2, 0, 0)}" mass="{_fmt(m_seg)}" diaginertia="{_vec(ixx, iyy_i, izz)}"/>')
        if i == hit:
            off = chain.hit_offset
            s.append(f'<site name="hit" pos="{_vec(off, 0, h / 2)}" size="0.001"/>')
            if contact_geom:
                s.append(f'<geom name="target" type="box" pos="{_vec(off, 0, 0)}" '
                         f'size="{_vec(l / 2, w / 2, h / 2)}" contype="0" conaffinity="0" mass="0"/>')
        if has_end and i == n - 1:
            # the supported end at x = L: a small body on a transverse slide of 2 kappa G A / l, pinned below;
            # half a segment's mass (pinned, it hardly moves), the rotary inertia of a point (`_point_inertia`)
            s.append(f'<body name="end" pos="{_vec(l, 0, 0)}"><joint name="s{n}" type="slide" axis="0 0 1" '
                     f'stiffness="{_fmt(chain.support_shear_stiffness)}"/><inertial pos="0 0 0" '
                     f'mass="{_fmt(m_seg / 2)}" diaginertia="{_vec(tiny, tiny, tiny)}"/></body>')
        parts.append("".join(s))
        closes.append("</body>")
    chain_xml = "".join(parts) + "".join(closes)
    extra = ""
    pinned, anchor = (("end", _vec(0, 0, 0)) if chain.shear else (f"seg{n - 1}", _vec(l, 0, 0)))
    if support in ("simply-supported", "clamped-clamped"):
        extra += f'<equality><connect name="pin" body1="{pinned}" anchor="{anchor}"/></equality>'
    if support == "clamped-clamped":
        joints = "".join(f'<joint joint="h{i}" coef="1"/>' for i in range(n))
        extra += f'<tendon><fixed name="clamp_end" stiffness="{_fmt(k_clamp)}" springlength="0">{joints}</fixed></tendon>'
    return chain_xml, extra


def _second_ball_xml(target, lay: _Layout) -> str:
    """A second free sphere (target kind "ball") below the first, on its own slide joint along z: centre
    at z = -R2, top (the contact point, site "hit") at z = 0. Its velocity is set after building."""
    r2, m2 = target.radius, target.mass
    i2 = 0.4 * m2 * r2 * r2
    lay.kind, lay.top = "ball", 0.0
    return (f'<body name="ball2" pos="{_vec(0, 0, -r2)}"><joint name="ball2_z" type="slide" axis="0 0 1"/>'
            f'<inertial pos="0 0 0" mass="{_fmt(m2)}" diaginertia="{_vec(i2, i2, i2)}"/>'
            f'<geom name="target" type="sphere" size="{_fmt(r2)}" contype="0" conaffinity="0" mass="0"/>'
            f'<site name="hit" pos="{_vec(0, 0, r2)}" size="0.001"/></body>')


def _set_second_ball_velocity(model, data, scene) -> None:
    """The second ball moves toward the first (+z) at its scene velocity."""
    if scene.target.kind == "ball":
        data.qvel[model.jnt_dofadr[model.joint("ball2_z").id]] = scene.target.velocity


#: height [m] of a modal oscillator's body at rest (out of the ball's way; its displacement is xpos - this)
MODE_BODY_Z = -1.0


def _modal_xml(target, lay: _Layout) -> str:
    parts = []
    for i, (om, mm, ph) in enumerate(zip(target.omega, target.modal_mass, target.phi)):
        if abs(ph) < 1e-12:
            continue       # a mode with phi = 0 at the contact point is never excited
        m_i = mm / ph**2
        parts.append(f'<body name="mode{i}" pos="0 0 {_fmt(MODE_BODY_Z)}"><joint name="q{i}" type="slide" axis="0 0 1" '
                     f'stiffness="{_fmt(m_i * om * om)}"/><inertial pos="0 0 0" mass="{_fmt(m_i)}" '
                     f'diaginertia="1e-6 1e-6 1e-6"/></body>')
        lay.n_modes += 1
    lay.kind = "modal"
    return "".join(parts)


def build_xml(scene, settings: EngineSettings, chain: HenckyChain | None = None,
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
        if chain is None:
            chain = _chain_for(scene, settings)
        world, extra = _beam_xml(target, chain, lay, native, chain_root_of(settings.option("chain_root", "auto"), chain))
    elif target.kind == "ball":
        world = _second_ball_xml(target, lay)
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
            # the oscillators' bodies (placed at z = MODE_BODY_Z): their xpos comes from the same kinematics as the
            # ball's site, so delta is consistent after mj_step too (qpos is then the NEXT state's: reading it made
            # the sampled delta lag by one step, an O(dt) error, -0.20 % f_m at dt = 2e-7 on a five-mode scene)
            self.mode_bodies = np.array([model.jnt_bodyid[j] for j, nm in enumerate(names) if nm.startswith("q")])
        self.ball_geom = model.geom("ball").id
        self.force6 = np.zeros(6)

    def delta_points(self, d) -> tuple[float, float]:
        """(delta [m], downward displacement of the target's contact point [m]) for d's kinematics."""
        z_tip = d.site_xpos[self.tip, 2]
        if self.lay.kind == "modal":
            z_hit = float(np.sum(d.xpos[self.mode_bodies, 2] - MODE_BODY_Z))   # each oscillator's upward displacement
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



class _Run:
    """A live MuJoCo job: model, data, probe and what the samples need."""

    def __init__(self, **kw: Any) -> None:
        self.__dict__.update(kw)


SUPPORTED_KINDS = ("rigid-plate", "beam", "modal", "ball")


def _check_kind(scene) -> None:
    """Targets this adapter models; others (Kirchhoff plate) become a `skipped` row."""
    kind = scene.target.kind
    if kind not in SUPPORTED_KINDS:
        raise EngineError(f"mujoco: target kind {kind!r} is not supported; supported: {', '.join(SUPPORTED_KINDS)}.")


def check_scene(scene, contact: str) -> None:
    """EngineError when this adapter cannot build `scene` with `contact` (a `skipped` row; `impactval tune` refuses
    up front)."""
    _check_kind(scene)
    if scene.target.kind == "modal" and contact != "hertz":
        raise EngineError(f"mujoco: a modal target has no surface to collide with; use contact 'hertz' "
                          f"(got {contact!r}).")


class MujocoAdapter(SteppingAdapter):
    """MuJoCo (`pip install 'impactval[mujoco]'`); see the module docstring for the model."""

    name = "mujoco"
    module = "mujoco"
    contacts = ("hertz", "native", "native-hertz")
    integrators = INTEGRATORS
    integrator_methods = {"Euler": "symplectic-euler", "implicitfast": "symplectic-euler-implicit-damping",
                          "RK4": "rk4"}
    min_segments = 2
    Options = MujocoOptions
    sample_lag = 1          # after mj_step, positions-derived data describe the step's start (see step)


    # ------------------------------------------------------------------ planning
    def chain(self, scene, settings: EngineSettings) -> HenckyChain | None:
        """The Hencky chain this job builds (None for a plate or modal target)."""
        if scene.target.kind != "beam":
            return None
        return _chain_for(scene, settings)

    def contact_law(self, scene, settings: EngineSettings):

        if settings.contact == "native" and (settings.option("solref") or settings.option("solimp")):
            return None          # a user-tuned pair: its law is known only after building (see build)
        return super().contact_law(scene, settings)

    def plan(self, scene, settings: EngineSettings) -> Plan:
        from impactval.engines.chain import chain_notes, model_error, model_error_diagnostics
        from impactval.reference.hertz import ContactLaw

        check_scene(scene, settings.contact)     # refused here, as every adapter's unsupported scene (tune asks first)
        chain = self.chain(scene, settings)
        law = self.contact_law(scene, settings) or ContactLaw.hertz(scene.alpha)
        if settings.contact == "native-hertz":
            law = ContactLaw.hertz(scene.alpha)
        om, what = omega_max(scene, law, chain)
        integ = settings.integrator or INTEGRATORS[0]
        diag: dict = {"integrator": integ}     # also on a row refused before stepping (its series in a sweep)
        notes: list[str] = []
        err = math.nan
        if chain is not None:
            hertz = model_error(scene, chain)      # the sizing's (and its notes') measure
            # the row's: under its own contact law (a native row's linear spring k: the chain's linear theory vs
            # the continuum's, what the runner compares it with; a user solref's k is known after build, see there)
            me, me_diag = model_error_diagnostics(scene, chain, law, hertz)
            err = me.largest
            diag.update(segments=chain.n, **me_diag, rotary_inertia=chain.rotary,
                        chain_root=chain_root_of(settings.option("chain_root", "auto"), chain))
            notes = chain_notes(scene, chain, hertz, float(settings.option("chain_tol", DEFAULT_CHAIN_TOL)))
        elif scene.target.kind in ("rigid-plate", "ball", "modal"):
            err = 0.0           # a modal target is its modes exactly: one oscillator per mode
        return Plan(STABILITY[integ] / om, f"{integ}, {what}", err, diag, tuple(notes))

    # ------------------------------------------------------------------ model
    def build(self, scene, settings: EngineSettings) -> _Run:
        """The scene as a MuJoCo model at first touch, ready to step."""
        import mujoco

        check_scene(scene, settings.contact)
        info: dict = {}
        chain = self.chain(scene, settings)
        xml, lay = build_xml(scene, settings, chain)
        model = mujoco.MjModel.from_xml_string(xml)
        if lay.kind == "beam":
            # MuJoCo's default equality solref (0.02 s) makes the supports springs of ~20 rad/s
            # (first frequency -96 %); 2*dt is the stiffest time constant refsafe allows
            tc = settings.option("equality_timeconst") or 2.0 * settings.dt
            model.eq_solref[:, 0] = tc
            model.eq_solref[:, 1] = 1.0
            info["equality_solref"] = (float(tc), 1.0)
        plate = plate_times(scene)           # a second ball: the two-ball contact's (reduced mass)
        alpha = scene.alpha
        potential = (lambda dl: 0.4 * alpha * dl**2.5)
        if settings.contact != "hertz":
            a_inv_mass = _contact_diag_a(mujoco, model, scene)
            info["contact_inverse_mass"] = a_inv_mass
            if settings.contact == "native":
                imp = float(settings.option("native_impedance", NATIVE_IMPEDANCE))
                solref = settings.option("solref") or (-plate.k0 * a_inv_mass, 0.0)
                solimp = settings.option("solimp") or (imp, imp, 0.001, 0.5, 2.0)
                model.pair_solref[0] = solref
                model.pair_solimp[0] = solimp
                info.update(native_solref=tuple(solref), native_solimp=tuple(solimp))
                k_lin = _linear_stiffness(solref, solimp, a_inv_mass)
                if k_lin is not None:
                    info["contact_stiffness"] = k_lin
                    potential = (lambda dl: 0.5 * k_lin * dl * dl)
                    if chain is not None:
                        # the spring as built (a user solref's is known only now): the chain's model error under
                        # it replaces the plan's in the row's diagnostics (cached: the plan's when the plan knew
                        # the spring; otherwise `result.model_error` keeps the plan's Hertz one)
                        from impactval.engines.chain import model_error_diagnostics
                        from impactval.reference.hertz import ContactLaw

                        info.update(model_error_diagnostics(scene, chain, ContactLaw.linear(k_lin))[1])
                else:
                    potential = _tabulated_potential(mujoco, model, scene, plate)
            else:
                k_scale, solimp, rms = fit_native_hertz(contact_scene(scene))   # a second ball: its equivalent
                solref = (-k_scale * a_inv_mass, 0.0)
                model.pair_solref[0] = solref
                model.pair_solimp[0] = solimp
                info.update(native_hertz_solref=tuple(solref), native_hertz_solimp=tuple(solimp),
                            native_hertz_fit_rms=rms, contact_law="fitted solimp shape toward alpha*delta^1.5")
                potential = _tabulated_potential(mujoco, model, scene, plate)
        data = mujoco.MjData(model)
        probe = _Probe(mujoco, model, lay, scene, settings.contact)
        data.qvel[probe.ball_dof] = -scene.ball.velocity
        _set_second_ball_velocity(model, data, scene)
        integ = settings.integrator or INTEGRATORS[0]
        run = _Run(mj=mujoco, model=model, data=data, lay=lay, probe=probe, contact_mode=settings.contact,
                   alpha=alpha, potential=potential, sync=integ in ("Euler", "implicitfast"),
                   v_prev=np.zeros(model.nv), v_mean=np.zeros(model.nv), mv=np.zeros(model.nv), n_steps=0,
                   dt=settings.dt,
                   x_ball0=float(data.qpos[probe.ball_qpos]), diagnostics=info, integrator=integ, chain=chain,
                   warnings=[], old_cb=mujoco.get_mjcb_passive(), old_warn=mujoco.get_mju_user_warning())
        # MuJoCo would print warnings and append them to ./MUJOCO_LOG.TXT; they become the status instead
        mujoco.set_mju_user_warning(run.warnings.append)
        if settings.contact == "hertz":
            mujoco.set_mjcb_passive(probe.hertz_callback())
        mujoco.mj_forward(model, data)
        run.z_tip0 = float(data.site_xpos[probe.tip, 2])
        delta, xs = probe.delta_points(data)
        f0 = alpha * delta**1.5 if (settings.contact == "hertz" and delta > 0) else 0.0
        e0 = float(data.energy[0]) + float(data.energy[1]) + (potential(delta) if delta > 0 else 0.0)
        run.sample = (delta, f0, 0.0, xs, scene.ball.velocity, e0)
        run.v_prev[:] = data.qvel           # the velocity the first step starts from
        if chain is not None:
            info["segments"] = chain.n
        return run

    def close(self, run: _Run) -> None:
        run.mj.set_mjcb_passive(run.old_cb)
        run.mj.set_mju_user_warning(run.old_warn)
        if run.lay.kind == "beam":
            run.diagnostics["equality_violation_max"] = _equality_violation(run.data)
        if run.warnings:
            run.diagnostics["mujoco_warnings"] = run.warnings[:5]

    # ------------------------------------------------------------------ stepping
    def stepper(self, run: _Run):
        """`step` as mujoco's own C call (no Python frame in the timed region)."""
        import functools

        return functools.partial(run.mj.mj_step, run.model, run.data)

    def step(self, run: _Run) -> None:
        """One mj_step, nothing else (timed). mj_step computes the forward dynamics of the state at its start,
        then integrates: after it, positions-derived data (site_xpos, energy, contact forces, qM) describe the
        state at the start of the step, so the adapter samples that state (sample_lag = 1) in `observe` and
        needs no extra mj_forward."""
        run.mj.mj_step(run.model, run.data)

    def observe(self, run: _Run) -> None:
        """The sample of the last step (not timed): warnings, delta, force, energy; then keep the velocity
        the next step starts from (`v_prev`)."""
        mj, m, d = run.mj, run.model, run.data
        run.n_steps += 1
        if d.warning[mj.mjtWarning.mjWARN_BADQACC].number > 0:
            raise EngineDiverged(f"MuJoCo reported NaN/huge accelerations after {run.n_steps} steps "
                                 f"(t = {run.n_steps * run.dt:.3g} s, dt = {run.dt:g} s): "
                                 f"{run.warnings[0].strip() if run.warnings else ''}")
        if not run.sync:
            # RK4 evaluates intermediate stages inside mj_step: the data describe no single state, so
            # recompute the new state and sample it (sample_lag = 0 for RK4)
            mj.mj_forward(m, d)
            run.v_prev[:] = d.qvel
        delta, xs = run.probe.delta_points(d)
        pe = float(d.energy[0]) + (run.potential(delta) if delta > 0 else 0.0)
        if run.sync:
            # Euler and implicitfast update the velocity first and move with it: qvel is a half-step
            # velocity and 1/2 v'Mv with it swings by O(omega dt). The sampled state (the step's start) gets
            # 1/2 v_before' M v_after with its mass matrix: with the potential at that state, the quantity
            # semi-implicit Euler conserves exactly for a linear system (the mean velocity, used before,
            # adds dt^2/8 f'M^-1 f: a bounded ripple of (omega dt)^2/4 of the energy that the 5 % growth
            # criterion took for instability at 0.42 of dt_limit on the rigid plate)
            mj.mj_mulM(m, d, run.mv, d.qvel)
            ke = 0.5 * float(run.v_prev @ run.mv)
        else:
            ke = float(d.energy[1])             # RK4: the new state's own kinetic energy
        if run.contact_mode == "hertz":
            f = run.alpha * delta**1.5 if delta > 0 else 0.0
        else:
            f = run.probe.native_force(d)
        z_tip = float(d.site_xpos[run.probe.tip, 2])
        run.sample = (delta, f, run.z_tip0 - z_tip, xs, -float(run.v_prev[run.probe.ball_dof]), pe + ke)
        run.v_prev[:] = d.qvel

    def contact(self, run: _Run) -> tuple[float, float]:
        return run.sample[0], run.sample[1]

    def energy(self, run: _Run) -> float:
        return run.sample[5]

    def kinematics(self, run: _Run) -> tuple[float, float, float]:
        return run.sample[2], run.sample[3], run.sample[4]

    def frequencies(self, run: _Run) -> np.ndarray:
        if run.lay.kind != "beam":
            return np.zeros(0)
        if run.model.nv > FD_FREQUENCIES_MAX_DOF and run.chain is not None:
            run.diagnostics["structure_frequencies_from"] = (
                f"the chain model (engines.chain): {run.model.nv} DOF is above {FD_FREQUENCIES_MAX_DOF}, where "
                f"MuJoCo's finite-differenced transition matrix costs seconds to minutes (~DOF^4)")
            return run.chain.frequencies()[:N_FREQUENCIES]
        return chain_frequencies(run.mj, run.model)[:N_FREQUENCIES]

    def describe(self, run: _Run) -> str:
        name = {"plate": "rigid-plate", "modal": f"modal-{run.lay.n_modes}", "ball": "two-spheres"}.get(
            run.lay.kind, f"hencky-chain-{run.lay.n_segments}")
        return f"mujoco-{name}-{run.contact_mode}"

    def simulate(self, scene, settings: EngineSettings):
        self.sample_lag = 0 if (settings.integrator or INTEGRATORS[0]) == "RK4" else 1
        sim = super().simulate(scene, settings)
        k_lin = sim.diagnostics.get("contact_stiffness")
        if settings.contact == "native" and k_lin:
            from impactval.reference.hertz import ContactLaw

            sim.contact_law = ContactLaw.linear(k_lin)
        from impactval.engines.base import add_validity, modes_not_applied

        n_modes, note = modes_not_applied(scene, settings, "mujoco")
        add_validity(sim.diagnostics, note)
        sim.settings = {"integrator": settings.integrator or INTEGRATORS[0],
                        "segments": sim.diagnostics.get("segments"), "modes": n_modes}
        if scene.target.kind == "beam":
            from impactval.engines.chain import continuum_frequencies

            sim.diagnostics["continuum_frequencies"] = [float(x) for x in
                                                        continuum_frequencies(scene.target, N_FREQUENCIES)]
        return sim


def _linear_stiffness(solref, solimp, a_inv_mass: float) -> float | None:
    """Linear stiffness [N/m] of a direct, undamped solref with a flat, small solimp (else None)."""
    if solref[0] < 0 and solref[1] == 0 and solimp[0] == solimp[1] and solimp[0] <= 1e-3:
        return -solref[0] / a_inv_mass
    return None


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


#: convergence tolerance of every solimp fit (scipy least_squares xtol = ftol) and its evaluations per start
SOLIMP_FIT_TOL = 1e-8
SOLIMP_FIT_EVALS = 300
#: smallest solimp d0 a fit may return (MuJoCo's impedance floor)
SOLIMP_MIN_D0 = 1e-4


def fit_solimp(residual, stiffness_ref: float, width_ref: float, dmax: float, starts, lower, upper,
               x_scale=None) -> tuple[float, tuple[float, ...], float]:
    """The one solimp fit (native-hertz here, `impactval.tune`'s pre-fit): a direct-solref stiffness and a
    Hertz-shaped solimp minimising `residual(k, solimp)` (a vector) by bounded least squares from each start.

    Parameters p = (ln(k / stiffness_ref), d0 / dmax, ln(width / width_ref), midpoint, power) within
    [lower, upper]: k = stiffness_ref e^p0 (in the caller's unit), solimp = (max(p1 dmax, SOLIMP_MIN_D0), dmax,
    width_ref e^p2 [m], midpoint, power). A start whose residual raises ValueError or ImpactvalError is
    skipped. Returns (k, solimp, RMS of the residual vector at the best start's optimum); EngineError
    when every start failed."""
    from scipy import optimize

    def unpack(p):
        solimp = (max(p[1] * dmax, SOLIMP_MIN_D0), dmax, math.exp(p[2]) * width_ref, p[3], p[4])
        return math.exp(p[0]) * stiffness_ref, tuple(float(x) for x in solimp)

    best = None
    for start in starts:
        try:
            sol = optimize.least_squares(lambda p: residual(*unpack(p)), np.array(start, float),
                                         bounds=(np.asarray(lower, float), np.asarray(upper, float)),
                                         x_scale=x_scale, xtol=SOLIMP_FIT_TOL, ftol=SOLIMP_FIT_TOL,
                                         max_nfev=SOLIMP_FIT_EVALS)
        except (ValueError, ImpactvalError):
            continue
        if best is None or sol.cost < best.cost:
            best = sol
    if best is None:
        raise EngineError(f"mujoco: the solimp fit failed from all {len(starts)} starts (impedance <= {dmax:g}); "
                          "use --contact native (a linear spring) for this scene.")
    k, solimp = unpack(best.x)
    return k, solimp, float(np.sqrt(np.mean(best.fun ** 2)))


@lru_cache(maxsize=16)
def fit_native_hertz(scene) -> tuple[float, tuple[float, ...], float]:
    """Fit the contact pair's direct solref stiffness and solimp shape so MuJoCo's static force law
    matches alpha*delta^1.5 on 0..1.2 delta_m (rigid-plate delta_m), on a plate with the scene's
    ball (the law scales with the effective mass, so it carries over to any target).

    Returns (stiffness scale k [N/m]: solref = (-k*A, 0) with A = efc_diagA of the contact row,
    solimp, RMS misfit of the force law over f_m). The impedance is kept <= NATIVE_HERTZ_DMAX (see there).
    """
    import mujoco

    from impactval.reference.hertz import plate_impact
    from impactval.scenarios.scene import RigidPlate, Scene

    plate_scene = Scene(scene.name + "-fit", scene.ball, RigidPlate(scene.target.material))
    xml, _ = build_xml(plate_scene, EngineSettings(dt=1e-6, contact="native"))
    model = mujoco.MjModel.from_xml_string(xml)
    plate = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
    a_inv_mass = _contact_diag_a(mujoco, model, plate_scene)
    d = mujoco.MjData(model)
    jq = model.jnt_qposadr[model.joint("ball_z").id]
    z0 = model.qpos0[jq]
    ball_geom = model.geom("ball").id
    deltas = np.linspace(0.02, 1.2, 30) * plate.delta_m
    target = scene.alpha * deltas**1.5

    def resid(k, solimp):
        model.pair_solref[0] = (-k * a_inv_mass, 0.0)
        model.pair_solimp[0] = solimp
        f = _static_contact_force(mujoco, model, d, jq, z0, deltas, ball_geom)
        return (f - target) / plate.f_m

    k, solimp, rms = fit_solimp(resid, plate.k0, 1.2 * plate.delta_m, NATIVE_HERTZ_DMAX,
                                starts=([0.0, 0.5, 0.0, 0.5, 1.5], [0.5, 0.2, 0.3, 0.3, 1.0], [0.2, 0.7, -0.5, 0.1, 3.0]),
                                lower=[-3.0, 0.1, -3.0, 0.01, 1.0], upper=[3.0, 1.0, 3.0, 0.99, 6.0])
    return k, solimp, rms


def _tabulated_potential(mujoco, model, scene, plate):
    """Contact potential [J] of the model's static force law (cumulative trapezoid on a fine table)."""
    d = mujoco.MjData(model)
    jq = model.jnt_qposadr[model.joint("ball_z").id]
    deltas = np.linspace(0.0, 3.0 * plate.delta_m, 601)
    f = _static_contact_force(mujoco, model, d, jq, model.qpos0[jq], deltas, model.geom("ball").id)
    pot = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(deltas))])
    return lambda dl: float(np.interp(dl, deltas, pot))
