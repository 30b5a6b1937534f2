"""Physically meaningful ranges of the scene fields, checked before any arithmetic (issue 18).

One table, `LIMITS`, gives for every number of a scene file its allowed range, unit and the reason
for it; the loader (`scenarios/scene.py`) and the Python API (`check_scene`) check against it, and
the README's scene-file section lists it. Outside these ranges the physics the reference solves
(quasi-static Hertz contact of continuum bodies, small strain, linear-elastic structure) does not
hold, or the numbers cannot be represented: the value is refused with the field, the range and a fix,
never computed into an inf or NaN. Cross-field checks (`check_scene`) refuse what each field allows
alone but the whole does not, e.g. an approach delta_m that is not small against the radius.

Strings that reach generated files (MuJoCo XML, URDF, CSV, markdown, HTML, file names) are limited
to a safe set (`NAME_RE`) or refused; free text (descriptions) must be one printable line.

New fields (new target kinds) add one `LIMITS` row; a field without a row gets the plain
"positive finite number" check.
"""
from __future__ import annotations

import math
import numbers
import re
from dataclasses import dataclass
from typing import Any, Iterable

from impactval.errors import SceneError


@dataclass(frozen=True)
class Limit:
    """Allowed values `low`..`high` (inclusive unless `open_low`/`open_high`) in `unit`, and why."""

    low: float
    high: float
    unit: str
    reason: str
    open_low: bool = False
    open_high: bool = False

    def contains(self, x: float) -> bool:
        above = x > self.low if self.open_low else x >= self.low
        below = x < self.high if self.open_high else x <= self.high
        return above and below

    def describe(self) -> str:
        lo, hi = ("(" if self.open_low else "["), (")" if self.open_high else "]")
        unit = "" if self.unit == "-" else f" {self.unit}"
        return f"{lo}{self.low:g}, {self.high:g}{hi}{unit}"


#: "section.key" -> Limit. Section "materials" covers every [materials.NAME] table.
LIMITS: dict[str, Limit] = {
    "ball.radius": Limit(1e-6, 10.0, "m", "a continuum Hertz ball: from 1 um (below, surface forces and "
                         "roughness dominate) to 10 m"),
    "ball.velocity": Limit(1e-6, 1e3, "m/s", "quasi-static elastic impact: from 1 um/s (slower, the approach "
                           "is sub-atomic) to 1 km/s, well below the sound speed of solids (3-6 km/s)"),
    "ball.mass": Limit(1e-18, 2e8, "kg", "from a 1 um ball of the lightest material (4e-18 kg) to a 10 m ball "
                       "of the densest (1.3e8 kg); given, or density x volume"),
    "materials.young": Limit(1e4, 1e13, "Pa", "from soft gels (~10 kPa) past diamond (1.2 TPa) to 10 TPa, for stiffness sweeps"),
    "materials.poisson": Limit(-1.0, 0.5, "-", "thermodynamic bounds of an isotropic solid; 0.5 "
                               "(incompressible) makes the contact modulus singular", open_low=True, open_high=True),
    "materials.density": Limit(1.0, 3e4, "kg/m^3", "from aerogels (~1) to osmium (22 600)"),
    "materials.yield_stress": Limit(1e4, 1e11, "Pa", "from soft gels (~10 kPa) to the strongest solids (~100 GPa)"),
    "target.length": Limit(1e-5, 1e3, "m", "a beam or plate from 10 um (MEMS) to 1 km"),
    "target.width": Limit(1e-6, 10.0, "m", "a beam section or plate side from 1 um to 10 m"),
    "target.height": Limit(1e-6, 10.0, "m", "a beam section from 1 um to 10 m"),
    "target.radius": Limit(1e-6, 10.0, "m", "a second ball: as [ball] radius"),
    "target.mass": Limit(1e-18, 2e8, "kg", "a second ball: as [ball] mass"),
    "target.thickness": Limit(1e-6, 1.0, "m", "a plate from 1 um to 1 m thick"),
    "target.impact_at": Limit(0.0, 1.0, "-", "a fraction of the length from x = 0", open_low=True),
    "target.omega": Limit(1e-2, 1e10, "rad/s", "structure modes from a 10 min period (slower, a free mass) "
                          "to 1e10 rad/s (above, no continuum mode)"),
    "target.modal_mass": Limit(1e-12, 1e9, "kg", "modal masses from 1 ng to 1e6 t"),
    "target.phi": Limit(-1.0, 1.0, "-", "shapes are max-normalised (abs(shape) <= 1 everywhere); rescale "
                        "phi by 1/max abs(shape) and modal_mass by max abs(shape)^2"),
}
#: the largest mode count of a beam or modal target (memory and time of the modal sums stay bounded)
MAX_MODES = 100_000
#: approach at the peak over ball radius above which Hertz's small-strain theory is refused
MAX_APPROACH_OVER_RADIUS = 0.1
#: beam proportions: length over height and width, and width over height (outside: a string, a
#: plate or a block, not a beam; and the mode count to converge grows without bound)
MAX_SLENDERNESS = 1000.0
MAX_SECTION_ASPECT = 100.0
#: a plate's larger side over its thickness: thinner is a foil (the mode count, and the solve time,
#: grow without bound: side/thickness 374 solved in 5 s, 780 in 58 s, 1300 in > 100 s, measured)
MAX_PLATE_SLENDERNESS = 400.0
#: names and tags: ASCII letters, digits, "_", "-", "." and (for derived names such as
#: "plate_steel[velocity=0.5]") "[", "]", "=", ",", "+", starting with a letter or digit, at most 128
#: characters; they become file names, XML attributes, CSV cells and markdown table cells, where
#: anything else (quotes, "<", "&", "|", "/", spaces, newlines) would need escaping
NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.\-\[\]=,+]{0,127}")
#: the longest description (one printable line)
MAX_DESCRIPTION = 500


