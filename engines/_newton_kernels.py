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
