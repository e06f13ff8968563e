"""Meta-Critic (Zhou et al., NeurIPS 2020, "Online Meta-Critic Learning for Off-Policy Actor-Critic
Methods") on top of DDPG.

Variant implemented (documented choice):

* **Auxiliary loss** ``h_omega``: an MLP ``-> 2 x 100 ReLU -> softplus`` (non-negative, as in the
  authors' code), averaged over the batch; not the set-based (permutation-invariant over the
  batch) design. Its input (``--aux-input``):

  - ``action`` (default): the goal-conditioned state and the actor's action,
    ``[(q - g)/q_half_range, qd/qd_scale, mu(s)/max_torque]``; ``h_omega`` reaches the actor through
    its action.
  - ``features``: Zhou et al.'s ``DDPG_MC_sa`` input, the actor's last hidden layer, the state and
    the STORED action ``[features(s), (q - g)/q_half_range, qd/qd_scale, tau/max_torque]``;
    ``h_omega`` reaches the actor through its features.

  Either can collapse to a constant that no longer moves the actor (then the run is DDPG): every
  run logs :func:`aux_grad_ratio` and warns when that happened.
* **Meta-objective**: the clipped-difference (``tanh``) variant. Each update, with the actor's
  parameters ``phi``, a training batch ``d_trn`` and a separate validation batch ``d_val`` from
  the replay buffer, and SGD virtual steps of size ``eta`` (``--virtual-lr``, default the actor lr):

  .. code-block:: text

      L_main(phi; d)   = -mean_{s in d} Q(s, mu_phi(s))              (main DDPG actor loss)
      phi_old          = phi - eta grad L_main(phi; d_trn)                          (main only)
      phi_new(omega)   = phi - eta grad [L_main + w h_omega](phi; d_trn)      (main + auxiliary)
      L_meta(omega)    = -tanh( L_main(phi_old; d_val) - L_main(phi_new; d_val) )
      omega <- Adam step on L_meta        (aux_lr, aux_weight_decay)

  i.e. ``omega`` is trained so that adding the auxiliary loss improves the validation objective,
  measured with the MAIN critic Q. The real actor update is one Adam step on
  ``L_main + w h_omega`` on ``d_trn`` (``w`` = ``--aux-weight``), with the gradient computed before
  ``omega``'s update (as in the authors' code).

The Q function is learned exactly as in DDPG (TD regression, target networks, soft updates). At
meta-test we use the main Q (the paper: "we use the critics (q-functions) that were trained during
meta-train"): ``L = -Q``; ``h_omega`` is saved in the checkpoint but not used there.

Its settings are :class:`MetaCriticConfig`'s: DDPG's :class:`BaselineConfig` plus ``h_omega``'s
(``aux_*``) and the virtual step (``virtual_lr``), flags of ``warp-critic baseline meta-critic``
only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch
from torch import nn
from torch.func import functional_call

from warp_critic.core.errors import warn
from warp_critic.learning.networks import Normalizer
from warp_critic.methods.baseline import train_baseline
from warp_critic.methods.baseline_config import BaselineConfig
from warp_critic.methods.ddpg import DDPGAgent
from warp_critic.methods.q_networks import _GoalInput, test_critic_from_checkpoint
from warp_critic.methods.replay import ReplayBuffer
from warp_critic.running.config import spec
from warp_critic.running.loop import TrainResult
from warp_critic.running.methods import Method, register

#: what ``h_omega`` sees besides ``s - g`` (:attr:`MetaCriticConfig.aux_input`)
AUX_INPUTS = ("action", "features")


@dataclass
class MetaCriticConfig(BaselineConfig):
    """Meta-Critic training: DDPG's fields and defaults (:class:`BaselineConfig`) plus the
    auxiliary loss ``h_omega`` and its virtual steps.

    Defaults follow Zhou et al. 2020's code: meta-critic (``h_omega``) Adam lr 1e-3, weight decay
    1e-4, 2 x 100 hidden units, auxiliary weight 1, virtual step size = the actor lr. A run written
    before 2026-12 (when every baseline's config held these fields) loads unchanged.
    """

    method: str = spec("meta-critic", "the baseline's name in the method registry")
    aux_lr: float = spec(1e-3, "learning rate of the auxiliary loss h_omega (Adam)", gt=0, cap=1e3)
    aux_weight_decay: float = spec(1e-4, "weight decay of h_omega", ge=0)
    aux_hidden: int = spec(100, "h_omega hidden units (2 ReLU layers)", gt=0, cap=8192)
    aux_input: str = spec(
        "action",
        "what h_omega sees besides s - g. action: the actor's action mu(s), so its gradient "
        "reaches the actor through the action; features: the actor's last hidden layer and the "
        "stored action (Zhou et al.'s DDPG_MC_sa), so it reaches the actor through its features",
        choices=AUX_INPUTS,
    )
    aux_weight: float = spec(1.0, "weight of the auxiliary loss in the actor update", ge=0)
    virtual_lr: float | None = spec(
        None,
        "SGD step of the virtual actor updates (default: the actor lr)",
        gt=0,
        cap=1e3,
    )


class AuxiliaryLoss(_GoalInput):
    """``h_omega(s - g, a) >= 0`` per sample (2 x ``hidden`` ReLU, softplus output).

    ``features`` > 0 (``aux_input`` features): the input also holds that many actor features,
    ``[phi_features, (q - g)/q_half_range, qd/qd_scale, tau/max_torque]``, ``tau`` the stored action.
    """

    def __init__(self, dof: int, norm: Normalizer, hidden: int = 100, features: int = 0):
        super().__init__()
        self._init_norm(norm)
        self.net = nn.Sequential(
            nn.Linear(features + 3 * dof, hidden),
            nn.ReLU(),
            nn.Linear(hidden, hidden),
            nn.ReLU(),
            nn.Linear(hidden, 1),
            nn.Softplus(),
        )

    def forward(
        self, q: torch.Tensor, qd: torch.Tensor, tau: torch.Tensor, goal: torch.Tensor
    ) -> torch.Tensor:
        x = torch.cat([self.obs(q, qd, goal), tau / self.max_torque], dim=-1)
        return self.net(x).squeeze(-1)

    def of_features(
        self,
        feats: torch.Tensor,
        q: torch.Tensor,
        qd: torch.Tensor,
        tau: torch.Tensor,
        goal: torch.Tensor,
    ) -> torch.Tensor:
        """``h_omega([feats, s - g, tau])`` per sample (``aux_input`` features)."""
        x = torch.cat([feats, self.obs(q, qd, goal), tau / self.max_torque], dim=-1)
        return self.net(x).squeeze(-1)


def aux_grad_ratio(
    g_main: tuple[torch.Tensor, ...], g_aux: tuple[torch.Tensor, ...], w: float
) -> float:
    """``||w grad_phi h_omega|| / ||grad_phi L_main||`` over all actor parameters: how much the
    auxiliary loss moves the actor, relative to DDPG's own gradient.

    0 means ``h_omega`` no longer depends on the actor's action: it has collapsed to a constant
    (every ReLU dead, or the softplus saturated) and the actor update is plain DDPG. Every run
    logs it, so a collapse is visible in the metrics and in the run's summary line.
    """
    with torch.no_grad():
        aux = torch.stack([ga.detach().square().sum() for ga in g_aux]).sum().sqrt()
        main = torch.stack([gm.square().sum() for gm in g_main]).sum().sqrt()
        return float(w * aux / main.clamp_min(torch.finfo(main.dtype).tiny))


ALIVE_RATIO = 1e-6
"""A Meta-Critic update whose :func:`aux_grad_ratio` is below this is counted as DDPG's."""

ALIVE_SHARE = 0.5
"""A seed whose :func:`aux_alive` is below this trained as DDPG: it is warned about, reported as
collapsed, and its setting cannot be adopted by the baselines' search."""

#: the metrics columns :func:`aux_alive` and :func:`aux_alive_basis` read (a carried archive keeps
#: only these of a run's metrics: :mod:`warp_critic.reproduce.engine.carry`)
AUX_KEYS = ("iteration", "aux_loss", "aux_grad_ratio", "meta_improvement")


def aux_alive(metrics: list[dict]) -> float | None:
    """The fraction of the last quarter of a run's iterations in which ``h_omega`` still moved the
    actor (``aux_grad_ratio`` of at least :data:`ALIVE_RATIO`); ``None`` for a run that logged no
    ratio. Runs written before the ratio was logged are judged by ``meta_improvement``: a collapsed
    ``h_omega`` makes the two virtual steps equal, so exactly 0."""
    rows = [m for m in metrics if "aux_loss" in m]
    if not rows:
        return None
    tail = rows[-max(1, len(rows) // 4) :]
    if "aux_grad_ratio" in tail[0]:
        alive = [float(m["aux_grad_ratio"]) >= ALIVE_RATIO for m in tail]
    else:
        alive = [float(m["meta_improvement"]) != 0.0 for m in tail]
    return sum(alive) / len(alive)


def aux_alive_basis(metrics: list[dict]) -> str | None:
    """What :func:`aux_alive` judged ``metrics`` by: ``"aux_grad_ratio >= 1e-6"``, or
    ``"meta_improvement != 0"`` for runs written before the ratio was logged; ``None`` without
    Meta-Critic rows."""
    rows = [m for m in metrics if "aux_loss" in m]
    if not rows:
        return None
    tail = rows[-max(1, len(rows) // 4) :]
    return (
        f"aux_grad_ratio >= {ALIVE_RATIO:g}"
        if "aux_grad_ratio" in tail[0]
        else "meta_improvement != 0"
    )


class MetaCriticAgent(DDPGAgent):
    """DDPG plus the online-learned auxiliary actor loss ``h_omega``."""

    cfg: MetaCriticConfig

    def __init__(self, cfg: BaselineConfig, dof: int, norm: Normalizer, device):
        if not isinstance(cfg, MetaCriticConfig):
            raise TypeError(f"Meta-Critic needs a MetaCriticConfig, got {type(cfg).__name__}")
        super().__init__(cfg, dof, norm, device)
        feats = cfg.actor_hidden if cfg.aux_input == "features" else 0
        self.aux = AuxiliaryLoss(dof, norm, cfg.aux_hidden, feats).to(device)
        self.aux_opt = torch.optim.Adam(
            self.aux.parameters(), lr=cfg.aux_lr, weight_decay=cfg.aux_weight_decay, foreach=True
        )
        self.eta = cfg.virtual_lr if cfg.virtual_lr is not None else cfg.actor_lr

    def _main_loss(self, params: dict, b: dict[str, torch.Tensor]) -> torch.Tensor:
        a = functional_call(self.actor, params, (b["q"], b["qd"], b["goal"]))
        return -self.q(b["q"], b["qd"], a, b["goal"]).mean()

    def actor_step(
        self, b: dict[str, torch.Tensor], buffer: ReplayBuffer, gen: torch.Generator
    ) -> dict[str, float]:
        val = buffer.sample(self.cfg.batch_size, gen)  # separate validation batch
        names = [n for n, _ in self.actor.named_parameters()]
        phi = dict(self.actor.named_parameters())
        w = self.cfg.aux_weight
        # actor losses on the training batch
        if self.cfg.aux_input == "features":  # Zhou et al.: [actor features, s, stored action]
            feats = self.actor.features(b["q"], b["qd"], b["goal"])
            a = self.actor.head(feats)
            aux = self.aux.of_features(feats, b["q"], b["qd"], b["tau"], b["goal"]).mean()
        else:
            a = self.actor(b["q"], b["qd"], b["goal"])
            aux = self.aux(b["q"], b["qd"], a, b["goal"]).mean()
        main = -self.q(b["q"], b["qd"], a, b["goal"]).mean()
        g_main = torch.autograd.grad(main, list(phi.values()), retain_graph=True)
        g_aux = tuple(  # a function of omega; zero where h_omega does not reach (features input:
            # the final layer)
            torch.zeros_like(p) if g is None else g
            for p, g in zip(
                phi.values(),
                torch.autograd.grad(aux, list(phi.values()), create_graph=True, allow_unused=True),
            )
        )
        # virtual steps, evaluated on the validation batch with the main Q
        phi_old = {n: (p - self.eta * gm).detach() for (n, p), gm in zip(phi.items(), g_main)}
        phi_new = {
            n: p.detach() - self.eta * (gm + w * ga)
            for (n, p), gm, ga in zip(phi.items(), g_main, g_aux)
        }
        with torch.no_grad():
            val_old = self._main_loss(phi_old, val)
        val_new = self._main_loss(phi_new, val)
        meta = -torch.tanh(val_old - val_new)
        g_omega = torch.autograd.grad(meta, list(self.aux.parameters()), allow_unused=True)
        # real actor step on main + w * auxiliary (gradient taken with the current omega)
        self.actor_opt.zero_grad(set_to_none=True)
        for n, gm, ga in zip(names, g_main, g_aux):
            phi[n].grad = (gm + w * ga).detach()
        self.actor_opt.step()
        # meta-critic step
        self.aux_opt.zero_grad(set_to_none=True)
        for p, g in zip(self.aux.parameters(), g_omega):
            p.grad = None if g is None else g.detach()
        self.aux_opt.step()
        return {
            "actor_loss": main.item(),
            "aux_loss": aux.item(),
            "meta_loss": meta.item(),
            "meta_improvement": (val_old - val_new).item(),
            "aux_grad_ratio": aux_grad_ratio(g_main, g_aux, w),
        }

    def state_dict(self) -> dict:
        state = super().state_dict()
        state.update(aux=self.aux.state_dict(), aux_opt=self.aux_opt.state_dict())
        return state

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        self.aux.load_state_dict(state["aux"])
        self.aux_opt.load_state_dict(state["aux_opt"])


def train_meta_critic(cfg: MetaCriticConfig, **kwargs) -> TrainResult:
    """Train (or resume) Meta-Critic; ``kwargs`` go to :func:`~warp_critic.methods.baseline.train_baseline`."""
    result = train_baseline(replace(cfg, method="meta-critic"), MetaCriticAgent, **kwargs)
    for r in result.seeds or [result]:
        alive = aux_alive(r.metrics)
        if alive is not None and alive < ALIVE_SHARE:
            warn(
                f"{r.run_dir}: h_omega moved the actor in only {alive:.0%} of the last quarter's "
                "iterations (aux_grad_ratio < 1e-6): this Meta-Critic run trained as DDPG"
            )
    return result


register(
    Method(
        name="meta-critic",
        order=2,
        label="Meta-Critic",
        colour="tab:green",
        config=MetaCriticConfig,
        train=train_meta_critic,
        critic_loader=test_critic_from_checkpoint,
        cite="Zhou et al. 2020",
        preset={"method": "meta-critic", "iterations": 300},
        preset_description="Meta-Critic baseline: Zhou et al.'s settings (MetaCriticConfig defaults), 300 iterations",
        paper_label="paper (Table 1, Meta-Critic)",
        table_label="paper: Meta Critic",
        run_summary=lambda rows: {
            "aux_alive": aux_alive(rows),
            "aux_alive_basis": aux_alive_basis(rows),
        },
    )
)