def _where(src: str, section: str) -> str:
    return f"{src}: [{section}]" if section else f"{src}:"


def limit_for(section: str, key: str) -> Limit | None:
    """The LIMITS row of `key` in `section` ("materials.NAME" counts as "materials")."""
    head = section.split(".", 1)[0] if section.startswith("materials") else section
    return LIMITS.get(f"{head}.{key}")


def is_real(value: Any) -> bool:
    """A real number (int, float, numpy scalar), not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and not (
        hasattr(value, "dtype") and value.dtype.kind == "b")


def check_number(src: str, section: str, key: str, value: Any, unit: str = "", *, positive: bool = True) -> float:
    """`value` as a float, checked against `LIMITS` (or, without a row, positive and finite).

    Comparisons run before any arithmetic, and integers too large for a float are refused, not
    converted (int("1" + 400 zeros) would raise OverflowError).
    """
    lim = limit_for(section, key)
    unit = lim.unit if lim else unit
    unit_s = "" if unit in ("", "-") else f" in {unit}"
    kind = ("positive finite number" if (lim.low >= 0 if lim else positive) else "finite number")
    if lim is None:
        wanted = f"{kind}{unit_s}"
    else:
        wanted = f"{kind} in {lim.describe()} ({lim.reason})"
    x = math.nan
    if is_real(value):
        if isinstance(value, numbers.Integral) and abs(int(value)) > 2**1023:
            x = math.inf if value > 0 else -math.inf     # float(int) would raise OverflowError
        else:
            x = float(value)
    ok = math.isfinite(x) and (lim.contains(x) if lim else (x > 0 or not positive))
    if not ok:
        shown = repr(value) if len(repr(value)) <= 80 else repr(value)[:80] + "..."
        raise SceneError(f"{_where(src, section)} {key} must be a {wanted}, got {shown}.")
    return x


def check_count(src: str, section: str, key: str, value: Any, what: str = "modes") -> int:
    """A whole count from 1 to MAX_MODES."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not 1 <= value <= MAX_MODES:
        raise SceneError(f"{_where(src, section)} {key} must be a whole number from 1 to {MAX_MODES} "
                         f"(the number of {what}; or omitted for an automatic choice), got {value!r}.")
    return int(value)


def check_name(src: str, key: str, value: Any, section: str = "") -> str:
    """A scene name, tag or material name from the safe set `NAME_RE`."""
    if not isinstance(value, str) or not NAME_RE.fullmatch(value):
        shown = repr(value) if not isinstance(value, str) or len(value) <= 80 else repr(value[:80]) + "..."
        raise SceneError(f"{_where(src, section)} {key} must be 1-128 ASCII letters, digits and _ - . [ ] = , + "
                         f"(starting with a letter or digit; it becomes a file name and a cell of the reports), "
                         f"got {shown}.")
    return value


