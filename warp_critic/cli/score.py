"""``warp-critic score``: the paper's Table 1 protocol over meta-trained critics (seeds).

The work is :mod:`warp_critic.evaluation.protocol`: for every goal std and goal-noise reading, each
run directory's critic trains ``--inits`` fresh policies (model-free) for ``--num-goals`` new goals
sampled around training goals ``--around``; the errors of all runs are pooled, as in the paper ("the
mean squared error between last state and goal over 10 new goals, 5 seeds and 5 new policy
initialization"). Every run sees the same goals and policy initialisations (``--seed``). Each cell
is ``mean(std)`` over the pooled errors: ``MSE`` (mean over the joints, the paper's metric) and
``sum sq.`` (``||q_T - g||^2``, the task loss).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from warp_critic.cli.flags import comma_list, user_message
from warp_critic.core.errors import UserError

__all__ = ["HELP", "DESCRIPTION", "add_arguments", "run_from_args"]

HELP = "score critics with the paper's Table 1 protocol (seeds pooled); prints the table"
DESCRIPTION = (
    "The paper's Table 1 protocol: each run's critic (any method: ours or any baseline) trains "
    "fresh policies, model-free, for new goals sampled around training goals; the final errors of "
    "all runs (one per seed) are pooled. Each cell is mean(std): MSE (mean over the joints, the "
    "paper's metric) and sum sq. (||q_T - g||^2, the task loss). Lists are comma-separated."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the arguments of ``warp-critic score`` to ``p``."""
    p.add_argument(
        "run_dirs", nargs="+", metavar="RUN_DIR", help="run directories (one per meta-train seed)"
    )
    p.add_argument(
        "--stds",
        type=comma_list(float),
        default=[0.1, 0.4],
        help="goal stds (rad), e.g. 0.1,0.4 (default); the paper: 0.1 .. 1.0",
    )
    p.add_argument(
        "--goal-noise",
        type=comma_list(str),
        default=["per-joint", "distance"],
        dest="goal_noise",
        help="readings of 'at a distance of N(0, std)': per-joint and/or distance (default both; "
        "see warp_critic.evaluation.metatest.sample_goals)",
    )
    p.add_argument(
        "--around",
        type=comma_list(int),
        default=[0, 1],
        help="training goals to sample around, e.g. 0,1 (default; the paper: two of the four); "
        "'' = all",
    )
    p.add_argument("--num-goals", type=int, default=10, help="new goals per cell (default 10)")
    p.add_argument(
        "--inits", type=int, default=5, help="fresh policy initialisations per goal (default 5)"
    )
    p.add_argument(
        "--seed", type=int, default=1, help="seed of the goals and policy initialisations"
    )
    p.add_argument("--device", default="auto", help="cpu, cuda or auto (default auto)")
    p.add_argument("--out", default=None, help="write the table as JSON here")


def run_from_args(args: argparse.Namespace) -> int:
    """Run the protocol and print the table; a user mistake raises ``UserError``."""
    from warp_critic.evaluation.protocol import ProtocolConfig, format_table, run_protocol
    from warp_critic.running.files import write_result
    from warp_critic.running.locks import check_not_owned

    pc = ProtocolConfig(
        run_dirs=args.run_dirs,
        stds=args.stds,
        goal_noise=args.goal_noise,
        around=args.around or None,
        num_goals=args.num_goals,
        inits=args.inits,
        seed=args.seed,
        device=args.device,
    )
    try:
        pc.validate()  # the runs (one method, each once) before anything is written
    except UserError as e:  # a field of the protocol: the flag or RUN_DIR
        raise UserError(user_message(e, rename={"run_dirs": "RUN_DIR"})) from None
    out = _check_out(args.out, pc.run_dirs) if args.out else None
    for run in pc.run_dirs:  # each run's table-*.json goes into its folder
        check_not_owned(Path(run) / "table.json", "RUN_DIR")
    try:
        result = run_protocol(pc)
    except UserError as e:
        raise UserError(user_message(e, rename={"run_dirs": "RUN_DIR"})) from None
    print(
        f"{len(pc.run_dirs)} run(s) x {pc.num_goals} goals x {pc.inits} inits per cell, "
        f"around training goals {result.around or 'all'}; {result.seconds:.0f} s"
    )
    print("\n".join(format_table(result)))
    if out is not None:
        write_result(out, result.to_dict())
        print(f"written: {out}")
    return 0


def _check_out(path: str, run_dirs: list[str]) -> Path:
    """``--out``: a ``.json`` outside any folder another command owns, replacing at most a score of
    the same runs (:func:`~warp_critic.running.files.check_replaceable`)."""
    from warp_critic.evaluation.protocol import RESULT_KIND
    from warp_critic.running.files import check_output_file, check_replaceable
    from warp_critic.running.locks import check_not_owned

    out = check_output_file(path, "--out")
    check_not_owned(out, "--out")
    runs = sorted(str(Path(r).resolve()) for r in run_dirs)

    def same(old: dict) -> str | None:
        theirs = old.get("runs")
        if isinstance(theirs, list) and sorted(str(Path(str(r)).resolve()) for r in theirs) == runs:
            return None
        return f"of the runs {', '.join(map(str, theirs)) if isinstance(theirs, list) else '?'}"

    check_replaceable(out, "out", RESULT_KIND, same)
    return out
