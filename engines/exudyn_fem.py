"""Solid finite-element model of a beam for Exudyn's FFRF reduced-order body (issue 6).

The beam is meshed with triquadratic 27-node hexahedra (scikit-fem `ElementHex2`), its mass and
stiffness matrices are assembled by scikit-fem (linear elasticity, consistent mass), the supports
are built into the modes as constrained degrees of freedom, and the modes come from a
shift-invert eigensolve (`scipy.sparse.linalg.eigsh`, sigma = 0) of the constrained system. The
result is handed to `exudyn.FEM.FEMinterface` (nodes, matrices, `modeBasis`, `eigenValues`).

Geometry (SI): x along the length [0, L], y vertical (the impact direction, top face at +h/2),
z across the width, centred. Supports:
- simply supported: pinned lines at the end faces' centroid lines (y = 0): u_x, u_y, u_z = 0 at
  x = 0 and u_y, u_z = 0 at x = L (a roller), so bending is free and no axial force builds up;
- clamped: every degree of freedom of the end face(s) fixed; cantilever: only the face x = 0.

The contact point is the cross-section at the impact position: a weighted average of the section's
nodes with the consistent (Simpson) weights of the quadratic faces, i.e. the section's mean
vertical displacement, which is what the Euler-Bernoulli reference calls the beam deflection. The
contact force is spread over the section with the same weights (no local indentation of the
beam: that is Hertz's job).

Only vertical-bending modes are kept: a mode counts as vertical bending when more than half its
kinetic energy is in the section-mean vertical motion (torsion of a flat section moves the nodes
vertically too, but its section mean is zero); eigenvalues within 1e-6 of each other are first
rotated so that each vector is as much or as little vertical bending as possible; the first `n`
are kept. Modes of a symmetric section loaded at its centroid that are not vertical
bending (lateral, torsion, axial) are not excited by the impact.

Cost: the default mesh (1 x 1 elements per section, element length = height) of the worked beam
has 2.7k DOF and builds in about 1 s; results are cached on disk per geometry, material, support,
mesh and mode count (see `cache_dir`).
"""
from __future__ import annotations

import hashlib
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: bump when the model changes, so old cache files are not reused
MODEL_VERSION = "fe-hex27-v3"
#: most eigenpairs computed while looking for the vertical-bending modes (the count doubles from 2 n + 12 until it
#: holds n of them): a short, wide section's higher modes are three-dimensional (torsion, lateral, axial, section
#: modes), and 40 vertical modes of a user's 50 x 19 x 8.5 mm PMMA cantilever took the 1,472 lowest of 4,428 DOF (59 s;
#: 736: 9 s; the stubby catalogue beam's 11 take 272); above this the body keeps the vertical modes found and its
#: `model_error` holds the truncation
MOST_EIGENPAIRS = 600
#: ... but at least this many (else the mesh is refused)
MIN_VERTICAL_MODES = 4


@dataclass(frozen=True)
class FeBeam:
    """The FE beam's data for the FFRF body.

    `nodes` [m] (n_nodes x 3), `mass` and `stiffness` (scipy CSR, 3 n_nodes square, node-major
    x, y, z order), `mode_basis` (3 n_nodes x n, mass-normalised vertical-bending modes),
    `omega` [rad/s] of those modes, `contact_nodes` / `contact_weights` (the impact section),
    `phi_contact` [1/sqrt(kg)] the modes' mean vertical displacement of the impact section,
    `omega_all` [rad/s] every computed eigenfrequency, `elements` (nx, ny, nz), `n_dof`.
    """

    nodes: np.ndarray
    mass: object
    stiffness: object
    mode_basis: np.ndarray
    omega: np.ndarray
    contact_nodes: np.ndarray
    contact_weights: np.ndarray
    phi_contact: np.ndarray
    omega_all: np.ndarray
    elements: tuple[int, int, int]
    n_dof: int
    build_s: float = 0.0
    cached: bool = False


