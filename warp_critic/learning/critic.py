"""The critic ``L_critic(s, a, g)``: an MLP (2 x 400, ELU, one scalar) over one input layout.

The layout (:mod:`warp_critic.learning.critic_inputs`, the ``critic_input`` setting) sets the first
layer's width and computes the normalised input; the critic carries the scene's fixed scales as
buffers, so that a checkpoint is self-contained. Batched seeds: :mod:`warp_critic.learning.stacked`.
"""

from __future__ import annotations

import torch
from torch import nn

from warp_critic.learning.critic_inputs import RolloutData, critic_input
from warp_critic.learning.networks import Normalizer


class Critic(nn.Module):
    """``L_critic(s, a, g)``: MLP ``[state, action, goal] -> scalar`` (2 x ``hidden``, ELU) over the
    layout ``inputs`` (:data:`~warp_critic.learning.critic_inputs.CRITIC_INPUTS`).

    Inputs are normalised with the scene's fixed :class:`~warp_critic.learning.networks.Normalizer`
    (stored as buffers so that a checkpoint is self-contained).
    """

    q_centre: torch.Tensor  # buffers (dof,)
    q_half_range: torch.Tensor
    max_torque: torch.Tensor
    q_wrap: torch.Tensor  # (dof,) bool: the continuous joints

    def __init__(self, dof: int, norm: Normalizer, hidden: int = 400, inputs: str = "full"):
        super().__init__()
        self.layout = critic_input(inputs)
        self.layout.check(norm)
        self.dof, self.inputs, self.hidden = dof, inputs, hidden
        # what the layout reads of the scene: the nominal inertia, the descriptor's size K
        self.inertia = norm.inertia if self.layout.needs_inertia else None
        self.dynamics_size = norm.dynamics_size if self.layout.told else 0
        n_in = self.layout.width(dof, self.dynamics_size)
        self.net = nn.Sequential(
            nn.Linear(n_in, hidden),
            nn.ELU(),
            nn.Linear(hidden, hidden),
            nn.ELU(),
            nn.Linear(hidden, 1),
        )
        self.register_buffer("q_centre", norm.q_centre.clone())
        self.register_buffer("q_half_range", norm.q_half_range.clone())
        self.register_buffer("max_torque", norm.max_torque.clone())
        # the continuous joints: from the scene, not the checkpoint (persistent=False)
        wrap = (
            norm.wrap
            if norm.wrap is not None
            else torch.zeros_like(norm.q_centre, dtype=torch.bool)
        )
        self.register_buffer("q_wrap", wrap.clone(), persistent=False)
        self._wraps = bool(wrap.any())
        self.qd_scale = norm.qd_scale

    @property
    def norm(self) -> Normalizer:
        """The scales the critic carries (on its device), as the layout reads them."""
        return Normalizer(
            self.q_centre,
            self.q_half_range,
            self.qd_scale,
            self.max_torque,
            self.q_wrap if self._wraps else None,
            self.inertia,
            self.dynamics_size,
        )

    @property
    def rollout_data(self) -> tuple[RolloutData, ...]:
        """What :meth:`forward` reads beside ``(s, a, g)``, by keyword (the layout's)."""
        return self.layout.rollout_data

    def torque_metric(self, q: torch.Tensor) -> torch.Tensor | None:
        """The metric ``P(q) (..., dof, dof)`` the inner update steps torques in at the states ``q
        (..., dof)`` (data): ``M(q) M(q_h)^-2 M(q)`` for the ``inertial`` layout, ``None`` (the
        identity: the paper's plain gradient) for the others."""
        return self.layout.torque_metric(self.norm, q)

    def features(
        self,
        q: torch.Tensor,
        qd: torch.Tensor,
        tau: torch.Tensor,
        goal: torch.Tensor,
        **data: torch.Tensor | None,
    ) -> torch.Tensor:
        """The normalised input ``(..., n_in)`` of the layout; ``data``: the rollout data it reads
        (``history`` ``(..., 2*dof)``, ``dynamics`` ``(..., K)``)."""
        return self.layout.features(self.norm, q, qd, tau, goal, data)

    def forward(
        self,
        q: torch.Tensor,
        qd: torch.Tensor,
        tau: torch.Tensor,
        goal: torch.Tensor,
        **data: torch.Tensor | None,
    ) -> torch.Tensor:
        """All ``(..., dof)`` (``data`` as for :meth:`features`) -> ``(...)``."""
        return self.net(self.features(q, qd, tau, goal, **data)).squeeze(-1)
