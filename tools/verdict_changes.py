#!/usr/bin/env python
"""The paper's claims judged by two reports side by side: which verdicts changed, and why.

    python tools/verdict_changes.py 41e5dc4:docs/paper/results.json docs/paper/results.json
    python tools/verdict_changes.py BEFORE AFTER --write docs/paper/README.md   # its block
    python tools/verdict_changes.py BEFORE AFTER --check docs/paper/README.md   # exit 1 if stale

BEFORE and AFTER are a report's ``results.json``: a file, or ``REV:PATH`` read from git (``git show
REV:PATH`` in this repository), so a republished report is compared with the one it replaces.
Every claim either report judges gets a row with both verdicts; a changed verdict is in bold and
gets a line saying why, from the two reports' own words: whether its rule changed (the text after
``rule`` in the claim's reason), whether its measurement changed, and both measurements. A claim
only one report judges is marked new or no longer judged. Nothing is written by hand: ``--write``
puts the block between ``<!-- verdicts:begin -->`` and ``<!-- verdicts:end -->``.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

from warp_critic.core.generated import emit

PROG = "verdict_changes"
ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- verdicts:begin -->", "<!-- verdicts:end -->"
RULE = re.compile(r"\brule(?: \([^)]*\))?: ")


class Bad(ValueError):
    """A user's input that cannot be read: one line, exit 2."""


def load(source: str) -> tuple[str, list[dict]]:
    """``(source, claims)`` of the report ``source``: a ``results.json`` file or ``REV:PATH``."""
    path = Path(source)
    if path.is_file():
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as e:
            raise Bad(f"{source}: cannot read ({e})") from None
    elif ":" in source and not path.exists():
        rev, _, inner = source.partition(":")
        done = subprocess.run(
            ["git", "show", f"{rev}:{inner}"], cwd=ROOT, capture_output=True, text=True
        )
        if done.returncode != 0:
            why = (done.stderr.strip().splitlines() or ["git show failed"])[-1]
            raise Bad(f"{source}: not in this repository's history ({why})")
        text = done.stdout
        rev_id = subprocess.run(
            ["git", "rev-parse", "--short", rev], cwd=ROOT, capture_output=True, text=True
        ).stdout.strip()
        source = f"{rev_id or rev}:{inner}"  # HEAD moves; the commit it named does not
    else:
        raise Bad(f"{source}: no such file (give a results.json, or REV:PATH from git)")
    try:
        claims = json.loads(text)["claims"]
    except (ValueError, KeyError, TypeError):
        raise Bad(f"{source}: not a reproduce report's results.json (no claims)") from None
    ok = isinstance(claims, list) and all(
        isinstance(c, dict) and all(isinstance(c.get(k), str) for k in ("claim", "verdict"))
        for c in claims
    )
    if not ok or not claims:
        raise Bad(f"{source}: its claims are not a list of claim/verdict records")
    return source, claims


def rule_of(claim: dict) -> str:
    """The rule a claim's reason quotes (the text after ``rule:``), or ``""``."""
    reason = str(claim.get("reason", ""))
    m = RULE.search(reason)
    return reason[m.end() :].strip() if m else ""


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def compare(before: list[dict], after: list[dict]) -> dict:
    """``{"rows": [(claim, verdict before or None, verdict after or None)], "why": [...],
    "changed", "judged_both", "new", "gone"}``: every claim of either report, in ``after``'s order
    then ``before``'s, and for each changed verdict why (rule and measurement, both reports')."""
    old = {c["claim"]: c for c in before}
    new = {c["claim"]: c for c in after}
    names = list(new) + [n for n in old if n not in new]
    rows, why = [], []
    for name in names:
        a, b = old.get(name), new.get(name)
        rows.append((name, a["verdict"] if a else None, b["verdict"] if b else None))
        if a is None or b is None or a["verdict"] == b["verdict"]:
            continue
        causes = []
        if rule_of(a) != rule_of(b):
            causes.append(f'its rule changed (before: "{rule_of(a)}"; after: "{rule_of(b)}")')
        else:
            causes.append("its rule is the same")
        if a.get("ours") != b.get("ours"):
            causes.append(
                f'its measurement changed (before: "{a.get("ours", "")}"; after: '
                f'"{b.get("ours", "")}")'
            )
        else:
            causes.append("its measurement is the same")
        why.append((name, a["verdict"], b["verdict"], "; ".join(causes)))
    both = [r for r in rows if r[1] is not None and r[2] is not None]
    return {
        "rows": rows,
        "why": why,
        "changed": len(why),
        "judged_both": len(both),
        "new": [r[0] for r in rows if r[1] is None],
        "gone": [r[0] for r in rows if r[2] is None],
    }


def block(before: tuple[str, list[dict]], after: tuple[str, list[dict]]) -> str:
    """The markdown of :func:`compare` (its sources named)."""
    c = compare(before[1], after[1])
    lines = [
        f"Verdicts of `{before[0]}` (before) and `{after[0]}` (after), written by "
        "`tools/verdict_changes.py`:",
        "",
        "| claim | before | after |",
        "|---|---|---|",
    ]
    for name, a, b in c["rows"]:
        changed = a is not None and b is not None and a != b
        show = [(f"**{v}**" if changed else v) if v else "(not judged)" for v in (a, b)]
        lines.append(f"| {_cell(name)} | {show[0]} | {show[1]} |")
    extra = []
    if c["new"]:
        extra.append(f"{len(c['new'])} claim(s) new")
    if c["gone"]:
        extra.append(f"{len(c['gone'])} no longer judged")
    lines += [
        "",
        f"{c['changed']} of the {c['judged_both']} claims both reports judge changed verdict"
        + (f" ({', '.join(extra)})" if extra else "")
        + ".",
    ]
    if c["why"]:
        lines += ["", "Why each changed:"]
        lines += [f"- **{_cell(n)}**: {a} -> {b}; {why}." for n, a, b, why in c["why"]]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    ap.add_argument("before", metavar="BEFORE", help="results.json, or REV:PATH from git")
    ap.add_argument("after", metavar="AFTER", help="results.json, or REV:PATH from git")
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--write", type=Path, metavar="FILE", help="rewrite FILE's verdicts block")
    mode.add_argument("--check", type=Path, metavar="FILE", help="exit 1 if FILE's block is stale")
    args = ap.parse_args(argv)
    try:
        body = block(load(args.before), load(args.after))
    except Bad as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    what = f"the verdicts block of {args.before} and {args.after}"
    return emit(PROG, body, BEGIN, END, write=args.write, check=args.check, what=what)


if __name__ == "__main__":
    sys.exit(main())
