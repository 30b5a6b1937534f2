"""impactval: validation suite for multibody physics engines on elastic impact."""
from impactval.errors import EngineError, ImpactvalError, SceneError

__version__ = "0.1.0"
__all__ = ["load_scene", "solve", "structure_modes", "ImpactvalError", "SceneError", "EngineError", "__version__"]


def load_scene(name_or_path):
    """Load a scene: a catalogue name (see ``impactval scenes``) or a path to a TOML file."""
    from impactval.scenarios.scene import load_scene as _load

    return _load(name_or_path)


def solve(scene, tol: float = 1e-6, **kwargs):
    """Reference solution of `scene` (Hertz contact + modal structure) to relative tolerance `tol`.

    See :func:`impactval.reference.solve.solve` for the options.
    """
    from impactval.reference.solve import solve as _solve

    return _solve(scene, tol=tol, **kwargs)


def structure_modes(scene, n=None):
    """The first `n` modes of `scene`'s target seen from the impact point: an object with arrays `omega`
    [rad/s], `modal_mass` [kg, shapes normalised to max 1] and `phi` (shape value at the impact point).

    Rigid plate and ball targets have none; a modal target gives its own (the n lowest); beams (either
    theory) and plates the n lowest. `n` may be omitted when the scene sets `modes` (or for a modal target).
    """
    from impactval.reference.structure import structure_modes as _modes

    return _modes(scene, n)
