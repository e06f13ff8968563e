"""Evaluation: meta-test (Algorithm 3), the paper's protocol and tables, and the named presets."""

from warp_critic.core.exports import lazy_exports

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
