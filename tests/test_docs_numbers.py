"""The numbers that README.md, RESULTS.md and the docs quote from the paper-setting report agree
with the published ``docs/paper/results.json`` (each read from the results, formatted, and looked
up in the text with its line breaks folded)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "paper" / "results.json"


def _results() -> dict:
    return json.loads(RESULTS.read_text())


def _text(name: str) -> str:
    return re.sub(r"\s+", " ", (ROOT / name).read_text())


def _g(x: float) -> str:
    return f"{x:.3g}"


def _e(x: float) -> str:
    """4.96e5 style (the docs' short scientific form)."""
    m, e = f"{x:.2e}".split("e")
    return f"{float(m):g}e{int(e)}"


def _cell(r: dict, table: str, value: float, method: str) -> float:
    return next(
        c["mse_mean"]
        for c in r["tables"]
        if c["table"] == table and c["value"] == value and c["method"] == method
    )


def _at_budget(r: dict, robot: str, method: str) -> float:
    return float(np.mean(r["metatrain"][f"{robot}/error_at_budget"][method]))


def _steps(r: dict, robot: str, method: str, level: str) -> float:
    return float(np.mean(r["metatrain"][f"{robot}/steps_to_levels"][method][level]["steps"]))


def _paper_hits(r: dict, table: str) -> int:
    return sum(
        bool(c["at_or_below_paper"])
        for c in r["tables"]
        if c["table"] == table and c["method"] == "ours" and c["paper"] is not None
    )


def _claim(r: dict, start: str) -> dict:
    return next(c for c in r["claims"] if c["claim"].startswith(start))


#: (file, template with {} for the value, value read from results.json)
QUOTES = [
    # Meta-Critic against DDPG (issue 45, item 9)
    (
        "docs/paper/README.md",
        "reacher training error at 1.28M steps {} (Meta-Critic) against {} (DDPG)",
        lambda r: (
            _g(_at_budget(r, "reacher", "meta-critic")),
            _g(_at_budget(r, "reacher", "ddpg")),
        ),
    ),
    (
        "docs/paper/README.md",
        "goal-grid mean {} against {}; KUKA training error at 1.2M steps {} against {}",
        lambda r: (
            _g(r["maps"]["goals_mse_mean"]["meta-critic"]),
            _g(r["maps"]["goals_mse_mean"]["ddpg"]),
            _g(_at_budget(r, "kuka", "meta-critic")),
            _g(_at_budget(r, "kuka", "ddpg")),
        ),
    ),
    (
        "docs/paper/README.md",
        "Table 1 at std 0.1 {} against {}.",
        lambda r: (
            _g(_cell(r, "table1", 0.1, "meta-critic")),
            _g(_cell(r, "table1", 0.1, "ddpg")),
        ),
    ),
    # the maps under one rule (item 1)
    (
        "RESULTS.md",
        "below 0.05 on only {} / {} of the cells and below every baseline in {} / {} of 49",
        lambda r: (
            f"{r['maps']['verdicts']['mass']['share']:.1%}",
            f"{r['maps']['verdicts']['length']['share']:.1%}",
            str(r["maps"]["verdicts"]["mass"]["below_all"]),
            str(r["maps"]["verdicts"]["length"]["below_all"]),
        ),
    ),
    (
        "docs/paper/README.md",
        "ours below 0.05 MSE on {} of the 7 x 7 cells",
        lambda r: (f"{r['maps']['verdicts']['mass']['share']:.1%}",),
    ),
    (
        "docs/paper/README.md",
        "below every baseline in {} of 49 cells; ours' worst cell {}, the baselines' {} |",
        lambda r: (
            str(r["maps"]["verdicts"]["mass"]["below_all"]),
            _g(r["maps"]["verdicts"]["mass"]["worst"]),
            _g(r["maps"]["verdicts"]["mass"]["worst_baseline"]),
        ),
    ),
    # the tables against the paper's own values (item 2)
    (
        "docs/reproduce.md",
        "MSE {} at std 0.1 and {} at std 0.4, pooled over 5 seeds (paper 0.02 / 0.07), at or below "
        "the paper in {} of 10 columns",
        lambda r: (
            _g(_cell(r, "table1", 0.1, "ours")),
            _g(_cell(r, "table1", 0.4, "ours")),
            str(_paper_hits(r, "table1")),
        ),
    ),
    (
        "RESULTS.md",
        "so Tables 1-3 are not met ({}, {} and {} of 10)",
        lambda r: tuple(str(_paper_hits(r, t)) for t in ("table1", "table2", "table3")),
    ),
    (
        "RESULTS.md",
        "MSE {} at std 0.1 and {} at std 0.4",
        lambda r: (_g(_cell(r, "table1", 0.1, "ours")), _g(_cell(r, "table1", 0.4, "ours"))),
    ),
    # the tables on a goal seed that chose nothing (item 6)
    (
        "RESULTS.md",
        "on goal seed {}, which chose nothing (stage `tables-heldout`), ours is at or below the "
        "paper in {}, {} and {} of 10 columns (Table 1 {}; std 0.1 / 0.4: {} / {})",
        lambda r: (
            str(r["tables_heldout"]["seed"]),
            *(
                str(r["tables_heldout"][t]["ours_at_or_below_paper"][0])
                for t in ("table1", "table2", "table3")
            ),
            _claim(r, "Table 1, held-out")["verdict"],
            _g(r["tables_heldout"]["table1"]["ours"][0]),
            _g(r["tables_heldout"]["table1"]["ours"][3]),
        ),
    ),
    # the stage-time sum the report's header prints (item 11)
    (
        "docs/paper/README.md",
        "the report's header sums {} stage times to {} s ({} h;",
        lambda r: (
            str(len(r["stages"])),
            f"{r['ledger']['stage_seconds_sum']:,.0f}",
            f"{r['ledger']['stage_seconds_sum'] / 3600:.1f}",
        ),
    ),
    # steps to a level (item 4)
    (
        "RESULTS.md",
        "ours is first at 0.1 and 0.03 rad^2 (at 0.03 {} env steps; Meta-Critic in {} of 5 seeds, "
        "DDPG in {} of 5)",
        lambda r: (
            _e(_steps(r, "reacher", "ours", "0.03")),
            str(5 - r["metatrain"]["reacher/steps_to_levels"]["meta-critic"]["0.03"]["never"]),
            str(5 - r["metatrain"]["reacher/steps_to_levels"]["ddpg"]["0.03"]["never"]),
        ),
    ),
]


# ids from the file and the quote only: a lambda's repr differs between processes, and pytest-xdist's
# workers must collect the same ids
@pytest.mark.parametrize(
    "name,template,values", QUOTES, ids=[f"{n}-{t[:40]}" for n, t, _ in QUOTES]
)
def test_quoted_numbers_match_the_published_results(name, template, values):
    quote = template.format(*values(_results()))
    assert quote in _text(name), f"{name} does not quote: {quote}"


def test_verdicts_quoted_in_the_docs_match_the_claims_table():
    r = _results()
    text = _text("docs/paper/README.md")
    for start, row in (
        ("Figure 5", "| Figure 5: heavier / lighter links (2-D, both reacher links) | {} |"),
        ("Figure 6", "| Figure 6: new link lengths (2-D) | {} |"),
        ("Table 1", "| Table 1: ours below the baselines, at the paper's level | {} |"),
        ("Figure 4", "| Figure 4: ours generalises over the reacher's full state space | {} |"),
        ("Table 1, held-out", "| Table 1 on held-out goal seed 1000 (chose nothing) | {} |"),
        ("Table 2, held-out", "| Table 2 on held-out goal seed 1000 | {} |"),
    ):
        assert row.format(_claim(r, start)["verdict"]) in text, start
