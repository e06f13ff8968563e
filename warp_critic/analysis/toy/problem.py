"""The 1-D toy problem of section 4.1 and its objectives (torch, elementwise over a batch of thetas).

Model ``s_{t+1} = s_t + a_t``, policy ``a_t = theta``, horizon ``T = 2``, sparse terminal cost
``r_2 = (s_2 - g)^2``, critic ``Q_phi(s, a) = phi (s + a)^2``. Derivations: ``docs/toy.md``.
"""

from __future__ import annotations

import functools
import operator
from collections.abc import Iterable

import numpy as np
import torch

T = 2
"""Horizon: states ``s_0, s_1, s_2``; actions at ``t = 0, 1``; reward only at ``t = T``."""
GAMMA = 1.0
"""Discount factor used in the TD error."""
ALPHA = 0.5
"""Inner (policy) learning rate of our method and of the Meta-Critic policy update."""
METHODS = ("supervised", "ours", "meta_critic")

DTYPE = torch.float64


def as_tensor(x) -> torch.Tensor:
    """Numbers or arrays as a float64 tensor."""
    return torch.as_tensor(np.asarray(x, dtype=np.float64), dtype=DTYPE)


def rollout(s0: torch.Tensor, theta: torch.Tensor) -> list[torch.Tensor]:
    """States ``[s_0, s_1, s_2]`` of ``pi_theta`` (``a_t = theta``) under the model ``s_{t+1} = s_t + a_t``."""
    states = [s0 + 0.0 * theta]
    for _ in range(T):
        states.append(states[-1] + theta)
    return states


def data_rollout(s0: torch.Tensor, theta: torch.Tensor) -> list[torch.Tensor]:
    """:func:`rollout` with the states detached: data, as in the paper's policy gradients."""
    return [s.detach() for s in rollout(s0, theta.detach())]


def reward(s: torch.Tensor, t: int, g: float) -> torch.Tensor:
    """Sparse cost: 0 for ``t < T``, ``(s_T - g)^2`` at ``t = T``."""
    return (s - g) ** 2 if t == T else torch.zeros_like(s)


def terminal_cost(states: list[torch.Tensor], g: float) -> torch.Tensor:
    """``r_2 = (s_2 - g)^2`` of a rollout."""
    return reward(states[T], T, g)


def critic(phi: torch.Tensor, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
    """``Q_phi(s, a) = phi (s + a)^2`` (also the form of ``L_critic``)."""
    return phi * (s + a) ** 2


def _total(terms: Iterable[torch.Tensor]) -> torch.Tensor:
    """``t_0 + t_1 + ...`` left to right (the order, hence the rounding, of ``sum``)."""
    return functools.reduce(operator.add, terms)


def critic_objective(
    phi: torch.Tensor, states: list[torch.Tensor], theta: torch.Tensor
) -> torch.Tensor:
    """``sum_{t=0}^{T-1} Q_phi(s_t, pi_theta(s_t))`` with the given (data) states."""
    return _total(critic(phi, states[t], theta) for t in range(T))


def td_error(
    phi: torch.Tensor,
    states: list[torch.Tensor],
    theta: torch.Tensor,
    g: float,
    gamma: float = GAMMA,
) -> torch.Tensor:
    """Supervised TD loss ``delta`` of eq. (2) on one rollout (states, actions and rewards are data).

    ``delta = sum_{t=0}^{T-1} (Q(s_t, a_t) - (r_t + gamma * V_{t+1}))^2`` with ``V_{t+1} = Q(s_{t+1}, a_{t+1})``
    for ``t + 1 < T`` and the terminal cost ``V_T = r_T``.
    """
    terms = []
    for t in range(T):
        nxt = reward(states[T], T, g) if t + 1 == T else critic(phi, states[t + 1], theta)
        target = reward(states[t], t, g) + gamma * nxt
        terms.append((critic(phi, states[t], theta) - target) ** 2)
    return _total(terms)


def inner_step(
    theta: torch.Tensor, states: list[torch.Tensor], coef: torch.Tensor, alpha: float
) -> torch.Tensor:
    """``theta - alpha * grad_theta sum_t coef (s_t + theta)^2`` (states as data), differentiable in ``coef``."""
    th = theta.detach().clone().requires_grad_(True)
    obj = critic_objective(coef, states, th)
    (grad,) = torch.autograd.grad(obj.sum(), th, create_graph=True)
    return th.detach() - alpha * grad


def task_loss_after_inner_step(
    phi: torch.Tensor,
    theta: torch.Tensor,
    states: list[torch.Tensor],
    s0: torch.Tensor,
    g: float,
    alpha: float = ALPHA,
) -> torch.Tensor:
    """Our outer objective: ``L_task = (s_2^new - g)^2`` for ``theta_new(phi)`` rolled out through the model."""
    theta_new = inner_step(theta, states, phi, alpha)
    new_states = rollout(s0, theta_new)
    return _total(reward(new_states[t], t, g) for t in range(T + 1))


def meta_critic_loss(
    beta: torch.Tensor,
    phi: torch.Tensor,
    theta: torch.Tensor,
    states: list[torch.Tensor],
    alpha: float = ALPHA,
) -> torch.Tensor:
    """Meta-Critic objective ``l(beta) = sum_t Q_phi(s_t, pi_{theta_new(beta)}(s_t))`` (states, phi as data)."""
    theta_new = inner_step(theta, states, phi.detach() + beta, alpha)
    return critic_objective(phi.detach(), states, theta_new)
