"""Methods: ours (model-based meta-training of the critic) and the DDPG and Meta-Critic baselines."""

from warp_critic.core.exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "warp_critic.methods.ours": ("TrainConfig", "meta_train"),
        "warp_critic.methods.baseline_config": ("BaselineConfig",),
        "warp_critic.methods.baseline": ("train_baseline",),
        "warp_critic.methods.ddpg": ("train_ddpg",),
        "warp_critic.methods.meta_critic": ("train_meta_critic",),
    },
)
