"""Physics: USD scenes, the Newton simulator of many worlds, and the Warp <-> torch bridge."""

# ruff: noqa: F401  (the TYPE_CHECKING imports name the lazy exports)

from typing import TYPE_CHECKING

from warp_critic.core.exports import lazy_exports

if TYPE_CHECKING:  # the names for IDEs and type checkers (Newton's pattern); at run time
    # they load lazily, on first use
    from warp_critic.physics.bridge import NewtonBridge
    from warp_critic.physics.load import load_any, load_scene
    from warp_critic.physics.scene import Scene, scenes_dir
    from warp_critic.physics.simulator import STANDARD_GRAVITY, Simulator, resolve_device
    from warp_critic.physics.variants import Variant

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "warp_critic.physics.scene": ("Scene", "scenes_dir"),
        "warp_critic.physics.load": ("load_scene", "load_any"),
        "warp_critic.physics.variants": ("Variant",),
        "warp_critic.physics.simulator": ("Simulator", "STANDARD_GRAVITY", "resolve_device"),
        "warp_critic.physics.bridge": ("NewtonBridge",),
    },
)
