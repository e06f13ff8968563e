#!/usr/bin/env python
"""What an identified run's model identifier reads from each rollout of a meta-test.

For each model given (``--variant`` texts, as ``meta-test --variant``), fresh policies are updated by
the run's identified critic as meta-test does, and the identifier's estimate from each update's
rollout is printed beside the model's true descriptor (``warp_critic.physics.descriptor``), for the
entries that differ between the models: where an estimate stays near the draws' mean whatever the
model, the rollout showed too little of it.

Usage::

    python tools/probe_identifier.py runs/told-identified-s0 \\
        --variant "arm2.mass=0.25:keep" --variant "arm2.mass=6:keep"
"""

from __future__ import annotations

import sys

from warp_critic.cli.flags import ToolParser, user_message

PROG = "probe_identifier"


def main(argv=None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument(
        "run_dir", help="an identified run (warp-critic identify, or a stage's -identified)"
    )
    p.add_argument(
        "--variant",
        action="append",
        required=True,
        help="a model, as meta-test --variant (repeat for each; at least one)",
    )
    p.add_argument("--goals", type=int, default=4, help="goals (default 4)")
    p.add_argument(
        "--goal-std",
        type=float,
        default=0.0,
        help="std (rad) around the training goals (default 0: the training goals)",
    )
    p.add_argument("--inits", type=int, default=5, help="fresh policies per goal (default 5)")
    p.add_argument("--seed", type=int, default=1, help="goals and policies (default 1)")
    p.add_argument("--device", default="cpu")
    args = p.parse_args(argv)
    for flag in ("goals", "inits"):
        if getattr(args, flag) < 1:
            p.error(f"--{flag} must be >= 1")
    if not args.goal_std >= 0:
        p.error("--goal-std must be >= 0")
    if args.seed < 0:
        p.error("--seed must be >= 0")
    from warp_critic.core import runtime

    runtime.init()
    import numpy as np

    from warp_critic.core.errors import UserError
    from warp_critic.methods.identify import probe_identifier

    try:
        r = probe_identifier(
            args.run_dir,
            args.variant,
            goals=args.goals,
            goal_std=args.goal_std,
            inits=args.inits,
            seed=args.seed,
            device=args.device,
        )
    except UserError as e:
        p.exit(2, f"{PROG}: error: {user_message(e)}\n")
    truth = np.array([row["truth"] for row in r["rows"]])
    shown = np.flatnonzero((truth != truth[0]).any(0) if len(truth) > 1 else truth[0] != 0)
    updates = len(r["rows"][0]["mean"])
    head = "".join(f"{f'update {u + 1}':>18}" for u in range(updates))
    for row in r["rows"]:
        torque = " ".join(f"{t:.2f}" for t in row["torque"])
        print(f"{row['variant']}  (mean |tau| per update, N m: {torque})")
        print(f"  {'entry':<24}{'truth':>8}{head}")
        for k in shown:
            cells = "".join(
                f"{row['mean'][u][k]:>10.3f} ±{row['std'][u][k]:<6.3f}" for u in range(updates)
            )
            print(f"  {r['names'][k]:<24}{row['truth'][k]:>8.3f}{cells}".rstrip())
    if not len(shown):
        print("the models given do not differ in any descriptor entry")
    return 0


if __name__ == "__main__":
    sys.exit(main())
