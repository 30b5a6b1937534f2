"""The result shape shared by the reference solver and every engine adapter (style.md, pattern 4)."""
from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np


class Status(str, enum.Enum):
    """How a job ended. A `str` enum: `Status.OK == "ok"`, so rows and CSV cells stay plain text."""

    OK = "ok"                        # metrics measured
    NO_CONTACT = "no-contact"        # the ball never touched the target (or tunnelled through it)
    UNSTABLE = "unstable"            # NaN/inf, energy growth, ball through the target, dt above the limit
    CRASHED = "crashed"              # the engine raised or its process died
    TIMEOUT = "timeout"              # no result within the job's timeout
    NOT_INSTALLED = "not-installed"  # the engine's package is missing (message: install command)
    SKIPPED = "skipped"              # the engine does not support this scene/setting combination
    INTERRUPTED = "interrupted"      # the run was stopped (Ctrl-C, SIGTERM) before this job finished

    def __str__(self) -> str:        # f"{status}" -> "ok", not "Status.OK"
        return self.value

    @property
    def failed(self) -> bool:
        """True for the statuses that make a run exit 1 (a job that should have worked did not)."""
        return self in FAILED


#: statuses every producer of an ImpactResult may report (plain strings, for messages and CSV)
STATUSES = tuple(s.value for s in Status)
#: statuses that count as a failed job (exit 1); not-installed, skipped and interrupted only inform
FAILED = frozenset({Status.NO_CONTACT, Status.UNSTABLE, Status.CRASHED, Status.TIMEOUT})


@dataclass(frozen=True)
class Metrics:
    """The three impact quantities: `t_m` [s], `f_m` [N], `delta_m` [m]."""

    t_m: float
    f_m: float
    delta_m: float

    def relative_to(self, ref: "Metrics") -> "Metrics":
        """Signed relative differences (self - ref) / ref."""
        return Metrics((self.t_m - ref.t_m) / ref.t_m, (self.f_m - ref.f_m) / ref.f_m,
                       (self.delta_m - ref.delta_m) / ref.delta_m)

    def as_dict(self) -> dict[str, float]:
        return {"t_m": self.t_m, "f_m": self.f_m, "delta_m": self.delta_m}


@dataclass(frozen=True)
class Contact:
    """One contact phase: start and end time [s], peak force [N] and peak approach [m]."""

    t_start: float
    t_end: float
    f_max: float
    delta_max: float


