"""The reference kernel's faster paths (issue 17 item 5: cost per call at a given step sequence) against
independent values: the moment tables against their exact series in rational arithmetic, the fused degree-5 mode
sweep against the generic one, and repeated / interleaved solves against each other (caches keyed right)."""
from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import impactval
from impactval.reference import kernel
from impactval.reference.hertz import plate_impact
from impactval.reference.solve import P_DEGREE


def _exact_moment(theta: float, l: int, terms: int) -> tuple[float, float]:
    """K_l(theta) = int_0^1 e^{i theta (1 - s)} s^l ds = sum_m (i theta)^m l!/(l + m + 1)!, in rationals."""
    t = Fraction(theta)
    re = im = Fraction(0)
    power = Fraction(1)
    for m in range(terms):
        c = Fraction(math.factorial(l), math.factorial(l + m + 1)) * power
        if m % 4 == 0:
            re += c
        elif m % 4 == 1:
            im += c
        elif m % 4 == 2:
            re -= c
        else:
            im -= c
        power *= t
    return float(re), float(im)


THETAS = [1e-7, 3e-6, 1e-4, 0.01, 0.5, 1.5, 1.999, 2.0, 2.01, 3.0, 10.0]


@pytest.mark.parametrize("together", [True, False], ids=["one-level", "each-alone"])
def test_moment_tables_match_the_exact_series(together):
    """Kr + i Ki = g eta K_l(omega eta) for both branches (series below |theta| = 2, recurrence above). The series
    length is chosen per table level from its largest |theta| < 2: tiny and large phases in one level (`together`)
    and alone must both be exact to roundoff, the imaginary part of a tiny phase (~theta/42, far below the real
    part) on its own scale too (a shared length once cut it at 3.6e-13)."""
    p = P_DEGREE
    groups = [THETAS] if together else [[th] for th in THETAS]
    for group in groups:
        omega = np.array(group)
        g = np.linspace(0.5, 2.0, len(group))
        Er, Ei, Kr, Ki, S = kernel.moments(omega, g, 1.0, 0, p)
        assert np.array_equal(Er[0], np.cos(omega)) and np.array_equal(Ei[0], np.sin(omega))
        for i, th in enumerate(group):
            for l in range(p + 1):
                re, im = _exact_moment(th, l, terms=120)
                mag = math.hypot(re, im)
                assert abs(Kr[0, l, i] / g[i] - re) <= 4e-15 * mag, (th, l)
                assert abs(Ki[0, l, i] / g[i] - im) <= 4e-15 * mag, (th, l)
                if th < 2.0:       # the imaginary part on its own scale
                    assert abs(Ki[0, l, i] / g[i] - im) <= 1e-14 * abs(im), (th, l)
        assert np.allclose(S[0], Ki[0].sum(axis=1), rtol=1e-14, atol=0)


def test_moment_levels_depend_on_their_step_and_the_finest_step():
    """Level j of a table set for base step H with J levels equals level j + k of the set for 2^k H with J + k levels
    (the same step and the same finest step: e^{i omega eta} is taken by cos/sin on the same levels, counted from the
    finest, and by angle doubling on the others), bit for bit: the fine run's tables (4H, J + 2 levels, from level 2)
    are those of a set for H alone (`integrate`)."""
    rng = np.random.default_rng(17)
    omega = np.sort(rng.uniform(1e2, 1e6, 50))
    g = rng.uniform(0.1, 1.0, 50)
    H = 3e-5
    for J in (0, 1, 4, 6):
        alone = kernel.moments(omega, g, H, J, P_DEGREE)
        for k in (1, 2, 3):
            shared = kernel.moments(omega, g, H * 2.0**k, J + k, P_DEGREE)
            for a, b in zip(alone, shared):
                assert np.array_equal(a, b[k:])


