"""Training defaults derived from a robot that carries none (a URDF, an MJCF, a plain USD).

Each default has one rule (:data:`RULES`, printed by ``--help``, stored in ``config.json`` and in
the summary line at the start of a run). ``dof`` joints, limits ``[lo_j, hi_j]``, range
``r_j = hi_j - lo_j`` (a continuous joint, with no limits: ``lo = -pi, hi = pi`` here), effort
limits ``e_j``; ``M(q)`` the joint-space mass matrix (armature included), ``g(q)`` the gravity
torque (``M qdd = tau - g(q)`` at rest):

* home pose ``q_h``: the file's own initial joint position when it authors a non-zero one inside
  the limits (an MJCF ``ref``, a USD joint state), else mid-range ``(lo + hi) / 2`` (0 for a
  continuous joint);
* goals: :data:`GOALS` draws ``U[q_h - d_j, q_h + d_j]`` (generator seeded with :data:`GOAL_SEED`),
  ``d_j = min(r_j / 4, GOAL_REACH)``, clipped to the limits;
* torque bound ``tau_j = min(e_j, c p_j + max |g_j|)`` with the push ``p_j = min(e_j, A_MAX *
  M_jj(q_h))``: joint ``j`` alone (the others held) accelerates by at most ``A_MAX`` rad/s^2 beyond
  holding itself against gravity at the home pose and every goal (``max |g_j|`` over them, under the
  run's gravity: ``--gravity 0`` drops the holding share, and the probe below runs at it too). A joint whose effort limit binds first accelerates less. The pushes
  together are capped by ``c = min(1, A_COUPLED / max_i sum_j |M^-1(q_h)|_ij p_j)``: no combination
  of signs accelerates a joint by more than ``A_COUPLED`` at the home pose. That matters where
  joint axes line up at home (the Panda's joints 1 and 3 at mid-range: opposite pushes spin the
  light link between them at 3,900 rad/s^2 without the cap);
* armature and damping (where the file authors none; a URDF never does armature): joint ``j``'s
  armature ``a_j =`` :data:`ARMATURE_FRACTION` ``x max_i M_ii(q_h)`` (the motor's reflected rotor
  inertia, scaled from MuJoCo Menagerie's Panda: armature 0.1 kg m^2 on joints whose largest
  ``M_ii`` at home is about 2 kg m^2), and damping ``b_j =`` :data:`DAMPING_RATE` ``x (M_jj(q_h) +
  a_j)`` (N m s/rad). They keep light distal links stable at a millisecond step (MuJoCo models
  carry both); the file's own ``armature``/``damping`` (MJCF default classes included) are kept,
  except that a damping too strong for an explicit step (newton's; MuJoCo's is implicit) raises the
  armature to ``b_j x T / 4 - M_jj`` (the damping's time constant at least one 2.5 ms step);
* ``dt`` and substeps: the control period is the KUKA's, ``T = 0.01`` s; ``dt = T / n`` for the
  first ``n`` of :data:`SUBSTEPS` (4: the KUKA's ``dt``; at most 10, ``dt >= 1`` ms) at which :data:`PROBE_WORLDS` rollouts of the
  horizon from the home pose under random saturated torques ``+-tau_j`` (random signs, seeded,
  redrawn every :data:`PROBE_HOLD` control steps, so that joints slam into their limits) stay finite with kinetic energy ``1/2 qd^T M(q) qd`` at most
  ``E_cap = 10 (sum_j tau_j min(r_j, 2 pi) + |gravity| sum_b m_b 2 R)`` (J), ``R`` the largest
  distance of a body's centre of mass from the first joint at the home pose;
* joint-limit gains (a URDF or MJCF: a URDF cannot author them, and newton's defaults, 1e4 N m/rad
  and 10 N m s/rad, are the same for a 0.0065 kg m^2 wrist and a 3 kg m^2 shoulder):
  ``ke_j = m_j LIMIT_OMEGA^2``, ``kd_j = 2 m_j LIMIT_OMEGA``, ``m_j = 1 / (M^-1(q_h))_jj`` the
  inertia joint ``j`` moves with the others free (armature included): each limit a critically
  damped spring of natural frequency :data:`LIMIT_OMEGA`. USD files keep the gains they author;
* continuous joints (no limits): goals and the probe see ``[q_h - pi, q_h + pi]``;
* gravity: on (9.81 m/s^2 along -z); ``--gravity 0`` for torque-mode (gravity-compensated) arms;
* horizon, learning rates, iterations, inner steps, critic input, start std, home starts, velocity
  scale: the KUKA's (``scenes/kuka.usda``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from warp_critic.core.errors import UserError

NO_EFFORT_LIMIT = 1e6  # N*m or N: a joint whose file gives no finite positive effort limit
CONTROL_PERIOD = 0.01  # s, the KUKA's dt x substeps (0.0025 x 4)
GOALS = 4
GOAL_SEED = 0
GOAL_REACH = 1.0  # rad or m
A_MAX = 50.0  # rad/s^2 (or m/s^2)
# what shapes an imported model beyond the file (in its content hash: a change here is a new model)
MODEL_RULES = "armature-damping-limit-gains-2"
ARMATURE_FRACTION = 0.05  # x the largest M_ii at home: a joint's armature where the file gives none
DAMPING_RATE = 2.0  # 1/s x (M_jj + armature): a joint's damping where the file gives none
LIMIT_OMEGA = 100.0  # rad/s: a limit spring's natural frequency, 0.25 rad per control step
# rad/s^2: 10 rad/s in one control period. The KUKA scene's hand-set bounds reach 870 at home
A_COUPLED = 1000.0
GRAVITY = 9.81
# at least the KUKA's 4 substeps (dt 0.0025 s): the probe's held torques do not switch as a policy's
# can; a Panda run at the probe's dt 0.005 s went non-finite at iteration 23 (measured). At most 10:
# dt >= 1 ms, stability comes from the model (armature, damping, limit gains), not tiny steps
SUBSTEPS = (4, 8, 10)
PROBE_WORLDS = 8
PROBE_SEED = 0
PROBE_HOLD = 10  # control steps a probe torque is held
ENERGY_FACTOR = 10.0
# the KUKA's schedule (scenes/kuka.usda)
KUKA_HORIZON = 50  # steps; typed on its own, the schedule's dict mixes value types
KUKA = dict(
    horizon=KUKA_HORIZON,
    qd_scale=5.0,
    alpha=3e-4,
    lr=3e-3,
    iterations=3000,
    inner_steps=3,
    critic_input="relative",
    start_std=0.4,
    home_starts=2,
)

RULES: dict[str, str] = {
    "armature": f"where the file gives none: {ARMATURE_FRACTION:g} x the largest M_ii at home (the "
    "motor's reflected inertia, scaled from MuJoCo Menagerie's Panda)",
    "damping": f"where the file gives none: {DAMPING_RATE:g}/s x (M_jj at home + armature); a file's "
    f"damping b above (M_jj + armature) / {CONTROL_PERIOD / SUBSTEPS[0]:g} s raises the armature to b x "
    f"{CONTROL_PERIOD / SUBSTEPS[0]:g} s - M_jj (newton integrates damping explicitly)",
    "limit_gains": f"a URDF's or MJCF's joint limits: critically damped springs at {LIMIT_OMEGA:g} rad/s on "
    "the inertia each joint moves with the others free at home, armature included (ke = m w^2, kd = 2 m w)",
    "home": "--home NAME=V,.. where given, else the file's own non-zero initial pose inside the limits, else mid-range (0 for continuous joints)",
    "goals": f"{GOALS} seeded draws U[home - d, home + d], d = min(range/4, {GOAL_REACH}), inside the limits",
    "max_torque": f"min(effort limit or MJCF actuator bound gear x ctrlrange capped by forcerange, c x min(effort limit, {A_MAX:g} rad/s^2 x M_jj(home)) + max |gravity torque| "
    f"over home and goals under the run's gravity), c <= 1 so that no sign combination of those pushes accelerates a joint "
    f"by more than {A_COUPLED:g} rad/s^2 at home",
    "dt": f"control period {CONTROL_PERIOD} s over the first of {', '.join(map(str, SUBSTEPS))} substeps at which {PROBE_WORLDS} rollouts under random +-max_torque "
    f"(signs redrawn every {PROBE_HOLD} steps) stay finite "
    f"with kinetic energy <= {ENERGY_FACTOR:g} x (sum tau x range + weight x 2 x reach)",
    "substeps": "control period / dt",
    "gravity": f"{GRAVITY} m/s^2 (--gravity 0 for a torque-mode arm)",
    **{key: "the KUKA's (scenes/kuka.usda)" for key in KUKA},
}


def home_value(lo: float, hi: float, file_q: float, big: float) -> float:
    """The home position of one joint [rad or m] (rule: module docstring)."""
    continuous = lo <= -big and hi >= big
    if file_q != 0.0 and lo <= file_q <= hi:
        return float(file_q)
    return 0.0 if continuous else 0.5 * (lo + hi)


def limits(scene, big: float = 1e9) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` with continuous joints as ``[home - pi, home + pi]``."""
    lo, hi = scene.q_lower, scene.q_upper
    continuous = (lo <= -big) & (hi >= big)
    home = scene.home
    return np.where(continuous, home - math.pi, lo), np.where(continuous, home + math.pi, hi)


