"""Where does a critic's meta-test error come from? Prints the numbers behind RESULTS.md's diagnosis.

For a run directory written by ``warp-critic meta-train``:

* trains fresh policies with the saved critic (model-free, as ``warp-critic meta-test``) and, after
  every policy step, prints the mean final squared error, its split over the joints, the final
  joint speeds and how often each joint's torque sits at its bound;
* prints the spread over initialisations per goal (a per-goal bias shows as a small spread);
* with ``--reachability``, optimises open-loop torques ``(T, dof)`` for the same goals through the
  *differentiable* model (Adam on ``max_torque * tanh(u)``) -- the error a perfect controller with
  the same torque bounds and horizon reaches, i.e. whether the goals are physically reachable.

Usage::

    python tools/diagnose_metatest.py runs/bench-kuka --goal-std 0 --around 0,1 --steps 4
    python tools/diagnose_metatest.py runs/bench-kuka --goal-std 0.1 --around 0,1 --reachability
    python tools/diagnose_metatest.py runs/bench-kuka --goal-std 0.1 --link-length 2.0   # a Table 3 column
"""

from __future__ import annotations

import sys

import numpy as np
import torch

from warp_critic.cli.flags import ToolParser, comma_list, parse_goals, user_message  # noqa: E402

PROG = "diagnose_metatest"


def _training_goals(run_dir: str) -> int | None:
    """How many training goals the run has (from its ``config.json``); ``None`` if unknown."""
    import json
    from pathlib import Path

    from warp_critic.core.errors import UserError

    if not Path(run_dir).is_dir():
        raise UserError(f"{run_dir}: run directory not found")
    try:
        return len(json.loads((Path(run_dir) / "config.json").read_text())["goals"])
    except (OSError, ValueError, KeyError, TypeError):
        return None  # meta-test's set-up reports what is wrong with the run


