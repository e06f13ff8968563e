"""Learning: the networks, the losses, rollouts, and the inner (policy) and outer (critic) updates."""

# ruff: noqa: F401  (the TYPE_CHECKING imports name the lazy exports)

from typing import TYPE_CHECKING

from warp_critic.core.exports import lazy_exports

if TYPE_CHECKING:  # the names for IDEs and type checkers (Newton's pattern); at run time
    # they load lazily, on first use
    from warp_critic.learning.critic import Critic
    from warp_critic.learning.critic_inputs import CRITIC_INPUTS, CriticInput
    from warp_critic.learning.inner import inner_update, policy_fn
    from warp_critic.learning.losses import critic_loss, final_error, task_loss, td_loss
    from warp_critic.learning.networks import MLPPolicy, Normalizer
    from warp_critic.learning.outer import OuterResult, meta_loss
    from warp_critic.learning.protocols import CriticFn, Policy
    from warp_critic.learning.rollout import Trajectory, rollout
    from warp_critic.learning.stacked import StackedCritic

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "warp_critic.learning.networks": ("MLPPolicy", "Normalizer"),
        "warp_critic.learning.critic": ("Critic",),
        "warp_critic.learning.stacked": ("StackedCritic",),
        "warp_critic.learning.critic_inputs": ("CRITIC_INPUTS", "CriticInput"),
        "warp_critic.learning.losses": ("final_error", "task_loss", "critic_loss", "td_loss"),
        "warp_critic.learning.protocols": ("CriticFn", "Policy"),
        "warp_critic.learning.rollout": ("Trajectory", "rollout"),
        "warp_critic.learning.inner": ("inner_update", "policy_fn"),
        "warp_critic.learning.outer": ("OuterResult", "meta_loss"),
    },
)
