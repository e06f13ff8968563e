"""End-effector tip positions for many worlds in one launch.

Launched by :meth:`warp_critic.physics.simulator.Simulator.tip_positions` after Newton's forward kinematics.
"""

from __future__ import annotations

import warp as wp


@wp.kernel
def tip_positions_kernel(
    body_q: wp.array(dtype=wp.transform),  # (W * B,) world poses of every body
    bodies_per_world: int,
    ee_body: int,  # end-effector body index inside one world
    tip_offset: wp.array(dtype=wp.vec3),  # (W,) tip in the end-effector frame (m), per world
    tips: wp.array(dtype=wp.vec3),  # (W,) output: tip positions in world coordinates (m)
):
    w = wp.tid()
    X = body_q[w * bodies_per_world + ee_body]
    tips[w] = wp.transform_point(X, tip_offset[w])
