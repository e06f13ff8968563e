"""``warp-critic baseline {ddpg,meta-critic} SCENE [flags]``: train a baseline critic.

Every field of :class:`~warp_critic.baselines.common.BaselineConfig` is a typed flag; the run
directory (default ``runs/<scene>-<method>``) has the same layout as meta-train's, so
``warp-critic meta-test RUN_DIR`` evaluates the learned Q (``L = -Q``) like our critic.
"""

from __future__ import annotations

import argparse

from .common import METHODS, BaselineConfig


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Positional ``method`` and ``scene``, then one flag per config field."""
    from ..cli import add_dataclass_arguments  # local: warp_critic.cli imports this module

    parser.add_argument("method", choices=METHODS, help="ddpg (Lillicrap et al. 2015) or meta-critic (Zhou et al. 2020)")
    parser.add_argument("scene", help="USD scene, e.g. scenes/reacher.usda")
    add_dataclass_arguments(parser, BaselineConfig, skip=("scene", "method"))


def run(args: argparse.Namespace) -> int:
    """Train the chosen baseline; prints progress, the final task loss and the meta-test alpha."""
    from ..cli import dataclass_from_args
    from ..config import parse_goals
    from .ddpg import train_ddpg
    from .meta_critic import train_meta_critic

    cfg = dataclass_from_args(BaselineConfig, args, method=args.method, scene=args.scene)
    cfg.goals = parse_goals(getattr(args, "goals", None))
    train = train_ddpg if cfg.method == "ddpg" else train_meta_critic
    result = train(cfg)
    last = result.metrics[-1] if result.metrics else {}
    print(f"run directory: {result.run_dir}")
    if last:
        print(f"final task loss (mean ||q_T - g||^2 of the {cfg.method} actor, no noise): {last['task_loss']:.5f}")
        if "fresh_policy_loss" in last:
            print(f"fresh policies trained with -Q on the training goals: {last['fresh_policy_loss']:.5f} "
                  f"(meta-test alpha {last['alpha']:.3g})")
    print(f"recording: rerun {result.run_dir / 'recording.rrd'}")
    print(f"meta-test: warp-critic meta-test {result.run_dir}")
    return 0
