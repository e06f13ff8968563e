"""warp-critic: model-based meta-learning of critics for policy gradients on Newton/Warp.

The public API, re-exported lazily from the layer packages (importing ``warp_critic`` imports neither
torch nor Warp)::

    from warp_critic import TrainConfig, meta_train, MetaTestConfig, meta_test

The layers, each importing only the ones before it: ``core`` -> ``physics`` -> ``learning`` ->
``running`` -> ``methods`` -> ``evaluation`` -> ``analysis`` -> ``reproduce`` -> ``cli`` (README.md).
"""

# ruff: noqa: F401  (the TYPE_CHECKING imports name the lazy exports)

from typing import TYPE_CHECKING

from warp_critic.core.exports import lazy_exports

if TYPE_CHECKING:  # the names for IDEs and type checkers (Newton's pattern); at run time
    # they load lazily, on first use
    from warp_critic.core.errors import DivergenceError, FieldError, SceneError, UserError
    from warp_critic.core.runtime import init
    from warp_critic.evaluation.metatest import MetaTestConfig, meta_test
    from warp_critic.evaluation.protocol import ProtocolConfig, run_protocol
    from warp_critic.methods.baseline_config import BaselineConfig
    from warp_critic.methods.ddpg import train_ddpg
    from warp_critic.methods.meta_critic import MetaCriticConfig, train_meta_critic
    from warp_critic.methods.ours import TrainConfig, meta_train
    from warp_critic.methods.sac import SACConfig, train_sac
    from warp_critic.methods.td3 import TD3Config, train_td3
    from warp_critic.physics.load import load_scene
    from warp_critic.physics.scene import Scene
    from warp_critic.physics.simulator import Simulator
    from warp_critic.physics.variants import Variant
    from warp_critic.running.rundir import RunDir

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
        "warp_critic.methods.meta_critic": ("MetaCriticConfig", "train_meta_critic"),
        "warp_critic.methods.td3": ("TD3Config", "train_td3"),
        "warp_critic.methods.sac": ("SACConfig", "train_sac"),
        "warp_critic.evaluation.metatest": ("MetaTestConfig", "meta_test"),
        "warp_critic.evaluation.protocol": ("ProtocolConfig", "run_protocol"),
    },
)
__all__.insert(0, "__version__")

__version__ = "0.1.0"
