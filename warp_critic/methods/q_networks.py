"""Baseline networks (goal-conditioned: they see ``s - g``): DDPG's actor and Q, and ``-Q`` as the
loss a fresh policy descends at meta-test.

Inputs ``x = [(q - g) / q_half_range, qd / qd_scale]`` (the scene :class:`~warp_critic.learning.networks.Normalizer`
scales) and the action ``tau / max_torque``, as in the paper ("the state becomes ``s - g``").
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import nn

from warp_critic.core.errors import UserError
from warp_critic.learning.networks import Normalizer, wrap_angles
from warp_critic.running.methods import names


class _GoalInput(nn.Module):
    """Holds the fixed normaliser as buffers (checkpoints are self-contained)."""

    q_half_range: torch.Tensor  # buffers: (dof,), (dof,), ()
    max_torque: torch.Tensor
    qd_scale: torch.Tensor
    q_wrap: torch.Tensor  # (dof,) bool: the continuous joints

    def _init_norm(self, norm: Normalizer) -> None:
        self.register_buffer("q_half_range", norm.q_half_range.detach().clone())
        self.register_buffer("max_torque", norm.max_torque.detach().clone())
        self.register_buffer("qd_scale", torch.tensor(float(norm.qd_scale)))
        wrap = (
            norm.wrap
            if norm.wrap is not None
            else torch.zeros_like(norm.q_centre, dtype=torch.bool)
        )
        self.register_buffer("q_wrap", wrap.detach().clone(), persistent=False)  # from the scene
        self._wraps = bool(wrap.any())

    def obs(self, q: torch.Tensor, qd: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """``[(q - g) / q_half_range, qd / qd_scale]`` ``(..., 2*dof)``."""
        dq = wrap_angles(q - goal, self.q_wrap if self._wraps else None)
        return torch.cat([dq / self.q_half_range, qd / self.qd_scale], dim=-1)


def _small_last_layer(layer: nn.Module, bound: float = 3e-3) -> None:
    """Lillicrap et al.: final layer weights and biases from U(-3e-3, 3e-3)."""
    if not isinstance(layer, nn.Linear):
        raise TypeError(f"expected a Linear layer, got {type(layer).__name__}")
    nn.init.uniform_(layer.weight, -bound, bound)
    nn.init.uniform_(layer.bias, -bound, bound)


class Actor(_GoalInput):
    """Deterministic goal-conditioned policy ``mu(s - g)``: 2 x ``hidden`` tanh, ``max_torque * tanh`` out."""

    def __init__(self, dof: int, norm: Normalizer, hidden: int = 64):
        super().__init__()
        self._init_norm(norm)
        self.dof = dof
        self.net = nn.Sequential(
            nn.Linear(2 * dof, hidden),
            nn.Tanh(),
            nn.Linear(hidden, hidden),
            nn.Tanh(),
            nn.Linear(hidden, dof),
        )
        _small_last_layer(self.net[-1])

    def forward(self, q: torch.Tensor, qd: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        return self.max_torque * torch.tanh(self.net(self.obs(q, qd, goal)))

    def features(self, q: torch.Tensor, qd: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """The last hidden layer's activations ``(..., hidden)`` (Meta-Critic's ``h_omega`` input in
        Zhou et al.'s design); ``forward`` is its final layer on them, the same operations."""
        return self.net[:-1](self.obs(q, qd, goal))

    def head(self, feats: torch.Tensor) -> torch.Tensor:
        """The torques ``(..., dof)`` [N m] from :meth:`features`: ``head(features(s)) == forward(s)``,
        bitwise."""
        return self.max_torque * torch.tanh(self.net[-1](feats))


class QNetwork(_GoalInput):
    """``Q(s - g, a)``: 2 x ``hidden`` ELU (the same body as our critic), inputs normalised."""

    def __init__(self, dof: int, norm: Normalizer, hidden: int = 400):
        super().__init__()
        self._init_norm(norm)
        self.dof = dof
        self.net = nn.Sequential(
            nn.Linear(3 * dof, hidden),
            nn.ELU(),
            nn.Linear(hidden, hidden),
            nn.ELU(),
            nn.Linear(hidden, 1),
        )
        _small_last_layer(self.net[-1])

    def forward(
        self, q: torch.Tensor, qd: torch.Tensor, tau: torch.Tensor, goal: torch.Tensor
    ) -> torch.Tensor:
        """All ``(..., dof)`` -> ``(...)``."""
        x = torch.cat([self.obs(q, qd, goal), tau / self.max_torque], dim=-1)
        return self.net(x).squeeze(-1)


class NegQ(nn.Module):
    """The loss a fresh policy descends at meta-test: ``L(q, qd, tau, g) = -Q(s - g, a)``."""

    def __init__(self, q: nn.Module):
        super().__init__()
        self.q = q

    def forward(
        self, q: torch.Tensor, qd: torch.Tensor, tau: torch.Tensor, goal: torch.Tensor
    ) -> torch.Tensor:
        return -self.q(q, qd, tau, goal)


def test_critic_from_checkpoint(
    ckpt: dict, norm: Normalizer, make_q: Callable[..., nn.Module] = QNetwork
) -> tuple[torch.nn.Module, dict]:
    """``-Q`` of a baseline's checkpoint (Meta-Critic: its main Q, not h_omega), and the run's
    meta-test defaults (the alpha selected at its last checkpoint, its inner steps).

    ``make_q(dof, norm, hidden)`` builds the network the checkpoint's ``q_state`` holds (the
    agent's ``q``: one :class:`QNetwork`, or e.g. a twin Q's minimum). ``norm`` is meta-test's
    normaliser (built from the run's ``max_torque``/``qd_scale``); the checkpoint's own normaliser
    buffers are loaded over it, so the Q sees exactly the inputs it was trained on.
    """
    method = ckpt.get("method")
    if method not in names(baseline=True):
        baselines = ", ".join(names(baseline=True))
        raise UserError(f"checkpoint method {method!r} is not a baseline ({baselines})")
    try:
        qnet = make_q(int(ckpt["dof"]), norm, int(ckpt.get("critic_hidden", 400)))
        qnet.load_state_dict(ckpt["q_state"])
    except (KeyError, RuntimeError) as e:
        raise UserError(
            f"{method} checkpoint has no usable Q network ({type(e).__name__}: {str(e).splitlines()[0]})"
        ) from None
    cfg = ckpt.get("config", {})
    given = cfg.get("metatest_alpha", cfg.get("alpha"))  # "alpha": runs written before 2026-12
    alpha = given if given is not None else ckpt.get("selected_alpha")
    return NegQ(qnet.eval()), {"alpha": alpha, "steps": int(cfg.get("inner_steps", 1))}


def soft_update(target: nn.Module, source: nn.Module, tau: float) -> None:
    """``target <- target + tau (source - target)`` for every parameter (one batched lerp)."""
    with torch.no_grad():
        torch._foreach_lerp_(list(target.parameters()), list(source.parameters()), tau)
