"""The dynamics of each world as a vector, relative to the scene's nominal model (privileged data).

A critic with the ``pose-dynamics`` input (:mod:`warp_critic.learning.networks`) is *told* the model
it acts on instead of having to identify it: the oracle end of dynamics-randomised training, which
measures how far knowing the model alone takes one critic across the mass and length maps.

The vector is read from the very model arrays a variant sets (:mod:`warp_critic.physics.redraw`), so
it describes any robot and any variant the same way -- a drawn training variant, an evaluation
cell, an added tip mass, a stretched link -- without knowing how the change was written. Per body of
one robot copy, then per joint (``K = 7 * bodies + 3 * joints`` numbers, all ``0`` at the nominal
model):

* ``log((m + e_m) / (m_0 + e_m))``: the mass ``m`` (kg) against the nominal ``m_0``, with
  ``e_m`` 1% of the nominal bodies' mean mass (a massless frame given a point mass stays finite);
* ``(c - c_0) / L``: the centre of mass (m, body frame, 3 numbers), ``L`` the longest nominal
  joint offset (1 m where every offset is zero);
* ``log((I + e_I) / (I_0 + e_I))``: the diagonal of the inertia about the COM (kg m^2, 3 numbers),
  ``e_I`` 1% of the nominal mean diagonal;
* ``(p - p_0) / L``: each joint's position in its parent body (m, 3 numbers): a length change moves
  the child joint.
"""

from __future__ import annotations

import numpy as np

from warp_critic.physics.redraw import BODY_FIELDS, JOINT_FIELDS

#: numbers per body and per joint in the descriptor
PER_BODY, PER_JOINT = 7, 3


def _arrays(source, worlds: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(mass (W, B), com (W, B, 3), inertia diagonal (W, B, 3), joint offset (W, J, 3))`` of a
    model (arrays with a ``numpy()``) or a builder (lists), ``worlds`` copies of one robot."""

    def get(name: str) -> np.ndarray:
        x = getattr(source, name)
        return np.asarray(x.numpy() if hasattr(x, "numpy") else x, dtype=np.float64)

    mass, com, inertia, x_p = (get(f) for f in BODY_FIELDS + JOINT_FIELDS)
    mass = mass.reshape(worlds, -1)
    B = mass.shape[1]
    com = com.reshape(worlds, B, 3)
    inertia = np.diagonal(inertia.reshape(worlds, B, 3, 3), axis1=-2, axis2=-1)
    offset = x_p.reshape(worlds, -1, 7)[..., :3]  # transforms: position, then quaternion
    return mass, com, inertia, offset


class DynamicsDescriptor:
    """``K`` numbers per world that tell its dynamics apart (module docstring).

    Args:
        scene: the scene whose nominal model (no variant) is the reference.
    """

    def __init__(self, scene):
        from warp_critic.physics.variants import Variant

        m0, c0, i0, p0 = _arrays(scene.world_builder(Variant()), 1)
        self.m0, self.c0, self.i0, self.p0 = m0[0], c0[0], i0[0], p0[0]
        self.e_m = 0.01 * float(self.m0.mean()) if self.m0.size else 1.0
        self.e_i = 0.01 * float(self.i0.mean()) if self.i0.size else 1.0
        longest = float(np.linalg.norm(self.p0, axis=-1).max()) if self.p0.size else 0.0
        self.length = longest if longest > 0.0 else 1.0
        self.size = PER_BODY * self.m0.shape[0] + PER_JOINT * self.p0.shape[0]
        bodies = list(scene.body_names)
        if len(bodies) != self.m0.shape[0]:
            bodies = [f"body{i}" for i in range(self.m0.shape[0])]
        joints = list(scene.joint_names)
        if len(joints) != self.p0.shape[0]:  # fixed joints have no DoF name
            joints = [f"joint{i}" for i in range(self.p0.shape[0])]
        #: ``K`` names, one per number: ``LINK.mass``, ``LINK.com.x``, ``LINK.inertia.x``, ...,
        #: ``JOINT.offset.x``, ...
        self.names = [
            f"{b}.{what}"
            for b in bodies
            for what in ("mass", "com.x", "com.y", "com.z", "inertia.x", "inertia.y", "inertia.z")
        ] + [f"{j}.offset.{x}" for j in joints for x in "xyz"]

    def of(self, source, worlds: int) -> np.ndarray:
        """``(worlds, K)`` float32 for a model with ``worlds`` copies (or a builder of one)."""
        m, c, inertia, p = _arrays(source, worlds)
        parts = [
            np.log((m + self.e_m) / (self.m0 + self.e_m))[..., None],
            (c - self.c0) / self.length,
            np.log((inertia + self.e_i) / (self.i0 + self.e_i)),
        ]
        bodies = np.concatenate(parts, axis=-1).reshape(worlds, -1)
        joints = ((p - self.p0) / self.length).reshape(worlds, -1)
        return np.concatenate([bodies, joints], axis=-1).astype(np.float32)


__all__ = ["DynamicsDescriptor", "PER_BODY", "PER_JOINT"]
