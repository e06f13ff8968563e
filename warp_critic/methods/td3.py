"""TD3 (Fujimoto, van Hoof, Meger, ICML 2018, "Addressing Function Approximation Error in
Actor-Critic Methods"): DDPG with twin critics, target policy smoothing and delayed updates.

One gradient update from a minibatch ``(s, a, r, s', done)`` of the replay buffer (goal-conditioned,
``s - g``, as DDPG's; see :mod:`warp_critic.methods.baseline`):

* target action with smoothing noise: ``a' = clip(mu'(s') + clip(eps, -c, c), -max_torque,
  max_torque)``, ``eps ~ N(0, sigma^2)``, with ``sigma`` (``policy_noise``) and ``c``
  (``noise_clip``) in units of ``max_torque``;
* twin critics, clipped double Q-learning: ``y = r + gamma (1 - done) min(Q1'(s', a'), Q2'(s', a'))``,
  both ``Q1`` and ``Q2`` regress on ``y`` (one Adam over both, as the authors' code);
* delayed policy and target updates: every ``policy_delay``-th critic update the actor descends
  ``-mean Q1(s, mu(s))`` (TD3's actor uses ``Q1``) and all target networks take a soft step ``tau``;
  on the other updates neither the actor nor any target changes.

Experience collection, exploration (Gaussian, std ``noise_std`` x max_torque), warm-up, rewards,
checkpoints and the alpha search for meta-test are the baselines' shared protocol
(:func:`~warp_critic.methods.baseline.train_baseline`). Meta-test descends ``L = -Q1``, as for
DDPG's critic. The networks are DDPG's here (actor 2 x 64 tanh, Q 2 x 400 ELU, the paper's task
networks) rather than the authors' 2 x 256 ReLU, so the three baselines differ only in the update.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

import torch

from warp_critic.learning.losses import td_loss
from warp_critic.learning.networks import Normalizer
from warp_critic.methods.baseline import train_baseline
from warp_critic.methods.baseline_config import BaselineConfig
from warp_critic.methods.ddpg import DDPGAgent
from warp_critic.methods.q_networks import QNetwork, soft_update, test_critic_from_checkpoint
from warp_critic.methods.replay import NOISE_KINDS, ReplayBuffer
from warp_critic.running.config import spec
from warp_critic.running.loop import TrainResult
from warp_critic.running.methods import Method, register

_SOURCE = "Fujimoto et al. 2018, and the authors' code github.com/sfujim/TD3"


@dataclass
class TD3Config(BaselineConfig):
    """TD3 training: the baselines' task and protocol fields, TD3's published settings as defaults.

    Source: Fujimoto, van Hoof, Meger 2018 (section 5 and appendix C) and the authors' repository
    (``main.py`` and ``TD3.py`` of github.com/sfujim/TD3): Adam with learning rate 3e-4 for both
    actor and critics (the repository's; the paper's table says 1e-3), minibatch 256, soft target
    rate tau 5e-3, gamma 0.99, Gaussian exploration noise std 0.1, target policy smoothing noise
    std 0.2 clipped to +-0.5, policy and target updates every 2 critic updates; all noise in units
    of the action scale (``max_torque``). Fields not named here (buffer, warm-up, reward, networks)
    are the shared baseline protocol of :class:`BaselineConfig`.
    """

    method: str = spec("td3", "the baseline's name in the method registry")
    actor_lr: float = spec(3e-4, "actor learning rate (Adam; TD3's code: 3e-4)", gt=0, cap=1e3)
    critic_lr: float = spec(
        3e-4, "learning rate of both Q networks (Adam; TD3's code: 3e-4)", gt=0, cap=1e3
    )
    batch_size: int = spec(256, "minibatch size (TD3: 256)", gt=0, cap=10**7)
    noise: str = spec(
        "gaussian",
        "exploration noise: gaussian (TD3) or ou (Ornstein-Uhlenbeck)",
        choices=NOISE_KINDS,
    )
    noise_std: float = spec(
        0.1, "exploration noise std as a fraction of max_torque (TD3: 0.1)", ge=0, cap=100
    )
    policy_noise: float = spec(
        0.2,
        "target policy smoothing: std of the noise on the target action, a fraction of max_torque (TD3: 0.2)",
        ge=0,
        cap=100,
    )
    noise_clip: float = spec(
        0.5,
        "target policy smoothing: the noise is clipped to +-this fraction of max_torque (TD3: 0.5)",
        ge=0,
        cap=100,
    )
    policy_delay: int = spec(
        2,
        "critic updates per actor and target update (TD3: 2)",
        gt=0,
        cap=10**6,
    )


class TD3Agent(DDPGAgent):
    """DDPG's actor, Q (``Q1``) and targets, plus ``Q2`` and its target; one Adam over both Qs."""

    cfg: TD3Config

    def __init__(self, cfg: BaselineConfig, dof: int, norm: Normalizer, device):
        if not isinstance(cfg, TD3Config):
            raise TypeError(f"TD3 needs a TD3Config, got {type(cfg).__name__}")
        super().__init__(cfg, dof, norm, device)
        self.q2 = QNetwork(dof, norm, cfg.critic_hidden).to(device)
        self.q2_target = copy.deepcopy(self.q2).requires_grad_(False)
        self.q_opt = torch.optim.Adam(
            [*self.q.parameters(), *self.q2.parameters()],
            lr=cfg.critic_lr,
            weight_decay=cfg.critic_weight_decay,
            foreach=True,
        )
        self.max_torque = norm.max_torque.to(device)
        self.updates = 0  # critic updates so far: the actor and targets move every policy_delay-th

    def target_action(self, b: dict[str, torch.Tensor], gen: torch.Generator) -> torch.Tensor:
        """``clip(mu'(s') + clip(eps, -c, c) max_torque, +-max_torque)`` (target policy smoothing)."""
        cfg = self.cfg
        a2 = self.actor_target(b["q2"], b["qd2"], b["goal"])
        eps = torch.randn(a2.shape, generator=gen).to(a2.device) * cfg.policy_noise
        eps = eps.clamp(-cfg.noise_clip, cfg.noise_clip) * self.max_torque
        return torch.maximum(torch.minimum(a2 + eps, self.max_torque), -self.max_torque)

    def twin_critic_step(
        self, b: dict[str, torch.Tensor], gen: torch.Generator
    ) -> dict[str, float]:
        """Both Qs regress on the clipped double-Q target of the smoothed target action."""
        cfg = self.cfg
        with torch.no_grad():
            a2 = self.target_action(b, gen)
            q_next = torch.minimum(
                self.q_target(b["q2"], b["qd2"], a2, b["goal"]),
                self.q2_target(b["q2"], b["qd2"], a2, b["goal"]),
            )
        q1 = self.q(b["q"], b["qd"], b["tau"], b["goal"])
        q2 = self.q2(b["q"], b["qd"], b["tau"], b["goal"])
        loss = td_loss(q1, b["reward"], b["done"], q_next, cfg.gamma) + td_loss(
            q2, b["reward"], b["done"], q_next, cfg.gamma
        )
        self.q_opt.zero_grad(set_to_none=True)
        loss.backward()
        self.q_opt.step()
        return {"critic_loss": loss.item(), "q_mean": q1.mean().item()}

    def update(
        self, buffer: ReplayBuffer, gen: torch.Generator, train_actor: bool = True
    ) -> dict[str, float]:
        """One critic update; every ``policy_delay``-th also the actor (unless warming up) and the
        targets. ``actor_loss`` is reported on those updates only."""
        b = buffer.sample(self.cfg.batch_size, gen)
        stats = self.twin_critic_step(b, gen)
        self.updates += 1
        if self.updates % self.cfg.policy_delay == 0:
            if train_actor:
                stats.update(self.actor_step(b, buffer, gen))
            soft_update(self.q_target, self.q, self.cfg.tau)
            soft_update(self.q2_target, self.q2, self.cfg.tau)
            soft_update(self.actor_target, self.actor, self.cfg.tau)
        return stats

    def state_dict(self) -> dict:
        return {
            **super().state_dict(),
            "q2": self.q2.state_dict(),
            "q2_target": self.q2_target.state_dict(),
            "updates": self.updates,
        }

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        self.q2.load_state_dict(state["q2"])
        self.q2_target.load_state_dict(state["q2_target"])
        self.updates = int(state["updates"])


def train_td3(cfg: TD3Config, **kwargs) -> TrainResult:
    """Train (or resume) TD3; ``kwargs`` go to :func:`~warp_critic.methods.baseline.train_baseline`."""
    return train_baseline(replace(cfg, method="td3"), TD3Agent, **kwargs)


register(
    Method(
        name="td3",
        order=3,
        label="TD3",
        colour="tab:red",
        config=TD3Config,
        train=train_td3,
        critic_loader=test_critic_from_checkpoint,
        cite="Fujimoto et al. 2018",
        preset={"method": "td3", "iterations": 300},
        preset_description=f"TD3 baseline: the published settings ({_SOURCE}; TD3Config defaults), "
        "300 iterations",
        reproduced_by_default=False,
    )
)
