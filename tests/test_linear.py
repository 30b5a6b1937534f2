"""Exact linear theory (issue 3, part 1) against closed forms and a direct integration of the linear ODE."""
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

import impactval
from impactval.errors import ImpactvalError
from impactval.reference.hertz import plate_impact
from impactval.reference.linear import solve_linear, solve_linear_modes
from impactval.reference.solve import structure_modes


def test_rigid_plate_linear_law_is_exact():
    scene = impactval.load_scene("plate_steel")
    p = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
    r = solve_linear(scene)
    assert r.t_m == pytest.approx(math.pi * p.delta_m / scene.ball.velocity, rel=1e-12)
    assert r.f_m == pytest.approx(0.8 * p.f_m, rel=1e-12)
    assert r.delta_m == pytest.approx(p.delta_m, rel=1e-12)
    # the eigen/root machinery (not the closed form) gives the same numbers
    run = solve_linear_modes(structure_modes(scene), scene.ball.mass, p.k0, scene.ball.velocity)
    assert run.metrics.t_m == pytest.approx(r.t_m, rel=1e-12)
    assert run.metrics.f_m == pytest.approx(r.f_m, rel=1e-12)
    # the series is the sine
    omega0 = scene.ball.velocity / p.delta_m
    assert np.allclose(r.delta, p.delta_m * np.sin(omega0 * r.t), rtol=0, atol=1e-12 * p.delta_m)
    assert r.rebound_velocity == pytest.approx(scene.ball.velocity, rel=1e-12)


def _direct(modes, mass, k, v0):
    """The linear ODE integrated by DOP853 (scaled units), end of contact and peak by events."""
    omega_c = math.sqrt(k / mass)
    ts, ls = 1.0 / omega_c, v0 / omega_c
    keep = np.abs(modes.phi) > 1e-12
    w, phi, mu = modes.omega[keep] * ts, modes.phi[keep], modes.modal_mass[keep] / mass
    n = len(w)

    def rhs(_t, y):
        x1, v1, q, vq = y[0], y[1], y[2:2 + n], y[2 + n:]
        f = x1 - phi @ q            # scaled: k ts^2/m0 = 1
        return np.concatenate(([v1, -f], vq, -w**2 * q + phi * f / mu))

    def end(_t, y):
        return y[0] - phi @ y[2:2 + n]
    end.terminal, end.direction = True, -1

    def top(_t, y):
        return y[1] - phi @ y[2 + n:]
    top.direction = -1
    y0 = np.zeros(2 + 2 * n)
    y0[1] = 1.0
    sol = solve_ivp(rhs, (0, 100.0), y0, method="DOP853", rtol=1e-12, atol=1e-14, events=(end, top),
                    first_step=1e-6)
    t_end = sol.t_events[0][-1] if len(sol.t_events[0]) else math.nan
    peaks = [y[0] - phi @ y[2:2 + n] for y in sol.y_events[1]]
    return t_end * ts, max(peaks) * ls


@pytest.mark.parametrize("name,modes", [("modal_two_mode", None), ("beam_ss_midspan", 6),
                                        ("beam_cantilever_tip", 5), ("beam_ss_quarter", 8),
                                        ("heavy_ball_slender_beam", 8), ("light_ball_heavy_beam", 4)])
def test_exact_solution_matches_direct_integration(name, modes):
    scene = impactval.load_scene(name)
    md = structure_modes(scene, modes)
    k = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity).k0
    t_end, d_max = _direct(md, scene.ball.mass, k, scene.ball.velocity)
    r = solve_linear(scene, modes=modes)
    assert r.modes == md.n
    assert abs(r.t_m / t_end - 1) <= 1e-8
    assert abs(r.delta_m / d_max - 1) <= 1e-8
    assert r.f_m == pytest.approx(k * r.delta_m, rel=1e-14)
    assert r.energy_error <= 1e-10


def test_custom_stiffness_and_energy():
    scene = impactval.load_scene("modal_two_mode")
    k = 3e7
    r = solve_linear(scene, stiffness=k)
    assert r.settings["k"] == k
    t_end, d_max = _direct(structure_modes(scene), scene.ball.mass, k, scene.ball.velocity)
    assert r.t_m == pytest.approx(t_end, rel=1e-8)
    assert r.delta_m == pytest.approx(d_max, rel=1e-8)


