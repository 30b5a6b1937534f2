"""One look for every plot: a fixed colour per engine (the same engine never changes colour between
panels or reports). Colours from the Okabe-Ito palette (readable with colour-blindness)."""
from __future__ import annotations

#: engine name -> matplotlib colour
ENGINE_COLOURS: dict[str, str] = {
    "mujoco": "#0072B2",       # blue
    "pybullet": "#D55E00",     # vermillion
    "exudyn": "#009E73",       # green
    "mujoco-warp": "#56B4E9",  # sky blue
    "newton": "#CC79A7",       # purple
    "reference": "#000000",    # black
}
#: colours for engines outside the map (third-party adapters), assigned in order of appearance
EXTRA_COLOURS = ("#E69F00", "#F0E442", "#999999", "#882255", "#44AA99")


def engine_colour(engine: str, _seen: dict[str, str] = {}) -> str:  # noqa: B006 - a deliberate per-process memo
    """The colour of `engine` (a fixed one for known engines, a stable extra one otherwise)."""
    if engine in ENGINE_COLOURS:
        return ENGINE_COLOURS[engine]
    if engine not in _seen:
        _seen[engine] = EXTRA_COLOURS[len(_seen) % len(EXTRA_COLOURS)]
    return _seen[engine]
