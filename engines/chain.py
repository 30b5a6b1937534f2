"""The Hencky chain beam shared by the chain engines (MuJoCo, PyBullet), sized from the scene.

A beam of length L becomes N rigid segments of length l = L/N joined by rotational springs: an
internal hinge has the stiffness EI/l, a clamped end 2EI/l (the end curvature lumped over half a
segment). Each segment has the mass rho*A*l and the rotary inertia about its centre
m*l^2/12 (`rotary="none"`: a rigid bar, the Euler-Bernoulli chain) or m*(l^2 + h^2)/12
(`rotary="section"`: plus the section's own rotary inertia, a Rayleigh beam). The ball hits the
segment containing x = impact_at*L at that point. `shear=True` (Timoshenko scenes, MuJoCo): a transverse
slide of kappa G A / l at every node (2 kappa G A / l at a supported end) and the section's rotary inertia,
a consistent (1/N^2) discretisation of Timoshenko theory, sized and error-estimated against it.

`HenckyChain.linear()` is the chain's small-deflection model in the node deflections w_0..w_N
(supports remove w_0 and, pinned or clamped at x = L, w_N): mass and stiffness matrices, and the
row that maps them to the contact point. From it: the chain's natural frequencies and mode data at
the contact point (`modes()`), the highest frequency of chain + ball + contact spring (the explicit
stability limit 2/omega_max), and `model_error`, the chain's own discretisation error on t_m, f_m,
delta_m: the reference solver run on the chain's exact modes against the continuum's (so the
estimate is the error of the chain as a model, with no time-step error of any engine in it), and
`linear_model_error`, the same under a linear contact spring k (a native row's law): the exact linear
theory on the chain's modes against the linear theory on the continuum; `model_error_diagnostics` gives
an adapter the row's one by contact law (the Hertz one kept as `model_error_hertz_*`).

`segments_for(scene, tol)` sizes N: the modes that matter (`reference.modechoice.required_modes`)
must have chain frequencies within `tol` of the continuum's (a Hencky chain's frequency error is
~c (j/N)^2 for mode j, so N scales with the highest mode that matters), then N grows (as the
1/N^2 law predicts) until `model_error` is within `tol` too.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

#: fewest segments of a chain
MIN_SEGMENTS = 8
#: the metric error the chain may have from its discretisation, as a fraction of the bar (1.5 %)
DEFAULT_CHAIN_TOL = 5e-3
#: reference tolerance used to measure the chain's model error (well below DEFAULT_CHAIN_TOL)
MODEL_ERROR_REF_TOL = 1e-5


@dataclass(frozen=True)
class ChainLinear:
    """Small-deflection model: `mass`, `stiffness` [kg, N/m] over the free node deflections,
    `contact_row` (w_contact = contact_row @ w)."""

    mass: np.ndarray
    stiffness: np.ndarray
    contact_row: np.ndarray


@dataclass(frozen=True)
class HenckyChain:
    """N segments of a beam (see the module docstring). Lengths in m, masses in kg, inertias in
    kg m^2, stiffnesses in N m/rad."""

    n: int
    length: float
    segment_length: float
    segment_mass: float
    rotary_inertia: float          # about the segment's centre, bending axis
    hinge_stiffness: float         # EI/l
    clamp_stiffness: float         # 2EI/l
    support: str
    hit_segment: int
    hit_offset: float              # contact point's distance from the hit segment's left end [m]
    height: float
    width: float
    rotary: str
    shear_stiffness: float = 0.0   # kappa G A / l [N/m] of a node's transverse slide (0: no slides, Euler-Bernoulli)
    support_shear_stiffness: float = 0.0   # 2 kappa G A / l [N/m]: a supported end's slide (half a segment)

    @property
    def shear(self) -> bool:
        """True for the shear-deformable (Timoshenko) chain: a transverse slide at every node."""
        return self.shear_stiffness > 0.0

    def linear(self) -> ChainLinear:
        if self.shear:
            return self._shear_linear()
        n, l = self.n, self.segment_length
        nodes = n + 1
        m = np.zeros((nodes, nodes))
        k = np.zeros((nodes, nodes))
        bar_m = self.segment_mass / 4.0 * np.ones((2, 2)) + self.rotary_inertia / l**2 * np.array([[1, -1], [-1, 1]])
        for i in range(n):
            m[i:i + 2, i:i + 2] += bar_m
        # rotation of bar i: (w_{i+1} - w_i)/l; hinge at node i turns by theta_i - theta_{i-1}
        theta = np.zeros((n, nodes))
        for i in range(n):
            theta[i, i], theta[i, i + 1] = -1.0 / l, 1.0 / l
        for i in range(1, n):
            d = theta[i] - theta[i - 1]
            k += self.hinge_stiffness * np.outer(d, d)
        if self.support in ("clamped-clamped", "cantilever"):
            k += self.clamp_stiffness * np.outer(theta[0], theta[0])
        if self.support == "clamped-clamped":
            k += self.clamp_stiffness * np.outer(theta[-1], theta[-1])
        row = np.zeros(nodes)
        xi = self.hit_offset / l
        row[self.hit_segment], row[self.hit_segment + 1] = 1.0 - xi, xi
        keep = np.arange(1, nodes if self.support == "cantilever" else nodes - 1)
        return ChainLinear(m[np.ix_(keep, keep)], k[np.ix_(keep, keep)], row[keep])

    def _shear_linear(self) -> ChainLinear:
        """The Timoshenko chain in the segments' centre deflections u_i and rotations psi_i (order u_0, psi_0,
        u_1, ...): node j's slide opens by s_j = (u_j - l/2 psi_j) - (u_{j-1} + l/2 psi_{j-1}) [m] against
        kappa G A / l, its hinge turns by psi_j - psi_{j-1} against EI/l; a supported end's point (x = 0, and
        x = L unless a cantilever) is held at w = 0 through a slide of 2 kappa G A / l, a clamped end's
        segment rotation through 2EI/l; every mass term is diagonal (segment mass, rotary inertia)."""
        n, l = self.n, self.segment_length
        dof = 2 * n
        m = np.diag(np.tile([self.segment_mass, self.rotary_inertia], n))
        k = np.zeros((dof, dof))

        def left(i):                 # w at segment i's left end
            r = np.zeros(dof)
            r[2 * i], r[2 * i + 1] = 1.0, -l / 2
            return r

        def right(i):
            r = np.zeros(dof)
            r[2 * i], r[2 * i + 1] = 1.0, l / 2
            return r

        def psi(i):
            r = np.zeros(dof)
            r[2 * i + 1] = 1.0
            return r

        for j in range(1, n):
            s, d = left(j) - right(j - 1), psi(j) - psi(j - 1)
            k += self.shear_stiffness * np.outer(s, s) + self.hinge_stiffness * np.outer(d, d)
        k += self.support_shear_stiffness * np.outer(left(0), left(0))
        if self.support != "cantilever":
            k += self.support_shear_stiffness * np.outer(right(n - 1), right(n - 1))
        if self.support in ("clamped-clamped", "cantilever"):
            k += self.clamp_stiffness * np.outer(psi(0), psi(0))
        if self.support == "clamped-clamped":
            k += self.clamp_stiffness * np.outer(psi(n - 1), psi(n - 1))
        row = np.zeros(dof)
        row[2 * self.hit_segment], row[2 * self.hit_segment + 1] = 1.0, self.hit_offset - l / 2
        return ChainLinear(m, k, row)

    def modes(self):
        """The chain's modes seen from the contact point: `reference.beams.Modes` (omega [rad/s],
        modal mass 1 kg for mass-normalised vectors, phi = the vectors at the contact point)."""
        from scipy import linalg

        from impactval.reference.beams import Modes

        lin = self.linear()
        w2, vecs = linalg.eigh(lin.stiffness, lin.mass)
        omega = np.sqrt(np.clip(w2, 0.0, None))
        return Modes(omega, np.ones_like(omega), lin.contact_row @ vecs, 0.0)

    def frequencies(self) -> np.ndarray:
        """Natural frequencies [rad/s], ascending (every mode of the chain)."""
        from scipy import linalg

        lin = self.linear()
        return np.sqrt(np.clip(linalg.eigh(lin.stiffness, lin.mass, eigvals_only=True), 0.0, None))

    def omega_max_with_ball(self, ball_mass: float, contact_stiffness: float) -> float:
        """Highest frequency [rad/s] of chain + ball + a linear contact spring [N/m] between them."""
        from scipy import linalg

        lin = self.linear()
        n = lin.mass.shape[0]
        m = np.zeros((n + 1, n + 1))
        k = np.zeros((n + 1, n + 1))
        m[:n, :n], k[:n, :n] = lin.mass, lin.stiffness
        m[n, n] = ball_mass
        row = np.append(lin.contact_row, -1.0)
        k += contact_stiffness * np.outer(row, row)
        return float(math.sqrt(max(float(linalg.eigh(k, m, eigvals_only=True)[-1]), 0.0)))


def hencky_chain(beam, n: int, rotary: str = "none", shear: bool = False) -> HenckyChain:
    """The N-segment Hencky chain of `beam` (a scenarios.scene.Beam); see the module docstring. `shear=True`:
    the Timoshenko chain (a transverse slide of kappa G A / l at every node, 2 kappa G A / l at a supported
    end, the section's rotary inertia: `rotary` becomes "section")."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 2:
        raise ValueError(f"a Hencky chain needs at least 2 segments, got {n!r}")
    if rotary not in ("none", "section"):
        raise ValueError(f"rotary must be 'none' or 'section', got {rotary!r}")
    mat = beam.material
    l = beam.length / n
    ei = mat.young * beam.second_moment
    m_seg = mat.density * beam.area * l
    if shear:
        rotary = "section"
    j = m_seg * (l * l + (beam.height**2 if rotary == "section" else 0.0)) / 12.0
    hit = min(int(beam.impact_x / l), n - 1)
    k_shear = beam.shear_coefficient * beam.shear_modulus * beam.area / l if shear else 0.0
    return HenckyChain(n, beam.length, l, m_seg, j, ei / l, 2.0 * ei / l, beam.support, hit,
                       beam.impact_x - hit * l, beam.height, beam.width, rotary, k_shear, 2.0 * k_shear)


@dataclass(frozen=True)
class ChainModelError:
    """Relative errors of the chain model (chain's exact modes vs continuum), signed (chain-cont)/cont."""

    t_m: float
    f_m: float
    delta_m: float

    @property
    def largest(self) -> float:
        return max(abs(self.t_m), abs(self.f_m), abs(self.delta_m))


@lru_cache(maxsize=8)
def continuum_metrics(scene) -> tuple[float, float, float]:
    """(t_m [s], f_m [N], delta_m [m]) of the continuum reference at MODEL_ERROR_REF_TOL, cached per process: what
    the engines' model errors and the automatic step (`base.contact_time`) compare with. A scene with an explicit
    `modes = n` is solved without it (`reference.explicit_modes.continuum_scene`): its reference is the n-mode model,
    but the engines model the whole structure, so they are sized and error-estimated against the continuum (sized
    against a 5-mode model, a chain grew from 44 to 390 segments chasing it); the runner adds the n-mode model's own
    departure from the continuum to the row's structure error."""
    from impactval.reference.explicit_modes import continuum_scene
    from impactval.reference.solve import solve

    r = solve(continuum_scene(scene), tol=MODEL_ERROR_REF_TOL)
    return r.t_m, r.f_m, r.delta_m


def model_error(scene, chain: HenckyChain) -> ChainModelError:
    """The chain's discretisation error on t_m, f_m, delta_m: the reference solver on the chain's
    own modes against the continuum reference (both at MODEL_ERROR_REF_TOL)."""
    from impactval.reference.solve import solve_modes

    ball = scene.ball
    run, _ = solve_modes(chain.modes(), ball.mass, scene.alpha, ball.velocity, MODEL_ERROR_REF_TOL)
    m = run.metrics
    t, f, d = continuum_metrics(scene)
    return ChainModelError(m.t_m / t - 1.0, m.f_m / f - 1.0, m.delta_m / d - 1.0)


@lru_cache(maxsize=16)
def _continuum_linear_metrics(scene, k: float) -> tuple[float, float, float]:
    from impactval.reference.explicit_modes import continuum_scene
    from impactval.reference.linear import solve_linear

    r = solve_linear(continuum_scene(scene), tol=MODEL_ERROR_REF_TOL, stiffness=k)     # the continuum, as above
    return r.t_m, r.f_m, r.delta_m


def linear_model_error(scene, chain: HenckyChain, k: float) -> ChainModelError:
    """The chain's error on t_m, f_m, delta_m under a linear contact spring `k` [N/m] (a native contact's law):
    the exact linear theory (reference/linear.py) on the chain's own modes against the linear theory on the
    scene's continuum (its own beam theory, MODEL_ERROR_REF_TOL), signed (chain - continuum)/continuum. The
    metrics are the ones the runner compares a linear-law row with: contact duration, peak spring force
    k*delta_m, peak approach. A coarse or capped chain can be much further off under a linear spring than
    `model_error` (Hertz) says: the spring's constant stiffness at small approach lets the short-wave modes
    the chain gets wrong take part (heavy_wc_slender_timoshenko, Warp's capped N = 56: t_m +15.0 % linear,
    +0.23 % Hertz)."""
    k = float(k)
    if not (math.isfinite(k) and k > 0):
        raise ValueError(f"a linear contact spring needs a positive stiffness in N/m, got {k!r}")
    return _linear_model_error(scene, chain, k)


@lru_cache(maxsize=32)
def _linear_model_error(scene, chain: HenckyChain, k: float) -> ChainModelError:
    from impactval.reference.linear import solve_linear_modes

    ball = scene.ball
    m = solve_linear_modes(chain.modes(), ball.mass, k, ball.velocity).metrics
    t, f, d = _continuum_linear_metrics(scene, k)
    return ChainModelError(m.t_m / t - 1.0, m.f_m / f - 1.0, m.delta_m / d - 1.0)


def law_model_error(scene, chain: HenckyChain, law) -> tuple[ChainModelError, str]:
    """(the chain's model error under the contact law `law` (`reference.hertz.ContactLaw`, or None: Hertz), the law's
    kind "hertz" or "linear"): `linear_model_error` for a linear law, else `model_error`."""
    if law is not None and getattr(law, "kind", "") == "linear":
        return linear_model_error(scene, chain, law.coefficient), "linear"
    return model_error(scene, chain), "hertz"


def model_error_diagnostics(scene, chain: HenckyChain, law, hertz: ChainModelError | None = None,
                            prefix: str = "model_error") -> tuple[ChainModelError, dict]:
    """(the model error the row carries, its diagnostics): `{prefix}_t_m/_f_m/_delta_m` under the row's contact law
    (`law_model_error`) and `model_error_law` ("hertz" or "linear": the law it was measured with, which the runner
    compares the row's error against); for a linear law also `{prefix}_hertz_*`, the Hertz one (`hertz`, when
    already computed), so nothing is lost."""
    me, kind = law_model_error(scene, chain, law)
    diag = {f"{prefix}_t_m": me.t_m, f"{prefix}_f_m": me.f_m, f"{prefix}_delta_m": me.delta_m, "model_error_law": kind}
    if kind == "linear":
        h = hertz if hertz is not None else model_error(scene, chain)
        diag.update({f"{prefix}_hertz_t_m": h.t_m, f"{prefix}_hertz_f_m": h.f_m, f"{prefix}_hertz_delta_m": h.delta_m,
                     "model_error_spring": float(law.coefficient)})
    return me, diag


def chain_notes(scene, chain: HenckyChain, me: ChainModelError, tol: float, capped_at: int | None = None) -> list[str]:
    """Validity notes of a chain row (shown with the row in the report): a Hencky chain discretises
    Euler-Bernoulli theory, so on a Timoshenko scene its `model_error` holds the beam-theory difference; and,
    with `capped_at` (the engine's most links), a chain whose own Euler-Bernoulli error stays above `tol`."""
    notes = []
    eb = euler_bernoulli(scene)
    own = me if (eb is scene or chain.shear) else model_error(eb, chain)
    if eb is not scene and not chain.shear and me.largest > tol:
        notes.append(f"Euler-Bernoulli chain on a Timoshenko scene: its model error {100 * me.largest:.2f} % is the "
                     f"beam-theory difference (the chain itself is {100 * own.largest:.2f} % off Euler-Bernoulli); "
                     "compare it on theory = \"euler-bernoulli\" or use a shear-deformable model: exudyn (solid beam), mujoco "
                     "with chain_root = auto, end or middle, mujoco-warp, pybullet or newton (semi-implicit/featherstone): their Timoshenko chains")
    if capped_at is not None and own.largest > tol and chain.n >= capped_at - 12:
        notes.append(f"chain capped at {chain.n} links (the engine's most links: {capped_at}): its own "
                     f"{'Timoshenko' if chain.shear else 'Euler-Bernoulli'} model error is {100 * own.largest:.2f} %, above chain_tol {100 * tol:g} %")
    return notes


def continuum_frequencies(beam, n: int) -> np.ndarray:
    from impactval.reference.beams import beam_frequencies

    mat = beam.material
    return beam_frequencies(beam.support, n, beam.length, mat.young, beam.second_moment, mat.density, beam.area)


@dataclass(frozen=True)
class ChainSizing:
    """How N was chosen: `n` segments, `modes_that_matter` (required_modes count), their largest
    relative frequency error `frequency_error`, the chain's `model_error` (largest over the metrics)."""

    n: int
    modes_that_matter: int
    frequency_error: float
    model_error: ChainModelError


def timoshenko_frequencies(beam, n: int) -> np.ndarray:
    """The n lowest Timoshenko frequencies [rad/s] of `beam` with a transverse deflection (reference/timoshenko.py)."""
    from impactval.reference import timoshenko as tim

    sec = tim.Section.of(beam)
    if beam.support == "simply-supported":
        return np.asarray(tim.ss_frequencies(sec, n)[0])
    return np.asarray(tim.clamped_frequencies(sec, beam.support, n))    # frequencies only: no mode shapes


def _freq_error(beam, chain: HenckyChain, count: int) -> float:
    if count <= 0:
        return 0.0
    if chain.shear:   # each Timoshenko frequency against the nearest chain frequency (the chain also has modes
        ch = chain.frequencies()  # without deflection, e.g. the simply supported pure-shear rotation at the cut-off)
        cont = timoshenko_frequencies(beam, count)
        near = ch[np.argmin(np.abs(ch[None, :] - cont[:, None]), axis=1)]
        return float(np.max(np.abs(near / cont - 1.0)))
    ch = chain.frequencies()[:count]
    cont = continuum_frequencies(beam, len(ch))
    return float(np.max(np.abs(ch / cont - 1.0)))


def segments_for(scene, tol: float = DEFAULT_CHAIN_TOL, rotary: str = "none", max_segments: int = 400,
                 adjust=None, shear: bool = False) -> ChainSizing:
    """Segments for `scene`'s beam so that the modes that matter are within `tol` in frequency and
    the chain's model error on t_m, f_m, delta_m is within `tol` (see the module docstring).
    `adjust(n) -> n` lets an engine move N (e.g. PyBullet: impact point near a segment centre).
    `shear=True` (a Timoshenko scene only): the Timoshenko chain, sized against Timoshenko theory."""
    from impactval.reference.modechoice import required_modes

    actual = scene
    shear = bool(shear) and euler_bernoulli(scene) is not scene
    if not shear:
        scene = euler_bernoulli(scene)  # a Hencky chain discretises Euler-Bernoulli: size it against that theory
    beam = scene.target

    def chain_of(b, k: int, r: str) -> HenckyChain:
        return hencky_chain(b, k, r, shear=shear)
    adjust = adjust or (lambda n: n)
    # the modes that matter, counted on Euler-Bernoulli theory also for the Timoshenko chain: Timoshenko's count
    # needs its mode shapes (minutes on a stubby cantilever); the model-error criterion below is the guarantee
    count = required_modes(euler_bernoulli(scene), tol).count
    n = adjust(max(MIN_SEGMENTS, 4 * count))
    # the frequency criterion measures discretisation: on the bar chain. A section's rotary inertia on an
    # Euler-Bernoulli scene (a Rayleigh beam) shifts the high modes that matter off Euler-Bernoulli's for good, so
    # sized on it N ran to the cap (ss_glass_wc_fast, rotary_inertia=section: N 375 and 44x the stepping time where
    # N = 49 meets chain_tol, 0.45 %); the model-error criterion below is on the chain as built (chain_tol holds)
    freq_rotary = rotary if shear else "none"
    for _ in range(6):            # frequency criterion: error ~ (j/N)^2
        err = _freq_error(beam, chain_of(beam, n, freq_rotary), count)
        if err <= tol or n >= max_segments:
            break
        n = adjust(min(max_segments, int(math.ceil(n * math.sqrt(err / tol) * 1.05))))
    me = model_error(scene, chain_of(beam, n, rotary))
    for _ in range(4):            # the metric criterion, the same 1/N^2 law
        if me.largest <= tol or n >= max_segments:
            break
        n = adjust(min(max_segments, int(math.ceil(n * math.sqrt(me.largest / tol) * 1.05))))
        me = model_error(scene, chain_of(beam, n, rotary))
    if me.largest > tol:          # capped: the error depends on where the impact point sits in its segment,
        best = (me.largest, n, me)  # so take the N near the cap with the smallest model error, among the
        # N the engine's `adjust` accepts (PyBullet: impact point near its segment's centre, which its native
        # sphere-box contact needs: off-centre, the hit link tilts under the ball, native t_m +3.8 % measured)
        for m in sorted({adjust(k) for k in range(max(MIN_SEGMENTS, max_segments - 12), max_segments + 1)}):
            e = model_error(scene, chain_of(beam, m, rotary))
            if e.largest < best[0]:
                best = (e.largest, m, e)
        _, n, me = best
    if actual is not scene:       # reported against the scene's own theory: discretisation + structure theory
        me = model_error(actual, chain_of(beam, n, rotary))
    return ChainSizing(n, count, _freq_error(beam, chain_of(beam, n, rotary), count), me)


def euler_bernoulli(scene):
    """`scene` with its beam in Euler-Bernoulli theory (the theory a Hencky chain discretises);
    the scene itself when it already is (or is not a beam)."""
    import dataclasses

    target = scene.target
    if getattr(target, "theory", "euler-bernoulli") == "euler-bernoulli":
        return scene
    return dataclasses.replace(scene, target=dataclasses.replace(target, theory="euler-bernoulli"))


def centred(impact_at: float, lo: int, hi: int, prefer: int) -> int:
    """The N in [lo, hi] that puts the impact point nearest a segment's centre (a point at a hinge is
    softer: mid-span N = 100 vs 101 differ by ~1 % in t_m), ties broken by closeness to `prefer`."""
    def off_centre(n: int) -> float:
        return round(abs((impact_at * n) % 1.0 - 0.5), 6)

    return min(range(max(lo, 2), max(hi, lo, 2) + 1), key=lambda n: (off_centre(n), abs(n - prefer)))


def centring(impact_at: float, max_segments: int):
    """An `adjust` for segments_for: move N up by at most 10 % to centre the impact point on a segment."""
    def adjust(n: int) -> int:
        n = min(n, max_segments)
        step = max(2, n // 10)
        hi = min(max_segments, n + step)
        lo = n if hi - n >= 2 else max(2, hi - step)      # at the cap: look below it
        return centred(impact_at, lo, hi, n)
    return adjust


def modal_omega_max(omega, modal_mass, phi, ball_mass: float, contact_stiffness: float) -> float:
    """Highest frequency [rad/s] of a modal target (one oscillator per mode, mass m_i/phi_i^2) + the ball on a
    linear contact spring [N/m] (delta = ball displacement - sum of the oscillators')."""
    from scipy import linalg

    om, mm, ph = (np.asarray(a, float) for a in (omega, modal_mass, phi))
    keep = np.abs(ph) > 1e-12
    om, mi = om[keep], mm[keep] / ph[keep] ** 2
    n = len(om)
    m = np.diag(np.concatenate(([ball_mass], mi)))
    k = np.diag(np.concatenate(([0.0], mi * om**2)))
    row = np.concatenate(([1.0], -np.ones(n)))
    k += contact_stiffness * np.outer(row, row)
    return float(math.sqrt(max(float(linalg.eigh(k, m, eigvals_only=True)[-1]), 0.0)))


def omega_max(scene, law, chain: HenckyChain | None = None) -> tuple[float, str]:
    """(highest frequency [rad/s] of the explicit model: structure + ball + contact spring at its tangent
    stiffness at the rigid-plate delta_m (the largest approach), a one-line description)."""
    from impactval.reference.hertz import plate_impact
    from impactval.reference.structure import contact_scene

    two_balls = scene.target.kind == "ball"
    scene = contact_scene(scene)      # a second ball: the relative motion (reduced mass, approach speed)
    ball = scene.ball
    p = plate_impact(ball.mass, scene.alpha, ball.velocity)
    k = law.stiffness(p.delta_m)
    target = scene.target
    if chain is not None:
        return chain.omega_max_with_ball(ball.mass, k), (f"Hencky chain N = {chain.n} + ball + contact spring "
                                                        f"{k:.3g} N/m")
    if target.kind == "modal":
        return modal_omega_max(target.omega, target.modal_mass, target.phi, ball.mass, k), \
            f"{len(target.omega)} modal oscillators + ball + contact spring {k:.3g} N/m"
    if two_balls:
        return math.sqrt(k / ball.mass), f"two balls (reduced mass {ball.mass:.4g} kg) on the contact spring {k:.3g} N/m"
    return math.sqrt(k / ball.mass), f"ball on the contact spring {k:.3g} N/m"