def safe_name(text: str) -> str:
    """`text` mapped into the safe set (for names taken from file stems): other characters become '_'."""
    out = re.sub(r"[^A-Za-z0-9_.\-\[\]=,+]+", "_", text).lstrip("._-[]=,+")[:128]
    return out or "scene"


def check_description(src: str, value: Any) -> str:
    """Free text shown in listings and reports: one printable line of at most MAX_DESCRIPTION characters."""
    if not isinstance(value, str):
        raise SceneError(f"{src}: description must be a string, got {value!r}.")
    if len(value) > MAX_DESCRIPTION or not value.isprintable():
        why = (f"{len(value)} characters" if len(value) > MAX_DESCRIPTION
               else f"control character {next(c for c in value if not c.isprintable())!r}")
        raise SceneError(f"{src}: description must be one printable line of at most {MAX_DESCRIPTION} characters "
                         f"(no newlines or control characters), got {why}.")
    return value


def check_tags(src: str, value: Any) -> tuple[str, ...]:
    """A list of tags, each from the safe set."""
    if not isinstance(value, (list, tuple)):
        raise SceneError(f"{src}: tags must be a list of strings (e.g. tags = [\"beam\"]), got {value!r}.")
    return tuple(check_name(src, f"tags[{i}]", t) for i, t in enumerate(value))


def check_strings(src: str, doc: Any, default_name: str) -> None:
    """The strings of a scene document: `name` (or `default_name`), `tags`, `description`."""
    check_name(src, "name", doc.get("name", default_name))
    check_tags(src, doc.get("tags", []))
    check_description(src, doc.get("description", ""))


# ----------------------------------------------------------------------------- a Scene as a whole

def _check_material(src: str, where: str, mat: Any) -> None:
    for key in ("young", "poisson", "density"):
        if not hasattr(mat, key):
            raise SceneError(f"{src}: {where} material must be a Material (young, poisson, density), got {mat!r}.")
        check_number(src, f"materials.{getattr(mat, 'name', '?')}", key, getattr(mat, key))
    check_name(src, "name", getattr(mat, "name", None), f"materials.{getattr(mat, 'name', '?')}")


def check_scene_fields(scene: Any, src: str | None = None) -> None:
    """Every field of a Scene built or changed in Python against the same limits as a scene file."""
    src = src or getattr(scene, "source", "") or f"scene {getattr(scene, 'name', '?')!r}"
    if not all(hasattr(scene, a) for a in ("name", "ball", "target")):
        raise SceneError(f"scene must be a Scene (from impactval.load_scene), got {type(scene).__name__}.")
    check_name(src, "name", scene.name)
    check_tags(src, getattr(scene, "tags", ()))
    check_description(src, getattr(scene, "description", ""))
    ball = scene.ball
    if not all(hasattr(ball, a) for a in ("radius", "velocity", "mass", "material")):
        raise SceneError(f"{src}: ball must be a Ball (radius, velocity, material, mass), got {ball!r}.")
    for key in ("radius", "velocity", "mass"):
        check_number(src, "ball", key, getattr(ball, key))
    _check_material(src, "[ball]", ball.material)
    target = scene.target
    if not hasattr(target, "kind") or not hasattr(target, "material"):
        raise SceneError(f"{src}: target must be a target object (RigidPlate, Beam, ModalTarget), got {target!r}.")
    _check_material(src, "[target]", target.material)
    from impactval.scenarios import scene as scene_module     # lazy: scene.py imports this module

    TARGET_KINDS = scene_module.TARGET_KINDS
    SUPPORTS = getattr(scene_module, "PLATE_SUPPORTS", ()) if target.kind == "plate" else scene_module.SUPPORTS

    if target.kind not in TARGET_KINDS:
        raise SceneError(f"{src}: [target] kind must be one of {', '.join(map(repr, TARGET_KINDS))}, "
                         f"got {target.kind!r}.")
    if hasattr(target, "support") and target.support not in SUPPORTS:
        raise SceneError(f"{src}: [target] support must be one of {', '.join(map(repr, SUPPORTS))}, "
                         f"got {target.support!r}.")
    lists = [k for k in ("omega", "modal_mass", "phi") if hasattr(target, k)]
    for k in lists:
        if not isinstance(getattr(target, k), (tuple, list)):
            raise SceneError(f"{src}: [target] {k} must be a tuple of numbers, got {getattr(target, k)!r}.")
    if lists and len({len(getattr(target, k)) for k in lists}) > 1:
        raise SceneError(f"{src}: [target] {', '.join(lists)} must have equal lengths, got "
                         f"{', '.join(str(len(getattr(target, k))) for k in lists)}.")
    fields = getattr(target, "__dataclass_fields__", {})
    for key in fields:
        value = getattr(target, key)
        if key == "modes" and value is not None:
            check_count(src, "target", key, value)
        elif limit_for("target", key) is not None:
            if isinstance(value, (tuple, list)):
                _check_list(src, key, value, positive=key != "phi")
            else:
                check_number(src, "target", key, value)
    check_scene(scene, src)


