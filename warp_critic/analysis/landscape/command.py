"""``warp-critic analyze landscape``: the 2-D illustration of section 4.2 (Figure 1 and the exploration
figure) on the Newton point mass, ``scenes/point_mass.usda`` of the installed package.

Flags only; the analysis is :func:`warp_critic.analysis.landscape.run.run_landscape`, what it computes
and what the results mean are in ``docs/landscape.md``.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from warp_critic.analysis import checks
from warp_critic.analysis.landscape.run import (
    GOAL_INPUTS,
    SUP_REWARDS,
    LandscapeConfig,
    run_landscape,
)
from warp_critic.core.errors import FieldError

__all__ = ["add_arguments", "config_from_args", "run_from_args"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the flags of ``warp-critic analyze landscape`` to ``parser`` (in ``--help`` order)."""
    d = LandscapeConfig()
    _add_run_flags(parser.add_argument, d)
    _add_rollout_flags(parser.add_argument, d)
    _add_goal_flags(parser.add_argument, d)
    _add_q_sup_flags(parser.add_argument, d)
    _add_variation_flags(parser.add_argument, d)


def _add_run_flags(A: Callable[..., object], d: LandscapeConfig) -> None:
    """Flags: where the results go, how large the run is, on what device."""
    A(
        "--out",
        type=Path,
        default=d.out,
        metavar="DIR",
        help=f"output folder for landscape.rrd, landscape.png, exploration.png (default {d.out})",
    )
    A(
        "--iterations",
        type=int,
        default=d.iterations,
        metavar="N",
        help=f"meta-training iterations of ours, and training iterations of Q_sup (>= 1; default {d.iterations})",
    )
    A(
        "--grid",
        type=int,
        default=d.grid,
        metavar="N",
        help=f"landscape grid points per axis, N^2 parallel worlds (>= 3, within memory; default {d.grid})",
    )
    A(
        "--range",
        type=float,
        default=d.range,
        metavar="R",
        help=f"policy parameters (constant forces) span [-R, R]^2 N (> 0; default {d.range})",
    )
    A("--seed", type=int, default=d.seed, metavar="S", help=f"random seed (default {d.seed})")
    A(
        "--device",
        type=str,
        default=d.device,
        metavar="DEV",
        help=f"cpu, cuda or auto (default {d.device})",
    )


def _add_rollout_flags(A: Callable[..., object], d: LandscapeConfig) -> None:
    """Flags: the physics of a rollout and the learning rates of ours."""
    A(
        "--horizon",
        type=int,
        default=d.horizon,
        metavar="T",
        help=f"control steps per rollout (>= 1; default {d.horizon})",
    )
    A(
        "--dt",
        type=float,
        default=d.dt,
        metavar="S",
        help=f"physics time step in s (> 0; default {d.dt})",
    )
    A(
        "--substeps",
        type=int,
        default=d.substeps,
        metavar="N",
        help=f"physics steps per control step (>= 1; default {d.substeps})",
    )
    A(
        "--alpha",
        type=float,
        default=d.alpha,
        metavar="LR",
        help=f"inner policy learning rate of ours (> 0; default {d.alpha})",
    )
    A(
        "--lr",
        type=float,
        default=d.lr,
        metavar="LR",
        help=f"Adam learning rate of both critics (> 0; default {d.lr})",
    )
    A(
        "--inits-per-state",
        type=int,
        default=d.inits_per_state,
        metavar="K",
        help=f"random policy initialisations per initial state (worlds = 2K; >= 1; default {d.inits_per_state})",
    )


def _add_goal_flags(A: Callable[..., object], d: LandscapeConfig) -> None:
    """Flags: the goals and initial states of training and of the test."""
    A("--goal", type=str, default="1,1", metavar="X,Y", help="training goal in m (default 1,1)")
    A(
        "--test-goals",
        type=str,
        default="-1.5,0.5;0.5,-1.5",
        metavar="X,Y;X,Y",
        help="unseen goals in m, ';'-separated (default -1.5,0.5;0.5,-1.5)",
    )
    A(
        "--init-states",
        type=str,
        default="0,0;-0.5,0.5",
        metavar="X,Y;X,Y",
        help="initial positions (at rest) used in training; the first one is also the landscapes' (default 0,0;-0.5,0.5)",
    )
    A(
        "--sup-alpha",
        type=float,
        default=d.sup_alpha,
        metavar="LR",
        help=f"policy learning rate of Q_sup's policy update (> 0; default {d.sup_alpha})",
    )