def _direct_piecewise(md, mass: float, k: float, t_stop: float):
    """DOP853 (rtol 1e-12) on the piecewise-linear ODE in units of 1/omega_c and v0/omega_c (contact spring k only
    while the gap is closed), gap zeros as events, dense output; returns (solution, phi of the modes)."""
    ts = math.sqrt(mass / k)
    w, phi, mu = md.omega * ts, md.phi, md.modal_mass / mass
    n = len(w)

    def rhs(_t, y):
        d = y[0] - phi @ y[2:2 + n]
        f = d if d > 0 else 0.0
        return np.concatenate(([y[1], -f], y[2 + n:], -w**2 * y[2:2 + n] + phi * f / mu))

    def gap(_t, y):
        return y[0] - phi @ y[2:2 + n]
    y0 = np.zeros(2 + 2 * n)
    y0[1] = 1.0
    sol = solve_ivp(rhs, (0, t_stop), y0, method="DOP853", rtol=1e-12, atol=1e-14, events=gap, first_step=1e-6,
                    max_step=0.05, dense_output=True)
    return sol, phi


def test_recontacts_match_direct_integration():
    """After separation the ball and structure move freely; a re-contact starts at the next upward zero
    of the gap. Contact start/end times against DOP853 on the piecewise-linear ODE with gap events."""
    scene = impactval.load_scene("heavy_ball_slender_beam")
    mass, v0 = scene.ball.mass, scene.ball.velocity
    window = 3e-3
    r = solve_linear(scene, modes=6, window=window)
    assert len(r.contacts) >= 2
    assert r.energy_error <= 1e-9
    k = plate_impact(mass, scene.alpha, v0).k0
    ts = math.sqrt(mass / k)
    t_stop = (r.contacts[0].t_end + window) / ts
    sol, _ = _direct_piecewise(structure_modes(scene, 6), mass, k, t_stop)
    crossings = np.sort(sol.t_events[0]) * ts
    mine = sorted([c.t_start for c in r.contacts[1:]] + [c.t_end for c in r.contacts if math.isfinite(c.t_end)])
    mine = [x for x in mine if x <= t_stop * ts * (1 - 1e-9)]
    crossings = crossings[crossings > 1e-3 * r.t_m]
    assert len(crossings) == len(mine)
    assert np.allclose(crossings, mine, rtol=0, atol=1e-8 * r.t_m)


@pytest.mark.parametrize("name", ["beam_ss_midspan", "beam_cantilever_tip"])
def test_automatic_beam_modes_meet_their_uncertainty(name):
    """n modes + residual flexibility vs 1024 modes + residual (measured: 1024+R and 2048+R agree to 3e-13
    relative; plain n-mode models converge like n^-3 to the same limit: 2048 plain modes are 9e-9 off)."""
    scene = impactval.load_scene(name)
    r = solve_linear(scene, tol=1e-7)
    assert r.model == "linear-modal+static"
    k = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity).k0
    big = solve_linear_modes(structure_modes(scene, 1024, residual=True), scene.ball.mass, k, scene.ball.velocity)
    for key in ("t_m", "f_m", "delta_m"):
        err = abs(getattr(r, key) - getattr(big.metrics, key))
        assert err <= getattr(r.uncertainty, key) + 1e-12 * getattr(r, key), key
        assert getattr(r.uncertainty, key) <= 1e-7 * getattr(r, key)


def test_secular_solver_matches_dense_eigh():
    from scipy import linalg

    from impactval.reference.linear import linear_system

    scene = impactval.load_scene("beam_cc_midspan")
    md = structure_modes(scene, 30)
    k = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity).k0
    sysm = linear_system(md, scene.ball.mass, k)
    b = np.concatenate(([1.0], -sysm.phi))
    K = k * np.outer(b, b) + np.diag(np.concatenate(([0.0], sysm.mass_diag[1:] * sysm.omega**2)))
    lam = linalg.eigh(K, np.diag(sysm.mass_diag), eigvals_only=True)
    assert np.allclose(np.sort(sysm.p**2), lam, rtol=1e-10)
    assert np.allclose(sysm.U.T @ np.diag(sysm.mass_diag) @ sysm.U, np.eye(len(lam)), atol=1e-10)
    assert np.allclose(sysm.U.T @ K @ sysm.U, np.diag(sysm.p**2), rtol=1e-9, atol=1e-6 * lam.max())


