"""Learning: the networks, the losses, rollouts, and the inner (policy) and outer (critic) updates."""

from warp_critic.core.exports import lazy_exports

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
