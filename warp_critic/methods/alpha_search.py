"""The step size meta-test uses with a baseline's ``-Q``: meta-test's protocol on the training worlds
for a grid of ``alpha`` values (see "Meta-test" in :mod:`warp_critic.methods.baseline`)."""

from __future__ import annotations

import copy
import math
from typing import TYPE_CHECKING

import torch

from warp_critic.core.errors import DivergenceError
from warp_critic.learning.inner import inner_update, policy_fn
from warp_critic.learning.losses import critic_loss, final_error
from warp_critic.learning.networks import MLPPolicy, Normalizer
from warp_critic.learning.rollout import rollout
from warp_critic.methods.q_networks import NegQ

if TYPE_CHECKING:  # a type only: importing it loads Newton (seconds)
    from warp_critic.physics.simulator import Simulator

ALPHA_GRID = tuple(10.0 ** (k / 2) for k in range(-12, 1))  # 1e-6, 3.2e-6, ..., 0.32, 1


def fresh_policy_errors(
    qnet: torch.nn.Module,
    norm: Normalizer,
    sim: Simulator,
    goal: torch.Tensor,
    horizon: int,
    steps: int,
    alphas,
    seed: int,
    q0: torch.Tensor | None = None,
) -> list[float]:
    """Meta-test's protocol on the training worlds, for every ``alpha``, with the critic ``qnet``
    (``(q, qd, tau, g) -> (W,)``, a baseline agent's ``q``): fresh policies (the same
    initialisation for every alpha), ``steps`` descents of ``sum_t -Q``, mean final ``||q_T - g||^2``."""
    neg_q = NegQ(copy.deepcopy(qnet)).requires_grad_(False)
    policy = MLPPolicy(norm)
    q0 = sim.zeros() if q0 is None else q0
    qd0 = torch.zeros_like(q0)
    gen = torch.Generator().manual_seed(seed)
    params = {
        k: v.requires_grad_(True)
        for k, v in policy.init(sim.worlds, generator=gen, device=sim.torch_device).items()
    }
    errors = []
    if steps == 1:  # one gradient serves every alpha
        traj = rollout(sim, policy_fn(policy, params), q0, qd0, horizon)
        loss = critic_loss(neg_q, policy, params, traj, goal).sum()
        grads = torch.autograd.grad(loss, list(params.values()))
    for alpha in alphas:
        try:
            if steps == 1:
                new = {k: (v - alpha * g).detach() for (k, v), g in zip(params.items(), grads)}
            else:
                new, _ = inner_update(
                    neg_q,
                    policy,
                    params,
                    sim,
                    q0,
                    qd0,
                    goal,
                    horizon=horizon,
                    alpha=alpha,
                    steps=steps,
                    create_graph=False,
                )
            after = rollout(sim, policy_fn(policy, new), q0, qd0, horizon)
            err = float(final_error(after.q[-1], goal).mean())
        except DivergenceError:
            err = math.inf
        errors.append(err if math.isfinite(err) else math.inf)
    return errors
