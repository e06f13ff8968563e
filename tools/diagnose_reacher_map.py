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
   fractions of ``|g - q_T|`` (MSE < 0.05 over the two joints is a miss below 0.32 rad). Last,
   the MSE split exactly into the error of the inits' mean final state (a miss every policy init
   shares: the critic's field) and the scatter of the inits' final states around that mean (a miss
   that depends on the fresh policy's random parameters): the share of the goals whose mean final
   state is below 0.05, and the median share of the MSE that is scatter.
3. With ``--shifts``, **is the critic's field the same everywhere?** The same grid of goal offsets
   again, with start and goal moved together so that the goal is home on joint 1, on joint 2, or on
   both (start ``q0 - g_j``, goal ``g - g_j``). A ``relative`` critic sees exactly the same inputs
   ``q - g``; the reacher's dynamics do not depend on joint 1 (its axis is parallel to gravity), but
   its inertia depends on joint 2 (the elbow). A share that changes with a shift is the dynamics or
   the policy telling the arm's places apart, which such a critic cannot see. Then the arm's
   response to 1 N m on each joint from rest at elbow angles 0 to 95% of the limit: the velocity
   change over one control step, ``dt M(q)^-1`` (rad/s), measured in the simulator.

Usage::

    python tools/diagnose_reacher_map.py runs/reacher-ours --grid 9 --inits 3
"""

from __future__ import annotations

import sys

import numpy as np
import torch

from warp_critic.cli.flags import ToolParser, user_message

PROG = "diagnose_reacher_map"


def _run(run_dir: str, goals, inits: int, seed: int, shift_joints: tuple[int, ...] = ()):
    """(setup, before, after) rollouts of meta-test with ``goals`` ``(G, dof)``; on the joints
    ``shift_joints`` start and goal are moved together by ``q0 - g``, so the goal is home there."""
    import dataclasses

    from warp_critic.evaluation.metatest import MetaTestConfig, setup_meta_test
    from warp_critic.learning.inner import policy_fn
    from warp_critic.learning.rollout import rollout

    m = setup_meta_test(MetaTestConfig(run_dir=run_dir, goals=goals, inits=inits, seed=seed))
    if shift_joints:
        shift = torch.zeros_like(m.goal)
        shift[:, list(shift_joints)] = m.goal[:, list(shift_joints)] - m.q0[:, list(shift_joints)]
        m = dataclasses.replace(
            m, q0=(m.q0 - shift).contiguous(), goal=(m.goal - shift).contiguous()
        )
    before = rollout(m.sim, policy_fn(m.policy, m.params), m.q0, m.qd0, m.horizon)
    params, _ = m.update(m.params, create_graph=False)
    with torch.no_grad():
        after = rollout(m.sim, policy_fn(m.policy, params), m.q0, m.qd0, m.horizon)
    return m, before, after


def main(argv=None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("run_dir")
    p.add_argument("--grid", type=int, default=9)
    p.add_argument("--inits", type=int, default=3)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument(
        "--shifts", action="store_true", help="also the grid with start and goal moved together"
    )
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
    # MSE = |g - mean_k q_k|^2 / dof + mean_k |q_k - mean_k q_k|^2 / dof, exactly
    final = after.q[-1].view(G, K, -1)
    centre = final.mean(1)
    mse_mean = ((centre - goal.view(G, K, -1)[:, 0]) ** 2).mean(-1)
    scatter = ((final - centre[:, None]) ** 2).mean((1, 2))
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
        "  median across/|g - q_T|  mean state MSE<0.05  median scatter/MSE"
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
            f"  {float((mse_mean[sel] < 0.05).float().mean()):19.0%}"
            f"  {float((scatter[sel] / mse[sel]).median()):18.2f}"
        )
    print(
        f"   all: MSE<0.05 on {float((mse < 0.05).float().mean()):.0%} of the grid; the inits'"
        f" mean final state on {float((mse_mean < 0.05).float().mean()):.0%}; scatter is"
        f" {float(scatter.sum() / mse.sum()):.0%} of the summed MSE"
    )
    if args.shifts:
        print("\n3. the same goal offsets, start and goal moved together (goal at home on ...)")
        print(
            "   goal at home on  MSE<0.05  "
            + "  ".join(
                f"[{a:.1f}, {b:.1f})"
                for a, b in zip(edges[:-1], edges[1:])
                if ((d0 >= a) & (d0 < b)).any()
            )
        )
        for name, joints in (
            ("no joint", ()),
            ("joint 1", (0,)),
            ("joint 2", (1,)),
            ("both", (0, 1)),
        ):
            err = mse  # no shift: the grid measured above
            if joints:
                s, _, moved_after = _run(args.run_dir, grid, K, args.seed, joints)
                err = ((moved_after.q[-1] - s.goal) ** 2).mean(-1).view(G, K).mean(1)
            bins = "  ".join(
                f"{float((err[sel] < 0.05).float().mean()):10.0%}"
                for a, b in zip(edges[:-1], edges[1:])
                if (sel := (d0 >= a) & (d0 < b)).any()
            )
            print(f"   {name:16s}  {float((err < 0.05).float().mean()):8.0%}  {bins}")
        _print_response(args.run_dir, float(hi[1]))
    return 0


def _print_response(run_dir: str, elbow_max: float) -> None:
    """Velocity change over one control step under 1 N m on each joint, from rest, per elbow angle."""
    from warp_critic.evaluation.metatest import MetaTestConfig, setup_meta_test
    from warp_critic.learning.rollout import rollout

    elbows = np.linspace(0.0, elbow_max, 4)
    poses = [[0.0, float(e)] for e in elbows for _ in range(2)]  # two worlds per pose
    m = setup_meta_test(MetaTestConfig(run_dir=run_dir, goals=poses, inits=1, seed=1))
    tau = torch.zeros_like(m.goal)
    tau[0::2, 0], tau[1::2, 1] = 1.0, 1.0
    tr = rollout(m.sim, lambda q, qd: tau, m.goal.clone(), torch.zeros_like(m.goal), 1)
    dqd = tr.qd[1] - tr.qd[0]
    print("   response to 1 N m from rest (rad/s after one control step): joint 1 / joint 2 torque")
    for i, e in enumerate(elbows):
        one, two = dqd[2 * i].tolist(), dqd[2 * i + 1].tolist()
        print(
            f"   elbow {e:5.2f} rad: [{one[0]:+.3f}, {one[1]:+.3f}] / [{two[0]:+.3f}, {two[1]:+.3f}]"
        )


if __name__ == "__main__":
    sys.exit(main())