def main(argv=None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("run_dir")
    p.add_argument("--goal-std", type=float, default=0.1, help="0 = the training goals themselves")
    p.add_argument("--goal-noise", default="per-joint", choices=["per-joint", "distance"])
    p.add_argument(
        "--around",
        type=comma_list(int),
        default=[0, 1],
        help="training goals to use / sample around, e.g. 0,1 ('' = all)",
    )
    p.add_argument("--num-goals", type=int, default=10)
    p.add_argument("--inits", type=int, default=5)
    p.add_argument(
        "--steps",
        type=int,
        default=None,
        help="policy steps (default: as meta-test, the run's inner steps x policy lifetime)",
    )
    p.add_argument("--seed", type=int, default=1)
    p.add_argument(
        "--goals",
        default=None,
        help="explicit goals, inline 'a,b;c,d' or a file (instead of sampling)",
    )
    p.add_argument(
        "--ee-mass",
        type=float,
        default=0.0,
        help="mass added at the end-effector tip (kg), as meta-test",
    )
    p.add_argument(
        "--link-length",
        type=float,
        default=None,
        help="set the end-effector link length (m), as meta-test",
    )
    p.add_argument(
        "--reachability",
        action="store_true",
        help="also optimise open-loop torques through the model",
    )
    p.add_argument("--reach-iterations", type=int, default=150)
    args = p.parse_args(argv)

    from warp_critic.core import runtime
    from warp_critic.core.errors import UserError
    from warp_critic.evaluation.metatest import MetaTestConfig, setup_meta_test
    from warp_critic.learning.inner import inner_update, policy_fn
    from warp_critic.learning.networks import MLPPolicy
    from warp_critic.learning.rollout import rollout
    from warp_critic.physics.scene import Variant

    around = args.around or None
    try:
        runtime.init()
        n_train = _training_goals(args.run_dir)
        # goal std 0: one goal per training goal named in --around (sampling with std 0 returns them)
        num_goals = (
            (len(around) if around else n_train or args.num_goals)
            if args.goal_std == 0
            else args.num_goals
        )
        m = setup_meta_test(
            MetaTestConfig(
                run_dir=args.run_dir,
                goals=parse_goals(args.goals),
                num_goals=num_goals,
                goal_std=args.goal_std,
                goal_noise=args.goal_noise,
                around=around,
                inits=args.inits,
                policy_steps=args.steps,
                seed=args.seed,
                device="cpu",
                ee_mass=args.ee_mass,
                link_length=args.link_length,
            )
        )
    except UserError as e:
        print(f"{PROG}: error: {user_message(e)}", file=sys.stderr)
        return 2
    scene, goals, goal, sim, norm, critic = m.scene, m.goals, m.goal, m.sim, m.norm, m.critic
    params, q0, qd0, steps, alpha, horizon = m.params, m.q0, m.qd0, m.steps, m.alpha, m.horizon
    G, K = goals.shape[0], m.inits

    def fmt(t: torch.Tensor) -> str:
        return np.array2string(t.numpy(), precision=3, floatmode="fixed", max_line_width=200)

    print(
        f"{args.run_dir}: {G} goals x {K} inits, goal std {args.goal_std} ({args.goal_noise}), "
        f"alpha {alpha}, {steps} policy steps, end-effector +{args.ee_mass} kg, link length "
        f"{'as trained' if args.link_length is None else f'{args.link_length} m'}"
    )
    traj = rollout(sim, policy_fn(MLPPolicy(norm), params), q0, qd0, horizon)
    untrained = ((traj.q[-1] - goal) ** 2).sum(-1).mean()
    policy_tau = traj.tau.detach()  # (T, G*K, dof), goal-major; the last policies' below
    print(
        f"step 0 (untrained): mean {untrained:.4f} (MSE over the joints {untrained / scene.dof:.5f})"
    )
    for step in range(1, steps + 1):
        params, _ = inner_update(
            critic,
            MLPPolicy(norm),
            params,
            sim,
            q0,
            qd0,
            goal,
            horizon=horizon,
            alpha=alpha,
            steps=1,
            create_graph=False,
        )
        traj = rollout(sim, policy_fn(MLPPolicy(norm), params), q0, qd0, horizon)
        sq = (traj.q[-1] - goal) ** 2
        policy_tau = traj.tau.detach()  # (T, G*K, dof), goal-major
        sat = (traj.tau.abs() / norm.max_torque > 0.9).float().mean((0, 1))
        print(
            f"step {step}: mean {sq.sum(-1).mean():.4f}  per joint {fmt(sq.mean(0))}\n"
            f"         final |qd| {fmt(traj.qd[-1].abs().mean(0))} rad/s  torque >90% of bound {fmt(sat)}"
        )
    per = sq.sum(-1).view(G, K)
    print("per goal: mean, spread over inits (max - min)")
    for i in range(G):
        print(
            f"  goal {i:2d} {fmt(goals[i])}  {per[i].mean():.4f}  {per[i].max() - per[i].min():.4f}"
        )

    if args.reachability:
        from warp_critic.reproduce.experiments.reach import open_loop_floor

        variant = Variant(ee_mass=args.ee_mass, link_length=args.link_length)
        home = torch.as_tensor(scene.home, dtype=torch.float32).expand(G, -1).clone()

        def optimise(u0: torch.Tensor | None) -> torch.Tensor:
            """Per goal the best final error of open-loop torques optimised from ``u0`` (``None``:
            zero torques)."""
            best = open_loop_floor(
                args.run_dir, [variant], goals, iterations=args.reach_iterations, u0=u0
            )
            return torch.as_tensor(best[0])

        from_zero = optimise(None)
        # a second start: the torques of each goal's best critic-trained policy, replayed open
        # loop (the same trajectory from the home pose at rest), so that the optimum found is never
        # above what a policy already reached; from zero torques a local optimiser can stall above
        # it (the Panda: RESULTS.md)
        at_home = bool(
            torch.allclose(q0, home.repeat_interleave(K, 0)) and not bool(qd0.abs().any())
        )
        tau = policy_tau.view(horizon, G, K, scene.dof)
        pick = per.argmin(1)  # (G,) the best init of each goal
        tau_best = tau[:, torch.arange(G), pick]  # (T, G, dof)
        lim = 1.0 - 1e-6
        from_policy = (
            optimise(torch.atanh((tau_best / norm.max_torque).clamp(-lim, lim)))
            if at_home
            else None
        )
        best = from_zero if from_policy is None else torch.minimum(from_zero, from_policy)
        print(
            f"open-loop floor: mean {best.mean():.4g} (MSE over the joints {best.mean() / scene.dof:.3g}); "
            f"{args.reach_iterations} Adam steps from zero torques"
            + (
                ""
                if from_policy is None
                else " and from the best policy's torques, the better per goal"
            )
        )
        print(f"  from zero torques: best final sq. error per goal {fmt(from_zero)}")
        if from_policy is None:
            print(
                "  (not started from the policies' torques: their starts are not the home pose at rest)"
            )
        else:
            print(f"  from the policy's torques: best final sq. error per goal {fmt(from_policy)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
