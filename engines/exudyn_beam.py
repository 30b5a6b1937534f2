"""Euler-Bernoulli finite-element beam for Exudyn (issue 11): an ANCF cable mesh sized from the scene.

Exudyn's `ObjectANCFCable2D` is a planar Bernoulli-Euler beam element in absolute nodal coordinates:
two `NodePoint2DSlope1` nodes, each with position (x, y) and slope (x', y'), cubic Hermite shape
functions, consistent mass rho*A (no rotary inertia, no shear: Euler-Bernoulli exactly), bending
stiffness EI on the curvature and axial stiffness EA on the axial strain. For the microscopic
deflections of an impact its linearisation about the straight beam is the classical Hermite beam
element (u axial, w = y deflection, w' = y' slope):

- bending: K = EI/l^3 [[12, 6l, -12, 6l], [6l, 4l^2, -6l, 2l^2], ...] on (w_i, w'_i, w_j, w'_j),
- axial: K = EA/(30 l) [[36, 3l, -36, 3l], [3l, 4l^2, -3l, -l^2], ...] on (u_i, u'_i, u_j, u'_j),
- mass (both): rho A l/420 [[156, 22l, 54, -13l], [22l, 4l^2, 13l, -3l^2], ...].

`HermiteBeam` assembles this linear model with numpy (independently of Exudyn; the tests check that
Exudyn's own linearised eigenvalues of the ANCF mesh agree, and both against the closed form).
From it come the mesh's exact bending modes seen from the impact node (`modes()`), which give the
model's own discretisation error (`model_error`: the reference solver on those modes against the
continuum, as for the chains), its highest frequency (explicit stability limit) and its energy.

Supports (ANCF coordinates per node: 0 = u, 1 = w, 2 = u' (axial stretch), 3 = w' (slope)):
simply supported = u, w fixed at x = 0 and w at x = L (a roller: no axial force builds up);
clamped = u, w, w' fixed at both ends; cantilever = u, w, w' fixed at x = 0.
The impact point is a node (the grid has a vertex at impact_x); the ball touches the top surface
(contact radius h/2 about the node on the axis).

Sizing (`elements_for`): the modes the scene needs must be reproduced by the mesh within `tol` in
frequency (a Hermite element's error grows like (k/N)^4 for mode k), then the mesh grows until the
model error on t_m, f_m, delta_m is within `tol` too. The modes the scene needs are
`reference.modechoice.required_modes(scene, mode_tol).count`, the count for a model *with* the residual
static flexibility of the rest: every mode of the mesh is in the Exudyn model (no modal truncation),
and a Hermite mesh is statically exact at its nodes (tested: its flexibility at the impact node equals
the closed form), so the modes it does not resolve still carry their exact static flexibility; what they
lack is their dynamic remainder, which is what `count` bounds. (A plain n-mode model needs
`count_without_residual`: 197 instead of 41 modes on tests/unseen/heavy_wc_slender.toml.)
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

#: fewest elements of a mesh, and most (the linear model is dense: 600 elements = 2404 coordinates, 46 MB a matrix)
MIN_ELEMENTS, MAX_ELEMENTS = 8, 600
#: the model error the mesh may have (relative, on each of t_m, f_m, delta_m), as a fraction of mode_tol
TOL_FRACTION = 0.5
#: reference tolerance for the model error (well below the tolerance the mesh is sized to)
MODEL_ERROR_REF_TOL = 1e-5
#: modes of the mesh given to the reference for the model error: up to this scaled frequency w = omega delta_m/v0,
#: the rest as their exact residual static flexibility (modechoice's weights table runs to the same w)
MODEL_ERROR_W_MAX = 2048.0

#: constrained coordinates (u, w, u', w' = 0 .. 3) per support node. Every support leaves one end free to slide along
#: the beam, as the linear reference assumes (no axial force) and the chains do (a roller): simply supported = pin +
#: roller; clamped-clamped = clamp + sliding clamp (w, w' held at x = L). With both clamps holding u too, a deflection
#: of ~h/2 stretched the centreline: a 3 kg aluminium ball at 30.8 m/s 0.16 L from a clamp of a 250 x 25 x 9.8 mm WC
#: beam (w = 4.4 mm at the impact point) gave f_m +6.4 % (membrane stiffening) where the chains gave -1.5 %
FIXED = {"simply-supported": ((0, (0, 1)), (-1, (1,))),
         "clamped-clamped": ((0, (0, 1, 3)), (-1, (1, 3))),
         "cantilever": ((0, (0, 1, 3)),)}


def element_grid(beam, n_elements: int) -> tuple[np.ndarray, int]:
    """Node positions x [m] (n_elements + 1, uniform on each side of the impact point) and the index of
    the impact node."""
    length, xc = beam.length, beam.impact_x
    ne = int(n_elements)
    if xc >= length * (1 - 1e-12):
        return np.linspace(0.0, length, ne + 1), ne
    if xc <= length * 1e-12:
        return np.linspace(0.0, length, ne + 1), 0
    n1 = min(max(1, int(round(ne * xc / length))), ne - 1)
    xs = np.concatenate([np.linspace(0.0, xc, n1 + 1), np.linspace(xc, length, ne - n1 + 1)[1:]])
    return xs, n1


def _hermite(l: float):
    """(bending stiffness / EI, axial stiffness / EA, mass / (rho A)) of one element of length l [m]."""
    kb = np.array([[12, 6 * l, -12, 6 * l], [6 * l, 4 * l * l, -6 * l, 2 * l * l],
                   [-12, -6 * l, 12, -6 * l], [6 * l, 2 * l * l, -6 * l, 4 * l * l]]) / l**3
    ka = np.array([[36, 3 * l, -36, 3 * l], [3 * l, 4 * l * l, -3 * l, -l * l],
                   [-36, -3 * l, 36, -3 * l], [3 * l, -l * l, -3 * l, 4 * l * l]]) / (30.0 * l)
    m = np.array([[156, 22 * l, 54, -13 * l], [22 * l, 4 * l * l, 13 * l, -3 * l * l],
                  [54, 13 * l, 156, -22 * l], [-13 * l, -3 * l * l, -22 * l, 4 * l * l]]) * (l / 420.0)
    return kb, ka, m


def _along(shape: np.ndarray, pos: np.ndarray, slope: np.ndarray, lengths: np.ndarray, order: int) -> np.ndarray:
    """d^order r / dx^order of one centreline coordinate at every element's Gauss points (samples x elements x
    points), from its node values `pos` and slopes `slope` (samples x nodes) and the Hermite cubics' derivatives
    `shape` in xi (4 x points) on elements of `lengths` [m]."""
    l = lengths[None, :, None]
    return (shape[0] * pos[:, :-1, None] + shape[1] * l * slope[:, :-1, None] + shape[2] * pos[:, 1:, None]
            + shape[3] * l * slope[:, 1:, None]) / l**order


@dataclass(frozen=True)
class HermiteBeam:
    """An ANCF cable mesh of a beam: `xs` node positions [m], `impact_node`; flexural rigidity `ei` [N m^2],
    axial rigidity `ea` [N], mass per length `rho_a` [kg/m], `support`. Coordinates are node-major in
    Exudyn's order (u, w, u', w') per node."""

    xs: np.ndarray
    impact_node: int
    ei: float
    ea: float
    rho_a: float
    support: str

    @property
    def n_elements(self) -> int:
        return len(self.xs) - 1

    @property
    def n_coordinates(self) -> int:
        return 4 * len(self.xs)

    def fixed(self) -> np.ndarray:
        """Constrained coordinate indices (supports)."""
        nn = len(self.xs)
        out = [4 * (node % nn) + c for node, comps in FIXED[self.support] for c in comps]
        return np.array(sorted(out), int)

    def matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """(mass [kg, kg m, kg m^2], stiffness [N/m ...]) of all 4 (N + 1) coordinates, dense."""
        n = self.n_coordinates
        mass, stiff = np.zeros((n, n)), np.zeros((n, n))
        for i, l in enumerate(np.diff(self.xs)):
            kb, ka, m = _hermite(float(l))
            w = np.array([4 * i + 1, 4 * i + 3, 4 * i + 5, 4 * i + 7])
            u = w - 1
            stiff[np.ix_(w, w)] += self.ei * kb
            stiff[np.ix_(u, u)] += self.ea * ka
            mass[np.ix_(w, w)] += self.rho_a * m
            mass[np.ix_(u, u)] += self.rho_a * m
        return mass, stiff

    def strain_energy(self, q: np.ndarray, chunk: int = 2048) -> np.ndarray:
        """Strain energy [J] of the ANCF cable at each row of `q` (samples x coordinates: node-major (u, w, u', w')
        displacements from the straight reference), as the element defines it, not its linearisation: axial strain
        |r'| - 1 and curvature (r' x r'') / |r'|^3 of the deformed centreline r(x), energy integral of
        (EA eps^2 + EI kappa^2) / 2 by 5-point Gauss quadrature per element.

        The linear matrices count an axial displacement as stretch: a slope w' shortens the beam's projection by
        ~w'^2 / 2 without any strain, which they take as strain energy ~EA (w'^2 / 2)^2 per length. Under a heavy
        ball at a cantilever's tip (slopes ~1e-2) that spurious energy reached 9 % of the impact energy and the run
        was flagged as energy growth at every step size; a rigid rotation has none here (tested)."""
        q = np.atleast_2d(np.asarray(q, float))
        xi, wt = np.polynomial.legendre.leggauss(5)
        xi = 0.5 * (xi + 1.0)
        wt = 0.5 * wt
        # Hermite cubics on [0, 1] and their first and second derivatives in xi: (4, Gauss points) each
        sh1 = np.array([-6 * xi + 6 * xi**2, 1 - 4 * xi + 3 * xi**2, 6 * xi - 6 * xi**2, -2 * xi + 3 * xi**2])
        sh2 = np.array([-6 + 12 * xi, -4 + 6 * xi, 6 - 12 * xi, -2 + 6 * xi])
        lengths = np.diff(self.xs)
        n = len(self.xs)
        out = np.empty(q.shape[0])
        for lo in range(0, q.shape[0], chunk):
            c = q[lo:lo + chunk].reshape(-1, n, 4)
            rx = self.xs[None, :] + c[:, :, 0]          # node positions and slopes of the deformed centreline
            ry = c[:, :, 1]
            sx = 1.0 + c[:, :, 2]
            sy = c[:, :, 3]
            d1x, d2x = _along(sh1, rx, sx, lengths, 1), _along(sh2, rx, sx, lengths, 2)
            d1y, d2y = _along(sh1, ry, sy, lengths, 1), _along(sh2, ry, sy, lengths, 2)
            norm = np.sqrt(d1x * d1x + d1y * d1y)
            eps = norm - 1.0
            kappa = (d1x * d2y - d1y * d2x) / norm**3
            dens = 0.5 * (self.ea * eps * eps + self.ei * kappa * kappa)
            out[lo:lo + chunk] = np.einsum("seg,g,e->s", dens, wt, lengths)
        return out

    @lru_cache(maxsize=4)
    def _bending_eig(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        from scipy import linalg

        mass, stiff = self.matrices()
        free = np.setdiff1d(np.arange(self.n_coordinates), self.fixed())
        bend = free[(free % 4 == 1) | (free % 4 == 3)]     # w, w': bending decouples from u, u' when linear
        vals, vecs = linalg.eigh(stiff[np.ix_(bend, bend)], mass[np.ix_(bend, bend)])
        return np.sqrt(np.maximum(vals, 0.0)), vecs, bend

    def frequencies(self) -> np.ndarray:
        """Every bending frequency of the mesh [rad/s], ascending."""
        return self._bending_eig()[0].copy()

    def modes(self):
        """The mesh's bending modes seen from the impact node (mass-normalised: modal mass 1 kg, phi [1/sqrt(kg)])."""
        from impactval.reference.beams import Modes

        omega, vecs, bend = self._bending_eig()
        row = int(np.flatnonzero(bend == 4 * self.impact_node + 1)[0])
        return Modes(omega.copy(), np.ones(len(omega)), vecs[row].copy(), 0.0)

    def static_flexibility(self) -> float:
        """Deflection per unit force at the impact node [m/N] (the whole mesh, static)."""
        mass, stiff = self.matrices()
        free = np.setdiff1d(np.arange(self.n_coordinates), self.fixed())
        bend = free[(free % 4 == 1) | (free % 4 == 3)]
        load = (bend == 4 * self.impact_node + 1).astype(float)
        return float(load @ np.linalg.solve(stiff[np.ix_(bend, bend)], load))

    def omega_max(self) -> float:
        """Highest frequency [rad/s] of the whole linear mesh (axial modes included: they set an explicit
        integrator's limit)."""
        from scipy import linalg

        mass, stiff = self.matrices()
        free = np.setdiff1d(np.arange(self.n_coordinates), self.fixed())
        ax = free[(free % 4 == 0) | (free % 4 == 2)]
        top = float(linalg.eigh(stiff[np.ix_(ax, ax)], mass[np.ix_(ax, ax)], eigvals_only=True)[-1])
        return max(math.sqrt(max(top, 0.0)), float(self.frequencies()[-1]))

    def __hash__(self) -> int:
        return hash((self.xs.tobytes(), self.impact_node, self.ei, self.ea, self.rho_a, self.support))

    def __eq__(self, other) -> bool:
        return isinstance(other, HermiteBeam) and hash(self) == hash(other) and np.array_equal(self.xs, other.xs)


def hermite_beam(beam, n_elements: int) -> HermiteBeam:
    """The ANCF/Hermite mesh of a scene `Beam` with `n_elements` elements."""
    mat = beam.material
    xs, k = element_grid(beam, n_elements)
    return HermiteBeam(xs, k, mat.young * beam.second_moment, mat.young * beam.area, mat.density * beam.area,
                       beam.support)


@dataclass(frozen=True)
class BeamSizing:
    """How the mesh was chosen: `n_elements`, `modes_that_matter` (the count the mesh must reproduce),
    `frequency_error` (largest relative error of those modes against the continuum), `model_error`
    (t_m, f_m, delta_m: signed relative error of the mesh as a model, see `model_error`), `tol`."""

    n_elements: int
    modes_that_matter: int
    frequency_error: float
    model_error: tuple[float, float, float]
    tol: float

    @property
    def largest(self) -> float:
        return max(abs(e) for e in self.model_error)


def _continuum(beam, n: int) -> np.ndarray:
    from impactval.reference.beams import beam_frequencies

    mat = beam.material
    return beam_frequencies(beam.support, n, beam.length, mat.young, beam.second_moment, mat.density, beam.area)


def frequency_error(beam, mesh: HermiteBeam, count: int) -> float:
    """Largest |relative error| of the mesh's first `count` bending frequencies against Euler-Bernoulli's."""
    if count <= 0:
        return 0.0
    om = mesh.frequencies()
    if len(om) < count:
        return math.inf
    return float(np.max(np.abs(om[:count] / _continuum(beam, count) - 1.0)))


def model_error(scene, mesh: HermiteBeam) -> tuple[float, float, float]:
    """Signed relative errors on t_m, f_m, delta_m of the mesh as a model: the reference solver on the
    mesh's exact modes (those up to w = MODEL_ERROR_W_MAX, the rest as their residual static flexibility)
    against the continuum reference, both at MODEL_ERROR_REF_TOL."""
    from impactval.engines.chain import continuum_metrics
    from impactval.reference.beams import truncate_modes
    from impactval.reference.hertz import plate_impact
    from impactval.reference.solve import solve_modes

    ball = scene.ball
    plate = plate_impact(ball.mass, scene.alpha, ball.velocity)
    md = mesh.modes()
    keep = max(1, int(np.searchsorted(md.omega * plate.delta_m / ball.velocity, MODEL_ERROR_W_MAX, side="right")))
    md = truncate_modes(md, keep, residual=True)
    run, _ = solve_modes(md, ball.mass, scene.alpha, ball.velocity, MODEL_ERROR_REF_TOL)
    m = run.metrics
    t, f, d = continuum_metrics(scene)
    return m.t_m / t - 1.0, m.f_m / f - 1.0, m.delta_m / d - 1.0


def modes_that_matter(scene, mode_tol: float) -> int:
    from impactval.reference.modechoice import required_modes

    return int(required_modes(scene, mode_tol).count)


def elements_for(scene, mode_tol: float = 1e-2, modes: int | None = None,
                 max_elements: int = MAX_ELEMENTS) -> BeamSizing:
    """Elements for `scene`'s (Euler-Bernoulli) beam: the modes that matter (`modes`, else
    `modes_that_matter(scene, mode_tol)`) within tol = TOL_FRACTION * mode_tol in frequency, then the
    model error on t_m, f_m, delta_m within tol (both errors fall like N^-4: N grows by that law)."""
    beam = scene.target
    tol = TOL_FRACTION * float(mode_tol)
    count = int(modes) if modes else modes_that_matter(scene, mode_tol)
    # a Hermite mesh has ~2N bending modes; mode k is within ~1 % once N ~ 1.2 k (measured): start there
    n = int(min(max(MIN_ELEMENTS, math.ceil(0.6 * count)), max_elements))
    err = frequency_error(beam, hermite_beam(beam, n), count)
    for _ in range(12):
        if err <= tol or n >= max_elements:
            break
        grow = (err / tol) ** 0.25 if math.isfinite(err) else 2.0
        n = int(min(max_elements, math.ceil(n * min(max(grow, 1.05), 2.0) * 1.02)))
        err = frequency_error(beam, hermite_beam(beam, n), count)
    me = model_error(scene, hermite_beam(beam, n))
    for _ in range(4):
        largest = max(abs(e) for e in me)
        if largest <= tol or n >= max_elements:
            break
        n = int(min(max_elements, math.ceil(n * max((largest / tol) ** 0.25, 1.1))))
        me = model_error(scene, hermite_beam(beam, n))
    return BeamSizing(n, count, frequency_error(beam, hermite_beam(beam, n), count), me, tol)
