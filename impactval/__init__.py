"""impactval: validation suite for multibody physics engines on elastic impact."""
from impactval.errors import EngineError, ImpactvalError, SceneError

__version__ = "0.1.0"
__all__ = ["load_scene", "solve", "structure_modes", "ImpactvalError", "SceneError", "EngineError", "__version__"]


def load_scene(name_or_path):
    """Load a scene: a catalogue name (see ``impactval scenes``) or a path to a TOML file.

    A Scene is returned as it is after checking its fields; anything else raises SceneError.
    """
    from impactval.scenarios.scene import load_scene as _load

    return _load(name_or_path)


_SOLVE_OPTIONS = ("window", "modes", "static_correction")
_SOLVE_OPTION_SET = frozenset(_SOLVE_OPTIONS)
_SOLVE_IMPL: list = []          # (checks module, reference solve, scene loader), imported on the first call


def solve(scene, tol: float = 1e-6, **kwargs):
    """Reference solution of `scene` (Hertz contact + modal structure) to relative tolerance `tol`.

    `scene` is a Scene, a catalogue name or a path to a TOML file. Options: `window` [s] (time
    followed after the first contact), `modes` (beam or plate mode count: an explicit count, here or
    the scene's, makes the reference exactly these n modes, the paper's modal model, without the
    dropped modes' residual; its uncertainty covers that model's time step, not its distance to the
    continuum), `static_correction` (bool, default True: the residual static flexibility of the
    dropped modes, used only with an automatic mode count, ignored with an explicit one); see
    :func:`impactval.reference.solve.solve`. Bad arguments raise ImpactvalError naming the argument.
    """
    if not _SOLVE_IMPL:
        from impactval import checks
        from impactval.reference.solve import solve as _solve
        from impactval.scenarios.scene import load_scene as _load

        _SOLVE_IMPL[:] = [checks, _solve, _load]
    checks, _solve, _load = _SOLVE_IMPL
    if kwargs:
        if not _SOLVE_OPTION_SET.issuperset(kwargs):
            unknown = sorted(set(kwargs) - _SOLVE_OPTION_SET)
            raise ImpactvalError(f"solve() has no option {unknown[0]!r}; options: tol, {', '.join(_SOLVE_OPTIONS)}.")
        if "window" in kwargs:
            kwargs["window"] = checks.check_window(kwargs["window"])
        if "modes" in kwargs and not ((m := kwargs["modes"]).__class__ is int and 1 <= m <= checks.MAX_MODES):
            kwargs["modes"] = checks.check_modes(m)
        if "static_correction" in kwargs:
            kwargs["static_correction"] = checks.check_flag(kwargs["static_correction"], "static_correction")
    if not (tol.__class__ is float and 1e-12 <= tol <= 0.1):      # a float in range passes at a glance
        tol = checks.check_tol(tol)
    return _solve(_load(scene), tol=tol, **kwargs)


def structure_modes(scene, n=None):
    """The first `n` modes of `scene`'s target seen from the impact point: an object with arrays `omega`
    [rad/s], `modal_mass` [kg, shapes normalised to max 1] and `phi` (shape value at the impact point).

    `scene` is a Scene, a catalogue name or a path to a TOML file (as for :func:`solve`). Rigid plate and ball
    targets have none; a modal target gives its own (the n lowest); beams (either theory) and plates the n lowest.
    `n` (1 .. 100000) may be omitted when the scene sets `modes` (or for a modal target). Bad arguments raise
    ImpactvalError naming the argument.
    """
    from impactval import checks
    from impactval.reference.structure import structure_modes as _modes
    from impactval.scenarios.scene import load_scene as _load

    n = checks.check_modes(n, "n")
    return _modes(_load(scene), n)
