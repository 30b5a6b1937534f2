"""Typed per-engine options (`--option ENGINE.key=value`), validated at the edge (style.md, pattern 6).

Each adapter declares `Options`, a frozen dataclass whose fields are its options; a field's
`metadata["doc"]` says what it means (unit, default) and `metadata["check"]` (optional) converts and
validates a raw value, returning the value or raising ValueError with what is allowed. Unknown keys are
refused with the allowed list. In a run, "ENGINE.key" goes to that engine only (as "key") and plain
"key" to every engine; a prefix naming an engine that is not in the run (e.g. "bullet.x", a typo of
pybullet) is refused by `check_prefixes`.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
from dataclasses import dataclass, field, fields, replace
from typing import Any, Callable, Iterable

from impactval.errors import EngineError


def option(default: Any, doc: str, check: Callable[[Any], Any] | None = None,
           contacts: tuple[str, ...] | None = None) -> Any:
    """A dataclass field for an Options class: default, one-line doc (with unit), value check, and `contacts`: the
    contact modes (`settings.contact`) it applies to (None: every one; see `inapplicable_notes`)."""
    return field(default=default, metadata={"doc": doc, "check": check, "contacts": contacts})


def inapplicable_notes(settings, engine: str) -> tuple[str, ...]:
    """Row notes for options given (not at their default) that do not apply to the row's contact mode: they are
    ignored, which a user asking for e.g. a native contact stiffness under the Hertz contact must be told (user
    test s20 fuzz2, finding 7)."""
    opts = settings.options
    if not dataclasses.is_dataclass(opts):
        return ()
    notes = []
    for f in fields(opts):
        allowed = f.metadata.get("contacts")
        value = getattr(opts, f.name)
        if allowed and settings.contact not in allowed and value != f.default:
            shown = f"{value:g}" if isinstance(value, float) else str(value)
            notes.append(f"option {engine}.{f.name} = {shown} does not apply to contact {settings.contact!r} "
                         f"(only to {' / '.join(allowed)}): ignored")
    return tuple(notes)


# ---------------------------------------------------------------------------- value checks

def positive(value: Any) -> float:
    """A positive finite number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"must be a positive number, got {value!r}")
    return float(value)


def non_negative(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
        raise ValueError(f"must be a non-negative number, got {value!r}")
    return float(value)


def one_of(*allowed: str) -> Callable[[Any], str]:
    def check(value: Any) -> str:
        if value not in allowed:
            raise ValueError(f"must be one of {', '.join(allowed)}, got {value!r}")
        return value
    return check


def in_range(low: float, high: float, high_open: bool = False) -> Callable[[Any], float]:
    def check(value: Any) -> float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) \
            and low <= value and (value < high if high_open else value <= high)
        if not ok:
            raise ValueError(f"must be a number in [{low:g}, {high:g}{')' if high_open else ']'}, got {value!r}")
        return float(value)
    return check


def boolean(value: Any) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"must be true or false, got {value!r}")
    return value


def numbers(n: int, what: str = "numbers") -> Callable[[Any], tuple[float, ...]]:
    """n numbers, given as a sequence or a comma-separated string ("0.002,1")."""
    def check(value: Any) -> tuple[float, ...]:
        items = value.split(",") if isinstance(value, str) else value
        try:
            out = tuple(float(x) for x in items)
        except (TypeError, ValueError):
            raise ValueError(f"must be {n} comma-separated {what}, got {value!r}") from None
        if len(out) != n or not all(math.isfinite(x) for x in out):
            raise ValueError(f"must be {n} comma-separated finite {what}, got {value!r}")
        return out
    return check