def cache_dir() -> Path:
    """Where FE models are cached: $IMPACTVAL_CACHE/exudyn-fe, else <tmp>/impactval-cache/exudyn-fe."""
    root = os.environ.get("IMPACTVAL_CACHE") or os.path.join(tempfile.gettempdir(), "impactval-cache")
    return Path(root) / "exudyn-fe"


def default_elements(beam, n_modes: int) -> tuple[int, int, int]:
    """Default mesh (nx, ny, nz): elements at most as long as the beam is high and at least two per
    half-wave of the highest kept mode (nx >= 2 n + 2), one quadratic element through the height and
    across the width (enough for bending: the displacement field is quadratic in each direction, so
    there is no shear locking; 2 x 2 moves the worked beam's first three frequencies by <= 0.06 %)."""
    nx = max(8, int(math.ceil(beam.length / beam.height)), 2 * n_modes + 2)
    return nx, 1, 1


def _x_grid(beam, nx: int) -> np.ndarray:
    """Element vertices along x, with one at the impact position (so the section has nodes)."""
    xc, length = beam.impact_x, beam.length
    if xc >= length * (1 - 1e-12):
        return np.linspace(0.0, length, nx + 1)
    n1 = min(max(1, int(round(nx * xc / length))), nx - 1)
    return np.concatenate([np.linspace(0.0, xc, n1 + 1), np.linspace(xc, length, nx - n1 + 1)[1:]])


