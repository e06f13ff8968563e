"""DDPG (Lillicrap et al. 2015): supervised Q learning, the paper's Algorithm 1.

One gradient update from a minibatch ``(s, a, r, s', done)`` of the replay buffer (all states
goal-conditioned, ``s - g``; see :mod:`warp_critic.methods.baseline`):

* Q: TD regression ``(Q(s, a) - y)^2`` with ``y = r + gamma (1 - done) Q'(s', mu'(s'))`` from the
  target networks ``Q'``, ``mu'`` (Adam, ``--critic-lr``, optional L2 ``--critic-weight-decay``);
* actor: deterministic policy gradient, descend ``-mean Q(s, mu(s))`` (Adam, ``--actor-lr``);
* targets: soft updates ``theta' <- tau theta + (1 - tau) theta'``.

Exploration: the actor's torques plus noise (``--noise`` Ornstein-Uhlenbeck or Gaussian, clipped to
``+-max_torque``; :meth:`DDPGAgent.explore`). Experience collection, rewards, checkpoints and the
training loop are the baselines' protocol (:mod:`warp_critic.methods.baseline`). The learned Q is what meta-test uses
(``L = -Q``).
"""

from __future__ import annotations

import copy
from dataclasses import replace

import torch

from warp_critic.learning.losses import td_loss
from warp_critic.learning.networks import Normalizer
from warp_critic.methods.baseline import train_baseline
from warp_critic.methods.baseline_config import BaselineConfig
from warp_critic.methods.q_networks import (
    Actor,
    QNetwork,
    soft_update,
    test_critic_from_checkpoint,
)
from warp_critic.methods.replay import ExplorationNoise, ReplayBuffer
from warp_critic.running.loop import TrainResult
from warp_critic.running.methods import Method, register


class DDPGAgent:
    """Actor, Q, their target copies and optimisers."""

    def __init__(self, cfg: BaselineConfig, dof: int, norm: Normalizer, device):
        self.cfg, self.norm, self.device = cfg, norm, device
        self.noise: ExplorationNoise | None = None  # per episode: begin_episode
        self.actor = Actor(dof, norm, cfg.actor_hidden).to(device)
        self.q = QNetwork(dof, norm, cfg.critic_hidden).to(device)
        self.actor_target = copy.deepcopy(self.actor).requires_grad_(False)
        self.q_target = copy.deepcopy(self.q).requires_grad_(False)
        # foreach: one batched kernel per Adam operation instead of one per tensor (on CPU torch
        # defaults to the per-tensor loop); the same elementwise arithmetic, bit for bit
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=cfg.actor_lr, foreach=True)
        self.q_opt = torch.optim.Adam(
            self.q.parameters(),
            lr=cfg.critic_lr,
            weight_decay=cfg.critic_weight_decay,
            foreach=True,
        )

    # -- exploration (the :class:`~warp_critic.methods.baseline.Agent` protocol) ----------------------
    def begin_episode(self, worlds: int, gen: torch.Generator) -> None:
        """A new exploration episode: the noise process (built at the first, drawing from ``gen``)
        restarts (OU: from 0)."""
        if self.noise is None:
            cfg = self.cfg
            shape = (worlds, self.actor.dof)
            self.noise = ExplorationNoise(
                cfg.noise, cfg.noise_std, cfg.ou_theta, shape, gen, self.device
            )
        self.noise.reset()

    def explore(
        self, q: torch.Tensor, qd: torch.Tensor, g: torch.Tensor, gen: torch.Generator
    ) -> torch.Tensor:
        """``clip(mu(s - g) + noise max_torque, +-max_torque)`` ``(W, dof)`` [N m]; the noise draws
        from the generator :meth:`begin_episode` got."""
        assert self.noise is not None, "begin_episode() first"
        limit = self.norm.max_torque
        tau = self.actor(q, qd, g) + self.noise.sample() * limit
        return torch.maximum(torch.minimum(tau, limit), -limit)

    # -- one update -------------------------------------------------------------------------------
    def critic_step(self, b: dict[str, torch.Tensor]) -> dict[str, float]:
        cfg = self.cfg
        with torch.no_grad():
            a2 = self.actor_target(b["q2"], b["qd2"], b["goal"])
            q_next = self.q_target(b["q2"], b["qd2"], a2, b["goal"])
        q = self.q(b["q"], b["qd"], b["tau"], b["goal"])
        loss = td_loss(q, b["reward"], b["done"], q_next, cfg.gamma)
        self.q_opt.zero_grad(set_to_none=True)
        loss.backward()
        self.q_opt.step()
        return {"critic_loss": loss.item(), "q_mean": q.mean().item()}

    def actor_step(
        self, b: dict[str, torch.Tensor], buffer: ReplayBuffer, gen: torch.Generator
    ) -> dict[str, float]:
        a = self.actor(b["q"], b["qd"], b["goal"])
        loss = -self.q(b["q"], b["qd"], a, b["goal"]).mean()
        self.actor_opt.zero_grad(set_to_none=True)
        # only the actor's gradient: Q's weight gradients (a third of the Q backward) are not needed
        loss.backward(inputs=list(self.actor.parameters()))
        self.actor_opt.step()
        return {"actor_loss": loss.item()}

    def update(
        self, buffer: ReplayBuffer, gen: torch.Generator, train_actor: bool = True
    ) -> dict[str, float]:
        """One minibatch update of Q (and, unless warming up, of the actor), then the targets."""
        b = buffer.sample(self.cfg.batch_size, gen)
        stats = self.critic_step(b)
        if train_actor:
            stats.update(self.actor_step(b, buffer, gen))
        soft_update(self.q_target, self.q, self.cfg.tau)
        soft_update(self.actor_target, self.actor, self.cfg.tau)
        return stats

    # -- checkpoints ------------------------------------------------------------------------------
    def state_dict(self) -> dict:
        return {
            "actor": self.actor.state_dict(),
            "q": self.q.state_dict(),
            "actor_target": self.actor_target.state_dict(),
            "q_target": self.q_target.state_dict(),
            "actor_opt": self.actor_opt.state_dict(),
            "q_opt": self.q_opt.state_dict(),
        }

    def load_state_dict(self, state: dict) -> None:
        self.actor.load_state_dict(state["actor"])
        self.q.load_state_dict(state["q"])
        self.actor_target.load_state_dict(state["actor_target"])
        self.q_target.load_state_dict(state["q_target"])
        self.actor_opt.load_state_dict(state["actor_opt"])
        self.q_opt.load_state_dict(state["q_opt"])


def train_ddpg(cfg: BaselineConfig, **kwargs) -> TrainResult:
    """Train (or resume) DDPG; ``kwargs`` go to :func:`~warp_critic.methods.baseline.train_baseline`."""
    return train_baseline(replace(cfg, method="ddpg"), DDPGAgent, **kwargs)


register(
    Method(
        name="ddpg",
        order=1,
        label="DDPG",
        colour="tab:orange",
        config=BaselineConfig,
        train=train_ddpg,
        critic_loader=test_critic_from_checkpoint,
        cite="Lillicrap et al. 2015",
        preset={"method": "ddpg", "iterations": 300},
        preset_description="DDPG baseline: the published settings (BaselineConfig defaults), 300 iterations",
        paper_label="paper (Table 1, DDPG)",
        table_label="paper: DDPG",
    )
)
