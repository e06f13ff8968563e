"""SAC (Haarnoja, Zhou, Hartikainen, Tucker, Ha, Tan, Kumar, Zhu, Gupta, Abbeel, Levine 2018, "Soft
Actor-Critic Algorithms and Applications"): maximum-entropy actor-critic with a tanh-squashed
Gaussian policy, twin Q functions and an automatically tuned entropy temperature.

The policy is stochastic: ``u ~ N(mu(s - g), sigma(s - g)^2)`` per joint, ``tau = max_torque
tanh(u)``; it explores by sampling itself (:meth:`SACAgent.explore`, no added noise), and its
noise-free evaluation (and the recording) uses ``max_torque tanh(mu)``. Log-probabilities are of
the normalised action ``a = tau / max_torque`` in ``(-1, 1)^dof`` (what the Qs see), with the
change of variables of the squashing: ``log pi(a|s) = sum_j [log N(u_j; mu_j, sigma_j^2)
- log(1 - tanh(u_j)^2)]`` (the paper's appendix C).

One gradient update from a minibatch ``(s, a, r, s', done)`` of the replay buffer (goal-conditioned,
``s - g``, as DDPG's; see :mod:`warp_critic.methods.baseline`), in the order of the authors' code
(softlearning's ``SAC._do_training``):

* twin critics: ``a' ~ pi(s')``, ``y = r + gamma (1 - done) (min(Q1'(s', a'), Q2'(s', a'))
  - T log pi(a'|s'))``, ``Q1`` and ``Q2`` regress on ``y`` (one Adam over both);
* actor (reparameterised, ``a = tanh(mu + sigma eps)``): descend ``mean(T log pi(a|s) -
  min(Q1, Q2)(s, a))``;
* temperature ``T = exp(log_T)``: descend ``-mean(log_T (log pi(a|s) + H_target))`` (the
  constraint ``E[-log pi] >= H_target``; ``H_target = -dof`` by default, the paper's ``-dim(A)``);
* targets: soft updates of both Qs with ``tau`` every update (no target actor).

During the protocol's warm-up (random torques) only the critics learn; the actor and the temperature
start with the first iteration after it. At meta-test a fresh policy descends ``L = -min(Q1, Q2)``,
the twin critics' minimum (:class:`TwinQ`), the critic SAC's own actor follows. The networks are
DDPG's (actor body 2 x 64 tanh, Q 2 x 400 ELU, the paper's task networks) rather than the authors'
2 x 256 ReLU, so the baselines differ only in their update and exploration.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, fields, replace
from functools import partial

import torch
from torch import nn
from torch.nn import functional as F

from warp_critic.core.errors import FieldError
from warp_critic.learning.losses import td_loss
from warp_critic.learning.networks import Normalizer
from warp_critic.methods.baseline import train_baseline
from warp_critic.methods.baseline_config import BaselineConfig
from warp_critic.methods.q_networks import (
    QNetwork,
    _GoalInput,
    _small_last_layer,
    soft_update,
    test_critic_from_checkpoint,
)
from warp_critic.methods.replay import ReplayBuffer
from warp_critic.running.config import spec
from warp_critic.running.loop import TrainResult
from warp_critic.running.methods import Method, register

_SOURCE = "Haarnoja et al. 2018, and the authors' code github.com/rail-berkeley/softlearning"
#: the policy's log standard deviation lies in this range (a smooth tanh map, as CleanRL's SAC):
#: below, the policy is deterministic to float precision; above, ``tanh`` saturates anyway
LOG_STD_RANGE = (-5.0, 2.0)


#: the added-noise fields of the baselines' protocol that SAC has no use for, at their defaults
_NOISE_DEFAULTS = {
    f.name: f.default for f in fields(BaselineConfig) if f.name in ("noise_std", "ou_theta")
}


@dataclass
class SACConfig(BaselineConfig):
    """SAC training: the baselines' task and protocol fields, SAC's published settings as defaults.

    Source: Haarnoja et al. 2018 ("Soft Actor-Critic Algorithms and Applications", table 1 and
    section 5) and the authors' code (softlearning): Adam with learning rate 3e-4 for the actor, both
    Qs and the temperature, minibatch 256, soft target rate tau 5e-3, gamma 0.99, initial temperature
    1, target entropy ``-dim(A)``, one gradient update per environment step (the protocol's default
    ``updates_per_iteration``, the horizon, is one per control step of the batch of worlds). Fields
    not named here (buffer, warm-up, reward, networks) are the shared protocol of
    :class:`BaselineConfig`.
    """

    method: str = spec("sac", "the baseline's name in the method registry")
    actor_lr: float = spec(3e-4, "actor learning rate (Adam; SAC: 3e-4)", gt=0, cap=1e3)
    critic_lr: float = spec(
        3e-4, "learning rate of both Q networks (Adam; SAC: 3e-4)", gt=0, cap=1e3
    )
    batch_size: int = spec(256, "minibatch size (SAC: 256)", gt=0, cap=10**7)
    noise: str = spec(
        "none",
        "exploration: SAC samples its own stochastic policy, so no noise is added (none only)",
        choices=("none",),
    )
    temperature_lr: float = spec(
        3e-4, "learning rate of the entropy temperature's log (Adam; SAC: 3e-4)", gt=0, cap=1e3
    )
    init_temperature: float = spec(
        1.0, "initial entropy temperature T (softlearning: 1)", gt=0, cap=1e6
    )
    target_entropy: float | None = spec(
        None,
        "entropy the temperature steers the policy to, in nats of the normalised action "
        "(default: -dof, Haarnoja et al.'s -dim(A))",
        ge=-1e4,
        le=1e4,
    )

    def check(self, scene=None) -> None:
        """As every config's check, and the added-noise fields left at their defaults: SAC
        explores by sampling its policy, so a noise setting would be silently ignored."""
        super().check(scene)
        for name in ("noise_std", "ou_theta"):
            if getattr(self, name) != _NOISE_DEFAULTS[name]:
                raise FieldError(
                    name, "SAC adds no exploration noise (it samples its own policy); leave it out"
                )


class GaussianActor(_GoalInput):
    """``pi(tau | s - g)``: ``tau = max_torque tanh(u)``, ``u ~ N(mu, diag(sigma^2))``.

    Body 2 x ``hidden`` tanh (DDPG's actor), heads ``mu`` and ``log sigma`` (``(..., dof)`` each,
    final layers in +-3e-3 so a new policy starts near zero torque with ``sigma`` about 0.22, the
    middle of :data:`LOG_STD_RANGE`). ``forward`` is the deterministic ``max_torque tanh(mu)``.
    """

    def __init__(self, dof: int, norm: Normalizer, hidden: int = 64):
        super().__init__()
        self._init_norm(norm)
        self.dof = dof
        self.body = nn.Sequential(
            nn.Linear(2 * dof, hidden), nn.Tanh(), nn.Linear(hidden, hidden), nn.Tanh()
        )
        self.mu = nn.Linear(hidden, dof)
        self.log_std = nn.Linear(hidden, dof)
        _small_last_layer(self.mu)
        _small_last_layer(self.log_std)

    def gaussian(
        self, q: torch.Tensor, qd: torch.Tensor, goal: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``(mu, log sigma)`` of ``u``, both ``(..., dof)``."""
        h = self.body(self.obs(q, qd, goal))
        lo, hi = LOG_STD_RANGE
        return self.mu(h), lo + 0.5 * (hi - lo) * (torch.tanh(self.log_std(h)) + 1)

    def forward(self, q: torch.Tensor, qd: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """The mean action's torques ``max_torque tanh(mu)`` ``(..., dof)`` [N m]."""
        return self.max_torque * torch.tanh(self.gaussian(q, qd, goal)[0])

    def sample(
        self, q: torch.Tensor, qd: torch.Tensor, goal: torch.Tensor, gen: torch.Generator
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """A reparameterised draw: torques ``(..., dof)`` [N m] and ``log pi(a|s)`` ``(...)`` of
        the normalised action ``a = tau / max_torque`` (gradients reach ``mu`` and ``sigma``)."""
        mu, log_std = self.gaussian(q, qd, goal)
        eps = torch.randn(mu.shape, generator=gen).to(mu.device)
        u = mu + log_std.exp() * eps
        return self.max_torque * torch.tanh(u), squashed_log_prob(u, mu, log_std)


def squashed_log_prob(u: torch.Tensor, mu: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
    """``log pi(tanh(u))`` ``(...)`` summed over the last axis, for ``u ~ N(mu, exp(log_std)^2)``:
    the Gaussian's log-density minus ``log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2 u))`` (the
    exact identity, finite where ``tanh(u)`` rounds to +-1)."""
    z = (u - mu) / log_std.exp()
    gauss = -0.5 * z.square() - log_std - 0.5 * math.log(2 * math.pi)
    jacobian = 2 * (math.log(2.0) - u - F.softplus(-2 * u))
    return (gauss - jacobian).sum(-1)


class TwinQ(nn.Module):
    """Two :class:`QNetwork` s; ``forward`` is their minimum ``(...)``, the critic SAC's actor and
    meta-test follow. Checkpointed as one state (``q1.*``, ``q2.*``)."""

    def __init__(self, dof: int, norm: Normalizer, hidden: int = 400):
        super().__init__()
        self.q1 = QNetwork(dof, norm, hidden)
        self.q2 = QNetwork(dof, norm, hidden)

    def forward(
        self, q: torch.Tensor, qd: torch.Tensor, tau: torch.Tensor, goal: torch.Tensor
    ) -> torch.Tensor:
        return torch.minimum(self.q1(q, qd, tau, goal), self.q2(q, qd, tau, goal))


class SACAgent:
    """Gaussian actor, twin Qs (:class:`TwinQ`) and their targets, the log temperature, and their
    optimisers (the :class:`~warp_critic.methods.baseline.Agent` protocol)."""

    def __init__(self, cfg: BaselineConfig, dof: int, norm: Normalizer, device):
        if not isinstance(cfg, SACConfig):
            raise TypeError(f"SAC needs a SACConfig, got {type(cfg).__name__}")
        self.cfg = cfg
        self.actor = GaussianActor(dof, norm, cfg.actor_hidden).to(device)
        self.q = TwinQ(dof, norm, cfg.critic_hidden).to(device)
        self.q_target = copy.deepcopy(self.q).requires_grad_(False)
        self.log_temperature = torch.tensor(
            math.log(cfg.init_temperature), device=device, requires_grad=True
        )
        self.target_entropy = float(-dof if cfg.target_entropy is None else cfg.target_entropy)
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=cfg.actor_lr, foreach=True)
        self.q_opt = torch.optim.Adam(
            self.q.parameters(),
            lr=cfg.critic_lr,
            weight_decay=cfg.critic_weight_decay,
            foreach=True,
        )
        self.temperature_opt = torch.optim.Adam([self.log_temperature], lr=cfg.temperature_lr)

    @property
    def temperature(self) -> float:
        return float(self.log_temperature.detach().exp())

    # -- exploration: the policy's own samples ----------------------------------------------------
    def begin_episode(self, worlds: int, gen: torch.Generator) -> None:
        """Nothing carries over between SAC's exploration steps."""

    def explore(
        self, q: torch.Tensor, qd: torch.Tensor, g: torch.Tensor, gen: torch.Generator
    ) -> torch.Tensor:
        """A sample of the policy ``(W, dof)`` [N m] (within ``+-max_torque`` by the ``tanh``)."""
        return self.actor.sample(q, qd, g, gen)[0]

    # -- one update -------------------------------------------------------------------------------
    def critic_step(self, b: dict[str, torch.Tensor], gen: torch.Generator) -> dict[str, float]:
        """Both Qs regress on the soft clipped double-Q target of a fresh next action."""
        with torch.no_grad():
            a2, logp2 = self.actor.sample(b["q2"], b["qd2"], b["goal"], gen)
            soft = self.q_target(b["q2"], b["qd2"], a2, b["goal"]) - self.temperature * logp2
        q1 = self.q.q1(b["q"], b["qd"], b["tau"], b["goal"])
        q2 = self.q.q2(b["q"], b["qd"], b["tau"], b["goal"])
        loss = td_loss(q1, b["reward"], b["done"], soft, self.cfg.gamma) + td_loss(
            q2, b["reward"], b["done"], soft, self.cfg.gamma
        )
        self.q_opt.zero_grad(set_to_none=True)
        loss.backward()
        self.q_opt.step()
        return {"critic_loss": loss.item(), "q_mean": q1.mean().item()}

    def actor_step(self, b: dict[str, torch.Tensor], gen: torch.Generator) -> dict[str, float]:
        """The actor descends ``T log pi - min Q`` of its own reparameterised samples, then the
        temperature moves toward the target entropy (with the actor's ``log pi``, held fixed)."""
        tau, logp = self.actor.sample(b["q"], b["qd"], b["goal"], gen)
        loss = (self.temperature * logp - self.q(b["q"], b["qd"], tau, b["goal"])).mean()
        self.actor_opt.zero_grad(set_to_none=True)
        loss.backward(inputs=list(self.actor.parameters()))  # the Qs' gradients are not needed
        self.actor_opt.step()
        temp_loss = -(self.log_temperature * (logp.detach() + self.target_entropy)).mean()
        self.temperature_opt.zero_grad(set_to_none=True)
        temp_loss.backward()
        self.temperature_opt.step()
        return {
            "actor_loss": loss.item(),
            "entropy": -logp.mean().item(),
            "temperature": self.temperature,
        }

    def update(
        self, buffer: ReplayBuffer, gen: torch.Generator, train_actor: bool = True
    ) -> dict[str, float]:
        """One minibatch update of the Qs (and, unless warming up, of the actor and the
        temperature), then the Qs' targets."""
        b = buffer.sample(self.cfg.batch_size, gen)
        stats = self.critic_step(b, gen)
        if train_actor:
            stats.update(self.actor_step(b, gen))
        soft_update(self.q_target, self.q, self.cfg.tau)
        return stats

    # -- checkpoints ------------------------------------------------------------------------------
    #: the networks and optimisers a checkpoint holds, by attribute (and key) name
    PARTS = ("actor", "q", "q_target", "actor_opt", "q_opt", "temperature_opt")

    def state_dict(self) -> dict:
        state = {k: getattr(self, k).state_dict() for k in self.PARTS}
        return {**state, "log_temperature": self.log_temperature.detach().cpu().clone()}

    def load_state_dict(self, state: dict) -> None:
        for k in self.PARTS:
            getattr(self, k).load_state_dict(state[k])
        with torch.no_grad():
            self.log_temperature.copy_(state["log_temperature"])


def train_sac(cfg: SACConfig, **kwargs) -> TrainResult:
    """Train (or resume) SAC; ``kwargs`` go to :func:`~warp_critic.methods.baseline.train_baseline`."""
    return train_baseline(replace(cfg, method="sac"), SACAgent, **kwargs)


register(
    Method(
        name="sac",
        order=4,
        label="SAC",
        colour="tab:purple",
        config=SACConfig,
        train=train_sac,
        critic_loader=partial(test_critic_from_checkpoint, make_q=TwinQ),
        cite="Haarnoja et al. 2018",
        preset={"method": "sac", "iterations": 300},
        preset_description=f"SAC baseline: the published settings ({_SOURCE}; SACConfig defaults), "
        "300 iterations",
        reproduced_by_default=False,
    )
)
