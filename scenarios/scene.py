"""Scene definitions (frozen dataclasses) and the TOML loader with validation at the edge.

A scene is a ball hitting a target at first touch. SI units everywhere:
lengths in m, speeds in m/s, masses in kg, frequencies in rad/s, moduli in Pa.

TOML format (public, names fixed)::

    name = "beam_ss_midspan"           # optional; default: file stem
    description = "..."                # optional
    tags = ["beam", "paper"]           # optional
    [ball]
    radius = 0.01                      # m
    velocity = 1.0                     # m/s, approach speed at first touch
    material = "steel"
    mass = 0.0327                      # optional, kg (overrides density x volume)
    [target]
    kind = "beam"                      # "rigid-plate" | "beam" | "modal" | "ball" | "plate"
    material = "steel"                 # contact face (for a beam also its density and modulus)
    support = "simply-supported"       # beam: "simply-supported" | "clamped-clamped" | "cantilever"
    length = 0.5                       # beam, m
    width = 0.01                       # beam, m
    height = 0.01                      # beam, m (depth in the impact direction)
    impact_at = 0.5                    # beam, fraction of the length from x = 0
    modes = 40                         # beam, plate: optional mode count (default: automatic)
    theory = "euler-bernoulli"         # beam, optional: "euler-bernoulli" (default) | "timoshenko"
    omega = [..]                       # modal, rad/s
    modal_mass = [..]                  # modal, kg (max-normalised shapes)
    phi = [..]                         # modal, each mode's shape value at the impact point
    radius = 0.01                      # ball: the second sphere's radius, m
    velocity = 0.0                     # ball, optional: its speed toward the first ball, m/s (default 0)
    mass = 0.0327                      # ball, optional, kg (overrides density x volume)
    length = 0.4                       # plate (simply supported): x side, m
    width = 0.3                        # plate: y side, m
    thickness = 0.005                  # plate: m
    impact_at = [0.5, 0.5]             # plate: [x, y] fractions of length and width
    [materials.NAME]                   # optional: add or override materials (young, poisson, density, yield_stress)
    young = 2.1e11
    poisson = 0.3
    density = 7800
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Mapping

from impactval.errors import SceneError
from impactval.scenarios import limits
from impactval.scenarios.materials import BUILTIN_MATERIALS, Material

SUPPORTS = ("simply-supported", "clamped-clamped", "cantilever")
PLATE_SUPPORTS = ("simply-supported",)
BEAM_THEORIES = ("euler-bernoulli", "timoshenko")
TARGET_KINDS = ("rigid-plate", "beam", "modal", "ball", "plate")
CATALOGUE_DIR = Path(__file__).parent / "catalogue"


@dataclass(frozen=True)
class Ball:
    """The impacting sphere: `radius` [m], approach `velocity` v0 [m/s], `mass` m0 [kg]."""

    radius: float
    velocity: float
    material: Material
    mass: float


@dataclass(frozen=True)
class RigidPlate:
    """A rigid, immovable target with a flat elastic contact face of `material`."""

    material: Material
    kind: str = field(default="rigid-plate", init=False)


@dataclass(frozen=True)
class Beam:
    """Beam of rectangular section hit on its top face.

    `length`, `width`, `height` [m] (height = depth in the impact direction), `impact_at` is the
    fraction of the length from x = 0 (the clamped end of a cantilever), `modes` the mode count
    (None = chosen automatically to meet the tolerance), `theory` "euler-bernoulli" or "timoshenko"
    (shear and rotary inertia, Cowper's shear coefficient).
    """

    material: Material
    support: str
    length: float
    width: float
    height: float
    impact_at: float
    modes: int | None = None
    theory: str = "euler-bernoulli"
    kind: str = field(default="beam", init=False)

    @property
    def shear_coefficient(self) -> float:
        """Cowper's shear coefficient of a rectangle, 10(1 + nu)/(12 + 11 nu) [-]."""
        nu = self.material.poisson
        return 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu)

    @property
    def shear_modulus(self) -> float:
        """G = E / (2 (1 + nu)) [Pa]."""
        return self.material.young / (2.0 * (1.0 + self.material.poisson))

    @property
    def area(self) -> float:
        """Cross-section area A [m^2]."""
        return self.width * self.height

    @property
    def second_moment(self) -> float:
        """Second moment of area I [m^4] for bending in the impact direction."""
        return self.width * self.height**3 / 12.0

    @property
    def impact_x(self) -> float:
        """Impact position x [m] from x = 0."""
        return self.impact_at * self.length


