"""A reproduce ledger (:mod:`~warp_critic.reproduce.engine.ledger`) as text to publish, carry and
merge: the output folder named as the report's command gave it (never a machine's absolute path),
and two ledgers of one run merged (an archive's and an output's, over sittings)."""

from __future__ import annotations

import json
from pathlib import Path


def _out_flag(command: str) -> tuple[list[str], int] | None:
    """``(tokens, index of the --out value)`` of a reproduce command line, or ``None``."""
    import shlex

    try:
        tokens = shlex.split(command)
    except ValueError:
        return None
    if "--out" not in tokens[:-1]:
        return None
    return tokens, tokens.index("--out") + 1


def out_as_shown(command: str, out: Path) -> str:
    """How a published ledger names the output folder: as the report's command gave it where
    that is relative (``runs/paper``), else by its own name."""
    found = _out_flag(command)
    given = found[0][found[1]] if found else ""
    return given if given and not Path(given).is_absolute() else Path(out).resolve().name


def portable_ledger(text: str, out: Path, shown: str) -> str:
    """``out``'s ledger as published: each call's command names the output folder ``shown``
    where it gave its absolute path (a machine's folder; the calls are the same calls), every
    other byte as it is."""
    import shlex

    root = Path(out).resolve()
    lines = []
    for line in text.splitlines(keepends=True):
        try:
            record = json.loads(line)
        except ValueError:
            lines.append(line)  # a torn last line: the report's reader skips it too
            continue
        found = _out_flag(record.get("command", "")) if isinstance(record, dict) else None
        if found is not None:
            tokens, i = found
            if Path(tokens[i]).is_absolute() and Path(tokens[i]).resolve() == root:
                tokens[i] = shown
                record["command"] = shlex.join(tokens)
                line = json.dumps(record, sort_keys=True) + "\n"
        lines.append(line)
    return "".join(lines)


def merge(first: str, second: str) -> str:
    """The records of the ledger text ``first``, then those of ``second`` that ``first`` lacks, in
    their order (pure). A line that is no record (a torn last line of a call that was writing) is
    dropped from both: a merged ledger may go on growing in the middle."""
    kept: list[str] = []
    seen: set[str] = set()
    for text in (first, second):
        for line in text.splitlines():
            try:
                json.loads(line)
            except ValueError:
                continue
            if line not in seen:
                seen.add(line)
                kept.append(line + "\n")
    return "".join(kept)
