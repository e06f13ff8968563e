"""Outer update (Algorithm 2 lines 8-10): differentiate the task loss of the *updated* policy
through the differentiable Newton model and through the inner update into the critic."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch

from warp_critic.learning.inner import inner_update, policy_fn
from warp_critic.learning.losses import task_loss
from warp_critic.learning.networks import PolicyParams
from warp_critic.learning.protocols import CriticFn, Policy
from warp_critic.learning.rollout import Trajectory, rollout, settled_worlds

if TYPE_CHECKING:  # a type only: importing it loads Newton (seconds)
    from warp_critic.physics.simulator import Simulator


@dataclass
class OuterResult:
    loss: torch.Tensor  # scalar, differentiable w.r.t. the critic: the mean of ``losses``
    losses: torch.Tensor  # (W,) per-world task loss, differentiable w.r.t. the critic
    per_world: torch.Tensor  # (W,) task loss of the updated policies (detached)
    before: Trajectory  # rollout of the initial policies (inner loop data)
    after: Trajectory  # rollout of the updated policies through the model (detached)
    params_new: PolicyParams  # updated policy parameters (detached)
    params: PolicyParams  # the policy parameters before the inner update (detached)
    # (W,) bool: the worlds that stayed finite in every rollout; with ``drop_diverged`` the others
    # are out of ``loss`` and ``losses`` (0 there) and get no gradient
    settled: torch.Tensor


def meta_loss(
    critic: CriticFn,
    policy: Policy,
    params: PolicyParams,
    sim: Simulator,
    q0: torch.Tensor,
    qd0: torch.Tensor,
    goal: torch.Tensor,
    *,
    horizon: int,
    alpha: float,
    inner_steps: int = 1,
    running_weight: float = 0.0,
    velocity_weight: float = 0.0,
    drop_diverged: bool = False,
) -> OuterResult:
    """Task loss of ``pi_{theta_new(phi)}`` rolled out through the model, mean over worlds.

    ``drop_diverged``: a world whose state diverges in any of its rollouts (inner or outer; see
    :func:`~.rollout.settled_worlds`) is dropped from the loss, the mean is over the others, and its
    gradient is exactly zero (guarded rollouts, :func:`~.rollout.rollout`); without it a diverged
    world raises :class:`~warp_critic.core.errors.DivergenceError`.
    """
    guard = drop_diverged
    params_new, trajs = inner_update(
        critic,
        policy,
        params,
        sim,
        q0,
        qd0,
        goal,
        horizon=horizon,
        alpha=alpha,
        steps=inner_steps,
        create_graph=True,
        check=not guard,
        guard=guard,
    )
    after = rollout(
        sim,
        policy_fn(policy, params_new),
        q0,
        qd0,
        horizon,
        differentiable=True,
        check=not guard,
        guard=guard,
    )
    per_world = task_loss(after, goal, running_weight, velocity_weight)
    if guard:
        settled = settled_worlds(after)
        for t in trajs:
            settled &= settled_worlds(t)
        per_world = torch.where(settled, per_world, torch.zeros_like(per_world))
        loss = per_world.sum() / settled.sum().clamp(min=1)
    else:  # the rollouts were checked: every world settled
        settled = torch.ones_like(per_world, dtype=torch.bool)
        loss = per_world.mean()
    return OuterResult(
        loss=loss,
        losses=per_world,
        per_world=per_world.detach(),
        before=trajs[0],
        after=Trajectory(after.q.detach(), after.qd.detach(), after.tau.detach(), after.dynamics),
        params_new={k: v.detach() for k, v in params_new.items()},
        params={k: v.detach() for k, v in params.items()},
        settled=settled,
    )