@pytest.mark.parametrize("ascending", [True, False])
def test_doubled_levels_match_the_exact_series(ascending):
    """Every level of a multi-level table set (e^{i omega eta} by angle doubling on two levels of three; each branch
    over its own modes when the modes ascend, both over all modes otherwise) against the exact series in rationals,
    as the single-level sets above: K_l to 4e-15 of its magnitude, e^{i omega eta} to 1e-15 of math.cos/sin of the same
    phase (the roundoff of two doublings in a row: 6.9e-16 measured on 4,160 frequencies)."""
    p = P_DEGREE
    order = np.argsort(THETAS) if ascending else np.arange(len(THETAS))[::-1]
    base = np.array(THETAS)[order]
    g = np.linspace(0.5, 2.0, len(base))
    for J in (1, 2, 3, 5):
        Er, Ei, Kr, Ki, S = kernel.moments(base, g, 2.0**J, J, p)     # the finest level J has eta = 1
        for j in range(J + 1):
            eta = 2.0**(J - j)
            for i, th0 in enumerate(base):
                th = th0 * eta
                assert abs(Er[j, i] - math.cos(th)) <= 1e-15 and abs(Ei[j, i] - math.sin(th)) <= 1e-15, (J, j, th)
                for l in range(p + 1):
                    re, im = _exact_moment(th, l, terms=int(80 + 3 * th))
                    mag = math.hypot(re, im)
                    assert abs(Kr[j, l, i] / (g[i] * eta) - re) <= 4e-15 * mag, (J, j, th, l)
                    assert abs(Ki[j, l, i] / (g[i] * eta) - im) <= 4e-15 * mag, (J, j, th, l)
            assert np.allclose(S[j], Ki[j].sum(axis=1), rtol=1e-14, atol=0)


def test_fused_sweep_equals_the_generic_sweep():
    """The degree-5 sweep (one pass over the modes, from one state buffer into another) and the generic per-degree sweep
    (in place) give the same new modal state, energy and next free displacement to roundoff (and the degree-5 sweep the
    new structure displacement), and the degree-5 sweep leaves the state it swept from as it was."""
    rng = np.random.default_rng(5)
    n = 37                                   # not a multiple of the vector width
    omega = rng.uniform(1e3, 1e6, n)
    g = rng.uniform(1e-9, 1e-7, n)
    Er, Ei, Kr, Ki, _ = kernel.moments(omega, g, 2e-6, 3, P_DEGREE)
    ew = omega / g
    coef = rng.normal(size=P_DEGREE + 1) * 1e3
    for jt in range(4):
        y0r, y0i = rng.normal(size=n) * 1e-6, rng.normal(size=n) * 1e-6
        ar, ai = np.zeros(n), np.zeros(n)
        br, bi = y0r.copy(), y0i.copy()
        e6, nxt6, ysum6 = kernel._sweep6(Er, Ei, Kr, Ki, jt, coef, y0r, y0i, ar, ai, ew)
        assert np.array_equal(y0r, br) and np.array_equal(y0i, bi)       # the state swept from is left as it was
        eg, nxtg = kernel._sweep(Er, Ei, Kr, Ki, jt, coef, br, bi, ew, P_DEGREE)
        # independent: complex arithmetic in numpy
        y = (Er[jt] + 1j * Ei[jt]) * (y0r + 1j * y0i) + ((Kr[jt] + 1j * Ki[jt]) * coef[:, None]).sum(axis=0)
        scale = np.abs(y).max()
        for yr_, yi_ in ((ar, ai), (br, bi)):
            assert np.abs(yr_ + 1j * yi_ - y).max() <= 1e-14 * scale
        e_ref = float(np.sum(ew * np.abs(y) ** 2))
        nxt_ref = float(np.sum(((Er[jt] + 1j * Ei[jt]) * y).imag))
        for e_, nxt_ in ((e6, nxt6), (eg, nxtg)):
            assert abs(e_ - e_ref) <= 1e-13 * e_ref
            assert abs(nxt_ - nxt_ref) <= 1e-13 * np.abs(y).sum()
        assert abs(ysum6 - float(y.imag.sum())) <= 1e-13 * np.abs(y).sum()     # the structure displacement


def test_interleaved_solves_repeat_exactly():
    """Solves that share the per-scene caches (modes, kernel arrays, plate impact) give the same answer whatever
    was solved in between: scene A, then B (same ball and contact, other beam), then A again."""
    a = impactval.load_scene("beam_ss_midspan")
    b = impactval.load_scene("beam_ss_quarter")
    first = impactval.solve(a, tol=1e-6, modes=160)
    other = impactval.solve(b, tol=1e-6, modes=160)
    again = impactval.solve(a, tol=1e-6, modes=160)
    assert (first.t_m, first.f_m, first.delta_m) == (again.t_m, again.f_m, again.delta_m)
    assert first.uncertainty == again.uncertainty and np.array_equal(first.t, again.t)
    assert other.t_m != first.t_m                  # another scene's answer, not a cached one
    # the plate impact the solves share is the closed form of each scene's own ball and contact
    pa = plate_impact(a.ball.mass, a.alpha, a.ball.velocity)
    from impactval.reference.solve import _plate
    assert _plate(a.ball.mass, a.alpha, a.ball.velocity) == pa


