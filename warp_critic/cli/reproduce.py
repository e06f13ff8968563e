"""``warp-critic reproduce``: flags and their checks; the work is :func:`warp_critic.reproduce.pipeline.reproduce`.

Register in ``warp_critic/cli/main.py``'s ``build_parser``::

    from warp_critic.cli import reproduce as reproduce_cli
    rp = sub.add_parser("reproduce", help="...", description="...")
    reproduce_cli.add_arguments(rp)
    rp.set_defaults(func=reproduce_cli.run_from_args)
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from warp_critic.reproduce.experiments.settings import EXTRA_BASELINES, METHODS, STAGES

__all__ = ["add_arguments", "run_from_args", "config_from_args"]

HELP = "run the paper's experiments end to end and write REPORT.md, figures and report.rrd"
DESCRIPTION = (
    "Run the paper's experiments (toy, landscape, meta-training, reacher maps, KUKA tables) and write "
    "REPORT.md, results.json, PNG figures and report.rrd into --out. Each stage works in its own "
    "sub-directory keyed by a hash of its settings: complete stages are skipped, interrupted ones resume."
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the flags of ``warp-critic reproduce`` to ``parser``."""
    A = parser.add_argument
    A(
        "--out",
        type=Path,
        default=Path("runs/paper"),
        metavar="DIR",
        help="output folder (new, empty, or an earlier reproduce output; default runs/paper)",
    )
    A(
        "--seeds",
        type=_int,
        default=None,
        metavar="N",
        help="meta-train seeds 0..N-1 for every method (1 to 100, one process; default 5, with "
        "--quick 2)",
    )
    A(
        "--only",
        type=str,
        default=None,
        metavar="STAGE,...",
        help=f"run only these stages (comma-separated: {', '.join(STAGES)}, or one meta-training such as "
        "metatrain-kuka-ours, or beyond-maps / beyond-tables, or each method's own meta-test "
        "budget: budget (the choices), budget-tables-heldout, budget-maps-heldout); maps and "
        "tables also run the meta-training they read (skipped when complete)",
    )
    A(
        "--quick",
        action="store_true",
        help="tiny settings for every stage (a plumbing check in a few minutes, not the paper)",
    )
    A(
        "--beyond",
        action="store_true",
        help="also run the recipes beyond the paper (stage group beyond: dynamics-randomised "
        "meta-training, evaluated on the paper's maps and tables next to the nominal critic; "
        "reported apart from the reproduction); --only beyond runs just them. Also each "
        "method's own meta-test budget (chosen on its training goals, then the held-out tables "
        "and maps at it: hours at 300 steps, so not in a plain run)",
    )
    A(
        "--baselines",
        type=str,
        default=None,
        metavar="NAME,...",
        help="the baselines trained and reported (comma-separated; default "
        f"{','.join(_paper_baselines())}, the paper's two, always included): each added one, e.g. "
        f"{','.join((*_paper_baselines(), *EXTRA_BASELINES))}, gets its own stages "
        "(metatrain-<robot>-NAME, NAME-maps, NAME-tables) and rows in the report's curves, maps and "
        "tables; the paper's stages are unchanged",
    )
    A("--device", type=str, default="auto", metavar="DEV", help="cpu, cuda or auto (default auto)")
    A(
        "--jobs",
        type=_int,
        default=None,
        metavar="N",
        help="run independent stages in N local processes, each as soon as the stages it reads are "
        "complete, with a progress line per running stage every 10 minutes (default: one after "
        "the other, in this process, with progress bars)",
    )
    A(
        "--ray",
        nargs="?",
        const="local",
        default=None,
        metavar="ADDRESS",
        help="run each stage as a Ray task: no ADDRESS starts a local cluster, 'auto' joins the running one, "
        "HOST:PORT the head at that address (pip install -e '.[ray]'); results come back to --out",
    )
    A(
        "--hours",
        type=_float,
        default=None,
        metavar="H",
        help="a time limit for this call, for runs in sittings (a batch job's wall time, a lent "
        "machine): start a meta-training only if it is expected to end within H hours (by its "
        "time in the published run of docs/paper, scaled by this folder's pace, or, part way, by "
        "its recent speed; one without an estimate only in the first half), and at H hours stop "
        "what still runs as Ctrl-C does; a meta-test keeps its finished batches. Exits 75 when stopped: the same command goes on from there "
        "(not part of the report's command)",
    )
    A(
        "--status",
        action="store_true",
        help="print where --out stands for this command (each stage complete, part way with its "
        "iteration and time left, or not started, with the time it took in the published run of "
        "docs/paper where that ran it) and exit: runs nothing, writes nothing, works beside a "
        "running call",
    )
    A(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="STAGE.KEY=VALUE",
        help="override one stage setting (repeatable), e.g. toy.iters=50 or metatrain.kuka.ours.iterations=100",
    )


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid int value: {text!r}") from None