@dataclass(frozen=True)
class ModalTarget:
    """A structure given by its modes: `omega` [rad/s], `modal_mass` [kg] (max-normalised
    shapes), `phi` (shape value at the impact point, dimensionless)."""

    material: Material
    omega: tuple[float, ...]
    modal_mass: tuple[float, ...]
    phi: tuple[float, ...]
    kind: str = field(default="modal", init=False)


@dataclass(frozen=True)
class BallTarget:
    """A second free sphere on the same axis: `radius` [m], `velocity` [m/s] toward the first
    ball (default 0), `mass` [kg]; both spheres deform (Hertz with both curvatures)."""

    radius: float
    velocity: float
    material: Material
    mass: float
    kind: str = field(default="ball", init=False)


@dataclass(frozen=True)
class Plate:
    """Kirchhoff plate, simply supported on all four edges, hit on its face.

    `length` (x) and `width` (y) [m], `thickness` [m], `impact_at` = (x, y) fractions of length and
    width, `modes` the mode count (the n lowest, None = chosen automatically).
    """

    material: Material
    support: str
    length: float
    width: float
    thickness: float
    impact_at: tuple[float, float]
    modes: int | None = None
    kind: str = field(default="plate", init=False)

    @property
    def bending_stiffness(self) -> float:
        """D = E h^3 / (12 (1 - nu^2)) [N m]."""
        m = self.material
        return m.young * self.thickness**3 / (12.0 * (1.0 - m.poisson**2))


Target = RigidPlate | Beam | ModalTarget | BallTarget | Plate


@dataclass(frozen=True)
class Scene:
    """A ball hitting a target. `name` is the catalogue name (file stem) or given name."""

    name: str
    ball: Ball
    target: Target
    description: str = ""
    tags: tuple[str, ...] = ()
    source: str = ""

    @cached_property
    def e_star(self) -> float:
        """Contact modulus E* [Pa]: 1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2."""
        from impactval.reference.hertz import e_star      # the formulas live in one place

        m1, m2 = self.ball.material, self.target.material
        return e_star(m1.young, m1.poisson, m2.young, m2.poisson)

    @cached_property
    def alpha(self) -> float:
        """Hertz coefficient alpha [N/m^1.5]: ball on a flat face (paper eq. 20), or on a second
        ball (both curvatures, 1/R = 1/R1 + 1/R2)."""
        from impactval.reference.hertz import hertz_alpha, hertz_alpha_spheres

        if self.target.kind == "ball":
            return hertz_alpha_spheres(self.ball.radius, self.target.radius, self.e_star)
        return hertz_alpha(self.ball.radius, self.e_star)


# ----------------------------------------------------------------------------- validation helpers

def _where(src: str, section: str) -> str:
    return f"{src}: [{section}]" if section else f"{src}:"


def _positive(src: str, section: str, key: str, value: Any, unit: str) -> float:
    """A positive finite number in its physically meaningful range (scenarios/limits.py)."""
    return limits.check_number(src, section, key, value, unit)


def _check_keys(src: str, section: str, table: Mapping[str, Any], required: set[str], optional: set[str]) -> None:
    if not isinstance(table, Mapping):
        raise SceneError(f"{_where(src, section)} must be a table, got {type(table).__name__}.")
    unknown = set(table) - required - optional
    if unknown:
        allowed = ", ".join(sorted(required | optional))
        raise SceneError(f"{_where(src, section)} unknown key {sorted(unknown)[0]!r}; allowed keys: {allowed}.")
    missing = required - set(table)
    if missing:
        raise SceneError(f"{_where(src, section)} missing required key {sorted(missing)[0]!r}.")


