"""Command line: ``warp-critic <command> ...``.

Every user mistake ends in one line ``warp-critic: error: ...`` and exit code 2, never a traceback.
A diverged run ends in one line naming the iteration, exit code 1, with its last good checkpoint kept.
A full disk is one line and exit code 1. Ctrl-C and SIGTERM stop a command the same way at any moment
(exit 130, one line; a run says what it kept): :mod:`warp_critic.cli.signals`.
Nothing below this module imports it back.
"""

from __future__ import annotations

import sys

if __name__ == "__main__":  # python -m warp_critic.cli.main: the handlers before the imports
    from warp_critic.cli import signals as _signals

    _signals.install()

import argparse  # noqa: E402
import errno  # noqa: E402
from dataclasses import fields  # noqa: E402
from pathlib import Path  # noqa: E402

from warp_critic import __version__
from warp_critic.cli import import_robot
from warp_critic.cli.environment import check_utf8, console_never_fails, cwd_gone, utf8_mode
from warp_critic.cli.flags import (
    Parser,
    add_dataclass_arguments,
    dataclass_from_args,
    flag_of,
    user_message,
)
from warp_critic.cli.import_robot import derived_rules_epilog
from warp_critic.cli.messages import library_messages
from warp_critic.core.errors import DivergenceError, UserError

EXIT_USER_ERROR = 2
EXIT_DIVERGED = 1
EXIT_FAILED = 1  # the machine failed (a full disk), not the user's input
EXIT_INTERRUPTED = 130
POSITIONAL = ("scene", "run_dir", "method", "robot")


# ------------------------------------------------------------------------------------------------
# commands
# ------------------------------------------------------------------------------------------------


def cmd_meta_train(args: argparse.Namespace) -> int:
    from warp_critic.methods.ours import TrainConfig, meta_train

    cfg, given = dataclass_from_args(TrainConfig, args)
    _not_owned(cfg.out or cfg.default_out(), "--out")
    result = meta_train(cfg, given=given)
    last = result.metrics[-1] if result.metrics else {}
    print(f"run directory: {result.run_dir}")
    if last:
        print(
            f"final task loss (mean ||q_T - g||^2 of the updated policies): {last['task_loss']:.5f}"
        )
    print(f"recording: rerun {result.run_dir / 'recording.rrd'}")
    return 0


def cmd_meta_test(args: argparse.Namespace) -> int:
    from warp_critic.evaluation.metatest import MetaTestConfig, meta_test

    tc, _ = dataclass_from_args(MetaTestConfig, args)
    if tc.out:
        _not_owned(tc.out, "--out")
    else:
        _not_owned(Path(tc.run_dir) / "metatest.json", "result (give --out)")
    result = meta_test(tc, progress=print, record=not args.no_recording)
    print(f"results: {result['output']}")
    if "recording" in result:
        print(f"recording: rerun {result['recording']}")
    return 0


def cmd_baseline(args: argparse.Namespace) -> int:
    from warp_critic.methods import method

    entry = method(args.method)
    cfg, given = dataclass_from_args(entry.config, args)
    _not_owned(cfg.out or cfg.default_out(), "--out")
    train = entry.train
    result = train(cfg, given=given)
    last = result.metrics[-1] if result.metrics else {}
    print(f"run directory: {result.run_dir}")
    if last:
        print(
            f"final task loss (mean ||q_T - g||^2 of the {cfg.method} actor, no noise): {last['task_loss']:.5f}"
        )
        if "fresh_policy_loss" in last:
            print(
                f"fresh policies trained with -Q on the training goals: {last['fresh_policy_loss']:.5f} "
                f"(meta-test alpha {last['alpha']:.3g})"
            )
    print(f"recording: rerun {result.run_dir / 'recording.rrd'}")
    print(f"meta-test: warp-critic meta-test {result.run_dir}")
    return 0


def _not_owned(path, what: str) -> None:
    """Commands other than reproduce write nowhere in a reproduce output or a locked folder."""
    from warp_critic.running.locks import check_not_owned

    check_not_owned(path, what)


