"""Inner update (Algorithm 2 lines 6-7, Algorithm 3): train policies with the critic alone.

``theta_new = theta - alpha * grad_theta sum_t L_critic(s_t, pi_theta(s_t), g)`` on plain tensors.
Each inner step rolls the current policies out *forward only*: the simulator produces states as data
and no model gradient is ever taken here. With ``create_graph=True`` (meta-training) the result stays
a differentiable function of the critic's parameters (second order, through ``torch.autograd.grad``).
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from warp_critic.learning.losses import critic_loss
from warp_critic.learning.networks import PolicyParams
from warp_critic.learning.protocols import CriticFn, Policy, StepSize
from warp_critic.learning.rollout import Trajectory, rollout
from warp_critic.physics.simulator import Simulator


def policy_fn(
    policy: Policy, params: PolicyParams
) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
    """Bind parameters: ``policy(params, q, qd)`` -> a rollout's ``(q, qd) -> tau``."""
    return lambda q, qd: policy(params, q, qd)


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

    Returns the updated parameters and the rollout used for each step.
    """
    trajs = []
    for _ in range(steps):
        traj = rollout(
            sim, policy_fn(policy, params), q0, qd0, horizon, differentiable=False, check=check
        )
        loss = critic_loss(critic, policy, params, traj, goal).sum()  # worlds are independent
        grads = torch.autograd.grad(loss, list(params.values()), create_graph=create_graph)
        params = {k: v - alpha * g for (k, v), g in zip(params.items(), grads)}
        if not create_graph:
            params = {k: v.detach().requires_grad_(True) for k, v in params.items()}
        trajs.append(traj)
    return params, trajs
