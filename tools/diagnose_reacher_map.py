#!/usr/bin/env python
"""Why does a critic's reacher goal map (Figure 4) stop near the training goals? Prints the numbers.

For a run directory of ``warp-critic meta-train`` on the reacher:

1. **What the critic saw in training**: fresh policies on the training goals, from the home pose,
   before and after meta-test's updates (the states the inner loop evaluates the critic at during
   meta-training): the range of ``|q - g|`` per joint, of ``|qd|``, and of the distance to the goal.
2. **What the goal grid needs**: meta-test on a ``grid x grid`` goal grid over 95% of the joint
   limits; per goal, binned by its distance ``|g - q_0|`` from the start: how many reach MSE < 0.05,
   the median MSE, how far the updates moved the final state (``|q_T' - q_T|``) against how far it
   had to go (``|g - q_T|``), whether they moved it towards the goal (cosine between the two),
   the mean torque as a fraction of its bound after the updates, and the final miss split into how
   far the move fell short along the direction to the goal and how far it went across it, both as
   fractions of ``|g - q_T|`` (MSE < 0.05 over the two joints is a miss below 0.32 rad).

Usage::

    python tools/diagnose_reacher_map.py runs/reacher-ours --grid 9 --inits 3
"""

from __future__ import annotations

import sys

import numpy as np
import torch

from warp_critic.cli.flags import ToolParser, user_message

PROG = "diagnose_reacher_map"


def _run(run_dir: str, goals, inits: int, seed: int):
    """(setup, before, after) rollouts of meta-test with ``goals`` ``(G, dof)``."""
    from warp_critic.evaluation.metatest import MetaTestConfig, setup_meta_test
    from warp_critic.learning.inner import inner_update, policy_fn
    from warp_critic.learning.rollout import rollout

    m = setup_meta_test(MetaTestConfig(run_dir=run_dir, goals=goals, inits=inits, seed=seed))
    before = rollout(m.sim, policy_fn(m.policy, m.params), m.q0, m.qd0, m.horizon)
    params, _ = inner_update(
        m.critic,
        m.policy,
        m.params,
        m.sim,
        m.q0,
        m.qd0,
        m.goal,
        horizon=m.horizon,
        alpha=m.alpha,
        steps=m.steps,
        create_graph=False,
    )
    with torch.no_grad():
        after = rollout(m.sim, policy_fn(m.policy, params), m.q0, m.qd0, m.horizon)
    return m, before, after


def main(argv=None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("run_dir")
    p.add_argument("--grid", type=int, default=9)
    p.add_argument("--inits", type=int, default=3)
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args(argv)
    if args.grid < 2 or args.inits < 1:
        p.error("--grid >= 2 and --inits >= 1")
    from warp_critic.core.errors import UserError

    try:
        import json
        from pathlib import Path

        cfg = json.loads((Path(args.run_dir) / "config.json").read_text())
        train_goals = cfg["goals"]
    except (OSError, ValueError, KeyError) as e:
        p.exit(2, f"{PROG}: error: {args.run_dir}: not a run directory ({e})\n")
    try:
        m, before, after = _run(args.run_dir, train_goals, args.inits, args.seed)
    except UserError as e:
        p.exit(2, f"{PROG}: error: {user_message(e)}\n")
    fmt = lambda x: "[" + ", ".join(f"{v:.2f}" for v in x) + "]"  # noqa: E731
    seen_q = torch.cat([before.q, after.q])  # (2T+2, W, dof)
    seen_qd = torch.cat([before.qd, after.qd])
    rel = (seen_q - m.goal).abs()
    dist = (seen_q - m.goal).norm(dim=-1)
    print(
        "1. training goals: states the critic is evaluated at (policies before/after the updates)"
    )
    print(f"   training goals {fmt(np.ravel(train_goals))}, start {fmt(m.q0[0].tolist())}")
    print(f"   |q - g| per joint: max {fmt(rel.amax((0, 1)).tolist())}")
    print(f"   |q - g| (norm): 95th percentile {dist.quantile(0.95):.2f}, max {dist.max():.2f} rad")
    print(f"   |qd| per joint: max {fmt(seen_qd.abs().amax((0, 1)).tolist())} rad/s")
    train_mse = ((after.q[-1] - m.goal) ** 2).mean(-1)
    print(f"   MSE after the updates: mean {train_mse.mean():.4f}")

    lo, hi = m.sim.q_lower.cpu().numpy() * 0.95, m.sim.q_upper.cpu().numpy() * 0.95
    axes = [np.linspace(lo[j], hi[j], args.grid) for j in range(2)]
    grid = [[float(a), float(b)] for a in axes[0] for b in axes[1]]
    g, before, after = _run(args.run_dir, grid, args.inits, args.seed)
    G, K = len(grid), args.inits
    goal = g.goal
    mse = ((after.q[-1] - goal) ** 2).mean(-1).view(G, K).mean(1)
    need = goal - before.q[-1]  # how far the final state had to move
    moved = after.q[-1] - before.q[-1]
    cos = (need * moved).sum(-1) / (need.norm(dim=-1) * moved.norm(dim=-1) + 1e-9)
    # the final miss g - q_T' split along the direction to the goal and across it, relative to
    # the distance: MSE < 0.05 over two joints is a miss below sqrt(0.1) = 0.32 rad
    dist = need.norm(dim=-1) + 1e-9
    unit = need / dist[:, None]
    along = (moved * unit).sum(-1)
    short = (dist - along) / dist
    across = (moved - along[:, None] * unit).norm(dim=-1) / dist
    torque = (after.tau.abs() / g.norm.max_torque).mean((0, 2))
    d0 = (torch.tensor(grid) - g.q0[0].cpu()).norm(dim=-1)
    per = lambda x: x.view(G, K).mean(1)  # noqa: E731
    need_n, moved_n, cos_g, torque_g, short_g, across_g = (
        per(need.norm(dim=-1)),
        per(moved.norm(dim=-1)),
        per(cos),
        per(torque),
        per(short),
        per(across),
    )
    print(f"\n2. goal grid {args.grid} x {args.grid} over 95% of the limits, {K} inits per goal")
    print(
        "   |g - q0| (rad)  goals  MSE<0.05  median MSE  median |g - q_T|  median |q_T' - q_T|"
        "  median cos(toward goal)  mean torque/bound  median short/|g - q_T|"
        "  median across/|g - q_T|"
    )
    edges = [0.0, 1.0, 1.5, 2.0, 2.5, 3.0, 5.0]
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (d0 >= a) & (d0 < b)
        if not sel.any():
            continue
        print(
            f"   [{a:.1f}, {b:.1f})      {int(sel.sum()):5d}  {float((mse[sel] < 0.05).float().mean()):7.0%}"
            f"  {float(mse[sel].median()):10.3f}  {float(need_n[sel].median()):16.2f}"
            f"  {float(moved_n[sel].median()):19.2f}  {float(cos_g[sel].median()):23.2f}"
            f"  {float(torque_g[sel].mean()):17.2f}  {float(short_g[sel].median()):+22.2f}"
            f"  {float(across_g[sel].median()):23.2f}"
        )
    print(f"   all: MSE<0.05 on {float((mse < 0.05).float().mean()):.0%} of the grid")
    return 0


if __name__ == "__main__":
    sys.exit(main())
