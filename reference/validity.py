"""Where the models behind a result stop holding: Hertz's assumptions and first-order perturbation range.

Every check returns warning strings (an empty tuple when the result is within the assumptions); they go
into `ImpactResult.validity` and are printed by `impactval reference`. The numbers are stated here once:

- HERTZ_DELTA_OVER_R: Hertz's theory is a small-strain theory of a contact small against the radius;
  delta_m / R = (a / R)^2, and beyond a / R ~ 0.1 (delta_m / R = 1 %) the measured force-approach
  curves leave Hertz's (Johnson, Contact Mechanics, 1985, sec. 4.2; Yoffe 1984).
- HERTZ_SIZE_FRACTION: the half-space assumption wants the contact radius a = sqrt(R delta_m) small
  against the target's cross-section (a beam's width and height, a plate's thickness): flagged at 10 %.
- YIELD_P0_OVER_Y: first yield under a Hertz contact starts below the surface when the peak pressure
  p0 = 3 f_m / (2 pi a^2) reaches 1.6 Y (von Mises, nu = 0.3; Johnson 1985, sec. 6.2), for a material
  with a yield stress Y (scenarios/materials.py, or `yield_stress` in a [materials.NAME] table).
- SMALL_DEFLECTION_EFFECT: the structure is linear (small deflection, no axial force). Where it deflects by w at
  the impact point (the result's largest |x_structure|), it leaves out (a) large rotations, of relative size ~slope^2
  with slope ~ 1.5 w / l (l: the length the beam bends over, the impact point's distance d to the nearest support or a
  cantilever's clamp: the slope of a point-loaded beam's deflection curve next to its support, 1.5 w / d exactly for a
  simply supported or cantilever beam loaded at its middle or tip; in a contact shorter than a bending wave needs to
  reach the support, the distance sqrt(kappa t_m) it spreads, kappa = sqrt(E I / (rho A)): a 13 mm aluminium ball at
  50 m/s 79 mm from a clamp of a 0.4 m steel beam (t_m = 34 us, l = 22 mm) gives slope^2 0.32 % (0.026 % with d), and
  the geometrically exact chains (MuJoCo, PyBullet) differ from their own linear model by 0.28 % in t_m there, by
  0.0015 % at a tenth of the speed), and (b) for a beam whose ends are held axially (a real clamp or pin; the engines'
  beams slide at one end, as the reference assumes), membrane stretching, which stiffens it by MEMBRANE_C (w / h)^2
  (h: its height; the first mode's shape psi with the centreline's stretch spread evenly along it:
  6 (int psi'^2)^2 / (L int psi''^2): for sin(pi x / L) 3, for (1 - cos(2 pi x / L)) / 2 0.75); for a plate,
  Kirchhoff's theory wants w small against the thickness t (membrane stretching of order (w / t)^2). Flagged when
  one estimate passes 1 %: a 3 kg aluminium ball at 30.8 m/s near a clamp of a 9.8 mm clamped-clamped WC beam
  (w / h = 0.44, slope 0.16) gave Exudyn's geometrically exact ANCF beam f_m +6.4 % with both ends held, -0.15 %
  with one end sliding, and the Hencky chains -1.5 %; at a quarter of the speed (w / h = 0.11) +0.83 %, -0.11 % and
  +0.07 %. The catalogue's scenes are at most 0.25 % (heavy_ball_slender_beam's membrane estimate).
- PERTURBATION_SHIFT_MAX: a first-order result is (1 + shift) times the rigid-plate value with an error
  O(shift^2): flagged when |shift| > 10 % (error ~ 1 %), refused (NaN) when 1 + shift <= 0.
"""
from __future__ import annotations

import math

HERTZ_DELTA_OVER_R = 0.01
HERTZ_SIZE_FRACTION = 0.10
YIELD_P0_OVER_Y = 1.6
PERTURBATION_SHIFT_MAX = 0.10
SMALL_DEFLECTION_EFFECT = 0.01
#: membrane stiffening of a beam held axially at both ends, relative to its bending stiffness, per (w / h)^2
MEMBRANE_C = {"simply-supported": 3.0, "clamped-clamped": 0.75}
#: slope of a point-loaded beam next to its support, per w / d
SLOPE_PER_W_OVER_D = 1.5


def effective_radius(alpha: float, e_star: float) -> float:
    """The contact's effective radius R [m] from alpha = (4/3) E* sqrt(R) (ball on a flat face: the
    ball's radius; two curved bodies: R1 R2 / (R1 + R2))."""
    return (0.75 * alpha / e_star) ** 2


