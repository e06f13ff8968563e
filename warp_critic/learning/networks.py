"""Networks: the fixed input scales and the batched per-world policies (the critic: :mod:`.critic`).

Policy (paper, section 5): MLP ``s -> a`` with two hidden layers of 64 units and tanh. Every world
has its own parameters; they are stored stacked with a leading world dimension ``W`` so that one
batched matmul evaluates all policies, and an inner update is ``theta - alpha * grad`` on plain
tensors (no module, no in-place mutation).

Input normalisation (:class:`Normalizer`; documented, fixed from the scene, not learned), for the
policy and the critic's input layouts (:mod:`warp_critic.learning.critic_inputs`) alike:
  * joint positions and goals: ``(q - centre) / half_range`` of the joint limits; a continuous joint
    (no limits: a half range of at least ``CONTINUOUS_HALF_RANGE``) is an angle, seen wrapped:
    ``wrap(q) / pi`` with ``wrap`` to ``[-pi, pi)``, and so are its differences ``q - g``,
  * joint velocities: ``qd / qd_scale`` (``qd_scale`` a flag, rad/s),
  * actions: ``tau / max_torque``.
Policy output shaping: ``tau = max_torque * tanh(out)``, so torque limits always hold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import torch

PolicyParams = dict[str, torch.Tensor]

POLICY_INIT_SCHEMES = ("fresh", "fixed", "persistent")


CONTINUOUS_HALF_RANGE = 1e6  # rad: a joint whose limits are this far apart has none


class Inertia(Protocol):
    """A model's joint-space inertia as data: ``q (..., dof)`` -> ``M(q) (..., dof, dof)``, and
    ``home()`` -> ``M(q_h) (dof, dof)`` (e.g. :class:`~warp_critic.physics.inertia.NominalInertia`)."""

    def __call__(self, q: torch.Tensor, /) -> torch.Tensor: ...

    def home(self) -> torch.Tensor: ...


def wrap_angles(x: torch.Tensor, wrap: torch.Tensor | None) -> torch.Tensor:
    """``x (..., dof)`` with the joints where ``wrap (dof,)`` is true wrapped to ``[-pi, pi)``."""
    if wrap is None:
        return x
    return torch.where(wrap, torch.remainder(x + math.pi, 2 * math.pi) - math.pi, x)


@dataclass(frozen=True)
class Normalizer:
    """Fixed affine input scales (all ``(dof,)`` tensors); ``wrap``: the continuous joints (bool)."""

    q_centre: torch.Tensor
    q_half_range: torch.Tensor
    qd_scale: float
    max_torque: torch.Tensor
    wrap: torch.Tensor | None = None
    # the nominal model's M(q) (:class:`~warp_critic.physics.inertia.NominalInertia`), for the
    # ``inertial`` critic; evaluated lazily, so carrying it costs nothing
    inertia: Inertia | None = None
    # K, the numbers of a world's dynamics descriptor (Simulator.dynamics_size), for the
    # ``pose-dynamics`` and ``relative-dynamics`` critics; 0 where the caller has none
    dynamics_size: int = 0

    @staticmethod
    def from_limits(
        q_lower: torch.Tensor,
        q_upper: torch.Tensor,
        max_torque: torch.Tensor,
        qd_scale: float,
        inertia: Inertia | None = None,
        dynamics_size: int = 0,
    ) -> Normalizer:
        centre, half = (q_upper + q_lower) / 2, (q_upper - q_lower) / 2
        wrap = half >= CONTINUOUS_HALF_RANGE
        if not bool(wrap.any()):
            return Normalizer(
                centre, half, float(qd_scale), max_torque, None, inertia, dynamics_size
            )
        centre = torch.where(wrap, torch.zeros_like(centre), centre)
        half = torch.where(wrap, torch.full_like(half, math.pi), half)
        return Normalizer(centre, half, float(qd_scale), max_torque, wrap, inertia, dynamics_size)

    def q(self, q: torch.Tensor) -> torch.Tensor:
        return wrap_angles(q - self.q_centre, self.wrap) / self.q_half_range

    def dq(self, q: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """``(q - goal) / half_range``, continuous joints wrapped."""
        return wrap_angles(q - goal, self.wrap) / self.q_half_range

    def state(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        return torch.cat([self.q(q), qd / self.qd_scale], dim=-1)

    def action(self, tau: torch.Tensor) -> torch.Tensor:
        return tau / self.max_torque


# ------------------------------------------------------------------------------------------------
# policy: W independent MLPs evaluated in one batched call
# ------------------------------------------------------------------------------------------------


def init_policy(
    worlds: int,
    obs_dim: int,
    act_dim: int,
    *,
    hidden: int = 64,
    generator=None,
    device="cpu",
    out_scale: float = 0.1,
) -> PolicyParams:
    """PyTorch-default (Kaiming-uniform) initialisation for ``W`` policies.

    The last layer is scaled by ``out_scale`` so fresh policies start with small torques.
    Returns tensors ``w1 (W,h,obs) b1 (W,h) w2 (W,h,h) b2 (W,h) w3 (W,act,h) b3 (W,act)``.
    """

    def layer(n_out, n_in, scale=1.0):
        bound = 1.0 / math.sqrt(n_in)
        w = (torch.rand(worlds, n_out, n_in, generator=generator) * 2 - 1) * bound * scale
        b = (torch.rand(worlds, n_out, generator=generator) * 2 - 1) * bound * scale
        return w.to(device), b.to(device)

    w1, b1 = layer(hidden, obs_dim)
    w2, b2 = layer(hidden, hidden)
    w3, b3 = layer(act_dim, hidden, out_scale)
    return {"w1": w1, "b1": b1, "w2": w2, "b2": b2, "w3": w3, "b3": b3}


def policy_forward(params: PolicyParams, obs: torch.Tensor) -> torch.Tensor:
    """``obs (W, obs_dim)`` or ``(T, W, obs_dim)`` -> pre-shaping output ``(..., W, act_dim)``."""
    h = torch.tanh(torch.einsum("wij,...wj->...wi", params["w1"], obs) + params["b1"])
    h = torch.tanh(torch.einsum("wij,...wj->...wi", params["w2"], h) + params["b2"])
    return torch.einsum("wij,...wj->...wi", params["w3"], h) + params["b3"]


def policy_action(
    params: PolicyParams, norm: Normalizer, q: torch.Tensor, qd: torch.Tensor
) -> torch.Tensor:
    """Joint torques ``(..., W, dof)`` within ``+-max_torque``."""
    return norm.max_torque * torch.tanh(policy_forward(params, norm.state(q, qd)))


class MLPPolicy:
    """The paper's policy family as a function ``(params, q, qd) -> tau``: per-world MLPs over the
    normalised state, ``max_torque * tanh`` output. :mod:`warp_critic.learning.inner` takes any such function
    (the point-mass landscape uses a constant-force policy ``(params, q, qd) -> theta``)."""

    def __init__(self, norm: Normalizer, hidden: int = 64):
        self.norm, self.hidden = norm, hidden

    def __call__(self, params: PolicyParams, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        return policy_action(params, self.norm, q, qd)

    def init(self, worlds: int, *, generator=None, device="cpu") -> PolicyParams:
        """Fresh parameters for ``worlds`` policies (see :func:`init_policy`)."""
        dof = self.norm.max_torque.shape[0]
        return init_policy(
            worlds, 2 * dof, dof, hidden=self.hidden, generator=generator, device=device
        )


def detach_params(params: PolicyParams, requires_grad: bool = True) -> PolicyParams:
    return {k: v.detach().clone().requires_grad_(requires_grad) for k, v in params.items()}


def flat_params(params: PolicyParams) -> torch.Tensor:
    """``(W, n_params)``: all parameters of each world's policy in one row (for traces)."""
    return torch.cat([v.reshape(v.shape[0], -1) for v in params.values()], dim=1)