def _materials(src: str, doc: Mapping[str, Any]) -> dict[str, Material]:
    mats = dict(BUILTIN_MATERIALS)
    extra = doc.get("materials", {})
    if not isinstance(extra, Mapping):
        raise SceneError(f"{src}: [materials] must be a table of [materials.NAME] tables.")
    for name, table in extra.items():
        limits.check_name(src, "material name", name, "materials")
        sect = f"materials.{name}"
        _check_keys(src, sect, table, {"young", "poisson", "density"}, {"yield_stress", "source"})
        nu = table["poisson"]
        if isinstance(nu, bool) or not isinstance(nu, (int, float)) or not (-1.0 < nu < 0.5):
            raise SceneError(f"{_where(src, sect)} poisson must be a number in (-1, 0.5), got {nu!r}.")
        y = table.get("yield_stress")
        mats[name] = Material(name, _positive(src, sect, "young", table["young"], "Pa"), float(nu),
                              _positive(src, sect, "density", table["density"], "kg/m^3"),
                              None if y is None else _positive(src, sect, "yield_stress", y, "Pa"),
                              source=str(table.get("source", f"[materials.{name}] in {src}")))
    return mats


def _material(src: str, section: str, value: Any, mats: Mapping[str, Material]) -> Material:
    if not isinstance(value, str) or value not in mats:
        raise SceneError(f"{_where(src, section)} material {value!r} is unknown; known: {', '.join(sorted(mats))} "
                         f"(or define it in a [materials.NAME] table with young, poisson, density).")
    return mats[value]


def _float_list(src: str, key: str, value: Any) -> tuple[float, ...]:
    return limits.check_list(src, key, value)


# ----------------------------------------------------------------------------- one parser per target kind

