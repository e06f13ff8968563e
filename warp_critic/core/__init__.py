"""Core: user-facing errors, process set-up (Warp start, threads, seeds) and memory checks."""

# ruff: noqa: F401  (the TYPE_CHECKING imports name the lazy exports)

from typing import TYPE_CHECKING

from warp_critic.core.exports import lazy_exports

if TYPE_CHECKING:  # the names for IDEs and type checkers (Newton's pattern); at run time
    # they load lazily, on first use
    from warp_critic.core.errors import DivergenceError, FieldError, SceneError, UserError, warn
    from warp_critic.core.memory import available_memory, check_fits
    from warp_critic.core.runtime import init, init_warp, restore_rng, rng_state, seed_everything

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
