"""Identify the model from what a rollout shows, for a critic that was told it (``*-dynamics``).

A ``pose-dynamics`` critic (:mod:`warp_critic.learning.critic_inputs`) reads each world's dynamics
descriptor ``d`` (:class:`~warp_critic.physics.descriptor.DynamicsDescriptor`), privileged data. An
:class:`Identifier` estimates ``d`` from one trajectory's observed states and applied torques alone,
``[q_t, qd_t, qd_t - qd_{t-1}, tau_{t-1}]`` at every step: under ``qd_t - qd_{t-1} ~ dt M(q)^-1
(tau_{t-1} - bias)`` the response to the torques shows the inertia. It is trained by regression on
simulated rollouts whose ``d`` is known (:mod:`warp_critic.methods.identify`); at meta-test the
:class:`IdentifiedCritic` feeds the told critic the estimate instead of the truth, so the policy
update needs no model, no model gradient and no privileged data -- the teacher/adaptation split of
rapid motor adaptation (Kumar et al., 2021) applied to a meta-learned critic.

Shapes: a trajectory's steps ``(T, W, dof)`` -> ``d_hat (W, K)``. Two architectures
(``version``):

* ``1``: a per-step MLP, the mean over the steps, a linear head. A linear head over averaged
  features cannot form a ratio, and the mass is one (``M ~ tau / qdd``): on a fresh policy's small
  torques its estimate stays near the draws' mean (on the reacher, seed 0, a fresh policy's
  rollout: the second link's log mass ratio read 0.20-0.58 for true values from -1.36 to 1.78;
  ``tools/probe_identifier.py``).
* ``2`` (default): the same per-step MLP, plus the trajectory's second moments of the response
  ``z_t = [qd_t - qd_{t-1}, tau_{t-1}]`` (scaled, not centred) as ``log`` root mean squares and
  correlations, and a two-layer head over both. For one joint ``log m = log rms(tau) - log
  rms(qdd)`` exactly; the logs make the estimate independent of the torques' size, and the head
  is nonlinear, so coupled joints are within reach too.

The inputs are standardised with fixed buffers (``x_mean``, ``x_std``) set from the first training
batch and stored in the checkpoint.
"""

from __future__ import annotations

import torch
from torch import nn

from warp_critic.learning.critic_inputs import DYNAMICS, HISTORY, history_features, rollout_data_of


def identifier_inputs(q: torch.Tensor, qd: torch.Tensor, history: torch.Tensor) -> torch.Tensor:
    """``(T, W, 4*dof)``: ``[q_t, qd_t, qd_t - qd_{t-1}, tau_{t-1}]`` (``history`` from
    :func:`~warp_critic.learning.critic_inputs.history_features`), detached: observed data."""
    return torch.cat([q.detach(), qd.detach(), history.detach()], dim=-1)


def trajectory_inputs(traj) -> torch.Tensor:
    """:func:`identifier_inputs` at the steps where a trajectory's actions were taken."""
    T = traj.tau.shape[0]
    return identifier_inputs(traj.q[:T], traj.qd[:T], history_features(traj.qd, traj.tau))