@pytest.mark.parametrize("kw", [{"tol": 0}, {"stiffness": -1.0}, {"modes": 0}, {"window": -1}])
def test_bad_input_is_one_line_error(kw):
    with pytest.raises(ImpactvalError):
        solve_linear(impactval.load_scene("plate_steel"), **kw)


def test_series_match_direct_integration_through_a_recontact():
    """The series (ball, structure at the contact point, approach, energy), sampled from the eigen-coordinates'
    projections in contact and from the free modes in flight, against DOP853 on the piecewise-linear ODE at the
    same times, over two re-contacts."""
    scene = impactval.load_scene("heavy_ball_slender_beam")
    mass, v0 = scene.ball.mass, scene.ball.velocity
    window = 3e-3
    r = solve_linear(scene, modes=6, window=window)
    assert len(r.contacts) >= 3
    k = plate_impact(mass, scene.alpha, v0).k0
    ts, ls = math.sqrt(mass / k), v0 * math.sqrt(mass / k)
    sol, phi = _direct_piecewise(structure_modes(scene, 6), mass, k, r.t[-1] / ts)
    n = len(phi)
    y = sol.sol(r.t / ts)
    x_ball = y[0] * ls
    x_structure = (phi @ y[2:2 + n]) * ls
    scale = np.max(np.abs(x_ball))
    # measured: ball 6.5e-13, structure 3.0e-12 of the travel (DOP853's own error across the contact's kinks), energy
    # 4.4e-16
    assert np.max(np.abs(r.x_ball - x_ball)) <= 1e-10 * scale
    assert np.max(np.abs(r.x_structure - x_structure)) <= 1e-10 * scale
    assert np.max(np.abs(r.delta - (x_ball - x_structure))) <= 1e-10 * scale
    assert np.max(np.abs(r.f - k * np.maximum(x_ball - x_structure, 0.0))) <= 1e-10 * k * scale
    assert np.max(np.abs(r.energy / (0.5 * mass * v0**2) - 1.0)) <= 1e-13


def test_series_of_a_residual_model_split_its_approach_like_the_springs():
    """With the residual flexibility R the contact spring k and R act in series: delta = (x_ball - x_modes)/(1 + k R)
    and x_structure = x_modes + R f, so x_ball - x_structure = delta in contact and the energy stays put."""
    scene = impactval.load_scene("beam_cantilever_tip")
    mass, v0 = scene.ball.mass, scene.ball.velocity
    k = plate_impact(mass, scene.alpha, v0).k0
    md = structure_modes(scene, 24, residual=True)
    assert md.residual_flexibility > 0
    run = solve_linear_modes(md, mass, k, v0)
    inside = run.f > 0
    assert inside.sum() > 100
    assert np.allclose((run.x_ball - run.x_structure)[inside], run.delta[inside], rtol=0,
                       atol=1e-12 * run.metrics.delta_m)
    assert np.max(np.abs(run.energy / (0.5 * mass * v0**2) - 1.0)) <= 1e-10


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 40), count=st.integers(1, 900), t0=st.floats(0.0, 1e-2), h=st.floats(1e-9, 1e-5),
       cols=st.sampled_from([None, 1, 3]), seed=st.integers(0, 2**32 - 1))
def test_sines_on_a_grid_equal_the_direct_sum(n, count, t0, h, cols, seed):
    """`_sines_grid` (a block's offsets table times each block's start phase) against cos/sin summed directly, with
    blocks forced small so that many of them are stitched together."""
    from impactval.reference import linear

    rng = np.random.default_rng(seed)
    p = np.sort(rng.uniform(0.0, 1e7, n))
    shape = (n,) if cols is None else (n, cols)
    a, b = rng.normal(size=shape), rng.normal(size=shape)
    old = linear._BLOCK_ENTRIES
    linear._BLOCK_ENTRIES = 7 * n + 3           # blocks of 7 samples: the stitching is exercised
    try:
        got = linear._sines_grid(p, t0, h, count, a, b)
    finally:
        linear._BLOCK_ENTRIES = old
    tau = t0 + h * np.arange(count)
    P = np.outer(tau, p)
    want = np.cos(P) @ a + np.sin(P) @ b
    # both round the phase p t (up to 1e5 rad here: ~1e-11 rad) alike, not identically
    size = np.sum(np.abs(a) + np.abs(b), axis=0)
    assert got.shape == want.shape
    assert np.all(np.abs(got - want) <= 1e-10 * size)


