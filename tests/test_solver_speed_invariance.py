"""The reference kernel's faster paths (issue 17 item 5: cost per call at a given step sequence) against
independent values: the moment tables against their exact series in rational arithmetic, the fused degree-5 mode
sweep against the generic one, and repeated / interleaved solves against each other (caches keyed right)."""
from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

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


def test_moment_levels_are_the_halved_steps():
    """Level j of a table set for base step H equals level 0 of the set for H / 2^j (bit for bit)."""
    rng = np.random.default_rng(17)
    omega = np.sort(rng.uniform(1e2, 1e6, 50))
    g = rng.uniform(0.1, 1.0, 50)
    H = 3e-5
    full = kernel.moments(omega, g, H, 6, P_DEGREE)
    for j in range(7):
        single = kernel.moments(omega, g, H / 2.0**j, 0, P_DEGREE)
        for a, b in zip(full, single):
            assert np.array_equal(a[j], b[0])


def test_fused_sweep_equals_the_generic_sweep():
    """The degree-5 sweep (one pass over the modes) and the generic per-degree sweep give the same new modal state,
    energy and next free displacement to roundoff."""
    rng = np.random.default_rng(5)
    n = 37                                   # not a multiple of the vector width
    omega = rng.uniform(1e3, 1e6, n)
    g = rng.uniform(1e-9, 1e-7, n)
    Er, Ei, Kr, Ki, _ = kernel.moments(omega, g, 2e-6, 3, P_DEGREE)
    ew = omega / g
    coef = rng.normal(size=P_DEGREE + 1) * 1e3
    for jt in range(4):
        y0r, y0i = rng.normal(size=n) * 1e-6, rng.normal(size=n) * 1e-6
        ar, ai = y0r.copy(), y0i.copy()
        br, bi = y0r.copy(), y0i.copy()
        e6, nxt6 = kernel._sweep6(Er, Ei, Kr, Ki, jt, coef, ar, ai, ew)
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
    """kernel._solve_contact (Newton that skips the confirming step once the step is <= 2e-8 of the root) against
    the root of delta + c delta^1.5 = D in 50-digit decimal arithmetic (bisection, independent of the kernel),
    over c = B alpha spanning the structure-dominated (c sqrt(D) << 1) to the contact-dominated (>> 1) regime."""
    from decimal import Decimal, getcontext

    getcontext().prec = 50
    worst = 0.0
    for D in (1e-12, 3e-9, 1e-6, 2e-5, 1e-3):
        for c_sqrtD in (1e-8, 1e-3, 0.1, 1.0, 7.0, 1e3, 1e8):
            c = c_sqrtD / math.sqrt(D)
            B, alpha = c / 1e10, 1e10
            got = kernel._solve_contact(D, B, alpha)
            Dd, cd = Decimal(D), Decimal(B) * Decimal(alpha)
            lo, hi = Decimal(0), Dd
            for _ in range(200):
                mid = (lo + hi) / 2
                if mid + cd * mid * mid.sqrt() > Dd:
                    hi = mid
                else:
                    lo = mid
            exact = float((lo + hi) / 2)
            worst = max(worst, abs(got - exact) / exact)
    assert worst <= 4.5e-16, worst
