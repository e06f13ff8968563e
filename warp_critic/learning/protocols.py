"""What the inner and outer updates need of a critic and a policy (structural types, PEP 544).

Any callable with the signature fits: our :class:`~warp_critic.learning.critic.Critic` and
:class:`~warp_critic.learning.stacked.StackedCritic`, a baseline's ``-Q``
(:class:`~warp_critic.methods.q_networks.NegQ`), :class:`~warp_critic.learning.networks.MLPPolicy`.
"""

from __future__ import annotations

from typing import Protocol

import torch

from warp_critic.learning.networks import PolicyParams


class CriticFn(Protocol):
    """The loss ``L(s, a, g)`` a policy descends: ``q, qd, tau, g`` all ``(..., W, dof)`` (rad, rad/s,
    N·m, rad) -> ``(..., W)``. A critic that reads rollout data beside ``(s, a, g)`` names it in its
    ``rollout_data`` (:class:`~warp_critic.learning.critic_inputs.RolloutData`: ``history`` ``(..., W,
    2*dof)``, ``dynamics`` ``(W, K)``) and takes it by keyword
    (:func:`~warp_critic.learning.critic_inputs.rollout_kwargs`)."""

    def __call__(
        self,
        q: torch.Tensor,
        qd: torch.Tensor,
        tau: torch.Tensor,
        g: torch.Tensor,
        /,
        **extra: torch.Tensor,
    ) -> torch.Tensor: ...


class StepSize(Protocol):
    """A learning rate other than one float, e.g. one per world: ``alpha * grad`` (``grad`` with the
    worlds as its leading dim) -> the step, ``grad``'s shape."""

    def __mul__(self, grad: torch.Tensor, /) -> torch.Tensor: ...


class Policy(Protocol):
    """A batch of ``W`` policies as a pure function of their parameters: ``(params, q, qd) -> tau``,
    states ``(..., W, dof)`` -> torques ``(..., W, dof)`` (N·m), each world with its own parameters."""

    def __call__(
        self, params: PolicyParams, q: torch.Tensor, qd: torch.Tensor, /
    ) -> torch.Tensor: ...
