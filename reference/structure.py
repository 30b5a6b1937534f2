"""The modal data of any scene target, seen from its impact point (the one dispatch on target kind).

`structure_modes(scene, n)` returns `beams.Modes`: `omega` [rad/s], `modal_mass` [kg] (shapes normalised to
max |W| = 1), `phi` (shape value at the impact point) and, with `residual`, the static flexibility [m/N] of every
mode not returned (exact total minus the listed modes' share: the mode-acceleration correction).

- rigid plate, ball (a free second sphere: see reference/spheres.py): no modes;
- modal: the listed modes (the n lowest when n is given);
- beam: Euler-Bernoulli (reference/beams.py) or Timoshenko (reference/timoshenko.py) by `theory`;
- plate: Kirchhoff, simply supported (reference/plates.py).
"""
from __future__ import annotations

import numpy as np

from impactval.errors import ImpactvalError
from impactval.reference.beams import Modes, beam_modes, truncate_modes

#: target kinds with infinitely many modes (mode count chosen automatically unless the scene sets one)
CONTINUOUS_KINDS = ("beam", "plate")
#: target kinds with no structure modes (the contact sees a rigid body)
RIGID_KINDS = ("rigid-plate", "ball")


def _empty() -> Modes:
    return Modes(np.zeros(0), np.zeros(0), np.zeros(0), 0.0)


def structure_modes(scene, n: int | None = None, residual: bool = False) -> Modes:
    """The modal data of `scene`'s target: the first `n` modes (frequency order) of a beam or plate, the `n`
    lowest of a modal target (all when n is None), nothing for a rigid plate or a second ball. `residual` adds
    the static flexibility of the modes left out (beams, plates, truncated modal targets).

    The result depends on the (frozen) target only and is cached (read-only arrays): repeated solves of one
    scene do not recompute modes."""
    if n is not None and (isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0):
        raise ImpactvalError(f"n must be a whole number of modes (>= 0), got {n!r}.")
    key = (scene.target, None if n is None else int(n), bool(residual))
    try:
        hit = _CACHE.get(key)
    except TypeError:                  # a target with unhashable fields: no caching
        return _structure_modes(scene, n, residual)
    if hit is None:
        hit = _structure_modes(scene, n, residual)
        for a in (hit.omega, hit.modal_mass, hit.phi):
            a.flags.writeable = False
        if len(_CACHE) >= 64:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = hit
    return hit


_CACHE: dict = {}


def _structure_modes(scene, n: int | None, residual: bool) -> Modes:
    target = scene.target
    if target.kind in RIGID_KINDS:
        return _empty()
    if n == 0:      # no modes: the whole structure as its static flexibility (with `residual`)
        return Modes(np.zeros(0), np.zeros(0), np.zeros(0), static_flexibility(scene) if residual else 0.0)
    if target.kind == "modal":
        md = Modes(np.asarray(target.omega, float), np.asarray(target.modal_mass, float),
                   np.asarray(target.phi, float), 0.0)
        return md if n is None or n >= md.n else truncate_modes(md, int(n), residual)
    if n is None:
        n = target.modes
        if n is None:
            raise ImpactvalError(f"scene {scene.name!r}: give n, the number of {target.kind} modes wanted "
                                 f"(the scene sets no [target] modes).")
    if target.kind == "beam":
        return beam_modes(target, int(n), residual=residual)
    if target.kind == "plate":
        from impactval.reference.plates import plate_modes

        return plate_modes(target, int(n), residual=residual)
    raise ImpactvalError(f"unknown target kind {target.kind!r}")


def static_flexibility(scene) -> float:
    """Static flexibility w/F [m/N] of the target at the impact point, all modes together (0 for rigid
    targets; for a modal target the sum over its listed modes)."""
    target = scene.target
    if target.kind in RIGID_KINDS:
        return 0.0
    if target.kind == "modal":
        md = structure_modes(scene)
        return float(np.sum(md.phi**2 / (md.modal_mass * md.omega**2)))
    if target.kind == "plate":
        from impactval.reference.plates import static_flexibility as plate_static

        m = target.material
        return plate_static(m.young, m.poisson, target.length, target.width, target.thickness, *target.impact_at)
    md = beam_modes(target, 1, residual=True)
    return float(md.residual_flexibility + md.phi[0] ** 2 / (md.modal_mass[0] * md.omega[0] ** 2))


def contact_scene(scene):
    """The scene whose ball-and-target model the reference solves: for a second ball the equivalent ball on a
    rigid plate (reduced mass, relative speed, same alpha; reference/spheres.py), otherwise `scene` itself."""
    if scene.target.kind == "ball":
        from impactval.reference.spheres import equivalent_plate_scene

        return equivalent_plate_scene(scene)
    return scene
