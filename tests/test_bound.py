"""The reported uncertainty against the real error (issue 17 item 5).

Honesty: on random scenes (beams of all three supports and both theories, plates, modal targets, rigid plates;
random materials, balls 1-50 mm, 0.01-10 m/s, impact points; explicit mode counts with and without the
residual flexibility, and the automatic mode count) the real error does not exceed the reported uncertainty.
Real errors come from the independent ODE form (scipy DOP853, reference/ode.py) where it applies (no residual
flexibility, few modes) and otherwise from a much tighter solve (tol 1e-12, or many more modes at 1e-11).
Tightness: on the catalogue the reported uncertainty is within 10x of the real error where measured so (the
scenes listed in TEN_X_MISSES, none since round 11, would not make it; measured ratios in docs/reference.md).
"""
from __future__ import annotations

import numpy as np
import pytest

import impactval
from impactval.reference.hertz import plate_impact
from impactval.reference.ode import solve_ode
from impactval.reference.solve import solve_modes, structure_modes
from impactval.scenarios.scene import CATALOGUE_DIR, scene_from_dict

MATERIALS = ("steel", "aluminium", "titanium", "glass", "tungsten-carbide", "pmma")


def _log_uniform(rng, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def random_scene(rng, kinds=("beam", "beam", "plate", "modal", "rigid-plate"), timoshenko: float = 0.3,
                 clamped_timoshenko: bool = True):
    """(scene, explicit mode count or None, residual) for one random case (`clamped_timoshenko=False`: Timoshenko
    beams simply supported only, whose modes are closed-form and cheap in the thousands)."""
    ball = {"radius": _log_uniform(rng, 1e-3, 0.05), "velocity": _log_uniform(rng, 0.01, 10.0),
            "material": str(rng.choice(MATERIALS))}
    kind = str(rng.choice(kinds))
    n, residual = None, False
    if kind == "beam":
        support = str(rng.choice(["simply-supported", "clamped-clamped", "cantilever"]))
        height = _log_uniform(rng, 0.005, 0.05)
        target = {"kind": "beam", "material": str(rng.choice(MATERIALS)), "support": support,
                  "length": height * _log_uniform(rng, 4.0, 100.0), "width": _log_uniform(rng, 0.005, 0.05),
                  "height": height,
                  "impact_at": float(rng.uniform(0.1, 1.0) if support == "cantilever" else rng.uniform(0.05, 0.95))}
        if rng.random() < timoshenko:
            target["theory"] = "timoshenko"
            if not clamped_timoshenko:
                target["support"], target["impact_at"] = "simply-supported", float(rng.uniform(0.05, 0.95))
        n, residual = int(rng.choice([4, 8, 40, 160])), bool(rng.random() < 0.4)
    elif kind == "plate":
        target = {"kind": "plate", "material": str(rng.choice(MATERIALS)), "support": "simply-supported",
                  "length": _log_uniform(rng, 0.1, 1.0), "width": _log_uniform(rng, 0.1, 1.0),
                  "thickness": _log_uniform(rng, 0.003, 0.03),
                  "impact_at": [float(rng.uniform(0.05, 0.95)), float(rng.uniform(0.05, 0.95))]}
        n, residual = int(rng.choice([8, 24, 120])), bool(rng.random() < 0.4)
    elif kind == "modal":
        scene = scene_from_dict({"name": "random", "ball": ball,
                                 "target": {"kind": "rigid-plate", "material": "steel"}})
        p = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
        count = int(rng.integers(1, 8))
        w = np.array([_log_uniform(rng, 0.3, 1000.0) for _ in range(count)])    # omega delta_m / v0
        s = np.array([_log_uniform(rng, 0.01, 30.0) for _ in range(count)])     # (m0 / m) phi^2
        phi = rng.uniform(0.2, 1.0, count)
        target = {"kind": "modal", "material": str(rng.choice(MATERIALS)), "omega": (w * p.v0 / p.delta_m).tolist(),
                  "modal_mass": (scene.ball.mass * phi**2 / s).tolist(), "phi": phi.tolist()}
    else:
        target = {"kind": "rigid-plate", "material": str(rng.choice(MATERIALS))}
    return scene_from_dict({"name": "random", "ball": ball, "target": target}), n, residual


def _metrics(m) -> np.ndarray:
    return np.array([m.t_m, m.f_m, m.delta_m])


def _check_honest(m, unc, truth, label: str) -> float:
    """Assert |error| <= uncertainty per metric; return reported / real (max over metrics)."""
    x, u, tr = _metrics(m), _metrics(unc), _metrics(truth)
    err = np.abs(x - tr)
    assert np.all(err <= u), f"{label}: errors {err / tr} above the reported {u / x}"
    return float(np.max(u / x) / max(np.max(err / tr), 1e-16))


def _modes_case(seed: int):
    scene, n, residual = random_scene(np.random.default_rng(seed))
    md = structure_modes(scene, n, residual=residual) if n is not None else structure_modes(scene)
    return scene, md, n, residual


@pytest.mark.parametrize("seed", range(12))
def test_uncertainty_bounds_the_ode_form_on_random_scenes(seed):
    """Fast subset: random scenes of at most 8 modes without residual flexibility against DOP853 at rtol 1e-13."""
    rng = np.random.default_rng(1000 + seed)
    scene, n, _ = random_scene(rng)
    n = None if n is None else min(n, 8)
    md = structure_modes(scene, n) if n is not None else structure_modes(scene)
    m0, alpha, v0 = scene.ball.mass, scene.alpha, scene.ball.velocity
    truth, _ = solve_ode(md, m0, alpha, v0, rtol=1e-13, atol=1e-15)
    for tol in (1e-5, 1e-7):
        run, unc = solve_modes(md, m0, alpha, v0, tol)
        _check_honest(run.metrics, unc, truth, f"seed {1000 + seed}, {scene.target.kind}, tol {tol:g}")
        assert max(_metrics(unc) / _metrics(run.metrics)) <= tol


@pytest.mark.parametrize("seeds", [range(150), pytest.param(range(150, 1150), marks=pytest.mark.slow)],
                         ids=["150-scenes", "1000-scenes"])
def test_uncertainty_bounds_the_real_error_on_many_random_scenes(seeds):
    """Random scenes (up to 160 modes, with and without residual flexibility) at tol 1e-4, 1e-6, 1e-8 against the
    same model at tol 1e-12: the real error never exceeds the reported uncertainty (measured with the dense peak: 0 of
    11,448 comparisons on seeds 0-3999 and 0 of 11,476 on 8000-11999, 2 of 11,454 on seeds 4000-7999, 1.17x and 1.69x
    (round 6: the re-measured unresolved-mode table and its binned quadrature sum; round 5 had 1.09x and 1.69x there);
    round 9 (the smallest steps' error bounded, the step rules from a short contact's own duration): 0 of 45,658 on
    seeds 0-15999 and 1 of 11,398 (1.06x, seed 17666) on seeds 16000-19999, held out from round 9; docs/reference.md).
    The median of reported / real is below 10 (7.3 measured; 6.9 before round 9)."""
    ratios, misses = [], []
    for seed in seeds:
        scene, md, n, residual = _modes_case(seed)
        m0, alpha, v0 = scene.ball.mass, scene.alpha, scene.ball.velocity
        try:
            truth, truth_unc = solve_modes(md, m0, alpha, v0, 1e-12)
        except impactval.ImpactvalError:      # refused: a structure far softer than the contact
            continue
        for tol in (1e-4, 1e-6, 1e-8):
            run, unc = solve_modes(md, m0, alpha, v0, tol)
            x, u, tr = _metrics(run.metrics), _metrics(unc), _metrics(truth.metrics)
            err = np.abs(x - tr)
            if np.max(err / tr) < 100 * max(_metrics(truth_unc) / tr):
                continue          # the real error is at the truth's own level: nothing to compare
            if np.any(err > u):
                misses.append((float(np.max(err / u)), seed, scene.target.kind, n, residual, tol))
            ratios.append(float(np.max(u / x) / np.max(err / tr)))
    assert len(ratios) > 2.5 * len(seeds)
    assert not misses, misses
    assert np.median(ratios) < 10.0


def test_uncertainty_bounds_the_smallest_steps_error_on_an_over_resolved_plate(monkeypatch):
    """Held-out seed 6832 (a 120-mode plate at tol 1e-4): the unresolved modes set the base step far shorter than tol
    needs (n = 512), so the Richardson estimate is tiny while the error of the smallest steps at touch and separation,
    set by tol through J and converging at order 2.5 only, is most of the real error. Without its bound
    (SMALLEST_STEP_C = 0, the rule before round 9) the real error is above the reported uncertainty; with it the
    runs take more step levels and the uncertainty bounds the error."""
    from impactval.reference import solve as ref_solve

    scene, md, _, _ = _modes_case(6832)
    assert scene.target.kind == "plate"
    m0, alpha, v0 = scene.ball.mass, scene.alpha, scene.ball.velocity
    truth = solve_modes(md, m0, alpha, v0, 1e-12)[0].metrics
    run, unc = solve_modes(md, m0, alpha, v0, 1e-4)
    ratio = _check_honest(run.metrics, unc, truth, "seed 6832, tol 1e-4")
    assert ratio < 100.0
    monkeypatch.setattr(ref_solve, "SMALLEST_STEP_C", 0.0)
    run, unc = solve_modes(md, m0, alpha, v0, 1e-4)
    err, u = np.abs(_metrics(run.metrics) - _metrics(truth)), _metrics(unc)
    assert np.any(err > u), "the case no longer needs the smallest steps' bound: pick another"


@pytest.mark.parametrize("seed, contact_share", [(7263, 0.82), (6747, 0.055)])
def test_uncertainty_bounds_the_error_of_contacts_much_shorter_than_the_rigid_plate_time(seed, contact_share):
    """Strongly coupled light modes move with the ball like a lighter target, so the contact is shorter than the
    rigid-plate time the step rules start from: held-out seed 7263 (a 7-mode target, couplings s up to 27, contact
    0.82 t_plate) took the 32 base steps per t_plate at tol 1e-4, whose coarsest run was not asymptotic, and erred
    8.3e-5 against a reported 7.3e-5 (1.15x). The rules now take the first contact's own duration once a run has found
    it shorter (kernel.SHORT_CONTACT): at least 32 base steps per contact and the smallest step, and its error bound,
    relative to the contact. Seed 6747 (a plate, contact 0.055 t_plate) checks the second half: with the step count
    from the contact but the smallest step from t_plate it erred 4.1e-5 against 3.6e-5."""
    scene, md, _, _ = _modes_case(seed)
    m0, alpha, v0 = scene.ball.mass, scene.alpha, scene.ball.velocity
    truth = solve_modes(md, m0, alpha, v0, 1e-12)[0].metrics
    assert truth.t_m / plate_impact(m0, alpha, v0).t_m == pytest.approx(contact_share, rel=0.02)
    for tol in (1e-4, 1e-6):
        run, unc = solve_modes(md, m0, alpha, v0, tol)
        _check_honest(run.metrics, unc, truth, f"seed {seed}, tol {tol:g}")


def _truth_auto(scene, modes_used: int):
    """The scene with 8x the modes (32x for Timoshenko: its truncation error falls only ~2.5x per doubling) and
    their residual flexibility, tol 1e-11: independent of the mode-count estimate under test."""
    mult = 32 if getattr(scene.target, "theory", "") == "timoshenko" else 8
    try:
        md = structure_modes(scene, mult * modes_used, residual=True)
        return solve_modes(md, scene.ball.mass, scene.alpha, scene.ball.velocity, 1e-11)[0].metrics
    except impactval.ImpactvalError:    # over the node budget (a heavy ball): 8x the modes (Timoshenko: e/24 at worst)
        md = structure_modes(scene, 8 * modes_used, residual=True)
        return solve_modes(md, scene.ball.mass, scene.alpha, scene.ball.velocity, 1e-10)[0].metrics


def auto_and_truth(scene, tol: float):
    """(impactval.solve(scene, tol) with the automatic mode count, its truth by `_truth_auto`), or None when either is
    refused (a structure far softer than the contact, or a truth over the node budget)."""
    try:
        r = impactval.solve(scene, tol=tol)
        return r, _truth_auto(scene, r.modes)
    except impactval.ImpactvalError:
        return None


def _check_auto(scene, tol: float, label: str) -> float:
    """impactval.solve(scene, tol) with the automatic mode count, checked against `_truth_auto` (`_check_honest`)."""
    r = impactval.solve(scene, tol=tol)
    return _check_honest(r.metrics, r.uncertainty, _truth_auto(scene, r.modes), label)


@pytest.mark.slow
def test_automatic_mode_count_is_honest_on_random_beams():
    """Random beams (both theories) with the automatic mode count: time step + truncation bound the real error."""
    for seed in range(25):
        scene, _, _ = random_scene(np.random.default_rng(5000 + seed), kinds=("beam",), clamped_timoshenko=False)
        for tol in (1e-4, 1e-6):
            if (got := auto_and_truth(scene, tol)) is not None:
                r, truth = got
                _check_honest(r.metrics, r.uncertainty, truth, f"seed {5000 + seed}, tol {tol:g}")


@pytest.mark.parametrize("seed", [5168, 5180, 5185, 5303])
def test_automatic_mode_count_is_honest_where_dropped_modes_cancel(seed):
    """The four random beams of seeds 5000-5399 whose reported uncertainty was below the real error until round 7
    (1.19-1.92x): the difference between two counts nearly vanished while the modes beyond them did not (seed 5168:
    modes 7-12 cancel in f_m, mode 13 alone moves it 4.6e-5), or the first dropped mode was still dynamic (5180, a
    Timoshenko beam). Both tolerances, time step + truncation against 8x the modes (32x Timoshenko)."""
    scene, _, _ = random_scene(np.random.default_rng(seed), kinds=("beam",), clamped_timoshenko=False)
    for tol in (1e-4, 1e-6):
        _check_auto(scene, tol, f"seed {seed}, tol {tol:g}")


@pytest.mark.parametrize("seed", [9021, 9055])
def test_automatic_mode_count_is_honest_on_plates_hit_near_a_nodal_line(seed):
    """Random plates whose reported uncertainty was below the real error with the observed-ratio rule (until round 7):
    seed 9055 (impact at y = 0.5008 of the width: modes 3-4 all but still there, the count stopped at 4 modes, 40x
    at tol 1e-6) and 9021 (2.4x at tol 1e-4). Both tolerances, time step + truncation against 8x the modes."""
    scene, _, _ = random_scene(np.random.default_rng(seed), kinds=("plate",))
    for tol in (1e-4, 1e-6):
        _check_auto(scene, tol, f"seed {seed}, tol {tol:g}")


def test_residual_flexibility_does_not_blur_the_end_of_contact():
    """A soft plate with a large residual flexibility (found by the random check): the contact end was located on
    delta = gap - R alpha delta^1.5, which is not smooth there, and t_m carried an error of order (smallest
    step)^1.5 that the estimate missed (8.8e-10 at tol 1e-8, reported 1.9e-10). Located on the gap it converges."""
    scene = scene_from_dict({
        "name": "soft_plate", "ball": {"radius": 0.013641643, "velocity": 0.45085453, "material": "glass"},
        "target": {"kind": "plate", "material": "pmma", "support": "simply-supported", "length": 0.23198387,
                   "width": 0.18917100, "thickness": 0.0066614698, "impact_at": [0.38299437, 0.51878908]}})
    md = structure_modes(scene, 24, residual=True)
    assert md.residual_flexibility > 1e-7
    m0, alpha, v0 = scene.ball.mass, scene.alpha, scene.ball.velocity
    truth, _ = solve_modes(md, m0, alpha, v0, 1e-12)
    for tol in (1e-6, 1e-8):
        run, unc = solve_modes(md, m0, alpha, v0, tol)
        _check_honest(run.metrics, unc, truth.metrics, f"tol {tol:g}")


#: catalogue and tests' scenes whose reported uncertainty at tol 1e-6 is more than 10x the real error (measured
#: ratio x 1.5; docs/reference.md). Asserted honest and not looser than this. Round 10 (the a-posteriori truncation
#: estimate: the dropped modes driven by the run's own force, solve._swept_truncation) took the automatic-mode scenes
#: from 10.4-35.8x to 4.4-17.4x; round 11 (each mode-count run's time step at tol / 32 instead of tol / 6,
#: solve.STEP_SHARE) to 3.2-9.6x, the four left above 10x included: cantilever_titanium 3.9 (16.6 at round 10),
#: rand_wc_on_steel_cantilever 4.8 (10.5), steel_cc_pmma_ball 8.5 (17.4), stubby_steel 6.1 (10.5); the closest to 10x:
#: light_ball_heavy_beam 9.6 (6.0: its step and truncation errors are of opposite sign, so the real total shrinks
#: faster than the estimate as the step's share falls), ti_ss_steel_heavy 8.2 (9.9), heavy_wc_slender_timoshenko 8.0
#: (8.6). None left.
TEN_X_MISSES: dict[str, float] = {}
#: tests/unseen scenes measured within 10x at tol 1e-6 (catalogue scenes not in TEN_X_MISSES are held to 10x, and so
#: are catalogue scenes added later; scenes added to tests/unseen later are checked for honesty only until measured
#: and listed here or above)
WITHIN_10X = ("cc_aluminium_0p3", "al_cantilever_glass", "glass_on_pmma", "heavy_wc_slender",
              "heavy_wc_slender_timoshenko", "rand_glass_on_pmma_ss", "rand_wc_on_pmma_cc", "stubby_steel_timoshenko",
              "ti_ss_steel_heavy", "cantilever_titanium", "rand_wc_on_steel_cantilever", "steel_cc_pmma_ball",
              "stubby_steel")
_TEST_DIR = CATALOGUE_DIR.parents[1] / "tests"
_SCENES = sorted(p.stem for p in CATALOGUE_DIR.glob("*.toml")) + \
    [str(p) for p in sorted((_TEST_DIR / "unseen").glob("*.toml"))]


_SLOW_TRUTH = ("plate_ss_rectangular", "heavy_wc_slender_timoshenko")      # truth with thousands of modes: 3-46 s


def _stem(name: str) -> str:
    return name.rsplit("/", 1)[-1].removesuffix(".toml")


@pytest.mark.parametrize("name", [pytest.param(s, marks=pytest.mark.slow) if _stem(s) in _SLOW_TRUTH else s
                                  for s in _SCENES], ids=_stem)
def test_catalogue_uncertainty_is_within_10x_of_the_real_error(name):
    scene = impactval.load_scene(name)
    r = impactval.solve(scene, tol=1e-6)
    kind = scene.target.kind
    if kind in ("beam", "plate") and getattr(scene.target, "modes", None) is None:
        truth = _truth_auto(scene, r.modes)
    elif kind == "rigid-plate":
        truth = plate_impact(scene.ball.mass, scene.alpha, scene.ball.velocity)
    else:
        truth = impactval.solve(scene, tol=1e-12).metrics
    ratio = _check_honest(r.metrics, r.uncertainty, truth, name)
    stem = _stem(name)
    if "/" in name and stem not in TEN_X_MISSES and stem not in WITHIN_10X:
        return                 # a tests/unseen scene not measured yet: honesty only (above)
    assert ratio <= TEN_X_MISSES.get(stem, 10.0), f"{stem}: reported / real = {ratio:.1f}"


@pytest.mark.parametrize("w, theta", [(30.0, 3.0), (100.0, 3.5), (300.0, 2.5)])
def test_dense_peak_follows_the_ringing_between_nodes(w, theta):
    """delta carries each mode's ringing (amplitude ~ s w^-3.5); nodes omega H = 2.5-3.5 apart cannot interpolate it.
    The dense peak (kernel.dense_peak: the modes swept again and the peak found on sub-steps) against the ODE form
    (DOP853, rtol 1e-13) is >= 10x closer than the interpolant of the node values was, and never below the largest
    node value."""
    from impactval.reference import kernel
    from impactval.reference.beams import Modes
    from impactval.reference.solve import GRADING_WINDOW, P_DEGREE, SMALLEST_STEP_FACTOR, _select

    m0, alpha, v0, s = 0.0327, 1.5384e10, 1.0, 1.0
    p = plate_impact(m0, alpha, v0)
    omega_i = w * v0 / p.delta_m
    md = Modes(np.array([omega_i]), np.array([m0 / s]), np.array([1.0]))
    truth, _ = solve_ode(md, m0, alpha, v0, rtol=1e-13, atol=1e-15)
    n = omega_i * p.t_m / theta
    omega, g, ew = _select(md)
    J = kernel.levels(n, 1e-8, SMALLEST_STEP_FACTOR)
    out = kernel.solve_triple(omega, g, ew, m0, alpha, v0, 0.0, p.t_m / n, J, P_DEGREE, GRADING_WINDOW * p.t_m,
                              int(6 * n + 60 * J + 50))
    t, d, f, fl = out[2], out[3], out[4], out[8]
    node_peak = kernel.contacts(t, d, fl, f, 0.0)[0, 2]
    dense = out[9][0, 2]
    err_nodes, err_dense = abs(node_peak / truth.delta_m - 1), abs(dense / truth.delta_m - 1)
    assert err_dense * 10 <= err_nodes, (err_dense, err_nodes)
    assert dense >= d.max() * (1 - 1e-12)
    print(f"w {w:g}, omega H {theta:g}: node peak {err_nodes:.2e}, dense peak {err_dense:.2e}")


@pytest.mark.slow
def test_automatic_mode_count_is_honest_on_a_clamped_timoshenko_beam_with_close_frequency_pairs():
    """Seed 5017 of random clamped Timoshenko beams (tungsten carbide, clamped-clamped, L/h 27): its bending and shear
    spectra come within 1.8e-4 and 3.4e-5 of each other, and until round 8 the frequency search missed such pairs
    (every higher mode shifted by two), so the solve at tol 1e-6 (1024 modes) was 1.53x above its reported
    uncertainty against a truth that missed them too. Time step + truncation against 32x the modes."""
    scene, _, _ = random_scene(np.random.default_rng(5017), kinds=("beam",), timoshenko=1.0, clamped_timoshenko=True)
    assert scene.target.support == "clamped-clamped" and scene.target.theory == "timoshenko"
    _check_auto(scene, 1e-6, "seed 5017, tol 1e-6")


def test_delta_max_is_taken_from_the_highest_of_two_near_equal_humps():
    """A heavy steel ball on a stubby 4-mode titanium beam: delta has two humps within 2e-3 of each other, and at tol
    1e-4 the run's largest node sits on the lower one (nodes sample the higher hump's top low). The H and 2H runs
    both took that hump, so their difference did not show it: delta_m was 1.3e-3 low against a reported 5.7e-6
    (230x) before every node local maximum near the top was refined (kernel.PEAK_MARGIN). Truth: the ODE form
    (DOP853, rtol 1e-12)."""
    scene = scene_from_dict({
        "name": "two_humps", "ball": {"radius": 0.0204, "velocity": 5.24, "material": "steel"},
        "target": {"kind": "beam", "material": "titanium", "support": "clamped-clamped", "length": 0.2313,
                   "width": 0.00785, "height": 0.0449, "impact_at": 0.6554, "modes": 4}})
    md = structure_modes(scene, 4)
    truth, _ = solve_ode(md, scene.ball.mass, scene.alpha, scene.ball.velocity, rtol=1e-12, atol=1e-14)
    r = impactval.solve(scene, tol=1e-4)
    # the case the test is for: two humps, and the run's largest node is not on the one holding the peak
    dense = impactval.solve(scene, tol=1e-10)
    end = int(np.argmax((r.delta <= 0) & (r.t > 0)))
    humps = [k for k in range(1, end) if r.delta[k] >= max(r.delta[k - 1], r.delta[k + 1])
             and r.delta[k] > 0.99 * r.delta[:end].max()]
    t_top = dense.t[int(np.argmax(dense.delta))]
    t_node = r.t[int(np.argmax(r.delta[:end]))]
    assert len(humps) == 2 and abs(t_node - t_top) > 0.2 * r.t_m, (humps, t_node, t_top)
    for tol in (1e-4, 1e-6, 1e-8):
        r = impactval.solve(scene, tol=tol)
        _check_honest(r.metrics, r.uncertainty, truth, f"tol {tol:g}")


def test_a_long_contact_at_tol_1e_12_returns_its_best_estimate_with_a_warning_instead_of_a_refusal():
    """A 160-mode glass beam under an aluminium ball, contact 4 t_plate (~1e5 nodes at tol 1e-12): the estimate stops at
    roundoff near 1.5e-12, so every finer try grew the step count until it passed the node budget, and the solve was
    refused as if the structure were far softer than the contact (0.3 % of random scenes at tol 1e-12). Now the try
    with the smallest estimate is returned, with that estimate, and solve() says the uncertainty is above tol."""
    scene, md, _, _ = _modes_case(1127)
    m0, alpha, v0 = scene.ball.mass, scene.alpha, scene.ball.velocity
    run, unc = solve_modes(md, m0, alpha, v0, 1e-12)
    loose, loose_unc = solve_modes(md, m0, alpha, v0, 1e-10)
    assert np.all(np.abs(_metrics(run.metrics) - _metrics(loose.metrics)) <= _metrics(unc) + _metrics(loose_unc))
    assert unc.t_m / run.metrics.t_m < 1e-11
    r = impactval.solve(scene, modes=160, tol=1e-12)
    rel = r.uncertainty.t_m / r.t_m
    assert (rel > 1e-12) == any("above tol 1e-12" in v for v in r.validity), (rel, r.validity)
