#!/usr/bin/env python
"""Carry the complete stages of a ``warp-critic reproduce`` output to another machine.

A paper-setting reproduce runs for hours on a laptop CPU. ``save`` copies its complete stages into a
small archive folder (meta-training checkpoints without optimiser state or replay buffers, no
recordings; see :mod:`warp_critic.reproduce.engine.carry`); ``restore`` copies them into an output folder
elsewhere, where the same ``reproduce`` command then skips them and runs only the rest.

Usage::

    python tools/carry_stages.py save runs/paper docs/paper/stages      # after some stages finished
    python tools/carry_stages.py restore docs/paper/stages runs/paper   # on the next machine
    warp-critic reproduce --out runs/paper                              # runs what is left
    python tools/carry_stages.py list docs/paper/stages
    python tools/carry_stages.py publish runs/paper docs/paper          # the report + its stages, to commit

A run longer than a sitting, on machines that may be fresh each time, is resumed from an archive it
commits as it goes: each sitting restores it, runs, and saves each complete stage into it (with the
ledger of the calls that ran them, so the report counts every sitting's wall time and carries in
nothing), and the finished batches of a long meta-test part way (a sitting that ends loses at most
the batch it was in; ``--hours`` starts no meta-training that cannot end before the sitting does)::

    python tools/carry_stages.py restore docs/rerun runs/paper          # a sitting's start
    warp-critic reproduce --out runs/paper --beyond --baselines ddpg,meta-critic,td3 --jobs 2 --hours 2.8 &
    python tools/carry_stages.py save runs/paper docs/rerun && git add docs/rerun && git commit
"""

from __future__ import annotations

import sys
from pathlib import Path

from warp_critic.cli.flags import ToolParser, user_message
from warp_critic.core.errors import UserError

PROG = "carry_stages"


def main(argv: list[str] | None = None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="what", required=True, parser_class=ToolParser)
    s = sub.add_parser("save", help="copy OUT's complete stages into ARCHIVE")
    s.add_argument("out", metavar="OUT", help="a reproduce output folder")
    s.add_argument("archive", metavar="ARCHIVE", help="the archive folder (created if new)")
    r = sub.add_parser("restore", help="copy ARCHIVE's stages that OUT lacks into OUT")
    r.add_argument("archive", metavar="ARCHIVE")
    r.add_argument("out", metavar="OUT", help="a reproduce output folder (created if new)")
    ls = sub.add_parser("list", help="the archived stages")
    ls.add_argument("archive", metavar="ARCHIVE")
    pb = sub.add_parser(
        "publish",
        help="copy OUT's report and figures into DEST, and the stages it read into DEST/stages",
    )
    pb.add_argument("out", metavar="OUT", help="a reproduce output folder with its report")
    pb.add_argument("dest", metavar="DEST", help="the folder to commit (created if new)")
    args = p.parse_args(argv)
    from warp_critic.reproduce.engine import carry, publish
    from warp_critic.reproduce.experiments.records import CARRY

    try:
        if args.what == "list":
            print(carry.summary(Path(args.archive), CARRY.check))
            return 0
        if args.what == "publish":
            done = publish.publish(Path(args.out), Path(args.dest), CARRY)
            print(
                f"{PROG}: the report written to {args.dest}, with the {len(done.stages)} stage "
                f"record(s) it read in {Path(args.dest) / publish.ARCHIVE}"
                + (
                    f"; {len(done.omitted)} run(s) published without their checkpoint (a note "
                    "says why)"
                    if done.omitted
                    else ""
                )
                + "".join(
                    f"\n  removed the record written beside the report: {n}" for n in done.pruned
                )
            )
            return 0
        if args.what == "save":
            done = carry.save(Path(args.out), Path(args.archive), CARRY)
            dest = args.archive
        else:
            done = carry.restore(Path(args.archive), Path(args.out), CARRY)
            dest = args.out
    except UserError as e:
        p.exit(2, f"{PROG}: error: {user_message(e)}\n")
    print(
        f"{PROG}: {len(done.stages)} stage(s) copied to {dest}"
        + "".join(f"\n  {n}" for n in done.stages)
        + "".join(f"\n  {n}: part way, its new finished batches" for n in done.partway)
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