def _fraction(src: str, key: str, value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or not 0.0 < value < 1.0:
        raise SceneError(f"{src}: [target] {key} must be a fraction of the {what} strictly between 0 and 1, "
                         f"got {value!r}.")
    return float(value)


def _modes(src: str, t: Mapping[str, Any]) -> int | None:
    modes = t.get("modes")
    if modes is not None and (isinstance(modes, bool) or not isinstance(modes, int) or not 1 <= modes <= 100000):
        raise SceneError(f"{src}: [target] modes must be a whole number from 1 to 100000 (or omitted for an "
                         f"automatic choice), got {modes!r}.")
    return modes


def _rigid_plate_target(src: str, t: Mapping[str, Any], mats: Mapping[str, Material]) -> RigidPlate:
    _check_keys(src, "target", t, {"kind", "material"}, set())
    return RigidPlate(_material(src, "target", t["material"], mats))


def _beam_target(src: str, t: Mapping[str, Any], mats: Mapping[str, Material]) -> Beam:
    _check_keys(src, "target", t, {"kind", "material", "support", "length", "width", "height", "impact_at"},
                {"modes", "theory"})
    if t["support"] not in SUPPORTS:
        raise SceneError(f"{src}: [target] support must be one of {', '.join(map(repr, SUPPORTS))}, "
                         f"got {t['support']!r}.")
    at = t["impact_at"]
    if isinstance(at, bool) or not isinstance(at, (int, float)) or not math.isfinite(at) or not 0.0 < at <= 1.0:
        raise SceneError(f"{src}: [target] impact_at must be a fraction of the length in (0, 1] "
                         f"(0 < impact_at < 1 for a beam supported at both ends), got {at!r}.")
    if at >= 1.0 and t["support"] != "cantilever":
        raise SceneError(f"{src}: [target] impact_at = {at!r} is on a support of a {t['support']} beam; "
                         f"use a value strictly between 0 and 1.")
    theory = t.get("theory", "euler-bernoulli")
    if theory not in BEAM_THEORIES:
        raise SceneError(f"{src}: [target] theory must be one of {', '.join(map(repr, BEAM_THEORIES))}, "
                         f"got {theory!r}.")
    return Beam(_material(src, "target", t["material"], mats), t["support"],
                _positive(src, "target", "length", t["length"], "m"),
                _positive(src, "target", "width", t["width"], "m"),
                _positive(src, "target", "height", t["height"], "m"), float(at), _modes(src, t), theory)


def _modal_target(src: str, t: Mapping[str, Any], mats: Mapping[str, Material]) -> ModalTarget:
    _check_keys(src, "target", t, {"kind", "material", "omega", "modal_mass", "phi"}, set())
    omega = _float_list(src, "omega", t["omega"])
    mm = _float_list(src, "modal_mass", t["modal_mass"])
    phi = _float_list(src, "phi", t["phi"])
    if not len(omega) == len(mm) == len(phi):
        raise SceneError(f"{src}: [target] omega, modal_mass and phi must have equal lengths, got "
                         f"{len(omega)}, {len(mm)} and {len(phi)}.")
    for key, arr in (("omega", omega), ("modal_mass", mm)):
        bad = [v for v in arr if v <= 0]
        if bad:
            raise SceneError(f"{src}: [target] {key} values must be positive, got {bad[0]!r}.")
    return ModalTarget(_material(src, "target", t["material"], mats), omega, mm, phi)


def _ball_target(src: str, t: Mapping[str, Any], mats: Mapping[str, Material]) -> BallTarget:
    _check_keys(src, "target", t, {"kind", "material", "radius"}, {"velocity", "mass"})
    mat = _material(src, "target", t["material"], mats)
    radius = _positive(src, "target", "radius", t["radius"], "m")
    v = t.get("velocity", 0.0)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SceneError(f"{src}: [target] velocity must be a finite speed in m/s toward the first ball "
                         f"(negative: away from it), got {v!r}.")
    mass = (_positive(src, "target", "mass", t["mass"], "kg") if "mass" in t
            else mat.density * 4.0 / 3.0 * math.pi * radius**3)
    return BallTarget(radius, float(v), mat, mass)


def _plate_target(src: str, t: Mapping[str, Any], mats: Mapping[str, Material]) -> Plate:
    _check_keys(src, "target", t, {"kind", "material", "support", "length", "width", "thickness", "impact_at"},
                {"modes"})
    if t["support"] not in PLATE_SUPPORTS:
        raise SceneError(f"{src}: [target] support of a plate must be one of {', '.join(map(repr, PLATE_SUPPORTS))}, "
                         f"got {t['support']!r}.")
    at = t["impact_at"]
    if not isinstance(at, list) or len(at) != 2:
        raise SceneError(f"{src}: [target] impact_at of a plate must be [x_fraction, y_fraction] (two numbers "
                         f"strictly between 0 and 1), got {at!r}.")
    xy = (_fraction(src, "impact_at[0]", at[0], "length"), _fraction(src, "impact_at[1]", at[1], "width"))
    return Plate(_material(src, "target", t["material"], mats), t["support"],
                 _positive(src, "target", "length", t["length"], "m"),
                 _positive(src, "target", "width", t["width"], "m"),
                 _positive(src, "target", "thickness", t["thickness"], "m"), xy, _modes(src, t))


_TARGET_PARSERS = {"rigid-plate": _rigid_plate_target, "beam": _beam_target, "modal": _modal_target,
                   "ball": _ball_target, "plate": _plate_target}


def scene_from_dict(doc: Mapping[str, Any], source: str = "<scene>", default_name: str = "scene") -> Scene:
    """Build and validate a Scene from a parsed TOML document (a mapping)."""
    src = source
    _check_keys(src, "", doc, {"ball", "target"}, {"name", "description", "tags", "materials"})
    limits.check_strings(src, doc, default_name)     # name, tags, description: the safe set (issue 18)
    mats = _materials(src, doc)

    b = doc["ball"]
    _check_keys(src, "ball", b, {"radius", "velocity", "material"}, {"mass"})
    bmat = _material(src, "ball", b["material"], mats)
    radius = _positive(src, "ball", "radius", b["radius"], "m")
    velocity = _positive(src, "ball", "velocity", b["velocity"], "m/s")
    mass = (_positive(src, "ball", "mass", b["mass"], "kg") if "mass" in b
            else bmat.density * 4.0 / 3.0 * math.pi * radius**3)
    if "mass" not in b:
        _positive(src, "ball", "mass", mass, "kg")        # density x volume must be in range too
    ball = Ball(radius, velocity, bmat, mass)

    t = doc["target"]
    if not isinstance(t, Mapping):
        raise SceneError(f"{src}: [target] must be a table.")
    kind = t.get("kind")
    if kind not in TARGET_KINDS:
        raise SceneError(f"{src}: [target] kind must be one of {', '.join(map(repr, TARGET_KINDS))}, got {kind!r}.")
    target = _TARGET_PARSERS[kind](src, t, mats)

    name = doc.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise SceneError(f"{src}: name must be a non-empty string, got {name!r}.")
    desc = doc.get("description", "")
    if not isinstance(desc, str):
        raise SceneError(f"{src}: description must be a string, got {desc!r}.")
    tags = doc.get("tags", [])
    if not isinstance(tags, list) or not all(isinstance(x, str) for x in tags):
        raise SceneError(f"{src}: tags must be a list of strings, got {tags!r}.")
    if target.kind == "ball" and ball.velocity + target.velocity <= 0:
        raise SceneError(f"{src}: [target] velocity = {target.velocity!r} m/s: the balls never meet (approach speed "
                         f"[ball] velocity + [target] velocity must be positive).")
    return Scene(name, ball, target, desc, tuple(tags), source)


def catalogue_names() -> list[str]:
    """Names of the built-in scenes (file stems under scenarios/catalogue)."""
    return sorted(p.stem for p in CATALOGUE_DIR.glob("*.toml"))


_CHECKED: dict = {}


def _all_frozen(scene) -> bool:
    """True for a Scene whose ball, target and materials are frozen dataclasses (nothing in it can change)."""
    parts = (scene, scene.ball, scene.target, scene.ball.material, scene.target.material)
    if not all(dataclasses.is_dataclass(p) and type(p).__dataclass_params__.frozen for p in parts):
        return False
    try:
        hash(scene)             # a list inside (e.g. a modal target's omega) could still change
    except TypeError:
        return False
    return True


def load_scene(name_or_path: str | Path) -> Scene:
    """Load a scene from a catalogue name (e.g. ``"plate_steel"``) or a TOML file path.

    A Scene is returned as it is, after checking its fields (Python-built scenes obey the same limits).
    """
    if hasattr(name_or_path, "ball") and hasattr(name_or_path, "target"):
        if _CHECKED.get(id(name_or_path)) is not name_or_path:
            limits.check_scene_fields(name_or_path)
            if _all_frozen(name_or_path):       # immutable all the way down: checked once (repeated solves)
                if len(_CHECKED) > 256:
                    _CHECKED.clear()
                _CHECKED[id(name_or_path)] = name_or_path
        return name_or_path
    if not isinstance(name_or_path, (str, Path)) or not str(name_or_path).strip():
        raise SceneError(f"a scene is a Scene, a catalogue name (see `impactval scenes`) or a path to a .toml scene "
                         f"file, got {name_or_path!r}.")
    text_name = str(name_or_path)
    if "\x00" in text_name or len(text_name) > 4096:
        raise SceneError(f"a scene is a catalogue name or a path to a .toml scene file, got "
                         f"{text_name[:80]!r}{'...' if len(text_name) > 80 else ''} (a NUL character or too long).")
    path = Path(text_name)
    try:
        if not (text_name.endswith(".toml") or path.exists()):
            cand = CATALOGUE_DIR / f"{text_name}.toml"
            if not limits.NAME_RE.fullmatch(text_name) or not cand.exists():
                raise SceneError(f"no scene named {text_name[:80]!r}: not a file and not in the catalogue "
                                 f"(known: {', '.join(catalogue_names())}).")
            path = cand
        if not path.is_file():
            what = ("is a directory" if path.is_dir() else "is not a regular file" if path.exists()
                    else "file does not exist")
            raise SceneError(f"{path}: {what} (give a catalogue name or a path to a .toml scene file).")
        text = path.read_text(encoding="utf-8-sig")      # a byte-order mark (Windows editors) is dropped
        doc = tomllib.loads(text)
    except SceneError:
        raise
    except tomllib.TOMLDecodeError as err:
        raise SceneError(f"{path}: malformed TOML: {err}.") from None
    except ValueError as err:       # e.g. an integer literal of more than 4300 digits
        raise SceneError(f"{path}: malformed TOML: {str(err)[:120]}.") from None
    except RecursionError:
        raise SceneError(f"{path}: malformed TOML: nested too deeply.") from None
    except (OSError, UnicodeDecodeError) as err:
        raise SceneError(f"{path}: cannot read the file: {err}.") from None
    scene = scene_from_dict(doc, source=str(path), default_name=limits.safe_name(path.stem))
    limits.check_scene(scene, str(path))
    return scene


def load_catalogue(tag: str | None = None) -> list[Scene]:
    """All catalogue scenes, optionally only those carrying `tag`."""
    scenes = [load_scene(n) for n in catalogue_names()]
    return [s for s in scenes if tag is None or tag in s.tags]
