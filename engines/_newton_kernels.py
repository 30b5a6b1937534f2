"""Warp kernel of the Newton adapter (imported only when that engine runs: imports warp)."""
from __future__ import annotations

import warp as wp


@wp.kernel
def record(body_q: wp.array(dtype=wp.transform), body_qd: wp.array(dtype=wp.spatial_vector),
           counter: wp.array(dtype=int), base: wp.array(dtype=int), states: wp.array2d(dtype=float)):
    """Runs after each solver step (k = steps so far): row k - base[0] of `states` (a chunk the host empties, see
    engines/_warp.py ChunkedRecord) = every body's pose (7: position, quaternion x y z w) then every body's twist
    (6: linear, angular) after the step."""
    k = counter[0] + 1
    r = k - base[0]
    if r >= states.shape[0]:
        return
    nb = body_q.shape[0]
    for b in range(nb):
        for i in range(7):
            states[r, 7 * b + i] = body_q[b][i]
        for i in range(6):
            states[r, 7 * nb + 6 * b + i] = body_qd[b][i]
    counter[0] = k


@wp.kernel
def hertz_force(body_q: wp.array(dtype=wp.transform), body_com: wp.array(dtype=wp.vec3), ball: int,
                ball_z0: float, hit_body: int, hit_local: wp.vec3, alpha: float,
                body_f: wp.array(dtype=wp.spatial_vector)):
    """Adds alpha*max(delta,0)^1.5 [N] from the current poses: up on the ball (through its centre),
    down on the target's hit point (force and moment about the hit body's centre of mass). delta = the hit
    point's z displacement from rest minus the ball's (its body z - ball_z0), each formed from small numbers
    (the hit body's frame rests at z = 0; its rotation's effect on hit_local as R v - v), so float32 resolves
    delta at the size of the displacements, not at the ulp of the contact point's height."""
    u_ball = wp.transform_get_translation(body_q[ball])[2] - ball_z0
    w_hit = float(0.0)
    if hit_body >= 0:
        rot = wp.transform_get_rotation(body_q[hit_body])
        qv = wp.vec3(rot[0], rot[1], rot[2])
        t = 2.0 * wp.cross(qv, hit_local)
        w_hit = wp.transform_get_translation(body_q[hit_body])[2] + rot[3] * t[2] + wp.cross(qv, t)[2]
    delta = w_hit - u_ball
    if delta <= 0.0:
        return
    f = alpha * delta * wp.sqrt(delta)
    body_f[ball] = body_f[ball] + wp.spatial_vector(0.0, 0.0, f, 0.0, 0.0, 0.0)
    if hit_body >= 0:
        force = wp.vec3(0.0, 0.0, -f)
        p = wp.transform_point(body_q[hit_body], hit_local)
        arm = p - wp.transform_point(body_q[hit_body], body_com[hit_body])
        body_f[hit_body] = body_f[hit_body] + wp.spatial_vector(force, wp.cross(arm, force))
