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


@wp.kernel
def hertz_passive(body_rootid: wp.array(dtype=int), body_isdofancestor: wp.array2d(dtype=int),
                  subtree_com: wp.array2d(dtype=wp.vec3), cdof: wp.array2d(dtype=wp.spatial_vector),
                  site_xpos: wp.array2d(dtype=wp.vec3), tip_site: int, hit_site: int, ball_body: int,
                  hit_body: int, alpha: float, qfrc_passive: wp.array2d(dtype=float)):
    """Adds alpha*max(delta,0)^1.5 [N] (delta = approach of the tip and hit sites [m], current
    kinematics) up on the ball at its tip and down on the target at its hit point, one dof per thread."""
    dof = wp.tid()
    tip = site_xpos[0, tip_site]
    hit = site_xpos[0, hit_site]
    delta = hit[2] - tip[2]
    if delta <= 0.0:
        return
    f = alpha * delta * wp.sqrt(delta)
    j = point_jacobian_z(body_rootid, body_isdofancestor, subtree_com, cdof, tip, ball_body, dof) \
        - point_jacobian_z(body_rootid, body_isdofancestor, subtree_com, cdof, hit, hit_body, dof)
    qfrc_passive[0, dof] = qfrc_passive[0, dof] + j * f


@wp.kernel
def record(site_xpos: wp.array2d(dtype=wp.vec3), energy: wp.array(dtype=wp.vec2),
           qpos: wp.array2d(dtype=float), qvel: wp.array2d(dtype=float),
           nacon: wp.array(dtype=int), efc_address: wp.array2d(dtype=int), efc_force: wp.array2d(dtype=float),
           tip_site: int, hit_site: int, hit_top: float, alpha: float, native: int, nv: int, nq: int,
           offset: int, counter: wp.array(dtype=int), samples: wp.array2d(dtype=float),
           states: wp.array2d(dtype=float)):
    """Runs after each `mjw.step` (k = steps so far). Row k + offset of `samples` gets the sample of
    the kinematics, constraint forces and energy last computed: offset 0 = those `mjw.step` computed
    for the step's start (Euler, implicitfast); offset 1 = those of an extra `mjw.forward` after the
    step (RK4, whose last evaluation is its fourth stage). Columns: delta [m], contact force [N],
    downward displacement of the target's contact point [m], potential and kinetic energy [J].
    Row k+1 of `states` gets the state after the step (qpos then qvel)."""
    k = counter[0]
    if k + 2 >= samples.shape[0]:
        return
    tip = site_xpos[0, tip_site]
    hit = site_xpos[0, hit_site]
    delta = hit[2] - tip[2]
    f = float(0.0)
    if native != 0:
        for c in range(nacon[0]):
            adr = efc_address[c, 0]
            if adr >= 0:
                f = f + efc_force[0, adr]
    elif delta > 0.0:
        f = alpha * delta * wp.sqrt(delta)
    r = k + offset
    samples[r, 0] = delta
    samples[r, 1] = f
    samples[r, 2] = hit_top - hit[2]
    samples[r, 3] = energy[0][0]
    samples[r, 4] = energy[0][1]
    for i in range(nq):
        states[k + 1, i] = qpos[0, i]
    for i in range(nv):
        states[k + 1, nq + i] = qvel[0, i]
    counter[0] = k + 1
