"""Methods: ours (model-based meta-training of the critic) and the baselines (DDPG, Meta-Critic, TD3,
SAC; each one module and its registry entry, trained by :func:`~.baseline.train_baseline` through the
:class:`~.baseline.Agent` protocol). Importing this package registers every method in
:mod:`warp_critic.running.methods`."""

from warp_critic.core.exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "warp_critic.methods.ours": ("TrainConfig", "meta_train"),
        "warp_critic.methods.baseline_config": ("BaselineConfig",),
        "warp_critic.methods.baseline": ("train_baseline",),
        "warp_critic.methods.ddpg": ("train_ddpg",),
        "warp_critic.methods.meta_critic": ("train_meta_critic",),
        "warp_critic.methods.td3": ("TD3Config", "train_td3"),
        "warp_critic.methods.sac": ("SACConfig", "train_sac"),
        "warp_critic.running.methods": ("Method", "method", "methods", "names"),
    },
)

# every method module registers its entry when imported
from warp_critic.methods import ddpg, meta_critic, ours, sac, td3  # noqa: E402, F401