def contact_size(scene, f_m: float, delta_m: float) -> tuple[float, float]:
    """(contact radius a [m], peak pressure p0 [Pa]) of a Hertz contact at force f_m [N], approach delta_m [m]:
    a = sqrt(R delta_m), p0 = 3 f_m / (2 pi a^2)."""
    a = math.sqrt(effective_radius(scene.alpha, scene.e_star) * delta_m)
    return a, 1.5 * f_m / (math.pi * a * a)


def hertz_validity(scene, f_m: float, delta_m: float) -> tuple[str, ...]:
    """Warnings where a result (peak force f_m [N], peak approach delta_m [m]) leaves Hertz's assumptions."""
    if not (math.isfinite(f_m) and math.isfinite(delta_m)) or delta_m <= 0.0:
        return ()
    radius, sizes, a_limit, yields, p0_limit = _scene_limits(scene)
    ratio = delta_m / radius
    a = math.sqrt(radius * delta_m)                # contact_size, with the scene's R computed once
    p0 = 1.5 * f_m / (math.pi * a * a)
    if ratio <= HERTZ_DELTA_OVER_R and a <= a_limit and p0 <= p0_limit:
        return ()                                  # (NaN comparisons fall through to the checks one by one)
    out = []
    if ratio > HERTZ_DELTA_OVER_R:
        out.append(f"Hertz: delta_m is {100 * ratio:.3g} % of the contact radius of curvature R = {radius:.3g} m "
                   f"(a/R = {a / radius:.2g}), above the {100 * HERTZ_DELTA_OVER_R:g} % where small-strain "
                   f"Hertz theory holds")
    over = [f"{100 * a / size:.3g} % of its {name} {size:.3g} m" for name, size in sizes
            if a > HERTZ_SIZE_FRACTION * size]
    if over:
        out.append(f"Hertz: contact radius a = {a:.3g} m is {' and '.join(over)} (> {100 * HERTZ_SIZE_FRACTION:g} % of "
                   f"the target's size): the half-space assumption fails")
    for who, mat, y in yields:
        if p0 > YIELD_P0_OVER_Y * y:
            out.append(f"yield: peak contact pressure p0 = {p0 / 1e9:.3g} GPa exceeds {YIELD_P0_OVER_Y:g} x the "
                       f"yield stress of the {who} ({mat.name}, {y / 1e9:.3g} GPa): plastic flow starts at "
                       f"p0 = {YIELD_P0_OVER_Y:g} Y, so the elastic f_m and rebound are upper bounds")
    return tuple(out)


def _scene_limits(scene):
    """What hertz_validity needs of a scene alone: (R [m], the target's (name, size [m]) pairs, the smallest
    HERTZ_SIZE_FRACTION x size [m] (inf: none), the (who, material, yield stress [Pa]) to check, the smallest
    YIELD_P0_OVER_Y x yield stress [Pa] (inf: none)). Kept per scene object (repeated solves) when the scene is
    immutable all the way down (frozen dataclasses, hashable: scenarios.scene's rule), else computed each call."""
    hit = _LIMITS.get(id(scene))
    if hit is not None and hit[0] is scene:
        return hit[1]
    radius = effective_radius(scene.alpha, scene.e_star)
    target = scene.target
    sizes = tuple((name, size) for name in ("width", "height", "thickness")
                  if isinstance(size := getattr(target, name, None), (int, float)) and size > 0)
    ball_mat, target_mat = scene.ball.material, target.material
    pairs = [("ball and target", ball_mat)] if ball_mat == target_mat else [("ball", ball_mat), ("target", target_mat)]
    yields = tuple((who, mat, y) for who, mat in pairs if (y := getattr(mat, "yield_stress", None)))
    out = (radius, sizes, min((HERTZ_SIZE_FRACTION * size for _, size in sizes), default=math.inf), yields,
           min((YIELD_P0_OVER_Y * y for _, _, y in yields), default=math.inf))
    from impactval.scenarios.scene import _all_frozen

    if _all_frozen(scene):
        if len(_LIMITS) > 256:
            _LIMITS.clear()
        _LIMITS[id(scene)] = (scene, out)        # holds the scene: its id cannot be reused while cached
    return out


_LIMITS: dict = {}


