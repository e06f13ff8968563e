#!/usr/bin/env python
"""The calls of a reproduce output's ledger, one table row each, written from ``ledger.jsonl``.

    python tools/ledger_calls.py docs/paper                              # print the table
    python tools/ledger_calls.py docs/paper --write docs/paper/README.md # its block
    python tools/ledger_calls.py docs/paper --check docs/paper/README.md # exit 1 when stale

A long reproduction runs over many calls (sittings, restarts); the published folder says how. Each
row: the call's start and end (UTC), its wall time, its status (``done``, ``interrupted``,
``failed``, or ``killed`` for a call that could not write its end: it ends at its last record) and
the stages it completed, the total below. The block sits between ``<!-- calls:begin -->`` and
``<!-- calls:end -->``; it is never written by hand.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from warp_critic.core.generated import emit
from warp_critic.reproduce.engine.ledger import calls, read
from warp_critic.reproduce.engine.stage import stage_of_dir

PROG = "ledger_calls"
BEGIN, END = "<!-- calls:begin -->", "<!-- calls:end -->"


def _stages(dirs: list[str]) -> str:
    """Stage directories as their stage names (the hash dropped), or ``-``."""
    return ", ".join(stage_of_dir(d) for d in dirs) or "-"


def block(rows: list[dict]) -> str:
    found = calls(rows)
    if not found:
        raise ValueError("its ledger holds no call")
    lines = [
        "| call | start (UTC) | end | wall (s) | status | stages completed |",
        "|---:|---|---|---:|---|---|",
    ]
    for i, c in enumerate(found, 1):
        lines.append(
            f"| {i} | {c['start'].replace('T', ' ')[:16]} | {c['end'][11:16]} | "
            f"{c['wall_s']:,.0f} | {c['status']} | {_stages(c['stages'])} |"
        )
    wall = sum(c["wall_s"] for c in found)
    done = sum(len(c["stages"]) for c in found)
    cpus = sorted({c["cpu"] for c in found if c["cpu"]})
    lines += [
        "",
        f"{len(found)} calls, {wall:,.0f} s ({wall / 3600:.1f} h) of wall time, {done} stages "
        f"completed; CPU: {', '.join(cpus) or 'not recorded'} (written by `tools/ledger_calls.py` "
        "from `ledger.jsonl`).",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    ap.add_argument("folder", type=Path, help="a reproduce output or a published report folder")
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--write", type=Path, metavar="FILE", help="rewrite FILE's calls block")
    mode.add_argument("--check", type=Path, metavar="FILE", help="exit 1 if FILE's block is stale")
    args = ap.parse_args(argv)
    try:
        if not (args.folder / "ledger.jsonl").is_file():
            raise ValueError(f"{args.folder}: no ledger.jsonl")
        body = block(read(args.folder))
    except (OSError, ValueError) as e:
        print(f"{PROG}: error: {getattr(e, 'strerror', None) or e}", file=sys.stderr)
        return 2
    return emit(PROG, body, BEGIN, END, write=args.write, check=args.check, what="the calls block")


if __name__ == "__main__":
    sys.exit(main())
