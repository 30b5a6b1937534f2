"""Warp kernels of the MuJoCo Warp adapter (imported only when that engine runs: imports warp).

All arrays are those of one world (index 0) of a `mujoco_warp` Data. Units SI; float32 like the engine.
"""
from __future__ import annotations

import warp as wp


@wp.func
def point_jacobian_z(body_rootid: wp.array(dtype=int), body_isdofancestor: wp.array2d(dtype=int),
                     subtree_com: wp.array2d(dtype=wp.vec3), cdof: wp.array2d(dtype=wp.spatial_vector),
                     point: wp.vec3, body: int, dof: int) -> float:
    """z row of the translational Jacobian of `point` [m] on `body` for one dof (0 off the chain)."""
    if body <= 0:
        return 0.0
    if body_isdofancestor[body, dof] == 0:
        return 0.0
    offset = point - subtree_com[0, body_rootid[body]]
    c = cdof[0, dof]
    jp = wp.spatial_bottom(c) + wp.cross(wp.spatial_top(c), offset)
    return jp[2]


@wp.func
def approach(xpos: wp.array2d(dtype=wp.vec3), xquat: wp.array2d(dtype=wp.quat), hit_body: int, hit_local: wp.vec3,
             hit_z0: float, q_ball: float, ball_sign: float, ball_q0: float) -> wp.vec2:
    """(delta, w_hit) [m]: the approach = the hit point's z displacement from rest w_hit minus the ball's (its slide
    qpos q_ball - ball_q0, times the slide axis' z; q_ball of the same state as the kinematics xpos, xquat), each formed from small numbers: the hit body's frame z - its rest z
    (hit_z0, the centre line at z = 0) plus its rotation's effect on the site offset hit_local as R v - v from the
    quaternion (w, x, y, z: 2 s u x v + 2 u x (u x v)). The sites' world z (at the contact's height h/2, plus the ball
    radius for the tip) round at ulp(h/2 + r) in float32: 1.9e-9 m on a 51 mm beam, a fifth of a 9.8e-9 m approach."""
    u_ball = (q_ball - ball_q0) * ball_sign
    w_hit = float(0.0)
    if hit_body > 0:
        q = xquat[0, hit_body]
        u = wp.vec3(q[1], q[2], q[3])
        t = 2.0 * wp.cross(u, hit_local)
        w_hit = (xpos[0, hit_body][2] - hit_z0) + q[0] * t[2] + wp.cross(u, t)[2]
    return wp.vec2(w_hit - u_ball, w_hit)


@wp.kernel
def hertz_passive(body_rootid: wp.array(dtype=int), body_isdofancestor: wp.array2d(dtype=int),
                  subtree_com: wp.array2d(dtype=wp.vec3), cdof: wp.array2d(dtype=wp.spatial_vector),
                  site_xpos: wp.array2d(dtype=wp.vec3), tip_site: int, hit_site: int, ball_body: int,
                  hit_body: int, alpha: float, xpos: wp.array2d(dtype=wp.vec3), xquat: wp.array2d(dtype=wp.quat),
                  qpos: wp.array2d(dtype=float), hit_local: wp.vec3, hit_z0: float, ball_q: int, ball_sign: float,
                  ball_q0: float, qfrc_passive: wp.array2d(dtype=float)):
    """Adds alpha*max(delta,0)^1.5 [N] (delta = approach of the tip and hit points [m] from `approach`, current
    kinematics) up on the ball at its tip and down on the target at its hit point, one dof per thread."""
    dof = wp.tid()
    tip = site_xpos[0, tip_site]
    hit = site_xpos[0, hit_site]
    delta = approach(xpos, xquat, hit_body, hit_local, hit_z0, qpos[0, ball_q], ball_sign, ball_q0)[0]
    if delta <= 0.0:
        return
    f = alpha * delta * wp.sqrt(delta)
    j = point_jacobian_z(body_rootid, body_isdofancestor, subtree_com, cdof, tip, ball_body, dof) \
        - point_jacobian_z(body_rootid, body_isdofancestor, subtree_com, cdof, hit, hit_body, dof)
    qfrc_passive[0, dof] = qfrc_passive[0, dof] + j * f


@wp.kernel
def record(energy: wp.array(dtype=wp.vec2),
           qpos: wp.array2d(dtype=float), qvel: wp.array2d(dtype=float),
           nacon: wp.array(dtype=int), efc_address: wp.array2d(dtype=int), efc_force: wp.array2d(dtype=float),
           alpha: float, native: int, nv: int, nq: int,
           xpos: wp.array2d(dtype=wp.vec3), xquat: wp.array2d(dtype=wp.quat), hit_body: int, hit_local: wp.vec3,
           hit_z0: float, ball_q: int, ball_sign: float, ball_q0: float, ball_prev: wp.array(dtype=float),
           offset: int, counter: wp.array(dtype=int), base: wp.array(dtype=int), samples: wp.array2d(dtype=float),
           states: wp.array2d(dtype=float)):
    """Runs after each `mjw.step` (k = steps so far). Row k + offset of `samples` gets the sample of
    the kinematics, constraint forces and energy last computed: offset 0 = those `mjw.step` computed
    for the step's start (Euler, implicitfast); offset 1 = those of an extra `mjw.forward` after the
    step (RK4, whose last evaluation is its fourth stage). Columns: delta [m], contact force [N],
    downward displacement of the target's contact point [m], potential and kinetic energy [J].
    Row k+1 of `states` gets the state after the step (qpos then qvel). Rows are global minus base[0] (chunks the
    host empties, engines/_warp.py ChunkedRecord)."""
    k = counter[0]
    if k + 2 - base[0] >= samples.shape[0]:
        return
    # the kinematics are the sample's state; qpos is already the next one when offset = 0 (the ball's slide qpos of
    # the sample's state is then the one the previous call kept in ball_prev)
    q_now = qpos[0, ball_q]
    q_ball = q_now
    if offset == 0:
        q_ball = ball_prev[0]
    ball_prev[0] = q_now
    dw = approach(xpos, xquat, hit_body, hit_local, hit_z0, q_ball, ball_sign, ball_q0)
    delta = dw[0]
    f = float(0.0)
    if native != 0:
        for c in range(nacon[0]):
            adr = efc_address[c, 0]
            if adr >= 0:
                f = f + efc_force[0, adr]
    elif delta > 0.0:
        f = alpha * delta * wp.sqrt(delta)
    r = k + offset - base[0]
    samples[r, 0] = delta
    samples[r, 1] = f
    samples[r, 2] = -dw[1]
    samples[r, 3] = energy[0][0]
    samples[r, 4] = energy[0][1]
    rs = k + 1 - base[0]
    for i in range(nq):
        states[rs, i] = qpos[0, i]
    for i in range(nv):
        states[rs, nq + i] = qvel[0, i]
    counter[0] = k + 1
