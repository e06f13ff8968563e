"""Losses (pure functions).

* task loss (outer loop, paper eq. 3 with the reward of section 5): ``||q_T - g||^2`` in joint space,
  optionally plus ``running_weight * mean_t ||q_t - g||^2`` over the rollout and
  ``velocity_weight * ||qd_T||^2`` at the end (arrive and stop; both off by default);
* TD loss (the baselines' and the landscape's supervised Q, the paper's Algorithm 1):
  ``mean (Q(s, a) - y)^2`` with ``y = r + gamma (1 - done) Q'(s', a')``;
* critic loss (inner loop, Algorithm 2 line 7): ``sum_t L_critic(s_t, pi_theta(s_t), g)``.
"""

from __future__ import annotations

import torch

from warp_critic.learning.critic_inputs import rollout_kwargs
from warp_critic.learning.networks import PolicyParams
from warp_critic.learning.protocols import CriticFn, Policy
from warp_critic.learning.rollout import Trajectory


def final_error(q_final: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    """Joint-space squared error ``||q_T - g||^2`` per world: ``(W, dof) -> (W,)`` (rad^2)."""
    return ((q_final - goal) ** 2).sum(-1)


def task_loss(
    traj: Trajectory, goal: torch.Tensor, running_weight: float = 0.0, velocity_weight: float = 0.0
) -> torch.Tensor:
    """Per-world task loss ``(W,)``; ``goal`` is ``(W, dof)``; ``velocity_weight`` in s^2."""
    loss = final_error(traj.q[-1], goal)
    if running_weight:
        loss = loss + running_weight * ((traj.q[1:] - goal) ** 2).sum(-1).mean(0)
    if velocity_weight:
        loss = loss + velocity_weight * (traj.qd[-1] ** 2).sum(-1)
    return loss


def critic_loss(
    critic: CriticFn, policy: Policy, params: PolicyParams, traj: Trajectory, goal: torch.Tensor
) -> torch.Tensor:
    """Per-world ``sum_t L_critic(s_t, pi_theta(s_t), g)`` ``(W,)``.

    The visited states are data (detached): the gradient reaches the policy parameters through the
    actions only, so no model gradient is needed (the paper's model-free policy update).
    """
    q, qd = traj.q[:-1].detach(), traj.qd[:-1].detach()  # (T, W, dof)
    return critic_loss_at(critic, traj, policy(params, q, qd), goal)


def critic_loss_at(
    critic: CriticFn, traj: Trajectory, tau: torch.Tensor, goal: torch.Tensor
) -> torch.Tensor:
    """Per-world ``sum_t L_critic(s_t, tau_t, g)`` ``(W,)`` for the actions ``tau (T, W, dof)``
    taken at the trajectory's states (:func:`critic_loss` with the policy's actions given)."""
    q, qd = traj.q[:-1].detach(), traj.qd[:-1].detach()  # (T, W, dof)
    g = goal.unsqueeze(0).expand_as(q)
    # the rollout data the critic reads beside (s, a, g): observed history, told dynamics
    return critic(q, qd, tau, g, **rollout_kwargs(critic, traj)).sum(0)


def td_loss(
    q: torch.Tensor,
    reward: torch.Tensor,
    done: torch.Tensor,
    q_next: torch.Tensor,
    gamma: float = 1.0,
) -> torch.Tensor:
    """Mean squared TD error ``(q - y)^2`` with the target ``y = r + gamma (1 - done) q_next`` held fixed.

    All ``(B,)``: ``q = Q(s, a)``, ``q_next = Q'(s', a')`` from the target network at the next state
    and action (DDPG: ``a' = mu'(s')``), ``done`` 1 where the episode ends without bootstrap.
    """
    y = (reward + gamma * (1.0 - done) * q_next).detach()
    return ((q - y) ** 2).mean()