def _add_q_sup_flags(A: Callable[..., object], d: LandscapeConfig) -> None:
    """Flags: Q_sup, the supervised critic, and how ours sees the goal."""
    A(
        "--sup-fit-steps",
        type=int,
        default=d.sup_fit_steps,
        metavar="N",
        help=f"TD minibatch steps per Q_sup iteration (>= 1; default {d.sup_fit_steps})",
    )
    A(
        "--sup-reward",
        type=str,
        default=d.sup_reward,
        choices=SUP_REWARDS,
        help="Q_sup cost: terminal ||q_T-g||^2 (the task cost) or running ||q_{t+1}-g||^2 (default terminal)",
    )
    A(
        "--ours-goal-input",
        type=str,
        default=d.ours_goal_input,
        choices=GOAL_INPUTS,
        help="how L_critic sees the goal: absolute M(s, a, g) (the paper's) or relative M(s - g, a), "
        "like Q_sup (default absolute)",
    )


def _add_variation_flags(A: Callable[..., object], d: LandscapeConfig) -> None:
    """Flags: training-time variation of goals and starts, and the descent check."""
    A(
        "--train-goals",
        type=str,
        default="",
        metavar="X,Y;X,Y",
        help="extra training goals in m, ';'-separated: every iteration each training world draws its goal from "
        "--goal and these (default none: the paper's one goal)",
    )
    A(
        "--goal-std",
        type=float,
        default=d.goal_std,
        metavar="M",
        help=f"every iteration each training world's goal gets N(0, M^2) noise per axis, in m (>= 0; default "
        f"{d.goal_std:g}: the paper's fixed goal)",
    )
    A(
        "--start-std",
        type=float,
        default=d.start_std,
        metavar="M",
        help=f"every iteration each training world's initial position gets N(0, M^2) noise per axis, in m (>= 0; "
        f"default {d.start_std:g}: the paper's fixed --init-states); the landscapes still start at the first "
        f"--init-states",
    )
    A(
        "--tolerance",
        type=float,
        default=d.tolerance,
        metavar="N",
        help=f"success radius around theta* for the descent check, in N (> 0; default {d.tolerance})",
    )


def _pair(field: str, text: str) -> tuple[float, float]:
    try:
        vals = tuple(float(p) for p in str(text).split(",") if p.strip())
    except ValueError:
        vals = ()
    if len(vals) != 2:
        raise FieldError(field, f"expects X,Y with finite numbers, got {text!r}")
    for v in vals:
        checks.number(field, v)
    return vals


def _pairs(field: str, text: str) -> tuple[tuple[float, float], ...]:
    try:
        return tuple(_pair(field, p) for p in str(text).split(";") if p.strip())
    except FieldError:
        raise FieldError(field, f"expects X,Y;X,Y;... with finite numbers, got {text!r}") from None


def config_from_args(args: argparse.Namespace) -> LandscapeConfig:
    """The validated :class:`LandscapeConfig` of the parsed flags (one-line errors naming the flag)."""
    from warp_critic.physics.simulator import resolve_device

    with checks.flag_errors():
        cfg = LandscapeConfig(
            out=Path(args.out),
            iterations=args.iterations,
            grid=args.grid,
            range=args.range,
            seed=args.seed,
            device=resolve_device(args.device),
            horizon=args.horizon,
            dt=args.dt,
            substeps=args.substeps,
            alpha=args.alpha,
            lr=args.lr,
            inits_per_state=args.inits_per_state,
            goal=_pair("goal", args.goal),
            test_goals=_pairs("test_goals", args.test_goals),
            init_states=_pairs("init_states", args.init_states),
            sup_alpha=args.sup_alpha,
            sup_fit_steps=args.sup_fit_steps,
            sup_reward=args.sup_reward,
            tolerance=args.tolerance,
            ours_goal_input=args.ours_goal_input,
            train_goals=_pairs("train_goals", args.train_goals),
            goal_std=args.goal_std,
            start_std=args.start_std,
        )
        checks.not_owned("out", args.out)
        return cfg.validate()


def run_from_args(args: argparse.Namespace) -> int:
    """Validate the parsed flags, run :func:`run_landscape` and return the exit code (0)."""
    run_landscape(config_from_args(args))
    return 0