def test_secular_roots_hugging_their_poles():
    """Couplings from 1e-24 to 1e3 (a mode near a node of the impact point up to a dominant one): every eigenvalue
    against a bisection of the secular equation in extended precision (its own, 80-bit), within 2 ulp, and the
    eigenvectors orthonormal."""
    from impactval.reference.linear import _secular

    rng = np.random.default_rng(7)
    n1 = 300
    d = np.concatenate(([0.0], np.sort(rng.uniform(1.0, 1e8, n1 - 1))))
    beta2 = 10.0 ** rng.uniform(-24, 3, n1)
    ks = 3.7
    lam, V, _ = _secular(d, beta2, ks)
    dl, bl = d.astype(np.longdouble), beta2.astype(np.longdouble)
    lo = dl.copy()
    hi = np.append(dl[1:], dl[-1] + ks * np.sum(bl))
    for _ in range(200):
        mid = lo + (hi - lo) / 2
        with np.errstate(divide="ignore"):         # mid on a pole: f = +-inf still says which side
            f = 1 + ks * np.sum(bl[:, None] / (dl[:, None] - mid[None, :]), axis=0)
        lo, hi = np.where(f < 0, mid, lo), np.where(f < 0, hi, mid)
    ref = (lo + (hi - lo) / 2).astype(float)
    assert np.all(np.abs(lam - ref) <= 2 * np.spacing(np.maximum(ref, 1e-300)))
    assert np.allclose(V.T @ V, np.eye(n1), atol=1e-10)


def test_contact_ending_on_a_grid_point_is_found():
    """A rigid plate's linear contact lasts pi sqrt(m/k), exactly the root-finding grid's 4000th point: the grid's sum
    and the direct one round differently there, and the bracket must still hold the root (13 % of random balls raised
    "f(a) and f(b) must have different signs" before the bracket was checked with the direct sum)."""
    md = structure_modes(impactval.load_scene("plate_steel"))
    rng = np.random.default_rng(11)
    for _ in range(300):
        m, k, v = 10 ** rng.uniform(-4, 1), 10 ** rng.uniform(3, 9), 10 ** rng.uniform(-2, 1)
        run = solve_linear_modes(md, m, k, v)
        assert run.metrics.t_m == pytest.approx(math.pi * math.sqrt(m / k), rel=1e-12)
        assert run.metrics.delta_m == pytest.approx(v * math.sqrt(m / k), rel=1e-12)


def test_mode_count_at_its_cap_says_the_uncertainty_is_above_tol(monkeypatch):
    """The automatic count's doubling stops at LINEAR_MODE_CAP; a result whose uncertainty is then above tol says so in
    its validity and on the terminal (a plate at tol 1e-6 stopped at 3,712 modes with 4.1e-6, without a word)."""
    from click.testing import CliRunner

    from impactval.cli import main
    from impactval.reference import linear

    scene = impactval.load_scene("beam_ss_midspan")
    free = solve_linear(scene, tol=1e-9)
    assert free.validity == () and max(free.uncertainty.f_m / free.f_m, free.uncertainty.t_m / free.t_m) <= 1e-9
    monkeypatch.setattr(linear, "LINEAR_MODE_CAP", 64)
    capped = solve_linear(scene, tol=1e-9)
    rel = max(capped.uncertainty.t_m / capped.t_m, capped.uncertainty.f_m / capped.f_m,
              capped.uncertainty.delta_m / capped.delta_m)
    assert capped.modes < 64 < free.modes and rel > 1e-9
    assert len(capped.validity) == 1 and "above tol 1e-09" in capped.validity[0]
    # the count kept and the one it was measured against (which reached the cap), not "stopped below the cap"
    assert f"stopped at {capped.modes} modes, measured against {2 * capped.modes}" in capped.validity[0]
    assert 2 * capped.modes >= 64
    out = CliRunner().invoke(main, ["reference", "beam_ss_midspan", "--model", "linear", "--tol", "1e-9"])
    assert out.exit_code == 0, out.output
    assert "! uncertainty" in out.output and "above tol 1e-09" in out.output


