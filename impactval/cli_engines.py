"""`impactval engines`: which engines are installed (with versions) and how to install the rest."""
from __future__ import annotations

import click


def engine_rows() -> list[tuple[str, str, str]]:
    """(engine, "installed" | "not installed", version or install command) per registered engine,
    without importing any engine (versions from package metadata)."""
    import importlib.util
    from importlib.metadata import PackageNotFoundError, version

    from impactval.engines import ENGINE_MODULES

    dists = {"mujoco": "mujoco", "pybullet": "pybullet", "exudyn": "exudyn", "mujoco-warp": "mujoco-warp",
             "newton": "newton"}
    rows = []
    for name, module in ENGINE_MODULES.items():
        if importlib.util.find_spec(module) is None:
            rows.append((name, "not installed", f"pip install 'impactval[{name}]'"))
            continue
        try:
            v = version(dists.get(name, name))
        except PackageNotFoundError:
            v = "unknown version"
        rows.append((name, "installed", v))
    return rows


@click.command(name="engines")
def engines_command() -> None:
    """List the engine adapters: installed ones with their version, the others with the install command."""
    for name, state, info in engine_rows():
        click.echo(f"{name:12s} {state:14s} {info}")