def draw_goals(scene) -> np.ndarray:
    """``(GOALS, dof)`` goals [rad or m] (rule: module docstring)."""
    lo, hi = limits(scene)
    home = scene.home
    d = np.minimum((hi - lo) / 4.0, GOAL_REACH)
    u = np.random.default_rng(GOAL_SEED).uniform(-1.0, 1.0, size=(GOALS, scene.dof))
    return np.clip(home + u * d, lo, hi)


def _simulator(scene, worlds: int, dt: float, substeps: int, gravity: float):
    from warp_critic.physics.simulator import Simulator
    from warp_critic.physics.variants import Variant

    return Simulator(
        scene,
        [Variant()] * worlds,
        dt=dt,
        substeps=substeps,
        device="cpu",
        differentiable=False,
        gravity=gravity,
        graphs=False,
    )


def mass_matrices(sim, q) -> np.ndarray:
    """``(W, dof, dof)`` joint-space mass matrices [kg m^2 or kg] at ``q`` ``(W, dof)``."""
    import newton
    import torch
    import warp as wp

    state = sim.model.state(requires_grad=False)
    wp.to_torch(state.joint_q).view(sim.worlds, sim.dof).copy_(torch.as_tensor(q))
    newton.eval_fk(sim.model, state.joint_q, state.joint_qd, state)
    H = newton.eval_mass_matrix(sim.model, state)
    return H.numpy()[:, : sim.dof, : sim.dof].astype(np.float64)