def test_theory_page_shows_the_exact_solutions_warnings(monkeypatch, tmp_path):
    """The linear solution's uncertainty above tol (and the Hertz reference's own warnings) reach the theory page."""
    from impactval.reference import linear
    from impactval.reports.theory import theory_page

    monkeypatch.setattr(linear, "LINEAR_MODE_CAP", 64)
    path, cmp = theory_page(impactval.load_scene("beam_ss_midspan"), tmp_path, tol=1e-9, plot=False)
    assert any(model == "linear" and "above tol 1e-09" in text for model, text in cmp.warnings)
    text = path.read_text()
    assert "Warnings of the exact solutions:" in text and "- linear: uncertainty" in text


def _random_modes(rng, n, residual=0.0):
    """n modes with distinct random frequencies in random order (the rank-one path unsorts its rows)."""
    from impactval.reference.beams import Modes

    omega = rng.permutation(np.sqrt(np.sort(rng.uniform(1e2, 1e10, n))))
    phi = rng.uniform(-2.0, 2.0, n) + np.where(rng.random(n) < 0.5, 0.05, -0.05)      # |phi| >= 0.05: kept
    return Modes(omega, rng.uniform(0.01, 2.0, n), phi, residual)


def test_rank_one_eigenvectors_are_applied_without_forming_them():
    """The rank-one path keeps U as O(modes) numbers (a Cauchy-like kernel) and applies it a block of columns at a
    time: U^T Y, U X and rows of U against U formed explicitly from `_secular` (the formula U was stored from: V scaled
    by sign(b)/sqrt(m), rows unsorted) and against a dense generalised eigh of (K, M), on a small random system with
    blocks forced small."""
    from scipy import linalg

    from impactval.reference import linear

    rng = np.random.default_rng(2024)
    n, mass, k = 37, 0.05, 3e7
    md = _random_modes(rng, n, residual=2e-9)
    old = linear._BLOCK_ENTRIES
    linear._BLOCK_ENTRIES = 5 * (n + 1) + 1         # blocks of 5 columns: the stitching is exercised
    try:
        sysm = linear.linear_system(md, mass, k)
        assert sysm.dense is None and sysm.order is not None
        Y, X = rng.normal(size=(n + 1, 3)), rng.normal(size=(n + 1, 2))
        got_T, got, got_1 = sysm.project(Y), sysm.expand(X), sysm.project(Y[:, 0])
        few = np.zeros(n + 1)
        few[[0, 5]] = (1.3, -0.4)                    # few nonzero rows: from those rows of U only
        got_few = sysm.project(few)
        U = sysm.U
    finally:
        linear._BLOCK_ENTRIES = old
    ks = k / (1.0 + k * md.residual_flexibility)
    b = np.concatenate(([1.0], -md.phi))
    m = np.concatenate(([mass], md.modal_mass))
    d = np.concatenate(([0.0], md.omega**2))
    order = np.argsort(d)
    bt = b / np.sqrt(m)
    lam, V, bv = linear._secular(d[order], bt[order] ** 2, ks)
    ref = np.empty_like(V)
    ref[order] = V * (np.sign(bt[order]) / np.sqrt(m[order]))[:, None]
    scale = np.max(np.abs(ref))
    assert np.allclose(sysm.p**2, lam, rtol=1e-15)
    assert np.max(np.abs(U - ref)) <= 1e-14 * scale
    for a, r in ((got_T, ref.T @ Y), (got_1, ref.T @ Y[:, 0]), (got, ref @ X), (got_few, ref.T @ few)):
        assert np.max(np.abs(a - r)) <= 1e-13 * np.max(np.abs(r))
    assert np.allclose(sysm.x1_row, ref[0], rtol=1e-14, atol=1e-15 * scale)
    assert np.allclose(sysm.x2_row, md.phi @ ref[1:], rtol=1e-12, atol=1e-14 * np.max(np.abs(sysm.x2_row)))
    assert np.allclose(sysm.bU, (b @ ref) / (1.0 + k * md.residual_flexibility), rtol=1e-10,
                       atol=1e-12 * np.max(np.abs(sysm.bU)))
    # a dense generalised eigh of (K, M): the same frequencies and (up to each column's sign) vectors
    K = ks * np.outer(b, b) + np.diag(m * d)
    lam_e, U_e = linalg.eigh(K, np.diag(m))
    srt = np.argsort(sysm.p)
    assert np.allclose(sysm.p[srt] ** 2, lam_e, rtol=1e-9)
    U_e *= np.sign(np.sum(U_e * U[:, srt], axis=0))
    assert np.allclose(U[:, srt], U_e, rtol=0, atol=1e-8 * scale)


