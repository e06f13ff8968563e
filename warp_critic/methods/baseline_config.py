"""The baselines' config (DDPG's; Meta-Critic's, TD3's and SAC's subclass it with their own
fields and defaults): the shared task fields of :class:`~warp_critic.running.task.TaskConfig` plus
the published DDPG settings; the protocol they train with is described in
:mod:`warp_critic.methods.baseline`."""

from __future__ import annotations

from dataclasses import dataclass

from warp_critic.core.errors import FieldError
from warp_critic.core.memory import check_fits
from warp_critic.methods.replay import NOISE_KINDS, REWARD_KINDS
from warp_critic.physics import schema
from warp_critic.running.config import filled, spec
from warp_critic.running.task import TaskConfig


@dataclass
class BaselineConfig(TaskConfig):
    """The baselines' training: DDPG's config, and the base of every other baseline's
    (``MetaCriticConfig``, ``TD3Config``, ``SACConfig`` add their own fields and published
    defaults; the method registry names each method's). ``None`` = the scene's default (as for
    meta-train).

    Defaults follow the published DDPG settings (Lillicrap et al. 2015): Adam with actor lr 1e-4 and
    critic lr 1e-3, gamma 0.99, minibatch 64, replay buffer 1e6, Ornstein-Uhlenbeck exploration
    noise (theta 0.15, sigma 0.2), final layers initialised in +-3e-3. Two documented deviations:
    tau = 5e-3 (TD3-era DDPG implementations; 1e-3 lags too far behind in runs of a few thousand
    updates) and no L2 weight decay on Q by default (``critic_weight_decay`` 1e-2 restores it);
    plus a 5-iteration random-action warm-up (``warmup_iterations`` 0 disables it).
    """

    method: str = spec(
        "ddpg", "the baseline's name in the method registry (warp_critic.running.methods)"
    )
    iterations: int = spec(
        300,
        "training iterations (one episode in every world, then the gradient updates)",
        gt=0,
        cap=10**8,
    )
    # -- DDPG ------------------------------------------------------------------------------------
    actor_lr: float = spec(1e-4, "actor learning rate (Adam)", gt=0, cap=1e3)
    critic_lr: float = spec(1e-3, "Q learning rate (Adam)", gt=0, cap=1e3)
    critic_weight_decay: float = spec(0.0, "L2 weight decay on Q (Lillicrap et al.: 1e-2)", ge=0)
    tau: float = spec(
        5e-3, "soft target update rate, in (0, 1] (Lillicrap et al.: 1e-3)", gt=0, le=1
    )
    gamma: float = spec(0.99, "discount factor, in (0, 1]", gt=0, le=1)
    batch_size: int = spec(64, "minibatch size", gt=0, cap=10**7)
    buffer_size: int = spec(1_000_000, "replay buffer capacity (transitions)", gt=0, cap=10**9)
    warmup_iterations: int = spec(
        5,
        "first iterations explore with uniformly random torques and train only Q (the actor starts once Q has seen varied actions; 0 = Lillicrap et al.)",
        ge=0,
    )
    updates_per_iteration: int | None = spec(
        None, "gradient updates per iteration (default: the horizon)", gt=0, cap=10**7
    )
    noise: str = spec(
        "ou", "exploration noise: ou (Ornstein-Uhlenbeck) or gaussian", choices=NOISE_KINDS
    )
    noise_std: float = spec(
        0.2, "noise scale (OU sigma or Gaussian std) as a fraction of max_torque", ge=0, cap=100
    )
    ou_theta: float = spec(0.15, "OU mean reversion per control step, in [0, 1]", ge=0, le=1)
    reward: str = spec(
        "dense",
        "dense: r_t = -||q_{t+1}-g||^2 every step; sparse: only -||q_T-g||^2 at the end",
        choices=REWARD_KINDS,
    )
    reward_scale: float = spec(1.0, "multiply the reward by this", gt=0)
    actor_hidden: int = spec(64, "actor hidden units (2 tanh layers)", gt=0, cap=8192)
    critic_hidden: int = spec(400, "Q hidden units (2 ELU layers)", gt=0, cap=8192)
    # -- meta-test defaults stored in the checkpoint ---------------------------------------------
    # named ``alpha`` before 2026-12 (a run's config.json / checkpoint may still say so: from_dict)
    metatest_alpha: float | None = spec(
        None,
        "meta-test's step size for fresh policies descending -Q (default: grid search on the training goals at every checkpoint)",
        gt=0,
        cap=1e6,
    )
    inner_steps: int | None = spec(
        None,
        "meta-test's default number of fresh-policy updates with -Q (default: the scene's, as meta-train's inner steps, else "
        + schema.fallback_text("inner_steps")
        + ")",
        gt=0,
        cap=10**4,
    )

    scene_fields = TaskConfig.scene_fields + ("inner_steps",)

    def check(self, scene=None) -> None:
        """:meth:`TaskConfig.check`, and: a minibatch no larger than the replay buffer, and, with
        ``scene``, the replay buffers' memory (``S`` seeds x the transitions they can hold x
        ``7 dof + 2`` float32 each) before any is allocated."""
        super().check(scene)
        if self.batch_size > self.buffer_size:
            raise FieldError(
                "batch_size",
                f"{self.batch_size} is more than the replay buffer holds (--buffer-size "
                f"{self.buffer_size}): a minibatch is drawn from the buffer",
            )
        if scene is not None and isinstance(self.horizon, int):
            seeds = len(self.seeds) if self.seeds else 1
            worlds = (len(self.goals) if self.goals else 1) * self.worlds_per_goal
            held = min(self.buffer_size, self.iterations * worlds * self.horizon)
            check_fits(
                "buffer_size" if held == self.buffer_size else "iterations",
                f"{seeds} replay buffer(s) of {held:,} transitions ({scene.dof} dof)",
                seeds * held * (7 * scene.dof + 2) * 4,
            )

    @classmethod
    def from_dict(cls, d: dict):
        """As :meth:`SerializableConfig.from_dict` (a key that is no field of ``cls`` is ignored,
        so a run written before 2026-12, whose config holds Meta-Critic's ``aux_*`` and
        ``virtual_lr`` whatever its method, loads as DDPG's, TD3's or SAC's: those methods never
        read them); a saved config's old key ``alpha`` (the field :attr:`metatest_alpha`'s name in
        runs written before 2026-12) is read as ``metatest_alpha``."""
        if "alpha" in d and "metatest_alpha" not in d:
            d = {**{k: v for k, v in d.items() if k != "alpha"}, "metatest_alpha": d["alpha"]}
        return super().from_dict(d)

    def n_updates(self) -> int:
        if self.updates_per_iteration is not None:
            return self.updates_per_iteration
        return filled(self.horizon, "horizon")
