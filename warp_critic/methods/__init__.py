"""Methods: ours (model-based meta-training of the critic) and the DDPG and Meta-Critic baselines."""

from warp_critic.core.exports import lazy_exports

_EXPORTS = {
    "warp_critic.methods.ours": ("TrainConfig", "meta_train"),
    "warp_critic.methods.baseline": ("BaselineConfig", "train_baseline"),
    "warp_critic.methods.ddpg": ("train_ddpg",),
    "warp_critic.methods.meta_critic": ("train_meta_critic",),
}
__all__ = [name for names in _EXPORTS.values() for name in names]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
