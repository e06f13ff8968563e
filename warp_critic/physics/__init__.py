"""Physics: USD scenes, the Newton simulator of many worlds, and the Warp <-> torch bridge."""

from warp_critic.core.exports import lazy_exports

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
