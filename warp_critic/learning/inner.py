"""Inner update (Algorithm 2 lines 6-7, Algorithm 3): train policies with the critic alone.

``theta_new = theta - alpha * grad_theta sum_t L_critic(s_t, pi_theta(s_t), g)`` on plain tensors.
Each inner step rolls the current policies out *forward only*: the simulator produces states as data
and no model gradient is ever taken here. With ``create_graph=True`` (meta-training) the result stays
a differentiable function of the critic's parameters (second order, through ``torch.autograd.grad``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import torch

from warp_critic.core.errors import FieldError
from warp_critic.learning.losses import critic_loss, critic_loss_at
from warp_critic.learning.networks import PolicyParams
from warp_critic.learning.protocols import CriticFn, Policy, StepSize
from warp_critic.learning.rollout import Trajectory, hold_diverged, rollout, settled_worlds

if TYPE_CHECKING:  # a type only: the simulator module loads Newton (seconds), which the command
    # line's method configs, importing this module, do not need
    from warp_critic.physics.simulator import Simulator

#: the most critic-gradient steps one fresh policy takes at meta-test (``--policy-steps``, or a
#: run's inner steps x policy lifetime): on the reacher's default meta-test (50 worlds, horizon 50)
#: a step takes about 0.1 s on a 2-core CPU, so the limit is about 20 minutes
MAX_POLICY_STEPS = 10_000


def check_policy_steps(lifetime: int, inner_steps: int) -> None:
    """A meta-training config's policy lifetime x inner steps: the steps its meta-test takes per
    policy, at most :data:`MAX_POLICY_STEPS` (a :class:`FieldError` on ``policy_lifetime``)."""
    steps = lifetime * inner_steps
    if steps > MAX_POLICY_STEPS:
        raise FieldError(
            "policy_lifetime",
            f"{lifetime} x {inner_steps} inner step(s) = {steps} critic-gradient steps per policy "
            f"at meta-test: at most {MAX_POLICY_STEPS}",
        )


def policy_fn(
    policy: Policy, params: PolicyParams
) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
    """Bind parameters: ``policy(params, q, qd)`` -> a rollout's ``(q, qd) -> tau``."""
    return lambda q, qd: policy(params, q, qd)


def critic_gradient(
    critic: CriticFn,
    policy: Policy,
    params: PolicyParams,
    traj: Trajectory,
    goal: torch.Tensor,
    create_graph: bool,
) -> tuple[torch.Tensor, ...]:
    """The step direction for each of ``params``: ``grad_theta sum_t L(s_t, pi_theta(s_t), g)``.

    A critic with a torque metric ``P(q)`` (``torque_metric``, e.g. the ``inertial`` layout) steps
    the torques in that metric: ``sum_t J_t^T P(q_t) dL/dtau_t``, ``J_t = dtau_t / dtheta``. Still a
    descent direction of the same loss (``P`` is positive definite), and the exact function of the
    critic that the outer loop differentiates (``P`` is data: the states are).
    """
    metric = getattr(critic, "torque_metric", None)
    P = metric(traj.q[:-1].detach()) if metric is not None else None
    if P is None:
        loss = critic_loss(critic, policy, params, traj, goal).sum()  # worlds are independent
        return torch.autograd.grad(loss, list(params.values()), create_graph=create_graph)
    tau = policy(params, traj.q[:-1].detach(), traj.qd[:-1].detach())  # (T, W, dof)
    loss = critic_loss_at(critic, traj, tau, goal).sum()
    (dtau,) = torch.autograd.grad(loss, tau, create_graph=create_graph)
    step = (P @ dtau.unsqueeze(-1)).squeeze(-1)
    return torch.autograd.grad(
        tau, list(params.values()), grad_outputs=step, create_graph=create_graph
    )


def inner_update(
    critic: CriticFn,
    policy: Policy,
    params: PolicyParams,
    sim: Simulator,
    q0: torch.Tensor,
    qd0: torch.Tensor,
    goal: torch.Tensor,
    *,
    horizon: int,
    alpha: float | StepSize,
    steps: int = 1,
    create_graph: bool = False,
    check: bool = True,
    guard: bool = False,
) -> tuple[PolicyParams, list[Trajectory]]:
    """``steps`` critic-gradient steps on ``W`` policies at once.

    Args:
        critic: the loss ``L(q, qd, tau, g)`` the policies descend.
        policy: ``(params, q, qd) -> tau``, e.g. :class:`~warp_critic.learning.networks.MLPPolicy`.
        params: per-world policy parameters (leading dim ``W``); must require grad.
        goal: ``(W, dof)`` goal per world.
        alpha: inner learning rate (or one per world, see :class:`~warp_critic.learning.protocols.StepSize`).
        create_graph: keep the graph of the update (meta-training); ``False`` at meta-test.
        check: raise on a non-finite state (``False``: a diverged world's parameters turn
            non-finite, the other worlds' are unaffected; see :func:`~.rollout.rollout`).
        guard: with ``check=False``, a world that diverges (:func:`~.rollout.settled_worlds`) is
            stepped on its start state held still (:func:`~.rollout.hold_diverged`), so that its
            parameters and the graph through them stay finite; its rollouts are returned as they
            ran, for the caller to drop it.

    Returns the updated parameters and the rollout used for each step.
    """
    trajs = []
    for _ in range(steps):
        traj = rollout(
            sim, policy_fn(policy, params), q0, qd0, horizon, differentiable=False, check=check
        )
        seen = hold_diverged(traj, settled_worlds(traj)) if guard else traj
        grads = critic_gradient(critic, policy, params, seen, goal, create_graph)
        params = {k: v - alpha * g for (k, v), g in zip(params.items(), grads)}
        if not create_graph:
            params = {k: v.detach().requires_grad_(True) for k, v in params.items()}
        trajs.append(traj)
    return params, trajs