def test_build_makes_what_init_makes():
    """result.build (the solver's cheap construction) gives the object the dataclass __init__ gives: the same fields
    in the same order, defaults, fresh default-factory values per instance, __post_init__'s status conversion; bad
    field names raise TypeError as __init__ does."""
    import dataclasses

    from impactval.reference.result import Contact, ImpactResult, Metrics, Status, build

    kw = dict(scene="s", source="reference", model="hertz-modal", t_m=1e-4, f_m=2e3, delta_m=3e-6,
              uncertainty=Metrics(1e-10, 1e-3, 1e-12), modes=7, t=np.arange(3.0), settings={"tol": 1e-6},
              contacts=(Contact(0.0, 1e-4, 2e3, 3e-6),), status="ok", validity=("w",))
    made, built = ImpactResult(**kw), build(ImpactResult, dict(kw))
    assert list(vars(made)) == list(vars(built)) == [f.name for f in dataclasses.fields(ImpactResult)]
    for name in vars(made):
        a, b = getattr(made, name), getattr(built, name)
        assert (np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b or (a != a and b != b)), name   # NaN
    assert built.status is Status.OK and built.success
    other = build(ImpactResult, dict(kw))
    assert other.diagnostics is not built.diagnostics and other.f is not built.f       # fresh factory values
    with pytest.raises(dataclasses.FrozenInstanceError):
        built.t_m = 0.0
    with pytest.raises(TypeError, match="no field 'tm'"):
        build(Metrics, {"tm": 1.0, "f_m": 1.0, "delta_m": 1.0})
    with pytest.raises(TypeError, match="needs field 'delta_m'"):
        build(Metrics, {"t_m": 1.0, "f_m": 1.0})
    assert build(Metrics, {"t_m": 1.0, "f_m": 2.0, "delta_m": 3.0}) == Metrics(1.0, 2.0, 3.0)
    # a dict naming every field (in another order) is taken as it is, __post_init__ still run
    full = {f.name: getattr(made, f.name) for f in reversed(dataclasses.fields(ImpactResult))}
    full["status"] = "ok"
    taken = build(ImpactResult, full)
    assert vars(taken) is full and taken.status is Status.OK
    assert all(getattr(taken, n) is getattr(made, n) for n in vars(made) if n != "status")


def test_per_scene_caches_follow_the_scene():
    """The per-target mode cache and the per-scene validity limits never hand one scene's data to another: two
    scenes differing in one field (the beam's height; the ball's yield stress) solve as freshly built copies do,
    also when solved in turn."""
    import dataclasses

    from impactval.reference.validity import hertz_validity

    a = impactval.load_scene("beam_ss_midspan")
    b = dataclasses.replace(a, target=dataclasses.replace(a.target, height=a.target.height * 1.5))
    ra, rb, ra2 = (impactval.solve(s, tol=1e-6, modes=40) for s in (a, b, a))
    assert rb.t_m != ra.t_m and (ra.t_m, ra.f_m, ra.delta_m) == (ra2.t_m, ra2.f_m, ra2.delta_m)
    fresh_b = dataclasses.replace(b, name=b.name)            # another object, equal fields: no cache hit by identity
    assert impactval.solve(fresh_b, tol=1e-6, modes=40).t_m == rb.t_m
    # validity: the same result read against a ball that yields far sooner, and back
    weak = dataclasses.replace(a.ball.material, name="weak", yield_stress=1e6)
    c = dataclasses.replace(a, ball=dataclasses.replace(a.ball, material=weak))
    warn_a, warn_c, warn_a2 = (hertz_validity(s, ra.f_m, ra.delta_m) for s in (a, c, a))
    assert any("weak" in w for w in warn_c) and not any("weak" in w for w in warn_a) and warn_a == warn_a2


