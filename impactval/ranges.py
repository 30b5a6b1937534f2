"""One range grammar for the command line: ``a:b:n`` (sweep --dt, tune --speeds, extremes --axis).

``a:b:n`` is n values from a to b, both included, equally spaced in log (geometric), in either
direction (``1e-5:1e-8:4`` = 1e-5, 1e-6, 1e-7, 1e-8); a and b positive, 2 <= n <= `MAX_POINTS`.
A value list is comma-separated; each item is one number or one range. Values are rounded to 12
significant digits, so a decade range gives exact powers of ten and every command turns the same
text into the same floats. Every refusal is an `ImpactvalError`: one line naming the option, the
text given and the fix.
"""
from __future__ import annotations

import math
from typing import Callable

from impactval.errors import ImpactvalError

#: most values one a:b:n range may expand to (a grid axis, not a sampling)
MAX_POINTS = 200
#: significant digits kept of each range value (removes float noise of geomspace: 1e-5:1e-8:4 -> exact decades)
DIGITS = 12


def log_range(start: float, stop: float, n: int) -> list[float]:
    """n values from `start` to `stop` (both included), equally spaced in log; 12 significant digits."""
    import numpy as np

    return [float(f"{v:.{DIGITS}g}") for v in np.geomspace(start, stop, n)]


def is_range(text: str) -> bool:
    """True when `text` is meant as a range (it holds a ':')."""
    return ":" in str(text)


def _in(unit: str) -> str:
    return f" in {unit}" if unit else ""


def number(token: str, option: str, *, unit: str = "", example: str = "", positive: bool = True,
           convert: Callable[[str], float] = float) -> float:
    """One value: `convert(token)` (float by default), finite, and positive unless `positive` is False."""
    tok = str(token).strip()
    try:
        value = float(convert(tok))
    except ImpactvalError:
        raise
    except (TypeError, ValueError, ArithmeticError):
        raise ImpactvalError(f"{option}: {tok!r} is not a number; give values{_in(unit)}, "
                             f"a list or a range a:b:n (e.g. {example}).") from None
    if not math.isfinite(value):
        raise ImpactvalError(f"{option}: values must be finite numbers, got {tok!r}.")
    if positive and value <= 0:
        raise ImpactvalError(f"{option}: values must be positive numbers{_in(unit)}, got {tok!r}.")
    return value


def parse_range(text: str, option: str, *, unit: str = "", example: str = "",
                convert: Callable[[str], float] = float) -> list[float]:
    """``a:b:n`` -> `log_range(a, b, n)`; a one-line ImpactvalError for anything else."""
    parts = str(text).strip().split(":")
    form = f"a:b:n (n log-spaced values from a to b{_in(unit)}, e.g. {example})"
    if len(parts) != 3:
        raise ImpactvalError(f"{option}: a range is {form}, got {text!r}.")
    try:
        count = float(parts[2])
    except ValueError:
        raise ImpactvalError(f"{option}: in a:b:n, n is a whole number of values (e.g. {example}), got {text!r}.") from None
    if not (count.is_integer() and 2 <= count <= MAX_POINTS):
        raise ImpactvalError(f"{option}: in a:b:n, need n >= 2 and n <= {MAX_POINTS} (a whole number; e.g. "
                             f"{example}), got {text!r}.")
    a = number(parts[0], option, unit=unit, example=example, convert=convert)
    b = number(parts[1], option, unit=unit, example=example, convert=convert)
    if a == b:
        raise ImpactvalError(f"{option}: in a:b:n, a and b must differ (give one value alone), got {text!r}.")
    return log_range(a, b, int(count))


def parse_list(text: str, option: str, *, unit: str = "", example: str = "", positive: bool = True,
               convert: Callable[[str], float] = float) -> list[float]:
    """A comma list of numbers and ``a:b:n`` ranges -> the values in the order given (duplicates kept)."""
    values: list[float] = []
    for item in str(text).split(","):
        item = item.strip()
        if not item:
            continue
        if is_range(item):
            values += parse_range(item, option, unit=unit, example=example, convert=convert)
        else:
            values.append(number(item, option, unit=unit, example=example, positive=positive, convert=convert))
    if not values:
        raise ImpactvalError(f"{option}: give at least one value (e.g. {example}).")
    return values


__all__ = ["MAX_POINTS", "log_range", "is_range", "number", "parse_range", "parse_list"]
