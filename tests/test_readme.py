"""The README's table of the paper's claims quotes the committed report (docs/paper/results.json):
it is the block ``tools/readme_claims.py --write`` gives, and, read back independently of that tool,
every number in a row's "measured" cell is one the report holds for that row, and the verdicts are
the report's."""

from __future__ import annotations

import json
import re

from conftest import ROOT
from helpers import load_tool

NUMBER = re.compile(r"\d+(?:\.\d+)?%?")


def claims_table() -> dict[str, tuple[str, str]]:
    """``{claim cell: (measured cell, verdict cell)}`` of the README's claims table."""
    text = (ROOT / "README.md").read_text()
    block = text.split("<!-- claims:begin -->")[1].split("<!-- claims:end -->")[0]
    rows = [r.strip().strip("|").split("|") for r in block.strip().splitlines()[2:]]
    return {c.strip(): (m.strip(), v.strip()) for c, m, v in rows}


def report_sources() -> tuple[dict[str, tuple[list[str], list[str]]], dict[str, dict]]:
    """For each README row (a prefix of its claim cell): the numbers the report holds for it, and the
    report claims whose verdicts the row's verdict cell gives, in order; and the report's claims."""
    r = json.loads((ROOT / "docs" / "paper" / "results.json").read_text())
    claims = {c["claim"]: c for c in r["claims"]}

    def claim(prefix: str) -> dict:
        (found,) = [c for name, c in claims.items() if name.startswith(prefix)]
        return found

    held = r["heldout"]["tables"]
    where = f"held-out goal seeds {', '.join(str(x) for x in held['seeds'])}"
    mheld = r["heldout"]["maps"]
    mwhere = f"held-out goal seeds {', '.join(str(x) for x in mheld['seeds'])}"
    table1 = {(t["method"], t["value"]): t for t in r["tables"] if t["table"] == "table1"}
    stds = (0.1, 0.4)
    cols = [held["table1"]["values"].index(x) for x in stds]
    t1 = [
        f"{c[k]:.3f}"
        for m in ("ours", "ddpg", "meta-critic")
        for ci in cols
        for c in [held["table1"]["rows"][m][ci]]
        for k in ("mean", "lo", "hi")
    ]
    t1 += [f"{table1['ours', x]['paper'][0]:.2f}" for x in stds] + [f"{x:g}" for x in stds]
    t1 += [str(x) for x in held["seeds"]] + ["95%"]
    grid = mheld["grid_mean"]
    maps = [f"{grid[k][m]['mean']:.3f}" for k in ("mass", "length") for m in grid[k]]
    maps += [
        str(mheld["verdicts"][k][f]) for k in ("mass", "length") for f in ("below_all", "cells")
    ]
    goals = [f"{v:.0%}" for v in mheld["goals_fraction_below_0.05"].values()] + ["0.05"]

    def numbers(*prefixes: str) -> list[str]:
        return [n for p in prefixes for n in NUMBER.findall(claim(p)["ours"])] + ["95%"]

    def tables(what: str) -> list[str]:
        return [f"Table {i} ({where}): {what}" for i in (1, 2, 3)]

    below, equal, values = (
        tables("ours below"),
        tables("ours at the baselines'"),
        tables("ours at the paper"),
    )
    return {
        "Table 1 (KUKA": (t1, [f"Table 1 ({where}): ours at the paper"]),
        "Tables 1-3: ours below": (numbers(*below), below),
        "Tables 1-3: ours trained on the baselines'": (numbers(*equal), equal),
        "Tables 1-3: ours at": (numbers(*values), values),
        "Figures 5 / 6": (maps, [f"Figure 5 ({mwhere})", f"Figure 6 ({mwhere})"]),
        "Figure 4": (goals, [f"Figure 4 ({mwhere})"]),
        "Figure 3: ours solves training in the fewest iterations": (
            numbers(
                "Figure 3 (reacher): ours solves training in fewer it",
                "Figure 3 (kuka): ours solves training in fewer it",
            ),
            [
                "Figure 3 (reacher): ours solves training in fewer it",
                "Figure 3 (kuka): ours solves training in fewer it",
            ],
        ),
        "Figure 3: ours solves training in the fewest environment": (
            numbers(
                "Figure 3 (reacher): ours solves training in fewer env",
                "Figure 3 (kuka): ours solves training in fewer env",
            ),
            [
                "Figure 3 (reacher): ours solves training in fewer env",
                "Figure 3 (kuka): ours solves training in fewer env",
            ],
        ),
        "Figure 3: ours the least": (
            numbers("Figure 3 (reacher): ours is the", "Figure 3 (kuka): ours is the"),
            ["Figure 3 (reacher): ours is the", "Figure 3 (kuka): ours is the"],
        ),
        "Figure 1": (numbers("Figure 1"), ["Figure 1"]),
    }, claims