def test_solve_plans_follow_the_scene_and_the_arguments():
    """solve()'s per-scene plans (kernel arguments kept per scene object, tol, window and mode count): every argument
    combination solves as a fresh scene does, in any order, and a scene with a mutable part is planned afresh each
    call (its ball made heavier in place changes the answer)."""
    import dataclasses

    a = impactval.load_scene("beam_ss_midspan")
    calls = [(1e-6, 0.0, 40), (1e-4, 0.0, 40), (1e-6, 0.0, 20), (1e-6, 2e-4, 40), (1e-6, 0.0, 40)]
    got = [impactval.solve(a, tol=t, window=w, modes=n) for t, w, n in calls]
    for (t, w, n), r in zip(calls, got):
        fresh = impactval.solve(dataclasses.replace(a, name=a.name), tol=t, window=w, modes=n)
        assert (r.t_m, r.f_m, r.delta_m, r.n_steps, r.modes) == (fresh.t_m, fresh.f_m, fresh.delta_m, fresh.n_steps,
                                                                  fresh.modes)
        assert r.uncertainty == fresh.uncertainty and len(r.contacts) == len(fresh.contacts)
    assert got[0].t_m != got[2].t_m and got[0].n_steps != got[1].n_steps and len(got[3].t) > len(got[0].t)

    class Ball:                                   # a plain (mutable) object as the ball: no plan may be kept
        radius, material, velocity, mass = a.ball.radius, a.ball.material, a.ball.velocity, a.ball.mass

    ball = Ball()
    s = dataclasses.replace(a, ball=ball)
    light = impactval.solve(s, tol=1e-6, modes=40)
    assert light.t_m == got[0].t_m
    ball.mass *= 4.0
    heavy = impactval.solve(s, tol=1e-6, modes=40)
    assert heavy.t_m > 1.2 * light.t_m


def test_validity_of_a_mutable_scene_is_not_kept():
    """A scene with a mutable part (a plain object as the ball's material) is checked afresh each call: changing
    its yield stress in place changes the warnings."""
    import dataclasses

    from impactval.reference.validity import hertz_validity

    a = impactval.load_scene("beam_ss_midspan")
    r = impactval.solve(a, tol=1e-4, modes=20)

    class Mat:                                    # equal to nothing else: ball and target are checked apart
        name, young, poisson, yield_stress = "mutable", a.ball.material.young, a.ball.material.poisson, 1e12

    m = Mat()
    s = dataclasses.replace(a, ball=dataclasses.replace(a.ball, material=m))
    assert not any("mutable" in w for w in hertz_validity(s, r.f_m, r.delta_m))
    m.yield_stress = 1e6
    assert any("mutable" in w for w in hertz_validity(s, r.f_m, r.delta_m))


def test_contact_equation_root_is_exact_to_roundoff():
    """kernel._contact_root (its series in e = c sqrt(D) up to e = 0.01, Newton on sqrt(delta) and a last Newton step
    on delta above) against the root of delta + c delta^1.5 = D and its square root in 50-digit decimal arithmetic
    (bisection, independent of the kernel), over c = B alpha spanning the structure-dominated (c sqrt(D) << 1, the
    series) to the contact-dominated (>> 1) regime, plus 300 random pairs; `_solve_contact` returns the same delta."""
    from decimal import Decimal, getcontext

    getcontext().prec = 50
    rng = np.random.default_rng(7)
    pairs = [(D, e) for D in (1e-12, 3e-9, 1e-6, 2e-5, 1e-3)
             for e in (1e-8, 1e-5, 1e-3, 0.003, 0.006, 0.0099, 0.01, 0.0101, 0.1, 1.0, 1.01, 7.0, 1e3, 1e8)]
    pairs += [(10.0 ** rng.uniform(-13, -2), 10.0 ** rng.uniform(-9, 9)) for _ in range(300)]
    worst_d = worst_s = 0.0
    for D, c_sqrtD in pairs:
        c = c_sqrtD / math.sqrt(D)
        B, alpha = c / 1e10, 1e10
        got, root = kernel._contact_root(D, B, alpha)
        assert kernel._solve_contact(D, B, alpha) == got
        Dd, cd = Decimal(D), Decimal(B) * Decimal(alpha)
        lo, hi = Decimal(0), Dd
        for _ in range(200):
            mid = (lo + hi) / 2
            if mid + cd * mid * mid.sqrt() > Dd:
                hi = mid
            else:
                lo = mid
        exact = (lo + hi) / 2
        worst_d = max(worst_d, abs(got - float(exact)) / float(exact))
        worst_s = max(worst_s, abs(root - float(exact.sqrt())) / float(exact.sqrt()))
    assert worst_d <= 4.5e-16, worst_d
    assert worst_s <= 4.5e-16, worst_s