def build_parser() -> argparse.ArgumentParser:
    """The ``warp-critic`` parser: every command's flags, in ``--help`` order."""
    p = Parser(
        prog="warp-critic",
        description="Model-based meta-learning of critics for policy gradients "
        "(Bechtle, Righetti, Meier, ICML 2022) on Newton/Warp.",
    )
    p.add_argument("--version", action="version", version=f"warp-critic {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    _add_meta_train(sub)
    _add_meta_test(sub)
    _add_baseline(sub)
    import_robot.add_parser(sub)
    _add_analyze(sub)
    _add_commands(sub)
    return p


def _add_meta_train(sub) -> None:
    from warp_critic.methods.ours import TrainConfig

    mt = sub.add_parser(
        "meta-train",
        help="meta-learn a critic through the differentiable Newton model (Algorithm 2)",
        description="Meta-learn the critic L(s, a, g) with a bi-level loop through the differentiable Newton model.",
    )
    mt.epilog = derived_rules_epilog()
    mt.formatter_class = argparse.RawDescriptionHelpFormatter
    mt.add_argument(
        "scene", help="USD scene, e.g. scenes/kuka.usda, or a robot file (.urdf, .xml, .usd)"
    )
    add_dataclass_arguments(mt, TrainConfig, skip=("scene",))
    mt.set_defaults(func=cmd_meta_train)


def _add_meta_test(sub) -> None:
    from warp_critic.evaluation.metatest import MetaTestConfig

    te = sub.add_parser(
        "meta-test",
        help="train fresh policies with a saved critic, model-free (Algorithm 3)",
        description="Train fresh policies for new goals / dynamics with a saved critic (any method); "
        "prints the final joint-space squared error per goal, mean and std, both summed "
        "over the joints (||q_T - g||^2, the task loss) and averaged over them (MSE, the "
        "paper's tables).",
    )
    te.add_argument("run_dir", help="run directory written by meta-train or baseline")
    add_dataclass_arguments(te, MetaTestConfig, skip=("run_dir",))
    te.add_argument(
        "--no-recording",
        action="store_true",
        help="write no rerun recording (default: OUT with the suffix .rrd, e.g. RUN_DIR/metatest.rrd)",
    )
    te.set_defaults(func=cmd_meta_test)


def _add_baseline(sub) -> None:
    from warp_critic.methods import methods

    baselines = methods(baseline=True)
    bl = sub.add_parser(
        "baseline",
        help="train a baseline: " + ", ".join(m.name for m in baselines),
        description="Train a baseline critic ("
        + ", ".join(m.label for m in baselines)
        + ") on the same scenes, goals and training distribution as meta-train; its run directory "
        "works with meta-test.",
    )
    bl_sub = bl.add_subparsers(dest="method", metavar="METHOD", parser_class=Parser, required=True)
    for entry in baselines:  # one parser per baseline: its own config's flags and defaults
        one = bl_sub.add_parser(
            entry.name,
            help=f"{entry.label} ({entry.cite})",
            description=f"Train {entry.label} ({entry.cite}) on the same scenes, goals and training "
            "distribution as meta-train; its run directory works with meta-test.",
        )
        one.epilog = derived_rules_epilog()
        one.formatter_class = argparse.RawDescriptionHelpFormatter
        one.add_argument(
            "scene",
            help="USD scene, e.g. scenes/reacher.usda, or a robot file (.urdf, .xml, .usd)",
        )
        add_dataclass_arguments(one, entry.config, skip=("scene", "method"))
        one.refused = _others_settings(entry, baselines)
        one.set_defaults(func=cmd_baseline)


def _others_settings(entry, baselines) -> dict[str, str]:
    """``{flag: why refused}`` for the flags of the other baselines' configs that ``entry``'s
    config lacks (``--aux-lr`` for DDPG): a user who gives one gets told whose setting it is."""
    own = {f.name for f in fields(entry.config)}
    owners: dict[str, list[str]] = {}
    for other in baselines:
        for f in fields(other.config):
            if f.name not in own:
                owners.setdefault(f.name, []).append(other.label)
    return {
        flag_of(name): f"is a {' and '.join(labels)} setting; {entry.name} does not use it"
        for name, labels in owners.items()
    }


def _add_analyze(sub) -> None:
    from warp_critic.analysis.landscape import command as landscape
    from warp_critic.analysis.toy import command as toy

    an = sub.add_parser(
        "analyze",
        help="the paper's analyses: toy (1-D, section 4.1) and landscape (2-D point mass, section 4.2)",
    )
    an_sub = an.add_subparsers(dest="analysis", metavar="ANALYSIS", parser_class=Parser)
    at = an_sub.add_parser(
        "toy", help="1-D analytic example: fixed points of Q learning, ours and Meta-Critic"
    )
    toy.add_arguments(at)
    at.set_defaults(func=toy.run_from_args)
    al = an_sub.add_parser(
        "landscape", help="2-D point mass: Q_true, Q_sup and L_critic landscapes"
    )
    landscape.add_arguments(al)
    al.set_defaults(func=landscape.run_from_args)


def _add_commands(sub) -> None:
    """The commands that live in their own module of ``warp_critic.cli``."""
    from warp_critic.cli import budget as budget_cli
    from warp_critic.cli import identify as identify_cli
    from warp_critic.cli import reproduce as reproduce_cli
    from warp_critic.cli import score as score_cli

    for name, module in (
        ("score", score_cli),
        ("identify", identify_cli),
        ("reproduce", reproduce_cli),
        ("budget", budget_cli),
    ):
        sp = sub.add_parser(name, help=module.HELP, description=module.DESCRIPTION)
        module.add_arguments(sp)
        sp.set_defaults(func=module.run_from_args)


def main(argv: list[str] | None = None) -> int:
    """The ``warp-critic`` command; ``argv`` given: called in-process (signal handlers restored after)."""
    from warp_critic.cli import signals

    if argv is None:
        utf8_mode()
        console_never_fails()
    gone = cwd_gone()  # before torch: its libraries abort the process without a working directory
    if gone:
        sys.stderr.write(f"warp-critic: error: {gone}\n")
        return EXIT_USER_ERROR
    previous = signals.install() if _main_thread() else None
    said = False
    try:
        code, said = _run(argv, in_process=argv is not None)
        if code == 0 and not signals.noted():  # a signal while the interpreter shuts down
            signals.note("after the command had finished: what it wrote is whole")
    finally:
        if previous is not None:
            if argv is not None:
                signals.restore(previous)
            else:  # the console script: a signal while the interpreter shuts down is one line too
                signals.exiting(said)
    if previous is not None and argv is None:
        signals.finish(code)  # the exit handlers under our handler, then no teardown to interrupt
    return code


def _run(argv: list[str] | None, in_process: bool) -> tuple[int, bool]:
    """``(exit code, whether a line about an interruption was written)``."""
    from warp_critic.cli import signals

    if in_process:
        signals.running()
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USER_ERROR, False
    from warp_critic.core.runtime import init
    from warp_critic.running.files import DiskFullError
    from warp_critic.running.loop import Interrupted
    from warp_critic.running.rundir import RunExistsError
    from warp_critic.running.seedrun import ResumeMismatch

    try:
        check_utf8(args)
        init()
        signals.running()
        with library_messages():  # library code logs (e.g. a robot's derived defaults); we print
            return int(args.func(args) or 0), False
    except ResumeMismatch as e:
        sys.stderr.write(f"warp-critic: error: {e.render(flag_of)}\n")
        return EXIT_USER_ERROR, False
    except RunExistsError as e:
        sys.stderr.write(
            f"warp-critic: error: {e} (continue it with --resume, or choose another --out)\n"
        )
        return EXIT_USER_ERROR, False
    except DiskFullError as e:
        sys.stderr.write(f"warp-critic: error: {e}\n")
        return EXIT_FAILED, False
    except UserError as e:
        sys.stderr.write(f"warp-critic: error: {user_message(e, POSITIONAL)}\n")
        return EXIT_USER_ERROR, False
    except DivergenceError as e:
        hint = " (continue with --resume)" if getattr(e, "checkpoint", None) is not None else ""
        sys.stderr.write(f"warp-critic: diverged: {e}{hint}\n")
        return EXIT_DIVERGED, False
    except Interrupted as e:
        hint = " (continue with --resume)" if e.checkpoint is not None else ""
        sys.stderr.write(f"warp-critic: {e}{hint}\n")
        return EXIT_INTERRUPTED, True
    except KeyboardInterrupt:
        sys.stderr.write(f"warp-critic: interrupted{signals.noted()}\n")
        return EXIT_INTERRUPTED, True
    except OSError as e:
        full = e.errno in (errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC))
        if e.filename is None and not full:
            raise
        # a path the system refuses (too long, a loop of links, ...) or a full disk: one line
        where = f"{e.filename}: " if e.filename is not None else ""
        sys.stderr.write(f"warp-critic: error: {where}{e.strerror or e}\n")
        return (EXIT_FAILED if full else EXIT_USER_ERROR), False


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