def _simpson_weights(coords: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Integral of each quadratic 1D shape function whose node sits at `coords` on the element
    vertex grid `grid` (vertices get h/6 per adjacent element, mid-nodes 4h/6)."""
    w = np.zeros(len(coords))
    for a, b in zip(grid[:-1], grid[1:]):
        h, mid = b - a, 0.5 * (a + b)
        tol = 1e-9 * max(abs(h), 1.0)
        w += np.where(np.isclose(coords, a, atol=tol) | np.isclose(coords, b, atol=tol), h / 6.0, 0.0)
        w += np.where(np.isclose(coords, mid, atol=tol), 4.0 * h / 6.0, 0.0)
    return w


def _assemble(beam, elements: tuple[int, int, int]):
    """Nodes (n x 3) and mass / stiffness matrices in node-major order, plus the vertex grids."""
    import skfem
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    nx, ny, nz = elements
    xg = _x_grid(beam, nx)
    yg = np.linspace(-beam.height / 2, beam.height / 2, ny + 1)
    zg = np.linspace(-beam.width / 2, beam.width / 2, nz + 1)
    mesh = skfem.MeshHex.init_tensor(xg, yg, zg)
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementHex2()), intorder=4)
    mat = beam.material
    lam, mu = lame_parameters(mat.young, mat.poisson)
    stiffness = skfem.asm(linear_elasticity(lam, mu), basis)

    @skfem.BilinearForm
    def mass_form(u, v, _w):
        return mat.density * (u[0] * v[0] + u[1] * v[1] + u[2] * v[2])

    mass = skfem.asm(mass_form, basis)
    comps = basis.split_indices()
    locs = basis.doflocs
    if not all(np.allclose(locs[:, comps[0]], locs[:, c]) for c in comps[1:]):
        raise RuntimeError("scikit-fem returned components at different locations; cannot map to nodes")
    nodes = locs[:, comps[0]].T.copy()
    perm = np.column_stack(comps).ravel()          # exudyn dof 3k+c = skfem dof comps[c][k]
    mass = mass.tocsr()[perm][:, perm].tocsr()
    stiffness = stiffness.tocsr()[perm][:, perm].tocsr()
    return nodes, mass, stiffness, (xg, yg, zg)


def _fixed_dofs(beam, nodes: np.ndarray) -> np.ndarray:
    """Constrained dof indices (node-major) for the beam's support."""
    tol = 1e-9 * beam.length
    at0 = np.abs(nodes[:, 0]) < tol
    at_l = np.abs(nodes[:, 0] - beam.length) < tol
    axis = np.abs(nodes[:, 1]) < 1e-9 * beam.height
    dofs: list[np.ndarray] = []

    def add(mask: np.ndarray, comps: tuple[int, ...]) -> None:
        idx = np.flatnonzero(mask)
        for c in comps:
            dofs.append(3 * idx + c)

    if beam.support == "simply-supported":
        add(at0 & axis, (0, 1, 2))
        add(at_l & axis, (1, 2))
    elif beam.support == "clamped-clamped":
        add(at0, (0, 1, 2))
        add(at_l, (0, 1, 2))
    elif beam.support == "cantilever":
        add(at0, (0, 1, 2))
    else:
        raise ValueError(f"unknown support {beam.support!r}")
    return np.unique(np.concatenate(dofs))


def _section_mean_operator(beam, nodes: np.ndarray, grids) -> tuple[object, np.ndarray]:
    """(A, plane_mass): A maps a displacement vector to each x-plane's section-mean vertical
    displacement (consistent quadratic weights); plane_mass [kg] lumps rho A dx onto the planes."""
    import scipy.sparse as sp

    xg, yg, zg = grids
    xs, plane = np.unique(np.round(nodes[:, 0] / beam.length, 12), return_inverse=True)
    ws = _simpson_weights(nodes[:, 1], yg) * _simpson_weights(nodes[:, 2], zg) / beam.area
    a = sp.csr_matrix((ws, (plane, 3 * np.arange(len(nodes)) + 1)), shape=(len(xs), 3 * len(nodes)))
    plane_mass = beam.material.density * beam.area * _simpson_weights(xs * beam.length, xg)
    return a, plane_mass


def _vertical_modes(vals: np.ndarray, vecs: np.ndarray, mass, a, plane_mass) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sort modes; rotate near-degenerate clusters so each vector is as much (or as little) vertical
    bending as possible; return (vals, vecs, bending fraction = kinetic energy of the section-mean
    vertical motion / total kinetic energy: ~1 for vertical bending, ~0 for torsion, lateral
    bending and axial modes)."""
    order = np.argsort(vals)
    vals, vecs = vals[order], vecs[:, order]
    out_vecs = vecs.copy()
    i = 0
    while i < len(vals):
        j = i + 1
        while j < len(vals) and abs(vals[j] - vals[i]) <= 1e-6 * abs(vals[i]):
            j += 1
        if j - i > 1:
            block = vecs[:, i:j]
            c = a @ block
            q = c.T @ (plane_mass[:, None] * c)
            _, rot = np.linalg.eigh(0.5 * (q + q.T))
            out_vecs[:, i:j] = block @ rot[:, ::-1]
        i = j
    c = a @ out_vecs
    bending = np.einsum("ij,ij->j", c, plane_mass[:, None] * c) / np.einsum("ij,ij->j", out_vecs, mass @ out_vecs)
    return vals, out_vecs, bending


def _key(beam, elements: tuple[int, int, int], n_modes: int) -> str:
    mat = beam.material
    text = repr((MODEL_VERSION, beam.support, beam.length, beam.width, beam.height, beam.impact_at,
                 mat.young, mat.poisson, mat.density, tuple(elements), n_modes))
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def fe_beam(beam, n_modes: int, elements: tuple[int, int, int] | None = None, use_cache: bool = True) -> FeBeam:
    """The FE model of `beam` with its first `n_modes` vertical-bending modes (cached on disk)."""
    import time

    from scipy.sparse.linalg import eigsh

    elements = tuple(int(e) for e in (elements or default_elements(beam, n_modes)))
    path = cache_dir() / f"{_key(beam, elements, n_modes)}.npz"
    if use_cache and path.exists():
        try:
            return _load(path, elements)
        except Exception:  # noqa: BLE001 - a broken cache file is rebuilt, never fatal
            pass
    t0 = time.perf_counter()
    nodes, mass, stiffness, (xg, yg, zg) = _assemble(beam, elements)
    n_dof = 3 * len(nodes)
    fixed = _fixed_dofs(beam, nodes)
    free = np.setdiff1d(np.arange(n_dof), fixed)
    a_mean, plane_mass = _section_mean_operator(beam, nodes, (xg, yg, zg))
    kff = stiffness[free][:, free].tocsc()
    mff = mass[free][:, free].tocsc()
    # a fixed start vector: ARPACK's own is drawn from a generator whose state persists across the calls of a process,
    # so two workers built the same beam's modes 1e-13 apart and two rows of one run disagreed in their structure part
    v0 = np.random.default_rng(0).standard_normal(len(free))
    k_most = min(len(free) - 2, max(MOST_EIGENPAIRS, 2 * n_modes + 12))
    k = min(2 * n_modes + 12, k_most)
    while True:
        vals, vecs_f = eigsh(kff, k=k, M=mff, sigma=0.0, which="LM", v0=v0)
        vecs = np.zeros((n_dof, vecs_f.shape[1]))
        vecs[free] = vecs_f
        vals, vecs, bending = _vertical_modes(vals, vecs, mass, a_mean, plane_mass)
        vertical = np.flatnonzero(bending > 0.5)
        if len(vertical) >= n_modes or k >= k_most:
            break
        k = min(2 * k, k_most)
    if len(vertical) < min(n_modes, MIN_VERTICAL_MODES):
        raise RuntimeError(f"the FE mesh {elements} yields only {len(vertical)} vertical bending modes among its "
                           f"{k} lowest, {n_modes} requested; use a finer mesh (option fe_elements)")
    sel = vertical[:n_modes]        # fewer than n_modes when the k_most lowest eigenpairs hold fewer (FeBeam.omega)
    basis = vecs[:, sel]
    norms = np.sqrt(np.einsum("ij,ij->j", basis, mass @ basis))
    basis = basis / norms
    # impact section: nodes at x = impact_x with tensor-product Simpson weights over the section
    tol = 1e-9 * beam.length
    section = np.flatnonzero(np.abs(nodes[:, 0] - beam.impact_x) < tol)
    w = _simpson_weights(nodes[section, 1], yg) * _simpson_weights(nodes[section, 2], zg)
    keep = w > 0
    section, w = section[keep], w[keep] / np.sum(w[keep])
    phi_c = w @ basis[3 * section + 1]
    sign = np.where(phi_c < 0, -1.0, 1.0)            # make the contact-point shape values non-negative
    basis = basis * sign
    phi_c = phi_c * sign
    res = FeBeam(nodes, mass.tocsr(), stiffness.tocsr(), basis, np.sqrt(np.abs(vals[sel])), section, w, phi_c,
                 np.sqrt(np.abs(vals)), elements, n_dof, time.perf_counter() - t0, False)
    if use_cache:
        try:
            _save(path, res)
        except OSError:
            pass
    return res


def _save(path: Path, fe: FeBeam) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
    m, k = fe.mass.tocsr(), fe.stiffness.tocsr()
    np.savez(tmp, nodes=fe.nodes, m_data=m.data, m_ind=m.indices, m_ptr=m.indptr, k_data=k.data, k_ind=k.indices,
             k_ptr=k.indptr, mode_basis=fe.mode_basis, omega=fe.omega, contact_nodes=fe.contact_nodes,
             contact_weights=fe.contact_weights, phi_contact=fe.phi_contact, omega_all=fe.omega_all,
             build_s=np.array(fe.build_s))
    os.replace(tmp, path)


def _load(path: Path, elements: tuple[int, int, int]) -> FeBeam:
    import scipy.sparse as sp

    d = np.load(path)
    n = 3 * len(d["nodes"])
    mass = sp.csr_matrix((d["m_data"], d["m_ind"], d["m_ptr"]), shape=(n, n))
    stiffness = sp.csr_matrix((d["k_data"], d["k_ind"], d["k_ptr"]), shape=(n, n))
    return FeBeam(d["nodes"], mass, stiffness, d["mode_basis"], d["omega"], d["contact_nodes"],
                  d["contact_weights"], d["phi_contact"], d["omega_all"], elements, n, float(d["build_s"]), True)