class Identifier(nn.Module):
    """``d_hat`` ``(W, K)`` from a trajectory's steps (module docstring).

    Args:
        dof: joints.
        size: ``K``, the descriptor's length.
        hidden: units of the per-step MLP's two ELU layers (and of version 2's head).
        version: the architecture (module docstring): ``2``; ``1`` loads identifiers written
            before version 2 existed.
    """

    x_mean: torch.Tensor
    x_std: torch.Tensor

    def __init__(self, dof: int, size: int, hidden: int = 128, version: int = 2):
        super().__init__()
        if version not in (1, 2):
            raise ValueError(f"identifier version {version!r}: 1 or 2")
        self.dof, self.size, self.hidden, self.version = dof, size, hidden, version
        self.step = nn.Sequential(
            nn.Linear(4 * dof, hidden), nn.ELU(), nn.Linear(hidden, hidden), nn.ELU()
        )
        n = 2 * dof  # the response z_t: velocity change and torque per joint
        self.moments = n + n * (n - 1) // 2 if version == 2 else 0
        if version == 1:
            self.head: nn.Module = nn.Linear(hidden, size)
        else:
            self.head = nn.Sequential(
                nn.Linear(hidden + self.moments, hidden), nn.ELU(), nn.Linear(hidden, size)
            )
        self.register_buffer("x_mean", torch.zeros(4 * dof))
        self.register_buffer("x_std", torch.ones(4 * dof))

    def standardise_from(self, x: torch.Tensor) -> None:
        """Fix the input scales from a batch ``x (..., 4*dof)`` (once, before training)."""
        flat = x.reshape(-1, x.shape[-1])
        self.x_mean.copy_(flat.mean(0))
        self.x_std.copy_(flat.std(0).clamp(min=1e-6))

    def response_moments(self, x: torch.Tensor) -> torch.Tensor:
        """``(W, moments)``: ``log`` root mean square of each scaled response channel ``z`` over the
        steps, then the correlation of each pair (``E[z_i z_j] / (rms_i rms_j)``, upper triangle)."""
        z = x[..., 2 * self.dof :] / self.x_std[2 * self.dof :]  # scaled, not centred: zero is rest
        second = torch.einsum("twi,twj->wij", z, z) / z.shape[0]
        ms = torch.diagonal(second, dim1=-2, dim2=-1)
        tiny = 1e-12
        rms = (ms + tiny).sqrt()
        i, j = torch.triu_indices(z.shape[-1], z.shape[-1], offset=1, device=z.device)
        corr = second[:, i, j] / (rms[:, i] * rms[:, j])
        return torch.cat([0.5 * torch.log(ms + tiny), corr], dim=-1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x (T, W, 4*dof)`` (:func:`identifier_inputs`) -> ``(W, K)``."""
        h = self.step((x - self.x_mean) / self.x_std).mean(0)
        if self.version == 2:
            h = torch.cat([h, self.response_moments(x)], dim=-1)
        return self.head(h)

    def of_trajectory(self, traj) -> torch.Tensor:
        """``(W, K)`` from a :class:`~warp_critic.learning.rollout.Trajectory`."""
        return self(trajectory_inputs(traj))


class IdentifiedCritic(nn.Module):
    """A told critic fed the :class:`Identifier`'s estimate: ``L(q, qd, tau, g, history)`` on one
    trajectory's steps ``(T, W, dof)``, ``history`` as for the ``history`` critic. Reads no model.

    ``identifier``: one :class:`Identifier`, or one per block of worlds for the seeds of a batched
    run (:class:`~warp_critic.learning.stacked.StackedCritic`: worlds seed-major, ``W / S`` each).
    The estimate is data (detached): training through this critic changes the critic only."""

    # the trajectory's observed responses (the identifier's input), never the true model
    rollout_data = (HISTORY,)

    def __init__(self, critic: nn.Module, identifier: Identifier | list[Identifier]):
        super().__init__()
        if DYNAMICS not in rollout_data_of(critic):
            raise ValueError("an identified critic wraps a critic that reads the dynamics")
        self.critic = critic
        self.identifiers = nn.ModuleList(
            identifier if isinstance(identifier, list) else [identifier]
        )

    @property
    def identifier(self) -> Identifier:
        """The first (with one seed: the only) identifier."""
        return self.identifiers[0]  # type: ignore[return-value]

    def estimate(self, q, qd, history) -> torch.Tensor:
        """``d_hat (W, K)`` from one trajectory's steps, each block of worlds by its identifier."""
        x = identifier_inputs(q, qd, history)
        if x.shape[1] % len(self.identifiers):
            raise ValueError(f"{x.shape[1]} worlds do not split into {len(self.identifiers)} seeds")
        blocks = x.chunk(len(self.identifiers), dim=1)
        return torch.cat([f(b) for f, b in zip(self.identifiers, blocks)], dim=0).detach()

    def forward(self, q, qd, tau, g, history=None):
        if history is None or q.dim() != 3:
            raise ValueError(
                "an identified critic needs one trajectory's steps (T, W, dof) and history"
            )
        return self.critic(q, qd, tau, g, dynamics=self.estimate(q, qd, history))


def identifier_from_checkpoint(ckpt: dict) -> Identifier | None:
    """The identifier a run's checkpoint carries (``warp-critic identify`` wrote it), or ``None``."""
    if "identifier_state" not in ckpt:
        return None
    meta = ckpt["identifier"]
    identifier = Identifier(
        int(ckpt["dof"]),
        int(meta["size"]),
        hidden=int(meta["hidden"]),
        version=int(meta.get("version", 1)),  # version 1 wrote no version
    )
    identifier.load_state_dict(ckpt["identifier_state"])
    return identifier


__all__ = [
    "Identifier",
    "IdentifiedCritic",
    "identifier_from_checkpoint",
    "identifier_inputs",
    "trajectory_inputs",
]
