"""Core: user-facing errors, process set-up (Warp start, threads, seeds) and memory checks."""

from warp_critic.core.exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "warp_critic.core.errors": (
            "UserError",
            "FieldError",
            "SceneError",
            "DivergenceError",
            "warn",
        ),
        "warp_critic.core.runtime": (
            "init",
            "init_warp",
            "seed_everything",
            "rng_state",
            "restore_rng",
        ),
        "warp_critic.core.memory": ("available_memory", "check_fits"),
    },
)
