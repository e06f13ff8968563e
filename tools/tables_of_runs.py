#!/usr/bin/env python
"""The KUKA's Table 1 and stress tables (added tip mass, stretched end link) for any runs.

``reproduce`` computes the tables for the 5 seeds of its stages; this tool computes Table 1 and the
two stress tables of issue 25 with the same settings (``reproduce``'s ``tables`` stage: 10 goals per
column, 5 inits, the run's own policy updates) for the run directories named on the command line: a
seed-0 run of a new recipe next to a stage's seed 0, without training 5 seeds first. Prints, per run
set, the MSE of each column (the mean over the set's runs and goals, as in the report). With
``--floors STAGE_DIR`` (a ``tables`` or ``beyond-tables`` stage of the same settings) it also prints
the open-loop floor of each stress column and how many columns meet issue 25's rule: at most twice
the floor where the floor is below the untrained policies' error, else no worse than no update.

Usage::

    python tools/tables_of_runs.py randomised=runs/paper/beyond-metatrain-kuka-randomised-HASH/run/seed0 \\
        told=runs/kuka-told-s0 --floors runs/paper/beyond-tables-HASH
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from warp_critic.cli.flags import RUN_SETS_HELP, ToolParser, run_sets, stage_on_sets

PROG = "tables_of_runs"
TABLES = ("table1", "stress_mass", "stress_length")


def meets(mse: float, floor: float, untrained: float) -> bool:
    """Issue 25's rule for one stress column."""
    return mse <= 2 * floor if floor < untrained else mse <= untrained


def _floors(stage_dir: str, settings: dict) -> dict:
    """The stress tables' floors of a tables stage whose settings match ``settings``."""
    path = Path(stage_dir) / "stage.json"
    try:
        stage = json.loads(path.read_text())
        theirs, floors = stage["settings"], stage["result"]["reach_floor"]
    except (OSError, ValueError, KeyError, TypeError):
        raise ValueError(f"--floors {stage_dir}: not a finished tables stage") from None
    keys = ("stress_masses", "stress_lengths", "num_goals", "dynamics_goal_std", "seed", "around")
    differ = [k for k in keys if theirs.get(k) != settings.get(k)]
    if differ or not floors:
        why = f"other settings ({', '.join(differ)})" if differ else "no floors"
        raise ValueError(f"--floors {stage_dir}: {why}")
    return floors


def main(argv=None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("run_dirs", nargs="+", metavar="NAME=RUN_DIRS", help=RUN_SETS_HELP)
    p.add_argument("--inits", type=int, default=None, help="policy inits (default: the paper's 5)")
    p.add_argument(
        "--goals", type=int, default=None, help="goals per column (default: the paper's 10)"
    )
    p.add_argument(
        "--floors", default=None, metavar="STAGE_DIR", help="a tables stage with the floors"
    )
    p.add_argument("--device", default="cpu")
    args = p.parse_args(argv)
    sets = run_sets(p, args.run_dirs)
    for flag in ("inits", "goals"):
        if getattr(args, flag) is not None and getattr(args, flag) < 1:
            p.error(f"--{flag} must be >= 1")
    from warp_critic.core import runtime

    runtime.init()  # before the imports below, which would start Warp with its banner
    from warp_critic.reproduce.experiments.settings import default_settings
    from warp_critic.reproduce.experiments.tables import run_tables_stage

    # the paper's Tables 2-3 are left at their trained column: this tool is for issue 25's tables
    s = dict(default_settings(quick=False, seeds=1)["tables"], reach_iterations=0)
    s.update(masses=[], lengths=[])
    if args.inits is not None:
        s["inits"] = args.inits
    if args.goals is not None:
        s["num_goals"] = args.goals
    try:
        floors = _floors(args.floors, s) if args.floors else {}
    except ValueError as e:
        p.exit(2, f"{PROG}: error: {e}\n")
    out = stage_on_sets(p, run_tables_stage, s, sets, args.device)
    first = next(iter(sets))
    cells = {(c["table"], c["column"], c["method"]): c for c in out["cells"]}
    for table in TABLES:
        values = out["columns"][table]
        print(f"\n{table} ({s['num_goals']} goals, {s['inits']} inits): MSE per column")
        print(f"{'runs':<24}" + "".join(f"{v:>9g}" for v in values))
        rows = [(name, "ours" if name == first else name) for name in sets]
        for name, m in rows:
            mse = [cells[(table, i, m)]["mse_mean"] for i in range(len(values))]
            line = f"{name + f' ({len(sets[name])})':<24}" + "".join(f"{x:>9.4f}" for x in mse)
            if table in floors:
                untrained = [cells[(table, i, m)]["untrained_mse_mean"] for i in range(len(mse))]
                met = sum(meets(*t) for t in zip(mse, floors[table], untrained))
                line += f"   {met}/{len(mse)} met"
            print(line)
        untrained = [cells[(table, i, "ours")]["untrained_mse_mean"] for i in range(len(values))]
        print(f"{'no update':<24}" + "".join(f"{x:>9.4f}" for x in untrained))
        if table in floors:
            print(f"{'open-loop floor':<24}" + "".join(f"{x:>9.2g}" for x in floors[table]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