def gravity_torques(scene, q: np.ndarray, gravity: float = GRAVITY) -> np.ndarray:
    """``(N, dof)`` gravity torques ``g(q)`` [N m or N] at the poses ``q`` ``(N, dof)``."""
    import torch

    q = np.atleast_2d(q)
    dt = 1e-4
    sim = _simulator(scene, q.shape[0], dt, 1, gravity)
    qt = torch.as_tensor(q, dtype=torch.float32)
    with torch.no_grad():
        _, qd = sim.step(qt, torch.zeros_like(qt), torch.zeros_like(qt))
    qdd = qd.double().numpy() / dt
    return -np.einsum("wij,wj->wi", mass_matrices(sim, q), qdd)


def torque_bounds(scene, goals: np.ndarray, gravity: float = GRAVITY) -> np.ndarray:
    """``(dof,)`` policy torque bounds [N m or N] (rule: module docstring)."""
    home = scene.home[None]
    sim = _simulator(scene, 1, 1e-3, 1, 0.0)
    m_home = mass_matrices(sim, home)[0]
    push = np.minimum(scene.effort_limit, A_MAX * np.diag(m_home))
    worst = float((np.abs(np.linalg.inv(m_home)) @ push).max())  # every sign combination's peak
    push = push * min(1.0, A_COUPLED / worst)
    poses = np.concatenate([home, goals])
    hold = np.abs(gravity_torques(scene, poses, gravity)).max(axis=0)
    return np.minimum(scene.effort_limit, push + hold)


