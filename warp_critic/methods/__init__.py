"""Methods: ours (model-based meta-training of the critic) and the baselines (DDPG, Meta-Critic, TD3,
SAC; each one module and its registry entry, trained by :func:`~.baseline.train_baseline` through the
:class:`~.baseline.Agent` protocol). Importing this package registers every method in
:mod:`warp_critic.running.methods`."""

# ruff: noqa: F401  (the TYPE_CHECKING imports name the lazy exports)

from typing import TYPE_CHECKING

from warp_critic.core.exports import lazy_exports

if TYPE_CHECKING:  # the names for IDEs and type checkers (Newton's pattern); at run time
    # they load lazily, on first use
    from warp_critic.methods.baseline import train_baseline
    from warp_critic.methods.baseline_config import BaselineConfig
    from warp_critic.methods.ddpg import train_ddpg
    from warp_critic.methods.meta_critic import MetaCriticConfig, train_meta_critic
    from warp_critic.methods.ours import TrainConfig, meta_train
    from warp_critic.methods.sac import SACConfig, train_sac
    from warp_critic.methods.td3 import TD3Config, train_td3
    from warp_critic.running.methods import Method, method, methods, names

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "warp_critic.methods.ours": ("TrainConfig", "meta_train"),
        "warp_critic.methods.baseline_config": ("BaselineConfig",),
        "warp_critic.methods.baseline": ("train_baseline",),
        "warp_critic.methods.ddpg": ("train_ddpg",),
        "warp_critic.methods.meta_critic": ("MetaCriticConfig", "train_meta_critic"),
        "warp_critic.methods.td3": ("TD3Config", "train_td3"),
        "warp_critic.methods.sac": ("SACConfig", "train_sac"),
        "warp_critic.running.methods": ("Method", "method", "methods", "names"),
    },
)

# every method module registers its entry when imported
from warp_critic.methods import ddpg, meta_critic, ours, sac, td3  # noqa: E402, F401