def _exact_lagrange(sig: list[Fraction]) -> list[list[Fraction]]:
    """L[k][l]: coefficient of s^l in the Lagrange basis polynomial of node k of sig, in rationals."""
    m = len(sig) - 1
    out = []
    for k in range(m + 1):
        poly = [Fraction(1)]
        for q in range(m + 1):
            if q != k:                               # poly *= (s - sig_q) / (sig_k - sig_q)
                den = sig[k] - sig[q]
                nxt = [Fraction(0)] * (len(poly) + 1)
                for l, a in enumerate(poly):
                    nxt[l + 1] += a / den
                    nxt[l] -= a * sig[q] / den
                poly = nxt
        out.append(poly)
    return out


def test_stencil_cache_holds_the_exact_lagrange_coefficients_of_the_graded_steps():
    """run's stencil cache (keyed by the step levels, integers) holds, for the stencils of a graded run (steps H/2^j
    halving towards touch and separation), the Lagrange coefficients of the node positions in units of the new step,
    computed here in rationals from the run's own node times (each position rounded to a multiple of 2^-20: the node
    times carry roundoff, the scheme's positions are exact dyadic numbers). Also: the three runs of solve_triple
    share one cache, and a run with its own cache gives the node values of one with the shared cache."""
    scene = impactval.load_scene("beam_ss_midspan")
    from impactval.reference.solve import _select, structure_modes

    md = structure_modes(scene, 40)
    omega, g, ew = _select(md)
    m0, alpha, v0 = scene.ball.mass, scene.alpha, scene.ball.velocity
    pl = plate_impact(m0, alpha, v0)
    H, J, p = pl.t_m / 37.0, 9, P_DEGREE
    Er, Ei, Kr, Ki, S = kernel.moments(omega, g, 4.0 * H, J + 2, p)
    cache = kernel.stencil_cache(p)
    runs = {}
    for j0, base in ((0, 4.0 * H), (1, 2.0 * H), (2, H)):      # the order solve_triple runs them in
        out = kernel.run(ew, m0, alpha, v0, md.residual_flexibility, base, J, p, 0.2 * pl.t_m, 0.0, Er, Ei, Kr, Ki,
                         S, 4000, j0, None, 0.0, None, None, cache)
        assert out[0] == kernel.STATUS_OK
        runs[j0] = (base, out)
    base, out = runs[2]
    cnt, t = out[1], out[2]
    own = kernel.run(ew, m0, alpha, v0, md.residual_flexibility, H, J, p, 0.2 * pl.t_m, 0.0, Er, Ei, Kr, Ki, S, 4000,
                     2, None, 0.0, None)
    assert own[1] == cnt                       # delta the same to roundoff (another compiled specialisation of run)
    assert np.max(np.abs(own[3][:cnt] - out[3][:cnt])) <= 1e-14 * np.max(out[3][:cnt])
    levels = [kernel._level(t[k] - t[k - 1], base) for k in range(1, cnt)]
    assert sorted(set(levels)) == list(range(J + 1))                       # every level is used
    checked, keys = 0, set()
    for k in range(1, cnt):                                                # the step from node k - 1 to node k
        first = max(k - 1 - p + 1, 0)
        m = k - first
        j = levels[k - 1]
        glev = np.array([levels[k - 2 - i] if k - 2 - i >= 0 else 0 for i in range(p)], dtype=np.int64)
        key = kernel._stencil_key(m, j, glev)
        keys.add(key)
        slot = kernel._stencil_slot(key)
        if cache[slot, p + 1, 0] != key:
            continue                                                       # evicted by a later pattern
        eta = t[k] - t[k - 1]
        sig = [Fraction(round((t[first + q] - t[k - 1]) / eta * 2**20), 2**20) for q in range(m + 1)]
        exact = _exact_lagrange(sig)
        scale = max(abs(float(a)) for row in exact for a in row)
        for q in range(m + 1):
            for l in range(m + 1):
                assert abs(cache[slot, q, l] - float(exact[q][l])) <= 1e-14 * scale, (k, q, l)
        checked += 1
    assert len(keys) >= 15 and checked >= len(keys) - 3 and cnt - 1 >= 4 * len(keys)   # few patterns, often reused