def armature_damping(
    scene, armature: np.ndarray, damping: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(armature, damping)``, ``(dof,)`` each [kg m^2 or kg, N m s/rad or N s/m]: the file's
    values, and where one is negative (the file gave none) the derived one (rule: module
    docstring). ``scene`` is the robot with the file's armature and 0 where it gave none."""
    sim = _simulator(scene, 1, 1e-3, 1, 0.0)
    m = np.diag(mass_matrices(sim, scene.home[None])[0])
    file_armature = np.maximum(armature, 0.0)
    moved = m - file_armature  # M_ii of the links alone
    armature = np.where(armature < 0, ARMATURE_FRACTION * float(moved.max()), armature)
    damping = np.where(damping < 0, DAMPING_RATE * (moved + armature), damping)
    # newton's step integrates damping explicitly (MuJoCo implicitly): a file's damping b whose time
    # constant (M_jj + a) / b is under one step of the longest dt gets the armature that makes it one
    step = CONTROL_PERIOD / SUBSTEPS[0]
    armature = np.maximum(armature, damping * step - moved)
    return armature, damping


def limit_gains(scene) -> tuple[np.ndarray, np.ndarray]:
    """``(ke, kd)``, ``(dof,)`` each [N m/rad, N m s/rad or N/m, N s/m]: joint-limit springs
    (rule: module docstring)."""
    sim = _simulator(scene, 1, 1e-3, 1, 0.0)
    mm = mass_matrices(sim, scene.home[None])[0]
    dead = [str(scene.joint_names[i]) for i in np.flatnonzero(~(np.abs(np.diag(mm)) > 1e-12))]
    try:
        if dead:
            raise np.linalg.LinAlgError
        m = 1.0 / np.diag(np.linalg.inv(mm))
    except np.linalg.LinAlgError:
        which = f"joint {', '.join(dead)} moves" if dead else "its joints move"
        raise UserError(
            f"{scene.path}: {which} no mass at the home pose (a zero joint axis?): the mass "
            "matrix is singular, not a robot to train"
        ) from None
    return m * LIMIT_OMEGA**2, 2.0 * m * LIMIT_OMEGA


def energy_cap(scene, max_torque: np.ndarray, gravity: float = GRAVITY) -> float:
    """``E_cap`` [J] of the stability probe (rule: module docstring)."""
    import torch

    lo, hi = limits(scene)
    work = float(np.sum(max_torque * np.minimum(hi - lo, 2 * math.pi)))
    sim = _simulator(scene, 1, 1e-3, 1, 0.0)
    poses = sim.body_poses(torch.as_tensor(scene.home[None], dtype=torch.float32))[0]
    model = sim.model
    com = model.body_com.numpy().astype(np.float64)
    mass = model.body_mass.numpy().astype(np.float64)
    centres = np.array(
        [_transform_point(poses[b], com[b]) for b in range(model.body_count)], dtype=np.float64
    )
    base = model.joint_X_p.numpy()[0, :3].astype(np.float64)
    reach = float(np.linalg.norm(centres - base, axis=1).max())
    return ENERGY_FACTOR * (work + gravity * float(mass.sum()) * 2.0 * reach)


def _transform_point(pose: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Position + quaternion ``(x, y, z, w)`` applied to a point."""
    t, (x, y, z, w) = pose[:3], pose[3:]
    u = np.array([x, y, z])
    return t + p + 2.0 * np.cross(u, np.cross(u, p) + w * p)


def stable(scene, dt: float, substeps: int, max_torque: np.ndarray, gravity: float) -> bool:
    """Whether the probe's random-torque rollouts stay finite and inside ``E_cap`` (docstring)."""
    import torch

    sim = _simulator(scene, PROBE_WORLDS, dt, substeps, gravity)
    cap = energy_cap(scene, max_torque, gravity)
    gen = torch.Generator().manual_seed(PROBE_SEED)
    bound = torch.as_tensor(max_torque, dtype=torch.float32)
    q = torch.as_tensor(scene.home, dtype=torch.float32).expand(PROBE_WORLDS, -1).clone()
    qd = torch.zeros_like(q)
    with torch.no_grad():
        for t in range(KUKA_HORIZON):
            if t % PROBE_HOLD == 0:  # saturated torques of random sign, held: slams into limits
                sign = torch.randint(0, 2, q.shape, generator=gen).float() * 2 - 1
            tau = sign * bound
            q, qd = sim.step(q, qd, tau)
            if not (torch.isfinite(q).all() and torch.isfinite(qd).all()):
                return False
            if t % 10 == 9 or t == KUKA_HORIZON - 1:
                M = mass_matrices(sim, q.double().numpy())
                v = qd.double().numpy()
                energy = 0.5 * np.einsum("wi,wij,wj->w", v, M, v)
                if not np.all(np.isfinite(energy)) or energy.max() > cap:
                    return False
    return True


def time_step(scene, max_torque: np.ndarray, gravity: float = GRAVITY) -> tuple[float, int]:
    """``(dt, substeps)`` from the stability probe; raises SceneError when none is stable."""
    from warp_critic.core.errors import SceneError

    for substeps in SUBSTEPS:
        dt = CONTROL_PERIOD / substeps
        if stable(scene, dt, substeps, max_torque, gravity):
            return dt, substeps
    raise SceneError(
        f"{scene.path}: unstable: random-torque rollouts diverge even at dt = "
        f"{CONTROL_PERIOD / SUBSTEPS[-1]:g} s (check masses, inertias, armature and joint limits)"
    )


def derive_defaults(scene, gravity: float = GRAVITY) -> dict[str, Any]:
    """The training defaults of ``scene`` (``Scene.defaults`` keys) by the rules of this module, at
    ``gravity`` [m/s^2]: the torque bounds hold the arm against that gravity, and the probe runs
    under it (``--gravity 0``: no holding share, a torque-mode arm's bounds)."""
    goals = draw_goals(scene)
    max_torque = torque_bounds(scene, goals, gravity)
    dt, substeps = time_step(scene, max_torque, gravity)
    # short decimals for config.json and an imported scene, never past a limit by rounding
    lo, hi = limits(scene)
    goals = np.clip([[round(float(v), 6) for v in g] for g in goals], lo, hi)
    torques = np.minimum([float(f"{v:.6g}") for v in max_torque], scene.effort_limit)
    return {
        "goals": [[float(v) for v in g] for g in goals],
        "max_torque": [float(v) for v in torques],
        "dt": dt,
        "substeps": substeps,
        "gravity": float(gravity),
        **KUKA,
    }


def summary(scene, values: dict[str, Any], derived: set[str]) -> str:
    """One line: the derived defaults in effect, each with its rule."""
    parts = [f"home {np.round(scene.home, 3).tolist()} ({RULES['home']})"]
    for key in ("goals", "max_torque", "dt", "substeps", "gravity", *KUKA):
        if key in derived:
            value = values[key]
            if key == "goals":
                value = f"{len(value)} goals"
            parts.append(f"{key} {value} ({RULES[key]})")
    return f"{scene.name}: derived defaults: " + "; ".join(parts)
