"""``warp-critic identify``: a model identifier for a run whose critic was told the model.

The work is :func:`warp_critic.methods.identify.train_identifier`; registered in
``warp_critic/cli/main.py``'s ``build_parser`` like ``reproduce``.
"""

from __future__ import annotations

import argparse

from warp_critic.core.errors import FieldError

__all__ = ["HELP", "DESCRIPTION", "add_arguments", "run_from_args"]

HELP = "train a model identifier for a run whose critic reads the model (pose-dynamics)"
DESCRIPTION = (
    "Train a model identifier for a run whose critic was told the model (meta-train --critic-input "
    "pose-dynamics or relative-dynamics, with --train-variants), and write the run with it into "
    "--out: its critic estimates each world's model from the rollouts it evaluates "
    "(warp_critic.learning.identify), so meta-test tests it without privileged data."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the arguments of ``warp-critic identify`` to ``p``."""
    p.add_argument("run_dir", help="a run whose critic reads the dynamics (pose-dynamics)")
    p.add_argument("--out", required=True, help="the new run folder (new or empty)")
    p.add_argument("--iterations", type=int, default=1000, help="regression steps (default 1000)")
    p.add_argument("--goals", type=int, default=8, help="goals per iteration (default 8)")
    p.add_argument("--inits", type=int, default=16, help="fresh policies per goal (default 16)")
    p.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate (default 1e-3)")
    p.add_argument("--hidden", type=int, default=128, help="per-step MLP units (default 128)")
    p.add_argument(
        "--version",
        type=int,
        default=2,
        choices=(1, 2),
        help="architecture: 2, with the response's moments and a nonlinear head (default); 1, "
        "the per-step features' mean and a linear head (warp_critic.learning.identify)",
    )
    p.add_argument(
        "--variants",
        default=None,
        help="draw the models from these ranges (meta-train --train-variants text) instead of "
        "the run's own train_variants, e.g. to give light masses a larger share",
    )
    p.add_argument("--seed", type=int, default=0, help="draws, goals and policies (default 0)")
    p.add_argument("--device", default="cpu", help="cpu, cuda or auto (default cpu)")


def run_from_args(args: argparse.Namespace) -> int:
    """Check the arguments, train, print the summary; a user mistake raises ``UserError``."""
    for flag in ("iterations", "goals", "inits", "hidden"):
        if getattr(args, flag) < 1:
            raise FieldError(flag, "must be >= 1")
    if not args.lr > 0:
        raise FieldError("lr", "must be > 0")
    if args.seed < 0:
        raise FieldError("seed", "must be >= 0")
    from warp_critic.methods.identify import train_identifier

    every = max(1, args.iterations // 20)

    def progress(it: int, loss: float) -> None:
        if it % every == 0 or it == args.iterations - 1:
            print(f"iteration {it}: loss {loss:.5f}", flush=True)

    try:
        r = train_identifier(
            args.run_dir,
            args.out,
            iterations=args.iterations,
            goals=args.goals,
            inits=args.inits,
            lr=args.lr,
            hidden=args.hidden,
            version=args.version,
            variants=args.variants,
            seed=args.seed,
            device=args.device,
            progress=progress,
        )
    except FieldError as e:  # a field of the run's or the meta-test's config: identify's flag
        own = {"train_variants": "variants", "num_goals": "goals"}.get(e.field)
        if own is None:
            raise
        raise FieldError(own, e.problem) from None
    except KeyboardInterrupt:  # the interruption line says what is on disk
        from warp_critic.cli import signals
        from warp_critic.methods.identify import identified

        signals.note(
            f"the identified run in {args.out} was written whole"
            if identified(args.out) is not None
            else f"{args.out} holds no identified run (it is written whole at the end): run it again"
        )
        raise
    print(
        f"final loss {r['loss']:.5f}; on a fresh draw the estimate misses the {r['varied']} "
        f"varied entries by {r['held_out']:.4f} on average (descriptor units)"
    )
    print(f"run: {args.out}")
    print(f"meta-test: warp-critic meta-test {args.out}")
    return 0
