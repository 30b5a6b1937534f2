"""One look for every figure and page: engine colours, reference styles, mark meanings.

Every plot in reports/ takes its colours from here, so an engine has the same colour in the
force curves, the trend plots, the speed/accuracy plots and the HTML page. Colours are the
Okabe-Ito palette (distinguishable with the common colour-vision deficiencies); an engine not
listed gets a stable colour from the rest of the palette (chosen by a hash of its name, so it
does not change from one report to the next).
"""
from __future__ import annotations

import hashlib

#: engine name -> colour (hex); the reference is always black, the linear theory grey
ENGINE_COLOURS: dict[str, str] = {
    "mujoco": "#0072B2",      # blue
    "pybullet": "#D55E00",    # vermillion
    "exudyn": "#009E73",      # bluish green
    "warp": "#CC79A7",        # reddish purple
    "newton": "#E69F00",      # orange
}
#: colours for engines not in ENGINE_COLOURS
EXTRA_COLOURS = ("#56B4E9", "#F0E442", "#8C564B", "#7F7F7F", "#17BECF", "#BCBD22")
REFERENCE_COLOUR = "#000000"
LINEAR_THEORY_COLOUR = "#808080"
#: line styles: reference solid, linear theory dashed, engines solid with markers off
REFERENCE_STYLE = {"color": REFERENCE_COLOUR, "lw": 2.2, "ls": "-"}
LINEAR_THEORY_STYLE = {"color": LINEAR_THEORY_COLOUR, "lw": 1.4, "ls": "--"}
#: marker drawn on a trend plot at a flagged night
REGRESSION_MARKER = {"marker": "P", "s": 90, "color": "#C00000", "zorder": 5}

#: comparison marks (asv's), in the order a reader wants them
MARKS = {
    "!": "newly failing (the baseline row had a result, this one has none)",
    "+": "worse past its threshold",
    "*": "fixed (the baseline row failed, this one has a result)",
    "-": "better past its threshold",
    "x": "not comparable (no baseline row with the same scene, engine and settings, or the scene or "
         "reference changed)",
}


def engine_colour(engine: str) -> str:
    """The colour of `engine` (an engine name or 'package.module:Class' adapter)."""
    name = str(engine).split(":")[-1].lower()
    if name in ENGINE_COLOURS:
        return ENGINE_COLOURS[name]
    digest = int(hashlib.sha1(name.encode()).hexdigest(), 16)
    return EXTRA_COLOURS[digest % len(EXTRA_COLOURS)]
