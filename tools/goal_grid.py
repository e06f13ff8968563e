#!/usr/bin/env python
"""Write the maps' goal grid of a 2-joint scene as a goals file for ``meta-train --goals``.

The goals are exactly those of ``reproduce``'s ``maps`` stage (Figure 4): ``--grid`` evenly spaced
angles per joint over the middle ``--fraction`` of the joint limits, ``q1`` major. Its use is a
diagnostic, not a recipe: a critic meta-trained on the grid's own goals measures what the critic,
the policy and the 3-update protocol can reach on that grid at all (a ceiling for one trained on the
four training goals), never a generalisation result.

Usage::

    python tools/goal_grid.py scenes/reacher.usda --grid 9 --out goals-9x9.txt
    warp-critic meta-train scenes/reacher.usda --goals goals-9x9.txt ...
"""

from __future__ import annotations

import sys
from pathlib import Path

from warp_critic.cli.flags import ToolParser, user_message

PROG = "goal_grid"


def main(argv=None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("scene", help="a 2-joint scene file (scenes/reacher.usda) or robot file")
    p.add_argument("--grid", type=int, default=9, help="goals per joint (default: 9)")
    p.add_argument(
        "--fraction",
        type=float,
        default=None,
        help="middle fraction of the limits (default: the maps stage's)",
    )
    p.add_argument("--out", required=True, help="the goals file to write (.txt, one goal a line)")
    args = p.parse_args(argv)
    if args.grid < 2:
        p.error("--grid must be >= 2")
    if args.fraction is not None and not 0 < args.fraction <= 1:
        p.error(f"--fraction must be in (0, 1] (got {args.fraction})")
    out = Path(args.out)
    if out.suffix != ".txt":
        p.error(f"--out {out}: must end in .txt (meta-train --goals reads .txt and .json)")
    if not out.parent.is_dir():
        p.error(f"--out {out}: no folder {out.parent}")
    from warp_critic.core import runtime

    runtime.init()  # before the imports below, which would start Warp with its banner
    import torch

    from warp_critic.core.errors import UserError
    from warp_critic.reproduce.experiments.goals import goal_grid
    from warp_critic.reproduce.experiments.settings import default_settings
    from warp_critic.running.task import TaskConfig, load_task_scene

    fraction = args.fraction
    if fraction is None:
        fraction = float(default_settings(False, 5)["maps"]["limit_fraction"])
    try:
        _, scene = load_task_scene(TaskConfig(scene=args.scene), announce=False)
        if scene.dof != 2:
            raise UserError(
                f"{args.scene}: the goal grid is for 2-joint scenes (this has {scene.dof})"
            )
        lo = torch.as_tensor(scene.q_lower, dtype=torch.float32)
        hi = torch.as_tensor(scene.q_upper, dtype=torch.float32)
        grid, _ = goal_grid(lo, hi, args.grid, fraction)
    except UserError as e:
        p.exit(2, f"{PROG}: error: {user_message(e)}\n")
    out.write_text("".join(f"{a!r},{b!r}\n" for a, b in grid.tolist()))
    print(f"{out}: {len(grid)} goals, {args.grid} per joint over {fraction:g} of the limits")
    return 0


if __name__ == "__main__":
    sys.exit(main())
