"""Evaluation: meta-test (Algorithm 3), the paper's protocol and tables, and the named presets."""

# ruff: noqa: F401  (the TYPE_CHECKING imports name the lazy exports)

from typing import TYPE_CHECKING

from warp_critic.core.exports import lazy_exports

if TYPE_CHECKING:  # the names for IDEs and type checkers (Newton's pattern); at run time
    # they load lazily, on first use
    from warp_critic.evaluation.metatest import MetaTestConfig, meta_test, setup_meta_test
    from warp_critic.evaluation.paper import GOAL_NOISE, PAPER_TABLES, PaperTable
    from warp_critic.evaluation.presets import PRESETS, preset
    from warp_critic.evaluation.protocol import ProtocolConfig, ProtocolResult, run_protocol

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "warp_critic.evaluation.metatest": (
            "MetaTestConfig",
            "meta_test",
            "setup_meta_test",
        ),
        "warp_critic.evaluation.protocol": ("ProtocolConfig", "ProtocolResult", "run_protocol"),
        "warp_critic.evaluation.paper": ("PAPER_TABLES", "PaperTable", "GOAL_NOISE"),
        "warp_critic.evaluation.presets": ("PRESETS", "preset"),
    },
)
