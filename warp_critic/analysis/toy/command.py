"""``warp-critic analyze toy``: the 1-D analytic example of section 4.1 / Appendix A.

Flags and their checks only; the analysis is :func:`warp_critic.analysis.toy.report.run_toy`, the
derivations, errata of the paper's formulas and what the results mean are in ``docs/toy.md``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from warp_critic.analysis import checks
from warp_critic.analysis.toy.curves import default_thetas
from warp_critic.analysis.toy.problem import ALPHA
from warp_critic.analysis.toy.report import check_settings, run_toy

__all__ = ["add_arguments", "run_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the flags of the ``analyze toy`` command to ``parser``."""
    parser.add_argument(
        "--s0",
        type=float,
        default=-6.0,
        metavar="S0",
        help="initial state s_0 (finite, non-zero, |s0| <= 1e6; default -6)",
    )
    parser.add_argument(
        "--goal",
        type=float,
        default=0.0,
        metavar="G",
        help="goal g; the terminal cost is (s_2 - g)^2 (|g| <= 1e6; default 0)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("runs/analysis-toy"),
        metavar="DIR",
        help="output folder for toy.rrd and the PNG figures (default runs/analysis-toy)",
    )
    parser.add_argument(
        "--iters",
        type=int,
        default=500,
        metavar="N",
        help="maximum iterations of each learning loop (1..1e6; default 500)",
    )
    parser.add_argument(
        "--theta0",
        type=float,
        default=0.1,
        metavar="THETA",
        help="initial policy parameter of the reported runs (|theta0| <= 1e6; default 0.1, "
        "see docs/toy.md)",
    )
    parser.add_argument(
        "--alpha",
        type=float,
        default=ALPHA,
        metavar="LR",
        help="inner policy learning rate of ours and of the Meta-Critic (> 0; default 0.5)",
    )
    parser.add_argument(
        "--grid",
        type=int,
        default=400,
        metavar="N",
        help="number of theta grid points of the curves (>= 3; default 400)",
    )
    parser.add_argument(
        "--plain-lr",
        type=float,
        default=0.05,
        metavar="LR",
        help="fixed policy learning rate of the plain supervised variant in the init sweep "
        "(> 0; default 0.05)",
    )


def run_from_args(args: argparse.Namespace) -> int:
    """Validate the parsed flags, run :func:`run_toy` and return the exit code (0)."""
    with checks.flag_errors():
        check_settings(
            s0=args.s0,
            goal=args.goal,
            theta0=args.theta0,
            alpha=args.alpha,
            plain_lr=args.plain_lr,
            iters=args.iters,
            grid=args.grid,
        )
        checks.not_owned("out", args.out)
        out = checks.out_dir("out", args.out)
    run_toy(
        out,
        float(args.s0),
        float(args.goal),
        iters=int(args.iters),
        theta0=float(args.theta0),
        alpha=float(args.alpha),
        plain_lr=float(args.plain_lr),
        thetas=default_thetas(float(args.s0), float(args.goal), int(args.grid)),
    )
    return 0
