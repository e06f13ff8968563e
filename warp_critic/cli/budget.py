"""``warp-critic budget``: the meta-test budget sweep (:mod:`warp_critic.reproduce.budget`).

For each method's meta-trained critics (the ``metatrain-<scene>-<method>`` stages of a ``warp-critic
reproduce`` output), fresh policies descend the critic for up to ``max(--budgets)`` steps at several
step sizes on the training goals; each method's (step size, steps) is the lowest error there, and
new goals (a seed that chose nothing) are scored at each method's own choice and ours also at the
baselines'. Resumable: the JSON is rewritten after each method; rerun the same command to go on.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from warp_critic.cli.flags import comma_list, user_message
from warp_critic.core.errors import UserError

__all__ = ["HELP", "DESCRIPTION", "add_arguments", "run_from_args"]

HELP = "meta-test budget sweep: each method's step size and step count, chosen on training goals"
DESCRIPTION = (
    "Meta-test every method's critics for 1 .. 300 critic-gradient steps at several step sizes on "
    "the training goals; choose each method's (step size, steps) there, then score new goals at "
    "each method's own choice and ours also at the baselines'. Lists are comma-separated."
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the arguments of ``warp-critic budget`` to ``p``."""
    from warp_critic.reproduce.budget import ALPHA_SCALES, BUDGETS, BudgetConfig

    d = BudgetConfig()
    p.add_argument(
        "--from",
        dest="source",
        required=True,
        metavar="DIR",
        help="a warp-critic reproduce output folder with the metatrain stages",
    )
    p.add_argument("--scene", required=True, help="reacher or kuka (the stages' scene)")
    p.add_argument(
        "--methods",
        type=comma_list(str),
        default=None,
        help="methods, ours first (default: every method whose meta-training the folder holds)",
    )
    p.add_argument("--out", required=True, help="the result JSON (resumed when it exists)")
    p.add_argument("--figure", default=None, help="also draw error against steps here (PNG)")
    p.add_argument(
        "--budgets",
        type=comma_list(int),
        default=list(BUDGETS),
        help=f"critic-gradient steps per fresh policy (default {','.join(map(str, BUDGETS))})",
    )
    p.add_argument(
        "--alpha-scales",
        dest="alpha_scales",
        type=comma_list(float),
        default=list(ALPHA_SCALES),
        help="multiples of each run's own meta-test step size (default "
        f"{','.join(map(str, ALPHA_SCALES))})",
    )
    ints = {  # whole-number flags: (field, help)
        "--inits": ("inits", "fresh policy initialisations per goal"),
        "--choose-seed": ("choose_seed", "seed of the initialisations on the training goals"),
        "--report-seed": ("report_seed", "goal seed of the reporting goals (column c: seed + c)"),
        "--num-goals": ("num_goals", "reporting goals per std"),
    }
    for flag, (field, text) in ints.items():
        default = getattr(d, field)
        p.add_argument(
            flag, dest=field, type=int, default=default, help=f"{text} (default {default})"
        )
    p.add_argument(
        "--report-stds",
        dest="report_stds",
        type=comma_list(float),
        default=d.report_stds,
        help="goal stds of the reporting goals, rad (default 0.1,0.5,1.0)",
    )
    p.add_argument("--device", default="auto", help="cpu, cuda or auto (default auto)")


def run_from_args(args: argparse.Namespace) -> int:
    """Run the sweep and print each method's choice; a user mistake raises ``UserError``."""
    from warp_critic.reproduce.budget import (
        BudgetConfig,
        plot_budget,
        run_budget,
        runs_of_reproduce,
    )
    from warp_critic.running.files import check_figure_file, check_output_file
    from warp_critic.running.locks import check_not_owned

    rename = {
        "from": "--from",
        "scene": "--scene",
        "choose_seed": "--choose-seed",
        "device": "--device",
        "out": "--out",
        "runs": "--methods",
        "budgets": "--budgets",
        "alpha_scales": "--alpha-scales",
        "inits": "--inits",
        "num_goals": "--num-goals",
        "report_seed": "--report-seed",
        "report_stds": "--report-stds",
    }
    try:
        src = Path(args.source)
        if not src.is_dir():
            raise UserError(f"--from: {src}: not a folder")
        out = check_output_file(args.out, "--out")  # a .json in a folder that is there
        if not out.parent.is_dir():
            raise UserError(f"--out: {out.parent}: no such folder")
        check_not_owned(out, "--out")
        if args.figure:
            check_figure_file(args.figure, "--figure")
        cfg = BudgetConfig(
            runs=runs_of_reproduce(src, args.scene, args.methods),
            budgets=args.budgets,
            alpha_scales=args.alpha_scales,
            inits=args.inits,
            choose_seed=args.choose_seed,
            report_seed=args.report_seed,
            report_stds=args.report_stds,
            num_goals=args.num_goals,
            device=args.device,
        )
        result = run_budget(cfg, out, log=print, base=src)
    except UserError as e:
        raise UserError(user_message(e, rename=rename)) from None
    for m, c in result["chosen"].items():
        print(
            f"{m}: chosen {c['steps']} step(s) at {c['scale']:g} x its alpha, "
            f"training-goal MSE {c['mse_train']:.4g}"
        )
    for m, rep in result["report"].items():
        for cell in rep["cells"]:
            print(
                f"  {m} at {cell['steps']} step(s), x{cell['scale']:g}, std {cell['std']:g}: "
                f"MSE {cell['mse_mean']:.4g} (untrained {cell['untrained']:.4g})"
            )
    print(f"written: {out}")
    if args.figure:
        print(
            f"figure: {plot_budget(result, Path(args.figure), f'{args.scene}: meta-test budget')}"
        )
    return 0
