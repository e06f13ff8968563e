"""Losses (pure functions).

* task loss (outer loop, paper eq. 3 with the reward of section 5): ``||q_T - g||^2`` in joint space,
  optionally plus ``running_weight * mean_t ||q_t - g||^2`` over the rollout and
  ``velocity_weight * ||qd_T||^2`` at the end (arrive and stop; both off by default);
* critic loss (inner loop, Algorithm 2 line 7): ``sum_t L_critic(s_t, pi_theta(s_t), g)``.
"""

from __future__ import annotations

import torch

from .networks import PolicyParams
from .rollout import Trajectory


def final_error(q_final: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    """Joint-space squared error ``||q_T - g||^2`` per world: ``(W, dof) -> (W,)`` (rad^2)."""
    return ((q_final - goal) ** 2).sum(-1)


def task_loss(traj: Trajectory, goal: torch.Tensor, running_weight: float = 0.0,
              velocity_weight: float = 0.0) -> torch.Tensor:
    """Per-world task loss ``(W,)``; ``goal`` is ``(W, dof)``; ``velocity_weight`` in s^2."""
    loss = final_error(traj.q[-1], goal)
    if running_weight:
        loss = loss + running_weight * ((traj.q[1:] - goal) ** 2).sum(-1).mean(0)
    if velocity_weight:
        loss = loss + velocity_weight * (traj.qd[-1] ** 2).sum(-1)
    return loss


def critic_loss(critic, policy, params: PolicyParams, traj: Trajectory, goal: torch.Tensor) -> torch.Tensor:
    """Per-world ``sum_t L_critic(s_t, pi_theta(s_t), g)`` ``(W,)``.

    The visited states are data (detached): the gradient reaches the policy parameters through the
    actions only, so no model gradient is needed (the paper's model-free policy update).
    """
    q, qd = traj.q[:-1].detach(), traj.qd[:-1].detach()  # (T, W, dof)
    tau = policy(params, q, qd)
    g = goal.unsqueeze(0).expand_as(q)
    return critic(q, qd, tau, g).sum(0)