def _float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid number: {text!r}") from None


def _paper_baselines() -> tuple[str, ...]:
    return tuple(m for m in METHODS if m != "ours")


def _only(text: str | None) -> list[str] | None:
    if text is None:
        return None
    return [s.strip() for s in str(text).split(",") if s.strip()]


def command_line(args: argparse.Namespace) -> str:
    parts = ["warp-critic", "reproduce", "--out", str(args.out)]
    if args.seeds is not None:
        parts += ["--seeds", str(args.seeds)]
    if args.only:
        parts += ["--only", args.only]
    if args.quick:
        parts.append("--quick")
    if getattr(args, "beyond", False):
        parts.append("--beyond")
    if getattr(args, "baselines", None):
        parts += ["--baselines", args.baselines]
    parts += ["--device", args.device]
    if getattr(args, "jobs", None) is not None:
        parts += ["--jobs", str(args.jobs)]
    if getattr(args, "ray", None) is not None:
        parts += ["--ray"] + ([] if args.ray == "local" else [args.ray])
    for o in args.overrides or []:
        parts += ["--set", o]
    return shlex.join(parts)


def config_from_args(args: argparse.Namespace):
    from warp_critic.reproduce.experiments.plan import ReproduceConfig
    from warp_critic.reproduce.experiments.settings import default_seeds

    seeds = args.seeds if args.seeds is not None else default_seeds(bool(args.quick))
    return ReproduceConfig(
        out=Path(args.out),
        seeds=seeds,
        only=_only(args.only),
        quick=bool(args.quick),
        device=args.device,
        overrides=list(args.overrides or []),
        command=command_line(args),
        seeds_given=args.seeds is not None,
        beyond=bool(getattr(args, "beyond", False)),
        baselines=_only(getattr(args, "baselines", None)),
    )


def run_from_args(args: argparse.Namespace) -> int:
    """Validate the flags, run the stages, write the report; returns the exit code (0)."""
    from warp_critic.core.errors import FieldError
    from warp_critic.core.runtime import init
    from warp_critic.physics.simulator import resolve_device
    from warp_critic.reproduce.engine.choose_executor import check_executor_flags, make_executor
    from warp_critic.reproduce.engine.timelimit import EXIT_TIME_LIMIT, TimeLimitReached
    from warp_critic.reproduce.pipeline import reproduce
    from warp_critic.running.loop import Interrupted

    rc = config_from_args(args)
    rc.validate()  # one-line UserError before any work
    jobs, ray = getattr(args, "jobs", None), getattr(args, "ray", None)
    check_executor_flags(jobs, ray)
    hours = getattr(args, "hours", None)
    if hours is not None:
        from warp_critic.reproduce.engine.timelimit import check_hours

        check_hours(hours)
    if getattr(args, "status", False):
        from warp_critic.reproduce.status import published_archive, status

        if hours is not None:
            raise FieldError("hours", "limits a call that runs stages; --status runs none")
        print(status(rc, published_archive()))
        return 0
    init()
    executor = make_executor(jobs, ray, resolve_device(rc.device))
    try:
        result = reproduce(rc, executor, hours=hours)
    except TimeLimitReached as e:
        sys.stderr.write(
            f"warp-critic: reproduce: stopped: {e}; the same command goes on from here\n"
        )
        return EXIT_TIME_LIMIT
    except KeyboardInterrupt as e:
        # a stage's run says what it kept; the way on is this same command (complete stages are
        # skipped, a stage's runs resume from their checkpoints), not a run's --resume flag
        from warp_critic.cli import signals

        kept = str(e).removeprefix("interrupted").lstrip("; ")
        kept = f"; {kept}" if kept else signals.noted()
        raise Interrupted(f"interrupted{kept}; the same reproduce command goes on from here") from e
    print(f"report: {result['report']}")
    print(f"recording: rerun {Path(result['out']) / 'report.rrd'}")
    return 0
