"""warp-critic: model-based meta-learning of critics for policy gradients on Newton/Warp.

The public API, re-exported lazily from the layer packages (importing ``warp_critic`` imports neither
torch nor Warp)::

    from warp_critic import TrainConfig, meta_train, MetaTestConfig, meta_test

The layers, each importing only the ones before it: ``core`` -> ``physics`` -> ``learning`` ->
``running`` -> ``methods`` -> ``evaluation`` -> ``analysis`` -> ``reproduce`` -> ``cli`` (README.md).
"""

from warp_critic.core.exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "warp_critic.core.errors": ("UserError", "FieldError", "SceneError", "DivergenceError"),
        "warp_critic.core.runtime": ("init",),
        "warp_critic.physics.scene": ("Scene",),
        "warp_critic.physics.load": ("load_scene",),
        "warp_critic.physics.variants": ("Variant",),
        "warp_critic.physics.simulator": ("Simulator",),
        "warp_critic.running.rundir": ("RunDir",),
        "warp_critic.methods.ours": ("TrainConfig", "meta_train"),
        "warp_critic.methods.baseline_config": ("BaselineConfig",),
        "warp_critic.methods.ddpg": ("train_ddpg",),
        "warp_critic.methods.meta_critic": ("train_meta_critic",),
        "warp_critic.evaluation.metatest": ("MetaTestConfig", "meta_test"),
        "warp_critic.evaluation.protocol": ("ProtocolConfig", "run_protocol"),
    },
)
__all__.insert(0, "__version__")

__version__ = "0.1.0"