def _check_list(src: str, key: str, values: Iterable[Any], positive: bool = True) -> tuple[float, ...]:
    values = list(values)
    if not values:
        raise SceneError(f"{src}: [target] {key} must be a non-empty list of numbers, got [].")
    if len(values) > MAX_MODES:
        raise SceneError(f"{src}: [target] {key} has {len(values)} entries; at most {MAX_MODES} modes are allowed.")
    out = []
    for i, v in enumerate(values):
        try:
            out.append(check_number(src, "target", key, v, positive=positive))
        except SceneError as err:
            raise SceneError(str(err).replace(f"[target] {key} ", f"[target] {key}[{i}] ", 1)) from None
    return tuple(out)


def check_list(src: str, key: str, values: Any) -> tuple[float, ...]:
    """A modal list (omega, modal_mass, phi): non-empty, at most MAX_MODES numbers, each in its range."""
    if not isinstance(values, (list, tuple)):
        raise SceneError(f"{src}: [target] {key} must be a non-empty list of numbers, got {values!r}.")
    return _check_list(src, key, values, positive=key != "phi")


def check_scene(scene: Any, src: str) -> None:
    """Cross-field checks, after every field is in its range (so nothing here overflows); run by
    `load_scene` and, for Scene objects, by `check_scene_fields` (so by `impactval.solve`).

    The peak approach on a rigid face, delta_m = (5 m v0^2 / (4 alpha))^(2/5), must stay small against
    the radius: Hertz theory assumes a contact radius sqrt(R delta) much smaller than R. Two balls (target kind
    "ball") are that ball on a rigid face with the reduced mass m1 m2 / (m1 + m2), the approach speed v1 + v2 and
    the effective radius R1 R2 / (R1 + R2) (reference/spheres.py): delta_m is checked against that radius.
    """
    ball = scene.ball
    try:
        alpha = float(scene.alpha)
    except (ArithmeticError, ValueError) as err:
        raise SceneError(f"{src}: the Hertz coefficient cannot be computed from the materials: {err}.") from None
    if not (math.isfinite(alpha) and alpha > 0):
        raise SceneError(f"{src}: the Hertz coefficient alpha = {alpha!r} N/m^1.5 is not a positive finite number; "
                         f"check the materials' young and poisson.")
    target = scene.target
    mass, speed, radius = ball.mass, ball.velocity, ball.radius
    two_balls = getattr(target, "kind", "") == "ball"
    if two_balls:           # the relative motion: a ball of the reduced mass and effective radius on a rigid face
        mass = ball.mass * target.mass / (ball.mass + target.mass)
        speed = ball.velocity + target.velocity
        radius = ball.radius * target.radius / (ball.radius + target.radius)
    # log space: no overflow whatever the inputs
    log_delta = 0.4 * (math.log(5.0 / 4.0) + math.log(mass) + 2.0 * math.log(speed) - math.log(alpha))
    ratio = math.exp(min(log_delta - math.log(radius), 50.0))
    if ratio > MAX_APPROACH_OVER_RADIUS:
        if two_balls:
            what = (f"the effective radius R1 R2 / (R1 + R2) (delta_m = {ratio * radius:.3g} m for the reduced mass "
                    f"{mass:g} kg, approach speed v1 + v2 = {speed:g} m/s, effective radius {radius:g} m)")
            fix = "lower the balls' speeds or masses, or use stiffer materials"
        else:
            what = (f"the radius (delta_m = {ratio * radius:.3g} m for mass {mass:g} kg, velocity {speed:g} m/s, "
                    f"radius {radius:g} m)")
            fix = "lower the velocity or the mass, or use a stiffer material"
        raise SceneError(
            f"{src}: [ball] the Hertz approach at the peak would be {ratio:.3g} x {what}; Hertz contact needs it below "
            f"{MAX_APPROACH_OVER_RADIUS:g} x {'that radius' if two_balls else 'the radius'}: {fix}.")
    if getattr(target, "kind", "") == "plate" and all(hasattr(target, k) for k in ("length", "width", "thickness")):
        r = max(target.length, target.width) / target.thickness
        if r > MAX_PLATE_SLENDERNESS:
            raise SceneError(f"{src}: [target] the plate's larger side over its thickness is {r:.3g}, above "
                             f"{MAX_PLATE_SLENDERNESS:g}: a foil, not a plate (its modes converge too slowly to solve); "
                             f"use a thicker or smaller plate.")
    if "beam" in str(getattr(target, "kind", "")) and all(hasattr(target, k) for k in ("length", "width", "height")):
        _check_beam_shape(src, target, ball.radius, ratio * ball.radius)


