#!/usr/bin/env python
"""The reacher's maps (Figure 4's goal grid, Figures 5-6's 2-D mass and length maps) for any runs.

``reproduce`` computes the maps for the 5 seeds of its stages; this tool computes the same maps, with
the paper's settings (``reproduce``'s ``maps`` stage: 15 x 15 goals, 7 x 7 masses and lengths, 5
inits, 3 updates), for the run directories named on the command line: a seed-0 run of a new recipe
next to a stage's seed 0, without training 5 seeds first. Prints, per run set, the share of each
grid below 0.05 MSE and the mean MSE over it (the mean over the set's runs, as in the report). The
first set's first run sets the scene, the training goals and the grids; every run must be of the
same scene. No reachability floor (``reproduce --only maps`` has it).

Usage::

    python tools/maps_of_runs.py nominal=runs/paper/metatrain-reacher-ours-HASH/run/seed0 \\
        mine=runs/my-recipe-s0 --grid 9
"""

from __future__ import annotations

import sys

import numpy as np

from warp_critic.cli.flags import RUN_SETS_HELP, ToolParser, run_sets, stage_on_sets

PROG = "maps_of_runs"
LEVEL = 0.05


def main(argv=None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("run_dirs", nargs="+", metavar="NAME=RUN_DIRS", help=RUN_SETS_HELP)
    p.add_argument(
        "--grid", type=int, default=None, help="goal grid side (default: the paper's 15)"
    )
    p.add_argument("--inits", type=int, default=None, help="policy inits (default: the paper's 5)")
    p.add_argument("--device", default="cpu")
    p.add_argument(
        "--cells",
        action="store_true",
        help="also print each set's goal grid and mass and length maps, cell by cell",
    )
    args = p.parse_args(argv)
    sets = run_sets(p, args.run_dirs)
    for flag in ("grid", "inits"):
        if getattr(args, flag) is not None and getattr(args, flag) < 1 + (flag == "grid"):
            p.error(f"--{flag} must be >= {1 + (flag == 'grid')}")
    from warp_critic.core import runtime

    runtime.init()  # before the imports below, which would start Warp with its banner
    from warp_critic.reproduce.experiments.maps import run_maps_stage
    from warp_critic.reproduce.experiments.settings import default_settings
    from warp_critic.reproduce.report.maps import elbow_bent

    s = dict(default_settings(quick=False, seeds=1)["maps"], reach_iterations=0)
    if args.grid is not None:
        s["grid"] = args.grid
    if args.inits is not None:
        s["inits"] = args.inits
    out = stage_on_sets(p, run_maps_stage, s, sets, args.device)
    first = next(iter(sets))
    print(
        f"{s['grid']} x {s['grid']} goal grid, 7 x 7 mass and length maps, {s['inits']} inits: "
        f"share below {LEVEL} MSE, mean MSE"
    )
    bent = elbow_bent(out)
    print(
        f"{'runs':<28} {'goal grid':>16} {'mass map':>16} {'length map':>16}   goal grid, "
        f"elbow within / past 90 deg ({int((~bent).sum())} / {int(bent.sum())} goals)"
    )
    for name in sets:
        m = "ours" if name == first else name
        cols = [np.asarray(out["goals"][m]["mse"]).ravel()]
        cols += [np.array([c["mse_mean"] for c in out[kind][m]]) for kind in ("mass", "length")]
        text = [f"{(x < LEVEL).mean():>6.0%}, {x.mean():7.3f}" for x in cols]
        split = " / ".join(
            f"{(part < LEVEL).mean():.0%}" if part.size else "-"
            for part in (cols[0][~bent], cols[0][bent])
        )
        print(
            f"{name + f' ({len(sets[name])})':<28} "
            + " ".join(f"{t:>16}" for t in text)
            + "   "
            + split
        )
    if args.cells:
        for name in sets:
            m = "ours" if name == first else name
            goals = np.asarray(out["goals"][m]["mse"]).reshape(s["grid"], s["grid"])
            maps = [("goal grid", "q1 (rad)", "q2", out["axis_q1"], out["axis_q2"], goals)]
            for kind, axis in (("mass", out["masses"]), ("length", out["lengths"])):
                cells = np.array([c["mse_mean"] for c in out[kind][m]]).reshape(len(axis), -1)
                maps.append((f"{kind} map", "link 1", "link 2", axis, axis, cells))
            for title, rows, columns, axis_r, axis_c, cells in maps:
                print(f"\n{name}, {title} (MSE; '.' below {LEVEL}): rows {rows}, columns {columns}")
                print(" " * 7 + "".join(f"{v:>7.3g}" for v in axis_c))
                for v, row in zip(axis_r, cells):
                    print(
                        f"{v:>7.3g}"
                        + "".join(f"{x:>7.3f}" if x >= LEVEL else f"{'.':>7}" for x in row)
                    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