def problems(table: dict[str, tuple[str, str]]) -> list[str]:
    """Where ``table`` (the README's claims table) says other than the report."""
    sources, claims = report_sources()
    found = [] if len(table) == len(sources) else [f"{len(table)} rows, {len(sources)} expected"]
    for prefix, (numbers, verdicts) in sources.items():
        rows = [k for k in table if k.startswith(prefix)]
        if len(rows) != 1:
            found.append(f"{prefix}: {len(rows)} rows")
            continue
        measured, verdict = table[rows[0]]
        quoted = NUMBER.findall(measured)
        missing = [n for n in quoted if n not in numbers]
        if not quoted or missing:
            found.append(f"{prefix}: {missing or 'no number'} not in the report's {numbers}")
        said = [
            next(c["verdict"] for name, c in claims.items() if name.startswith(p)) for p in verdicts
        ]
        # a row over several claims with the same verdict says it once
        if verdict != (said[0] if len(set(said)) == 1 else " / ".join(said)):
            found.append(f"{prefix}: verdict {verdict!r}, the report's {said}")
    return found


def test_readme_claims_table_quotes_results_json():
    assert problems(claims_table()) == []


def test_a_number_or_verdict_other_than_the_report_is_found():
    table = claims_table()
    row = next(k for k in table if k.startswith("Table 1 (KUKA"))
    measured, verdict = table[row]
    assert "0.017" in measured
    assert problems({**table, row: (measured.replace("0.017", "0.019"), verdict)}) != []
    other = "met" if verdict == "not met" else "not met"
    assert problems({**table, row: (measured, other)}) != []


def test_readme_claims_block_is_the_one_the_tool_writes(capsys):
    tool = load_tool("readme_claims")
    assert tool.main(["--check"]) == 0, "python tools/readme_claims.py --write"


def test_the_tool_writes_what_results_json_says(tmp_path, capsys):
    """Another Table 1 cell or verdict in results.json gives another block: --check fails until
    --write; a report without a claim the table reads is one line, exit 2."""
    tool = load_tool("readme_claims")
    r = json.loads((ROOT / "docs" / "paper" / "results.json").read_text())
    readme = tmp_path / "README.md"
    readme.write_text((ROOT / "README.md").read_text())
    r["heldout"]["tables"]["table1"]["rows"]["ours"][0]["mean"] = 0.5
    next(c for c in r["claims"] if c["claim"].startswith("Figure 4"))["verdict"] = "met"
    results = tmp_path / "results.json"
    results.write_text(json.dumps(r))
    args = ["--results", str(results), "--readme", str(readme)]
    assert tool.main(["--check", *args]) == 1
    assert tool.main(["--write", *args]) == 0 and tool.main(["--check", *args]) == 0
    row = dict((c, (m, v)) for c, m, v in tool.rows(r))
    assert row["Table 1 (KUKA, new goals): MSE 0.02 / 0.07 at goal std 0.1 / 0.4"][0].startswith(
        "0.500"
    )
    assert row["Figure 4 (reacher): ours low over the whole goal space"][1] == "met"
    r["claims"] = [c for c in r["claims"] if not c["claim"].startswith("Figure 1")]
    results.write_text(json.dumps(r))
    capsys.readouterr()
    assert tool.main(["--check", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert "Figure 1" in err and len(err.splitlines()) == 1
