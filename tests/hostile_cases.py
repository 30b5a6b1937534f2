"""The hostile-input tables, one copy for the tests and benchmarks/hostile_inputs.py (every case in its own
process): one good scene per target kind (each case changes one thing; units m, m/s, rad/s, kg), the bad
range texts (tests/test_ranges.py, tests/test_sweep.py) and the Python API calls (tests/test_hostile.py)."""

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


# ------------------------------------------------------------------------------------- range options
#: bad `a:b:n` / list texts of sweep --dt, tune --speeds, extremes --axis and run --dt, by the words their one-line
#: refusal holds besides the option (tests/test_ranges.py through the CLI, benchmarks/hostile_inputs.py per process)
BAD_RANGES: dict[str, tuple[str, ...]] = {
    "a:b:n": ("1:2", "1:2:3:4"),
    "n >= 2": ("1:2:1", "1:2:2.5"),
    "n <= 200": ("1:10:1e9",),
    "whole number": ("1:2:x",),
    "positive": ("0:1:3", "-1:1:3", "-1e-3", "-1", "0"),
    "must differ": ("1:1:3",),
    "not a number": ("abc:1:3", "abc", "a,b"),
    "finite": ("1e999:1:3", "nan:1:3", "inf"),
    "at least one": (",",),
}
BAD_RANGE_CASES = [(text, words) for words, texts in BAD_RANGES.items() for text in texts]


# ------------------------------------------------------------------------------------- the Python API
_PLATE = "impactval.load_scene('plate_steel')"
_BEAM = "impactval.load_scene('beam_ss_midspan')"
_MODAL = "impactval.load_scene('modal_two_mode')"
_REPLACE = "__import__('dataclasses').replace"
_NP = "__import__('numpy')"
_LINEAR = "__import__('impactval.reference.linear').reference.linear.solve_linear"
_FROM_DICT = "__import__('impactval.scenarios.scene').scenarios.scene.scene_from_dict"
_RUN = "__import__('impactval.runner').runner.run"

#: public calls (expressions, `impactval` imported) refused with one ImpactvalError line, by a word it must hold
#: ("" = any); tests/test_hostile.py evaluates them in process, benchmarks/hostile_inputs.py each in its own
API_REFUSED: dict[str, tuple[str, ...]] = {
    "scene": ("impactval.solve(None)", "impactval.solve(5)", "impactval.solve({})", "impactval.load_scene(None)",
              "impactval.load_scene(5)", "impactval.load_scene(b'plate_steel')", "impactval.load_scene('')",
              "impactval.load_scene('a\\x00b')", "impactval.load_scene('x' * 5000)",
              "impactval.load_scene(['plate_steel'])", f"{_RUN}([], 'mujoco')"),
    "nope": ("impactval.solve(__import__('pathlib').Path('nope.toml'))",),
    "": ("impactval.load_scene(__import__('tempfile').gettempdir())",),
    "tol": (f"impactval.solve({_PLATE}, tol='a')", f"impactval.solve({_PLATE}, tol=None)",
            f"impactval.solve({_PLATE}, tol=True)", f"impactval.solve({_PLATE}, tol=[1e-6])",
            f"impactval.solve({_PLATE}, tol={_NP}.nan)", f"{_LINEAR}({_PLATE}, tol=float('nan'))"),
    "window": (f"impactval.solve({_PLATE}, window='x')", f"impactval.solve({_PLATE}, window=-1)",
               f"impactval.solve({_PLATE}, window=None)"),
    "modes": (f"impactval.solve({_BEAM}, modes=0)", f"impactval.solve({_BEAM}, modes=2.5)",
              f"impactval.solve({_BEAM}, modes=10**9)"),
    "static_correction": (f"impactval.solve({_PLATE}, static_correction='no')",),
    "foo": (f"impactval.solve({_PLATE}, foo=1)",),
    "mass": (f"impactval.solve({_REPLACE}({_PLATE}, ball={_REPLACE}({_PLATE}.ball, mass=1e300)))",),
    "radius": (f"impactval.solve({_REPLACE}({_PLATE}, ball={_REPLACE}({_PLATE}.ball, radius=-1.0)))",),
    "velocity": (f"impactval.solve({_REPLACE}({_PLATE}, ball={_REPLACE}({_PLATE}.ball, velocity=float('nan'))))",),
    "name": (f"impactval.solve({_REPLACE}({_PLATE}, name='a\\nb'))",),
    "omega": (f"impactval.solve({_REPLACE}({_MODAL}, target={_REPLACE}({_MODAL}.target, omega=(1e-300, 1.0))))",),
    "target": (f"impactval.solve({_REPLACE}({_PLATE}, target=None))",),
    "table": (f"{_FROM_DICT}(None)", f"{_FROM_DICT}([1])"),
    "stiffness": (f"{_LINEAR}({_PLATE}, stiffness=-1.0)",),
    "model": (f"__import__('impactval.reference.perturbation').reference.perturbation.perturbation({_PLATE}, 'x')",),
    "engine": (f"{_RUN}(['plate_steel'], 5)",),
}
#: public calls at the edge of the ranges: a finite answer or one refusal line, never a traceback
API_EDGE: tuple[str, ...] = (
    "impactval.solve('plate_steel')", f"impactval.solve({_PLATE}, tol={_NP}.float32(1e-5))",
    f"impactval.solve({_BEAM}, modes={_NP}.int64(8), tol=1e-4)", f"impactval.load_scene({_PLATE})",
    f"{_LINEAR}({_PLATE}, stiffness=1e300)",
)
API_REFUSED_CASES = [(code, word) for word, codes in API_REFUSED.items() for code in codes]