def perturbation_validity(shift_t: float, shift_delta: float) -> tuple[tuple[str, ...], bool]:
    """(warnings, usable) for first-order relative shifts of t_m and delta_m (f_m moves 1.5x delta_m's).
    Not usable when a shift reaches -100 %: the first-order value would be zero or negative."""
    shifts = {"t_m": shift_t, "delta_m": shift_delta, "f_m": 1.5 * shift_delta}
    worst = max(shifts, key=lambda k: abs(shifts[k]))
    if any(1.0 + s <= 0.0 for s in shifts.values()):
        bad = min(shifts, key=shifts.get)
        return ((f"perturbation: first-order shift of {bad} is {100 * shifts[bad]:+.3g} % (<= -100 %): the light-"
                 f"ball expansion does not apply to this scene; use --model nonlinear"),), False
    if abs(shifts[worst]) > PERTURBATION_SHIFT_MAX:
        s = shifts[worst]
        return ((f"perturbation: first-order shift of {worst} is {100 * s:+.3g} % (> {100 * PERTURBATION_SHIFT_MAX:g} "
                 f"%): its error O(shift^2) ~ {100 * s * s:.2g} %; use --model nonlinear for an exact answer"),), True
    return (), True


def _deflection_parts(target) -> tuple[str, float, float, float, float]:
    """What the small-deflection check needs of a target alone: (kind, d [m]: the impact point's distance to the
    nearest support or a cantilever's clamp, kappa = sqrt(E I / (rho A)) [m^2/s], the beam's membrane coefficient,
    the height or thickness [m]). Kept per target object when it is a frozen dataclass (all scene targets are)."""
    hit = _DEFLECTION.get(id(target))
    if hit is not None and hit[0] is target:
        return hit[1]
    kind = getattr(target, "kind", "")
    if kind == "plate":
        out = (kind, math.inf, 0.0, 0.0, target.thickness)
    elif kind == "beam":
        x, m = target.impact_x, target.material
        d = x if target.support == "cantilever" else min(x, target.length - x)
        out = (kind, d, math.sqrt(m.young * target.second_moment / (m.density * target.area)),
               MEMBRANE_C.get(target.support, 0.0), target.height)
    else:
        out = (kind, math.inf, 0.0, 0.0, math.inf)
    params = getattr(type(target), "__dataclass_params__", None)
    if params is not None and params.frozen:
        if len(_DEFLECTION) > 256:
            _DEFLECTION.clear()
        _DEFLECTION[id(target)] = (target, out)     # holds the target: its id cannot be reused while cached
    return out


_DEFLECTION: dict = {}


def _bent_length(d: float, kappa: float, t_m: float) -> float:
    """The length [m] over which the beam bends next to the impact point: the distance d to the support, or the
    distance sqrt(kappa t_m) a bending wave spreads in the contact time t_m [s], whichever is shorter."""
    return min(d, math.sqrt(kappa * t_m)) if math.isfinite(t_m) and t_m > 0.0 else d


def deflection_validity(target, w_max: float, t_m: float = math.inf) -> tuple[str, ...]:
    """Warnings where the linear structure deflects too far for its theory: `w_max` [m] is the largest displacement
    of the impact point (the result's largest |x_structure|), `t_m` [s] the contact time; beams and plates only
    (module doc: SMALL_DEFLECTION_EFFECT). Called on every solve: ~0.5 us when nothing is flagged (the target's part
    cached)."""
    kind, d, kappa, c, h = _deflection_parts(target)
    if kind not in ("beam", "plate") or not (math.isfinite(w_max) and w_max > 0.0):
        return ()
    if kind == "plate":
        ratio = w_max / h
        if ratio * ratio <= SMALL_DEFLECTION_EFFECT:
            return ()
        return (f"small deflection: the plate deflects w = {w_max:.3g} m at the impact point, {100 * ratio:.3g} % of "
                f"its thickness {h:.3g} m: Kirchhoff's theory leaves out membrane stretching, of order "
                f"(w/t)^2 = {100 * ratio * ratio:.2g} % of the plate's stiffness",)
    bent = _bent_length(d, kappa, t_m)
    slope = SLOPE_PER_W_OVER_D * w_max / bent if bent > 0.0 else math.inf
    ratio = w_max / h
    membrane = c * ratio * ratio
    if slope * slope <= SMALL_DEFLECTION_EFFECT and membrane <= SMALL_DEFLECTION_EFFECT:
        return ()
    where = "" if bent >= d else f" over the {bent:.2g} m a bending wave spreads in the contact"
    held = (f"; held axially at both ends (a real {target.support} beam; the engines' beams slide at one end) it "
            f"would stiffen by ~{100 * membrane:.2g} % (membrane stretching)" if membrane > 0.0 else "")
    return (f"small deflection: the beam deflects w = {w_max:.3g} m at the impact point, {100 * ratio:.3g} % of its "
            f"height {h:.3g} m (slope ~{slope:.2g} rad{where}): the linear beam theory leaves out large "
            f"rotations (~slope^2 = {100 * slope * slope:.2g} %){held}",)