def _check_beam_shape(src: str, beam: Any, radius: float, delta_m: float) -> None:
    """A beam is slender but not a string, its section not a plate, and the contact patch fits on it."""
    length, width, height = beam.length, beam.width, beam.height
    for what, r in (("length / height", length / height), ("length / width", length / width)):
        if r > MAX_SLENDERNESS:
            raise SceneError(f"{src}: [target] {what} = {r:.3g} is above {MAX_SLENDERNESS:g}: a string or a wire, not a "
                             f"beam (its modes converge too slowly to solve); use a shorter or thicker beam.")
    if not 1.0 / MAX_SECTION_ASPECT <= width / height <= MAX_SECTION_ASPECT:
        raise SceneError(f"{src}: [target] width / height = {width / height:.3g} is outside [{1 / MAX_SECTION_ASPECT:g}, "
                         f"{MAX_SECTION_ASPECT:g}]: a plate or a blade, not a beam.")
    x = beam.impact_at * length
    ends = (x,) if getattr(beam, "support", "") == "cantilever" else (x, length - x)
    if min(ends) < height:
        raise SceneError(f"{src}: [target] impact_at = {beam.impact_at!r} is {min(ends):.3g} m from a support, closer "
                         f"than the beam's height ({height:g} m): beam theory does not hold there (the support "
                         f"carries the impact); use impact_at between {height / length:.3g} and "
                         f"{1 - height / length:.3g}.")
    patch = math.sqrt(radius * delta_m)
    if patch > 0.5 * width:
        raise SceneError(f"{src}: [target] the Hertz contact patch (diameter 2 sqrt(R delta_m) = {2 * patch:.3g} m) "
                         f"is wider than the beam (width {width:g} m): the face is not locally flat; use a width of "
                         f"at least {2 * patch:.3g} m, or a smaller or slower ball.")


def check_answer(scene_name: str, **values: float) -> None:
    """Refuse to print a non-finite answer: each named value must be a finite number."""
    for key, v in values.items():
        if v is None or not math.isfinite(float(v)):
            raise SceneError(f"scene {scene_name!r}: the solution's {key} is {v!r}, not a finite number: the scene is "
                             f"outside what the solver handles; check its numbers against the ranges in the README "
                             f"(scene files).")


def limits_table() -> str:
    """The LIMITS table in markdown (for the README)."""
    rows = ["| field | allowed | why |", "|---|---|---|"]
    for key, lim in LIMITS.items():
        rows.append(f"| `{key}` | {lim.describe()} | {lim.reason} |")
    rows.append(f"| `target.modes`, modal list length | 1 .. {MAX_MODES} | memory and time of the modal sums |")
    rows.append(f"| delta_m / `ball.radius` (two balls: / R1 R2 / (R1 + R2)) | <= {MAX_APPROACH_OVER_RADIUS:g} | "
                "Hertz: small contact radius against the ball radius |")
    rows.append(f"| beam `length/height`, `length/width` | <= {MAX_SLENDERNESS:g} | a beam, not a string "
                "(modes converge) |")
    rows.append(f"| plate larger side / `thickness` | <= {MAX_PLATE_SLENDERNESS:g} | a plate, not a foil "
                "(modes converge) |")
    rows.append(f"| beam `width/height` | {1 / MAX_SECTION_ASPECT:g} .. {MAX_SECTION_ASPECT:g} | a beam, not a plate |")
    rows.append("| contact patch sqrt(R delta_m) | <= width / 2 | the patch fits on the beam's face |")
    rows.append("| impact point's distance to a support | >= height | beam theory holds there |")
    return "\n".join(rows)
