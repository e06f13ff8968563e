"""Whether a robot's home pose stands it upright in balance under gravity.

At such a pose (the Jaco's mid-range: joints 2 and 3 at pi, the arm pointing straight up) gravity
pulls neither way, yet any lean grows: linearised, ``M dqdd = -G dq`` with ``G = dg/dq`` the gravity
stiffness, and a negative eigenvalue ``-lambda^2`` of ``M^-1 G`` is a fall that grows as
``exp(lambda t)``. Each start then falls the way its first torques tip it. Measured on the Jaco
(``jaco_clean.urdf``, 2026-12-06): the critic learned to drop joint 2 onto its lower limit for every
goal (0.534 -> 0.773 MSE after 200 iterations), while at ``--gravity 0`` (2.82 -> 0.89 summed after
100 iterations) or from Kinova's bent home pose (10.0 -> 1.19) it learns.

The pose is balanced when gravity's own acceleration there, ``|M^-1 g(q_h)|``, is below what a
:data:`LEAN` rad lean gives (``lambda^2 x LEAN``) and the fall grows at least :data:`GROWTH` times
over the KUKA's horizon. The import says so in one warning line; nothing is changed.
"""

from __future__ import annotations

import math

import numpy as np

from warp_critic.physics import derive

LEAN = 0.01  # rad: a pose is balanced when gravity there pulls less than this lean would
GROWTH = 10.0  # x over the horizon: a slower fall is no concern
EPS = 1e-3  # rad: the finite-difference step of the gravity stiffness


def upright_joints(scene, gravity: float) -> tuple[list[int], float]:
    """The joints of the fastest-growing fall from the home pose where that pose is balanced
    (empty where it is not) and the fall's growth over the horizon (x)."""
    if gravity == 0.0:
        return [], 1.0
    n, home = scene.dof, np.asarray(scene.home, dtype=np.float64)
    steps = EPS * np.eye(n)
    g = derive.gravity_torques(
        scene, np.concatenate([home[None], home + steps, home - steps]), gravity
    )
    stiffness = (g[1 : n + 1] - g[n + 1 :]).T / (2 * EPS)  # G_ij = dg_i / dq_j
    m = derive.mass_matrices(derive._simulator(scene, 1, 1e-3, 1, 0.0), home[None])[0]
    values, vectors = np.linalg.eig(np.linalg.solve(m, stiffness))
    k = int(np.argmin(values.real))
    rate2 = -float(values.real[k])  # lambda^2 [1/s^2]
    if not rate2 > 0.0:
        return [], 1.0
    growth = math.exp(math.sqrt(rate2) * derive.KUKA_HORIZON * derive.CONTROL_PERIOD)
    pull = float(np.abs(np.linalg.solve(m, g[0])).max())  # rad/s^2 at home, no torque
    if growth < GROWTH or pull >= rate2 * LEAN:
        return [], growth
    mode = np.abs(vectors[:, k].real)
    return [int(j) for j in np.flatnonzero(mode >= 0.3 * mode.max())], growth


def upright_note(scene, gravity: float) -> str | None:
    """One line for an import whose home pose is balanced upright, else ``None``."""
    joints, growth = upright_joints(scene, gravity)
    if not joints:
        return None
    names = ", ".join(f"{scene.joint_names[j]} = {scene.home[j]:.3g}" for j in joints)
    return (
        f"{scene.path}: the home pose ({names}) stands the arm upright in balance: gravity pulls "
        f"it neither way there and a lean grows {growth:.0f}x over the horizon, so each start falls "
        "the way its first torques tip it and a critic may learn to drop the arm onto a limit; "
        "import it with a bent home (warp-critic import --home NAME=V,..), or train at "
        "--gravity 0"
    )