@pytest.mark.parametrize("name", ["beam_ss_midspan", "modal_two_mode", "heavy_ball_slender_beam"])
def test_dense_peak_from_the_runs_kept_state_equals_the_sweep_from_touch(name):
    """run(peak_state=...) keeps the modes' state at the node before the first contact's largest node; dense_peak
    started there gives the peak the full sweep from touch gives (to roundoff), with that node the largest one, for
    the fine run (energy kept) and a coarse-style run (energy None)."""
    from impactval.reference.solve import _select, structure_modes

    scene = impactval.load_scene(name)
    md = structure_modes(scene, 40 if scene.target.kind == "beam" else None)
    omega, g, ew = _select(md)
    m0, alpha, v0 = scene.ball.mass, scene.alpha, scene.ball.velocity
    pl = plate_impact(m0, alpha, v0)
    H = pl.t_m / 37.0
    J = 8
    Er, Ei, Kr, Ki, S = kernel.moments(omega, g, 4.0 * H, J + 2, P_DEGREE)
    for energy in (True, None):
        pk = np.full(2 * len(ew) + 1, np.nan)
        st, cnt, t, d, f, x, u, e, fl = kernel.run(ew, m0, alpha, v0, md.residual_flexibility, H, J, P_DEGREE,
                                                   0.2 * pl.t_m, 0.0, Er, Ei, Kr, Ki, S, 4000, 2, None, 0.0, energy, pk)
        assert st == kernel.STATUS_OK
        end = kernel._first_end(fl[:cnt])
        assert int(pk[-1]) == int(np.argmax(d[:end]))
        full = kernel.dense_peak(t, d, f, x, u, end, Er, Ei, Kr, Ki, ew, 2, H, md.residual_flexibility, alpha, m0,
                                 P_DEGREE)
        kept = kernel.dense_peak(t, d, f, x, u, end, Er, Ei, Kr, Ki, ew, 2, H, md.residual_flexibility, alpha, m0,
                                 P_DEGREE, pk)
        assert kept == pytest.approx(full, rel=1e-13, abs=0.0)
        assert full >= np.max(d[:end]) * (1 - 1e-15)      # the dense peak is never below the largest node


@settings(max_examples=150, deadline=None)
@given(n=st.integers(1, 60), seed=st.integers(0, 2**32 - 1), shuffle=st.booleans(),
       share=st.floats(1e-9, 1e-2))
def test_largest_step_is_the_bisection_on_the_plain_sum(n, seed, shuffle, share):
    """The plain sum by a walk over the table (`_plain_sum`) is `unresolved`'s plain sum bit for bit, and the reported
    binned sum (its own walk) the one from `_bin` and `_factor`'s binary searches, for modes in ascending order (the
    usual: the walk moves a point or two) and shuffled (it walks down too), with phases below, inside and above the
    table and both coupling rows; and largest_step on the walk returns exactly its result on `unresolved`'s
    binary-search sum (round 7's step)."""
    from impactval.reference.solve import UNRESOLVED_C, UNRESOLVED_THETA
    rng = np.random.default_rng(seed)
    omega = np.sort(10.0 ** rng.uniform(2, 7, n))
    if shuffle:
        rng.shuffle(omega)
    s_w = 10.0 ** rng.uniform(-6, 1, n)
    sqrt_w = np.sqrt(10.0 ** rng.uniform(0, 3, n))
    row = rng.integers(0, UNRESOLVED_C.shape[0], n)
    for H in (1e-8, 1e-6, 1e-5, 1e-4, 1e-3):
        here = kernel._plain_sum(s_w, omega, sqrt_w, row, H, UNRESOLVED_THETA, UNRESOLVED_C)
        there = kernel.unresolved(s_w, omega, sqrt_w, row, H, UNRESOLVED_THETA, UNRESOLVED_C, True)
        assert here == there, (H, here, there)
        # the reported binned sum (its walk) against the binary searches of `_bin` and `_factor`, term by term
        sums = np.zeros(len(UNRESOLVED_THETA) + 1)
        for i in range(n):
            th = omega[i] * H
            sums[kernel._bin(th, UNRESOLVED_THETA)] += s_w[i] * kernel._factor(th, sqrt_w[i], UNRESOLVED_THETA,
                                                                                UNRESOLVED_C, row[i])
        binned = math.sqrt(sum(x * x for x in sums))
        assert kernel.unresolved(s_w, omega, sqrt_w, row, H, UNRESOLVED_THETA, UNRESOLVED_C) == binned, H
    target = share * kernel.unresolved(s_w, omega, sqrt_w, row, 1e-4, UNRESOLVED_THETA, UNRESOLVED_C, True)
    got = kernel.largest_step(s_w, omega, sqrt_w, row, 1e-4, UNRESOLVED_THETA, UNRESOLVED_C, target)
    assert got == kernel.largest_step(s_w, omega, sqrt_w, row, 1e-4, UNRESOLVED_THETA, UNRESOLVED_C, target, True)
