#!/usr/bin/env python
"""The README's table of the paper's claims, written from the committed report's numbers.

    python tools/readme_claims.py --write   # README.md's claims block, from docs/paper/results.json
    python tools/readme_claims.py --check   # exit 1 when the block is not the one --write gives

Every number and verdict in the block is read from ``results.json``: the held-out goal seeds'
pooled tables and maps (the claims of Tables 1-3 and Figures 4-6 are judged there), the seed-1
Table 1 cells' paper values, and the counts its claims state (``ours first at N of M levels``, ``below
both (all seeds) in N of M columns``, ...). A row over several claims gives their verdicts, once
where they agree. So the README says what the report computed, never more leniently.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

from warp_critic.core.generated import check_or_write, replace_block

PROG = "readme_claims"
ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- claims:begin -->", "<!-- claims:end -->"
STDS = (0.1, 0.4)


class Missing(ValueError):
    """results.json lacks what a row reads (a report without that stage)."""


def _claim(r: dict, prefix: str) -> dict:
    found = [c for c in r.get("claims", []) if c["claim"].startswith(prefix)]
    if len(found) != 1:
        raise Missing(f"no claim starting {prefix!r}")
    return found[0]


def _find(pattern: str, text: str) -> tuple[str, ...]:
    m = re.search(pattern, text)
    if m is None:
        raise Missing(f"{pattern!r} not in {text[:80]!r}")
    return m.groups()


def _verdict(r: dict, *prefixes: str) -> str:
    said = [_claim(r, p)["verdict"] for p in prefixes]
    return said[0] if len(set(said)) == 1 else " / ".join(said)


def _cell(r: dict, method: str, std: float) -> dict:
    for c in r["tables"]:
        if c["table"] == "table1" and c["method"] == method and c["value"] == std:
            return c
    raise Missing(f"no Table 1 cell of {method} at std {std}")


def _spread(r: dict, prefix: str) -> dict[str, str]:
    """The std over seeds per method, as the claim states it (``L_critic (ours) 0.0039, ...``)."""
    text = _claim(r, prefix)["ours"].split(": ", 1)[1]
    pairs = dict(re.findall(r"(L_critic \(ours\)|DDPG|Meta-Critic) ([0-9.e+-]+)", text))
    if len(pairs) != 3:
        raise Missing(f"{prefix}: {text!r}")
    return pairs


def _and(items: list[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _held(r: dict) -> tuple[dict, str]:
    """The pooled held-out tables and the claims' prefix naming their seeds."""
    if "heldout" not in r or "tables" not in r["heldout"]:
        raise Missing("no held-out tables")
    held = r["heldout"]["tables"]
    return held, f"held-out goal seeds {', '.join(str(s) for s in held['seeds'])}"


def _counts(r: dict, claims: list[str], pattern: str) -> list[tuple[str, ...]]:
    """The numbers ``pattern`` reads from each claim's measurement."""
    return [_find(pattern, _claim(r, c)["ours"]) for c in claims]


def _ci(cell: dict) -> str:
    return f"{cell['mean']:.3f} [{cell['lo']:.3f}, {cell['hi']:.3f}]"