def whole_numbers(n: int) -> Callable[[Any], tuple[int, ...]]:
    def check(value: Any) -> tuple[int, ...]:
        items = value.split(",") if isinstance(value, str) else value
        try:
            out = tuple(int(x) for x in items)
        except (TypeError, ValueError):
            raise ValueError(f"must be {n} positive whole numbers, got {value!r}") from None
        if len(out) != n or any(x < 1 for x in out) or any(isinstance(x, float) and x != int(x) for x in items):
            raise ValueError(f"must be {n} positive whole numbers, got {value!r}")
        return out
    return check


# ---------------------------------------------------------------------------- parsing

@dataclass(frozen=True)
class NoOptions:
    """An adapter without options."""


def describe(cls: type) -> str:
    """'key (doc); key (doc)' for an Options class."""
    return "; ".join(f"{f.name} ({f.metadata.get('doc', '')})" for f in fields(cls)) or "none"


def parse_options(cls: type, pairs: Iterable[tuple[str, Any]], engine: str) -> Any:
    """An instance of `cls` from (key, value) pairs; unknown keys and bad values raise EngineError
    naming the engine, the key, what is allowed."""
    known = {f.name: f for f in fields(cls)}
    values: dict[str, Any] = {}
    for key, value in pairs:
        f = known.get(key)
        if f is None:
            near = difflib.get_close_matches(key, known, n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise EngineError(f"{engine}: unknown option {key!r}{hint}; allowed: {describe(cls) if known else 'none'}.")
        check = f.metadata.get("check")
        if check is not None:
            try:
                value = check(value)
            except ValueError as err:
                raise EngineError(f"{engine}: option {key} {err} ({f.metadata.get('doc', '')}).") from None
        values[key] = value
    return cls(**values)


def engine_key(spec: str) -> str:
    """The name an option prefix uses for an engine spec: "mujoco" or the class name of "pkg.mod:Class"
    (lower case)."""
    return spec.split(":")[-1].lower() if ":" in spec else spec


def engine_keys(spec: str) -> set[str]:
    """Every prefix that names `spec`: its registry/entry-point name, or for "pkg.mod:Class" the class
    name (lower case) and the adapter's own `name`."""
    keys = {spec.lower(), engine_key(spec).lower()}
    if ":" in spec:
        try:
            from impactval.engines.base import adapter_class

            keys.add(str(adapter_class(spec).name).lower())
        except Exception:  # noqa: BLE001 - an unloadable spec is reported elsewhere
            pass
    return keys - {""}


def check_prefixes(options: Iterable[tuple[str, Any]], specs: Iterable[str]) -> None:
    """Refuse "ENGINE.key" options whose ENGINE is not one of the run's engines."""
    specs = list(specs)
    names = set().union(*(engine_keys(s) for s in specs)) if specs else set()
    for key, _ in options:
        head, dot, rest = key.partition(".")
        if not dot:
            continue
        if not rest:
            raise EngineError(f"option {key!r} has no key after {head!r}.; use ENGINE.KEY=VALUE.")
        if head.lower() not in names:
            near = difflib.get_close_matches(head.lower(), sorted(names), n=1, cutoff=0.5)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise EngineError(f"option {key!r} is for engine {head!r}, which is not in this run{hint}; "
                              f"engines in the run: {', '.join(sorted(engine_key(s) for s in specs))}.")


def options_for(settings, spec: str):
    """The settings one engine gets: options named "ENGINE.key" go to that engine only (as "key"),
    plain "key" options to every engine."""
    names = engine_keys(spec)
    opts = []
    for key, value in settings.options:
        head, dot, rest = key.partition(".")
        if not dot:
            opts.append((key, value))
        elif head.lower() in names:
            opts.append((rest, value))
    return replace(settings, options=tuple(opts))


def as_dict(options: Any) -> dict[str, Any]:
    return dataclasses.asdict(options) if dataclasses.is_dataclass(options) else {}


__all__ = ["option", "inapplicable_notes", "parse_options", "check_prefixes", "options_for", "describe", "NoOptions", "positive",
           "non_negative", "one_of", "in_range", "boolean", "numbers", "whole_numbers", "engine_key"]
