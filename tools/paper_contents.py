#!/usr/bin/env python
"""What the published report folder keeps, measured: every file of ``docs/paper`` in one category,
with its count, its size and why it is kept.

    python tools/paper_contents.py                              # print the table
    python tools/paper_contents.py --write docs/paper/README.md # its block
    python tools/paper_contents.py --check docs/paper/README.md # exit 1 when stale

The folder is part of every clone for ever, so ``docs/paper/README.md`` says what it holds; this
tool writes that table between ``<!-- contents:begin -->`` and ``<!-- contents:end -->`` from the
files themselves (sizes in MB of 10**6 bytes), so it is never written by hand. A file no category
names is listed as "other", never left out; the page itself is not measured.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from warp_critic.core.generated import emit
from warp_critic.running.rundir import OMITTED

PROG = "paper_contents"
ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "docs" / "paper"
BEGIN, END = "<!-- contents:begin -->", "<!-- contents:end -->"


@dataclass(frozen=True)
class Kind:
    what: str
    why: str
    holds: Callable[[PurePosixPath], bool]


def _in_run(p: PurePosixPath, name: str) -> bool:
    """``stages/STAGE/run/seedN/name``."""
    return len(p.parts) == 5 and p.parts[0] == "stages" and p.parts[2] == "run" and p.name == name


KINDS = (
    Kind(
        "critics, `stages/*/run/seed*/checkpoint.pt`",
        "anyone can meta-test them again; weights only (no optimiser state, replay buffer or "
        "target network)",
        lambda p: _in_run(p, "checkpoint.pt"),
    ),
    Kind(
        f"notes, `stages/*/run/seed*/{OMITTED}`",
        "stand in for a seed's critic that is not published, saying why (its record and config "
        "stay)",
        lambda p: _in_run(p, OMITTED),
    ),
    Kind(
        "stage records and raw errors, `stages/*/{stage,errors}.json.xz`",
        "every table cell, curve and verdict is read from them; xz-compressed (`xz -dc FILE`)",
        lambda p: (
            len(p.parts) == 3
            and p.parts[0] == "stages"
            and p.name in ("stage.json.xz", "errors.json.xz")
        ),
    ),
    Kind(
        "Meta-Critic's metrics, `stages/*/run/seed*/metrics.jsonl.xz`",
        "only the auxiliary-loss columns the report reads",
        lambda p: _in_run(p, "metrics.jsonl.xz"),
    ),
    Kind(
        "the runs' configs and the stages' own outputs (the toy's and landscape's images)",
        "what each run was trained with; the figures those stages draw",
        lambda p: p.parts[0] == "stages",
    ),
    Kind(
        "the report: `REPORT.md`, `results.json`, `ledger.jsonl`, `figures/`",
        "what a reader reads first; the calls that made it",
        lambda p: (
            str(p) in ("REPORT.md", "results.json", "ledger.jsonl") or p.parts[0] == "figures"
        ),
    ),
    Kind(
        "the tuning searches, `tuning/`",
        "every candidate's row and the rule's decision",
        lambda p: p.parts[0] == "tuning",
    ),
    Kind(
        "the meta-test budget sweep, `budget/`",
        "`warp-critic budget` on the published critics",
        lambda p: p.parts[0] == "budget",
    ),
)


#: the page that holds the table: not measured (its own size would change with the table)
PAGE = "README.md"


def measure(folder: Path) -> list[tuple[Kind | None, int, int]]:
    """``(kind, files, bytes)`` per kind that holds a file of ``folder`` (``None``: other), the
    folder's :data:`PAGE` left out."""
    sums: dict[int, list[int]] = {}
    for f in sorted(folder.rglob("*")):
        rel = PurePosixPath(f.relative_to(folder).as_posix())
        if not f.is_file() or str(rel) == PAGE:
            continue
        i = next((k for k, kind in enumerate(KINDS) if kind.holds(rel)), -1)
        entry = sums.setdefault(i, [0, 0])
        entry[0] += 1
        entry[1] += f.stat().st_size
    return [(KINDS[i] if i >= 0 else None, n, b) for i, (n, b) in sorted(sums.items())]


def critics(folder: Path) -> str:
    """Which seeds' critics the folder keeps, in words."""
    runs = sorted(folder.glob("stages/*/run/seed*"))
    kept = [r for r in runs if (r / "checkpoint.pt").is_file()]
    stages = {r.parent.parent.name for r in runs}
    seeds = sorted({r.name for r in kept})
    return (
        f"{len(kept)} of the {len(runs)} seeds' critics of {len(stages)} meta-trainings are kept "
        f"({', '.join(seeds) or 'none'})"
    )


def block(folder: Path) -> str:
    rows = measure(folder)
    total = sum(b for _, _, b in rows)
    lines = [
        f"{total / 1e6:.1f} MB in {sum(n for _, n, _ in rows)} files besides this page (written "
        f"by `tools/paper_contents.py`); {critics(folder)}.",
        "",
        "| what | files | MB | why |",
        "|---|---:|---:|---|",
    ]
    for kind, n, b in rows:
        what, why = (kind.what, kind.why) if kind else ("other", "(no category names it)")
        lines.append(f"| {what} | {n} | {b / 1e6:.2f} | {why} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    ap.add_argument("--folder", type=Path, default=PAPER, help="the published folder")
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--write", type=Path, metavar="FILE", help="rewrite FILE's contents block")
    mode.add_argument("--check", type=Path, metavar="FILE", help="exit 1 if FILE's block is stale")
    args = ap.parse_args(argv)
    if not args.folder.is_dir():
        print(f"{PROG}: error: {args.folder}: no such folder", file=sys.stderr)
        return 2
    return emit(
        PROG,
        block(args.folder),
        BEGIN,
        END,
        write=args.write,
        check=args.check,
        what="the contents block",
    )


if __name__ == "__main__":
    sys.exit(main())
