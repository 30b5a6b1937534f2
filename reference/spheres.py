"""Ball on ball: two free spheres on one axis, both deformable (Hertz with both curvatures).

The relative motion delta = x1 - x2 obeys m* delta'' = -alpha delta^1.5 with the reduced mass
m* = m1 m2 / (m1 + m2), the relative approach speed v = v1 + v2 (each positive toward the other ball) and
alpha = (4/3) E* / sqrt(1/R1 + 1/R2), E* from both materials. That is exactly a ball of mass m* and radius
R1 R2 / (R1 + R2) at speed v on a rigid plate, so t_m, f_m, delta_m have the closed form of
`hertz.plate_impact`. The centre of mass moves uniformly; each ball's displacement is the centre of mass's plus
its share of delta.
"""
from __future__ import annotations

import dataclasses


from impactval.reference.hertz import PlateImpact, plate_impact


def reduced_mass(scene) -> float:
    """m* = m1 m2 / (m1 + m2) [kg]."""
    m1, m2 = scene.ball.mass, scene.target.mass
    return m1 * m2 / (m1 + m2)


def approach_speed(scene) -> float:
    """Relative approach speed v1 + v2 [m/s] (each ball's speed toward the other)."""
    return scene.ball.velocity + scene.target.velocity


def equivalent_plate_scene(scene):
    """The same contact as a ball (mass m*, radius R1 R2/(R1 + R2), speed v1 + v2) on a rigid plate of the
    second ball's material: same alpha, same relative motion."""
    from impactval.scenarios.scene import Ball, RigidPlate, Scene

    b, t = scene.ball, scene.target
    r_eff = b.radius * t.radius / (b.radius + t.radius)
    return Scene(scene.name, Ball(r_eff, approach_speed(scene), b.material, reduced_mass(scene)),
                 RigidPlate(t.material), scene.description, scene.tags, scene.source)


def two_sphere_impact(scene) -> PlateImpact:
    """Closed form t_m [s], f_m [N], delta_m [m] of the two-ball impact (Hertz, reduced mass)."""
    return plate_impact(reduced_mass(scene), scene.alpha, approach_speed(scene))


def two_sphere_result(scene, relative):
    """The two-ball result from the relative-motion result `relative` (an ImpactResult of the equivalent
    plate scene): x_ball and x_structure become the two balls' displacements [m] toward the second ball,
    rebound_velocity the first ball's speed away from the second after the contact [m/s], energy the total."""
    m1, m2 = scene.ball.mass, scene.target.mass
    v1, v2 = scene.ball.velocity, scene.target.velocity
    v_cm = (m1 * v1 - m2 * v2) / (m1 + m2)          # toward the second ball
    t = relative.t
    x_cm = v_cm * t
    x1 = x_cm + m2 / (m1 + m2) * relative.x_ball
    x2 = x_cm - m1 / (m1 + m2) * relative.x_ball
    # the relative velocity after contact is -rebound_rel (toward each other); ball 1's own velocity:
    u1 = v_cm - m2 / (m1 + m2) * relative.rebound_velocity
    energy = relative.energy + 0.5 * (m1 + m2) * v_cm**2
    return dataclasses.replace(relative, model=relative.model.replace("hertz-rigid", "hertz-two-spheres"),
                               x_ball=x1, x_structure=x2, rebound_velocity=-u1, energy=energy,
                               settings={**relative.settings, "reduced_mass": reduced_mass(scene),
                                         "approach_speed": approach_speed(scene)})


def two_sphere_velocities_after(scene) -> tuple[float, float]:
    """Elastic exchange (restitution 1): each ball's velocity [m/s] toward the other after the contact."""
    m1, m2 = scene.ball.mass, scene.target.mass
    v1, v2 = scene.ball.velocity, scene.target.velocity
    v_cm = (m1 * v1 - m2 * v2) / (m1 + m2)
    return 2 * v_cm - v1, -(2 * v_cm) - v2


__all__ = ["reduced_mass", "approach_speed", "equivalent_plate_scene", "two_sphere_impact", "two_sphere_result",
           "two_sphere_velocities_after"]