def rows(r: dict) -> list[tuple[str, str, str]]:
    """``(the paper claims, measured, verdict)`` per row, from a report's ``results.json``."""
    out = []
    held, where = _held(r)
    t1 = held["table1"]
    at = [t1["values"].index(s) for s in STDS]
    paper = " / ".join(f"{_cell(r, 'ours', s)['paper'][0]:g}" for s in STDS)
    cells = {
        m: " / ".join(_ci(t1["rows"][m][ci]) for ci in at) for m in ("ours", "ddpg", "meta-critic")
    }
    out.append(
        (
            f"Table 1 (KUKA, new goals): MSE {paper} at goal std {' / '.join(f'{s:g}' for s in STDS)}",
            f"{cells['ours']} (DDPG {cells['ddpg']}, Meta-Critic {cells['meta-critic']}; mean "
            f"[95% interval] over the {where})",
            _verdict(r, f"Table 1 ({where}): ours at the paper"),
        )
    )
    for who, claim in (
        ("ours", "ours below"),
        ("ours trained on the baselines' 1.2M KUKA environment steps", "ours at the baselines'"),
    ):
        tables = [f"Table {i} ({where}): {claim}" for i in (1, 2, 3)]
        below = _counts(
            r,
            tables,
            r"below both \(all seeds\) in (\d+) of (\d+) columns, its 95% interval wholly "
            r"below both in (\d+) of",
        )
        out.append(
            (
                f"Tables 1-3: {who} below DDPG and Meta-Critic (comparative: the share of columns)",
                f"below both in {_and([f'{a} of {b}' for a, b, _ in below])} columns; the 95% "
                f"intervals apart in {_and([c for _, _, c in below])}",
                _verdict(r, *tables),
            )
        )
    values = [f"Table {i} ({where}): ours at the paper" for i in (1, 2, 3)]
    hits = _counts(
        r,
        values,
        r"within its printed std in (\d+) of (\d+) columns \(strictly at or below its value: "
        r"(\d+) of",
    )
    out.append(
        (
            "Tables 1-3: ours at the paper's values (its printed decimals, within its printed std)",
            f"within in {_and([f'{w} of {n}' for w, n, _ in hits])} columns; strictly at or below "
            f"the paper in {_and([f'{x} of {n}' for _, n, x in hits])}",
            _verdict(r, *values),
        )
    )
    maps = r["heldout"].get("maps")
    if maps is None:
        raise Missing("no held-out maps")
    mwhere = f"held-out goal seeds {', '.join(str(s) for s in maps['seeds'])}"
    grid = {
        m: " / ".join(f"{maps['grid_mean'][axis][m]['mean']:.3f}" for axis in ("mass", "length"))
        for m in ("ours", "ddpg", "meta-critic")
    }
    won = " / ".join(str(maps["verdicts"][k]["below_all"]) for k in ("mass", "length"))
    out.append(
        (
            "Figures 5 / 6 (reacher, new link masses / lengths): ours better than the baselines",
            f"ours below every baseline in {won} of {maps['verdicts']['mass']['cells']} cells; "
            f"grid mean MSE {grid['ours']}; DDPG {grid['ddpg']}; Meta-Critic {grid['meta-critic']}",
            _verdict(r, f"Figure 5 ({mwhere})", f"Figure 6 ({mwhere})"),
        )
    )
    share = maps["goals_fraction_below_0.05"]
    out.append(
        (
            "Figure 4 (reacher): ours low over the whole goal space",
            f"{share['ours']:.0%} of the goal grid below 0.05 MSE (DDPG {share['ddpg']:.0%}, "
            f"Meta-Critic {share['meta-critic']:.0%})",
            _verdict(r, f"Figure 4 ({mwhere})"),
        )
    )
    for axis in ("iterations", "environment steps"):
        claim = f"ours solves training in fewer {axis}"
        first = {
            robot: _find(
                r"ours first at (\d+) of (\d+) levels",
                _claim(r, f"Figure 3 ({robot}): {claim}")["ours"],
            )
            for robot in ("reacher", "kuka")
        }
        out.append(
            (
                f"Figure 3: ours solves training in the fewest {axis}"
                + (" (the paper's text)" if axis == "iterations" else ""),
                f"first at {first['reacher'][0]} of {first['reacher'][1]} error levels (reacher) "
                f"and {first['kuka'][0]} of {first['kuka'][1]} (KUKA), counted when a running mean "
                "stays below the level",
                _verdict(r, f"Figure 3 (reacher): {claim}", f"Figure 3 (kuka): {claim}"),
            )
        )
    spread = {
        robot: _spread(r, f"Figure 3 ({robot}): ours is the") for robot in ("reacher", "kuka")
    }
    out.append(
        (
            "Figure 3: ours the least sensitive to the seed",
            "; ".join(
                f"{name}: {'std ' if name == 'reacher' else ''}{s['L_critic (ours)']} "
                f"(DDPG {s['DDPG']}, Meta-Critic {s['Meta-Critic']})"
                for name, s in (("reacher", spread["reacher"]), ("KUKA", spread["kuka"]))
            ),
            _verdict(r, "Figure 3 (reacher): ours is the", "Figure 3 (kuka): ours is the"),
        )
    )
    ours_share, sup_share = _find(
        r"descent from (\S+) of the grid reaches theta\* of the unseen goals with L_critic vs (\S+) "
        r"with Q_sup",
        _claim(r, "Figure 1")["ours"],
    )
    reach = (
        f"from {ours_share} of the grid with both"
        if ours_share == sup_share
        else f"from {ours_share} of the grid with L_critic, {sup_share} with Q_sup,"
    )
    out.append(
        (
            "Figure 1 (point-mass landscape): L_critic leads to unseen goals, a supervised Q does not",
            f"descent reaches them {reach} in the paper's setting",
            _verdict(r, "Figure 1"),
        )
    )
    return out


def block(r: dict) -> str:
    """The markdown table between the README's claims markers."""
    lines = ["| the paper claims | measured | verdict |", "|---|---|---|"]
    lines += [f"| {c} | {m} | {v} |" for c, m, v in rows(r)]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n")[0])
    mode = ap.add_mutually_exclusive_group(required=True)
    mode.add_argument("--write", action="store_true", help="rewrite README.md's claims block")
    mode.add_argument("--check", action="store_true", help="exit 1 if the block is not current")
    ap.add_argument("--results", type=Path, default=ROOT / "docs" / "paper" / "results.json")
    ap.add_argument("--readme", type=Path, default=ROOT / "README.md")
    args = ap.parse_args(argv)
    try:
        r = json.loads(args.results.read_text())
        text = args.readme.read_text()
        new = replace_block(text, BEGIN, END, block(r), str(args.readme))
    except (OSError, ValueError, KeyError, TypeError) as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    what = f"the claims block ({len(rows(r))} rows)"
    return check_or_write(args.readme, text, new, check=args.check, prog=PROG, what=what)


if __name__ == "__main__":
    sys.exit(main())