@dataclass(frozen=True, eq=False)
class ImpactResult:
    """One impact as computed by the reference or by an engine.

    Metrics of the *first* contact: `t_m` (duration) [s], `f_m` (peak force) [N], `delta_m`
    (peak approach) [m]; `uncertainty` (same fields, absolute, None for engines).
    Series: `t` [s], `f` [N], `delta` [m], `x_ball`, `x_structure` [m] (contact-point
    displacements, positive into the target), `energy` [J] (ball kinetic + Hertz potential +
    structure energy). `rebound_velocity` [m/s] is the ball's speed away from the target after
    the first contact; `energy_error` the largest |E(t)/E(0) - 1|; `contacts` lists every contact
    in the simulated window. `source` is "reference" or the engine name.
    """

    scene: str
    source: str
    model: str
    t_m: float
    f_m: float
    delta_m: float
    uncertainty: Metrics | None = None
    modes: int = 0
    t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    f: np.ndarray = field(default_factory=lambda: np.zeros(0))
    delta: np.ndarray = field(default_factory=lambda: np.zeros(0))
    x_ball: np.ndarray = field(default_factory=lambda: np.zeros(0))
    x_structure: np.ndarray = field(default_factory=lambda: np.zeros(0))
    energy: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rebound_velocity: float = math.nan
    energy_error: float = math.nan
    contacts: tuple[Contact, ...] = ()
    status: Status = Status.OK
    message: str = ""
    version: str = ""
    settings: dict[str, Any] = field(default_factory=dict)
    n_steps: int = 0
    wall_time_build_s: float = 0.0
    wall_time_step_s: float = 0.0
    diagnostics: dict[str, Any] = field(default_factory=dict)
    dt: float = math.nan
    dt_limit: float = math.nan
    model_error: float = math.nan
    contact_law: Any = None
    validity: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.status.__class__ is not Status:
            object.__setattr__(self, "status", Status(self.status))   # accepts "ok" as well as Status.OK

    @property
    def success(self) -> bool:
        return self.status == Status.OK

    @property
    def metrics(self) -> Metrics:
        return Metrics(self.t_m, self.f_m, self.delta_m)

    @property
    def wall_time_s(self) -> float:
        return self.wall_time_build_s + self.wall_time_step_s

    @classmethod
    def failed(cls, scene: str, source: str, status: str, message: str, **kw: Any) -> "ImpactResult":
        """A result with no numbers: `status` says why (see STATUSES)."""
        if str(status) not in STATUSES:
            raise ValueError(f"unknown status {status!r}; known: {', '.join(STATUSES)}")
        return cls(scene, source, kw.pop("model", ""), math.nan, math.nan, math.nan, status=status,
                   message=message, **kw)

    def summary(self) -> dict[str, Any]:
        """Flat dict of the scalar fields (for tables and JSON)."""
        out: dict[str, Any] = {"scene": self.scene, "source": self.source, "model": self.model,
                               "status": str(self.status), "t_m": self.t_m, "f_m": self.f_m, "delta_m": self.delta_m}
        if self.uncertainty is not None:
            out.update({f"u_{k}": v for k, v in self.uncertainty.as_dict().items()})
        out.update({"modes": self.modes, "rebound_velocity": self.rebound_velocity,
                    "energy_error": self.energy_error, "n_contacts": len(self.contacts),
                    "n_steps": self.n_steps, "wall_time_s": self.wall_time_s, "message": self.message})
        return out


def build(cls, values: dict[str, Any]):
    """The instance `cls(**values)` of a frozen dataclass of this package with many fields (ImpactResult, the
    solver's Run), made without the generated __init__'s one object.__setattr__ per field: the reference
    solver builds one per call and its __init__ cost ~5 us of a ~100 us solve. Same fields in the same order,
    defaults and default factories as __init__ (a fresh list/dict/array per instance), __post_init__ run;
    unknown names raise TypeError as __init__ would. For hot paths only; `values` must hold what __init__
    would store (no conversion happens other than __post_init__'s). A `values` that names every field, in any
    order, becomes the instance's __dict__ itself (pass a fresh dict: the reference solver's result, ~2 us less)."""
    plain, factories, required, post = _TEMPLATES.get(cls) or _template(cls)
    if len(values) == len(plain) and values.keys() == plain.keys():
        obj = object.__new__(cls)
        object.__setattr__(obj, "__dict__", values)
        if post is not None:
            post(obj)
        return obj
    d = plain.copy()
    d.update(values)
    if len(d) != len(plain):
        raise TypeError(f"{cls.__name__} has no field {sorted(set(values) - set(plain))[0]!r}")
    if len(values) != len(plain):          # some fields left to their defaults
        if not required <= values.keys():
            raise TypeError(f"{cls.__name__} needs field {sorted(required - set(values))[0]!r}")
        for name, factory in factories:
            if name not in values:
                d[name] = factory()
    obj = object.__new__(cls)
    object.__setattr__(obj, "__dict__", d)
    if post is not None:
        post(obj)
    return obj


_TEMPLATES: dict = {}


def _template(cls):
    """(defaults in field order (None for the rest), (name, factory) pairs, required names, __post_init__) of `cls`."""
    if not (dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen):
        raise TypeError(f"build() makes frozen dataclasses, not {cls.__name__}")
    plain, factories, required = {}, [], []
    for f in dataclasses.fields(cls):
        if not f.init:
            raise TypeError(f"build() does not handle {cls.__name__}.{f.name} (init=False)")
        if f.default is not dataclasses.MISSING:
            plain[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            plain[f.name] = None
            factories.append((f.name, f.default_factory))
        else:
            plain[f.name] = None
            required.append(f.name)
    out = (plain, tuple(factories), frozenset(required), getattr(cls, "__post_init__", None))
    _TEMPLATES[cls] = out
    return out
