"""Outer update (Algorithm 2 lines 8-10): differentiate the task loss of the *updated* policy
through the differentiable Newton model and through the inner update into the critic."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from warp_critic.learning.inner import inner_update, policy_fn
from warp_critic.learning.losses import task_loss
from warp_critic.learning.networks import PolicyParams
from warp_critic.learning.protocols import CriticFn, Policy
from warp_critic.learning.rollout import Trajectory, rollout
from warp_critic.physics.simulator import Simulator


@dataclass
class OuterResult:
    loss: torch.Tensor  # scalar, differentiable w.r.t. the critic: the mean of ``losses``
    losses: torch.Tensor  # (W,) per-world task loss, differentiable w.r.t. the critic
    per_world: torch.Tensor  # (W,) task loss of the updated policies (detached)
    before: Trajectory  # rollout of the initial policies (inner loop data)
    after: Trajectory  # rollout of the updated policies through the model (detached)
    params_new: PolicyParams  # updated policy parameters (detached)


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
) -> OuterResult:
    """Task loss of ``pi_{theta_new(phi)}`` rolled out through the model, mean over worlds."""
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
    )
    after = rollout(sim, policy_fn(policy, params_new), q0, qd0, horizon, differentiable=True)
    per_world = task_loss(after, goal, running_weight, velocity_weight)
    return OuterResult(
        loss=per_world.mean(),
        losses=per_world,
        per_world=per_world.detach(),
        before=trajs[0],
        after=Trajectory(after.q.detach(), after.qd.detach(), after.tau.detach()),
        params_new={k: v.detach() for k, v in params_new.items()},
    )
