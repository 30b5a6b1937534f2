"""Warp kernel of the Newton adapter (imported only when that engine runs: imports warp)."""
from __future__ import annotations

import warp as wp


@wp.kernel
def record(body_q: wp.array(dtype=wp.transform), body_qd: wp.array(dtype=wp.spatial_vector),
           counter: wp.array(dtype=int), states: wp.array2d(dtype=float)):
    """Runs after each solver step: row k+1 of `states` = every body's pose (7: position, quaternion
    x y z w) then every body's twist (6: linear, angular) after the step."""
    k = counter[0] + 1
    if k >= states.shape[0]:
        return
    nb = body_q.shape[0]
    for b in range(nb):
        for i in range(7):
            states[k, 7 * b + i] = body_q[b][i]
        for i in range(6):
            states[k, 7 * nb + 6 * b + i] = body_qd[b][i]
    counter[0] = k


@wp.kernel
def hertz_force(body_q: wp.array(dtype=wp.transform), body_com: wp.array(dtype=wp.vec3), ball: int,
                radius: float, hit_body: int, hit_local: wp.vec3, hit_top: float, alpha: float,
                body_f: wp.array(dtype=wp.spatial_vector)):
    """Adds alpha*max(delta,0)^1.5 [N] from the current poses: up on the ball (through its centre),
    down on the target's hit point (force and moment about the hit body's centre of mass)."""
    zb = wp.transform_get_translation(body_q[ball])[2]
    p = wp.vec3(0.0, 0.0, hit_top)
    if hit_body >= 0:
        p = wp.transform_point(body_q[hit_body], hit_local)
    delta = p[2] - (zb - radius)
    if delta <= 0.0:
        return
    f = alpha * delta * wp.sqrt(delta)
    body_f[ball] = body_f[ball] + wp.spatial_vector(0.0, 0.0, f, 0.0, 0.0, 0.0)
    if hit_body >= 0:
        force = wp.vec3(0.0, 0.0, -f)
        arm = p - wp.transform_point(body_q[hit_body], body_com[hit_body])
        body_f[hit_body] = body_f[hit_body] + wp.spatial_vector(force, wp.cross(arm, force))
