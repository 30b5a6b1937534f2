"""Scene files of the hostile-input checks, shared by tests/test_hostile.py (Hypothesis and the named
refusals) and benchmarks/hostile_inputs.py (every case in its own process): one good scene per
target kind, each case changes one thing. Units: m, m/s, rad/s, kg."""

PLATE = """\
name = "x"
[ball]
radius = 0.01
velocity = 1.0
material = "steel"
[target]
kind = "rigid-plate"
material = "steel"
"""
MODAL = PLATE.replace('kind = "rigid-plate"', 'kind = "modal"') + \
    "omega = [30000.0, 120000.0]\nmodal_mass = [0.5, 0.8]\nphi = [1.0, 0.7]\n"
BEAM = PLATE.replace('kind = "rigid-plate"', 'kind = "beam"') + \
    'support = "simply-supported"\nlength = 0.5\nwidth = 0.01\nheight = 0.01\nimpact_at = 0.5\n'


def named(text: str, name: str) -> str:
    """The scene text with its name set to `name`."""
    return text.replace('name = "x"', f'name = "{name}"', 1)