def test_rank_one_system_keeps_no_square_matrix():
    """2,000 modes: every array kept on the LinearSystem is 1-D of length <= modes + 1 (U was (modes + 1)^2: 441 MB
    at 7,425 modes), and U U^T M = I through `expand`/`project` alone."""
    from impactval.reference import linear

    rng = np.random.default_rng(5)
    n = 2000
    sysm = linear.linear_system(_random_modes(rng, n, residual=1e-9), 0.03, 5e7)
    arrays = {f: getattr(sysm, f) for f in sysm.__dataclass_fields__ if isinstance(getattr(sysm, f), np.ndarray)}
    assert sysm.dense is None and len(arrays) >= 8
    for name, a in arrays.items():
        assert a.ndim == 1 and len(a) <= n + 1, name
    y = rng.normal(size=(n + 1, 2))
    back = sysm.expand(sysm.project(sysm.mass_diag[:, None] * y))
    assert np.max(np.abs(back - y)) <= 1e-10 * np.max(np.abs(y))


def test_repeated_frequencies_merge_into_one_mode_exactly(monkeypatch):
    """Modes of one frequency act on the contact as one mode (phi = 1, 1/m = sum phi^2/m: the group's other
    combinations are never excited), so the secular path stays O(modes) where the dense eigh of every mode took
    O(modes^3) (a 0.33 x 0.21 m plate, 11:7, 4,096 modes: 45 s -> 2 s). Against the dense eigh of the unmerged
    modes (still the path a zero frequency takes, its U kept whole): metrics, contacts and the structure's series
    within 1e-12, on a pair of equal modes and on an unseen square plate, each with a window (free flight)."""
    from impactval.reference import linear
    from impactval.reference.beams import Modes

    md = Modes(np.array([1e3, 2e3, 2e3, 5e3]), np.array([0.1, 0.2, 0.2, 0.3]), np.array([0.9, 0.5, -0.7, 0.2]))
    merged = linear.linear_system(md, 0.02, 1e6)
    assert merged.dense is None and len(merged.p) == 4                  # ball + 3 modes
    plate = impactval.load_scene("plate_ss_rectangular")
    square = dataclasses.replace(plate, target=dataclasses.replace(plate.target, length=0.25, width=0.25,
                                                                    impact_at=(0.37, 0.37)))
    sq_modes = structure_modes(square, 200, residual=True)
    k_sq = plate_impact(square.ball.mass, square.alpha, square.ball.velocity).k0
    cases = [(md, 0.02, 1e6, 5.0, 0.05), (sq_modes, square.ball.mass, k_sq, square.ball.velocity, 2e-3)]
    fast = [solve_linear_modes(m, mass, k, v, window=w) for m, mass, k, v, w in cases]
    monkeypatch.setattr(linear, "merge_repeated_modes", lambda o, p, m: (o, p, m))
    dense_sys = linear.linear_system(md, 0.02, 1e6)
    assert dense_sys.dense is not None and dense_sys.U is dense_sys.dense
    y = np.arange(5.0)
    assert np.allclose(dense_sys.project(y), dense_sys.dense.T @ y) and np.allclose(dense_sys.expand(y),
                                                                                     dense_sys.dense @ y)
    assert np.allclose(dense_sys.U.T @ np.diag(dense_sys.mass_diag) @ dense_sys.U, np.eye(5), atol=1e-12)
    for a, (m, mass, k, v, w) in zip(fast, cases):
        b = solve_linear_modes(m, mass, k, v, window=w)
        for x, y_ in zip((a.metrics.t_m, a.metrics.f_m, a.metrics.delta_m), (b.metrics.t_m, b.metrics.f_m,
                                                                               b.metrics.delta_m)):
            assert x == pytest.approx(y_, rel=1e-12)
        assert len(a.contacts) == len(b.contacts) and len(a.t) == len(b.t)
        assert np.max(np.abs(a.x_structure - b.x_structure)) <= 1e-12 * np.max(np.abs(b.x_structure))
    assert fast[0].t[-1] > 0.05 and fast[1].t[-1] > 2e-3                 # the windows' free flight compared too
