"""One error base class for everything a user can get wrong (style.md, pattern 7)."""


class ImpactvalError(ValueError):
    """Bad input: the message names the file or field, the value, and what is allowed."""


class SceneError(ImpactvalError):
    """A scene (TOML file, catalogue name or Python object) is invalid."""


class EngineError(ImpactvalError):
    """An engine name or engine setting is invalid."""
