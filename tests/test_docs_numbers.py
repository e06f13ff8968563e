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


def _find_int(text: str, pattern: str) -> tuple[str, ...]:
    m = re.search(pattern, text)
    assert m is not None, (pattern, text)
    return m.groups()


def _paper_hits(r: dict, table: str) -> int:
    return sum(
        bool(c["at_or_below_paper"])
        for c in r["tables"]
        if c["table"] == table and c["method"] == "ours" and c["paper"] is not None
    )


def _claim(r: dict, start: str) -> dict:
    return next(c for c in r["claims"] if c["claim"].startswith(start))


def _held(r: dict, table: int, what: str) -> dict:
    """The held-out seeds' claim of Table ``table`` that starts ``what`` (``ours at the paper``)."""
    seeds = ", ".join(str(s) for s in r["heldout"]["tables"]["seeds"])
    return _claim(r, f"Table {table} (held-out goal seeds {seeds}): {what}")


def _hcell(r: dict, method: str, std: float) -> float:
    t1 = r["heldout"]["tables"]["table1"]
    return t1["rows"][method][t1["values"].index(std)]["mean"]


def _stress(r: dict, table: str, field: str = "mse_mean", method: str = "ours") -> list[float]:
    cells = [c for c in r["tables"] if c["table"] == table and c["method"] == method]
    return [c[field] for c in sorted(cells, key=lambda c: c["value"])]


def _final(r: dict, robot: str, method: str) -> float:
    """The report's one final training error (mean of the last 10% iterations), mean over seeds."""
    return float(r["metatrain"][f"{robot}/{method}"]["final_mean"])


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
        "ours below every baseline in {} of 49 cells ({}); the lowest grid mean (ours {}, DDPG {}, "
        "Meta-Critic {}, TD3 {}); ours below 0.05 MSE on {} of the 7 x 7 cells; ours' worst cell "
        "{}, the baselines' {} |",
        lambda r: (
            str(r["maps"]["verdicts"]["mass"]["below_all"]),
            f"{r['maps']['verdicts']['mass']['below_all'] / r['maps']['verdicts']['mass']['cells']:.0%}",
            *(
                _g(r["maps"]["grid_means"]["mass"][f"this run: {k}"])
                for k in (
                    "L_critic (ours)",
                    "DDPG, all seeds",
                    "Meta-Critic, all seeds",
                    "TD3, all seeds",
                )
            ),
            f"{r['maps']['verdicts']['mass']['share']:.1%}",
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
        "so Table 1 is met and Tables 2-3 are not (strictly at or below the paper: {}, {} and {} of 10)",
        lambda r: tuple(
            _find_int(_held(r, t, "ours at the paper")["ours"], r"its value: (\d+) of")[0]
            for t in (1, 2, 3)
        ),
    ),
    (
        "RESULTS.md",
        "On goal seed 1 alone (stage `tables`, shown, not judged): MSE {} at std 0.1 and {} at std "
        "0.4, strictly at or below the paper in {}, {} and {} of 10 columns",
        lambda r: (
            _g(_cell(r, "table1", 0.1, "ours")),
            _g(_cell(r, "table1", 0.4, "ours")),
            *(str(_paper_hits(r, t)) for t in ("table1", "table2", "table3")),
        ),
    ),
    (
        "RESULTS.md",
        "within its printed std: within in {}, {} and {} of 10 columns, so Table {} is met",
        lambda r: (
            *(
                _find_int(_held(r, t, "ours at the paper")["ours"], r"std in (\d+) of")[0]
                for t in (1, 2, 3)
            ),
            "1" if _held(r, 1, "ours at the paper")["verdict"] == "met" else "none",
        ),
    ),
    # the held-out seeds' Table 1 and ours at the baselines' environment steps (issue 54, 3 and 5)
    (
        "RESULTS.md",
        "Table 1, ours: MSE {} at std 0.1 and {} at std 0.4 (paper 0.02 / 0.07; DDPG {} / {}, "
        "Meta-Critic {} / {}, TD3 {} / {})",
        lambda r: tuple(
            _g(_hcell(r, m, s)) for m in ("ours", "ddpg", "meta-critic", "td3") for s in (0.1, 0.4)
        ),
    ),
    (
        "RESULTS.md",
        "its interval wholly below both baselines' in {}, {} and {} columns",
        lambda r: tuple(
            _find_int(_held(r, t, "ours below")["ours"], r"wholly below both in (\d+) of")[0]
            for t in (1, 2, 3)
        ),
    ),
    (
        "RESULTS.md",
        "is below both baselines in {} of 10, {} of 11 and {} of 11 columns of Tables 1-3 on the "
        "held-out seeds (Table 1: {} at std 0.1 and {} at std 0.4, against ours' {} / {} at 9.6M)",
        lambda r: (
            *(
                _find_int(_held(r, t, "ours at the baselines'")["ours"], r"in (\d+) of")[0]
                for t in (1, 2, 3)
            ),
            _g(_hcell(r, "ours-equal-steps", 0.1)),
            _g(_hcell(r, "ours-equal-steps", 0.4)),
            _g(_hcell(r, "ours", 0.1)),
            _g(_hcell(r, "ours", 0.4)),
        ),
    ),
    (
        "RESULTS.md",
        "MSE {} at std 0.1 and {} at std 0.4",
        lambda r: (_g(_cell(r, "table1", 0.1, "ours")), _g(_cell(r, "table1", 0.4, "ours"))),
    ),
    (
        "docs/paper/README.md",
        "std 0.1 / 0.4: {} / {} (paper 0.02 / 0.07) |",
        lambda r: (_g(_hcell(r, "ours", 0.1)), _g(_hcell(r, "ours", 0.4))),
    ),
    (
        "docs/paper/README.md",
        "Table 1 std 0.1 / 0.4: {} / {} against ours' {} / {} at 9.6M |",
        lambda r: tuple(
            _g(_hcell(r, m, x)) for m in ("ours-equal-steps", "ours") for x in (0.1, 0.4)
        ),
    ),
    (
        "docs/paper/README.md",
        "ours below every baseline row in {} of 49 cells ({}); grid mean ours {} [{}, {}]",
        lambda r: (
            str(r["heldout"]["maps"]["verdicts"]["mass"]["below_all"]),
            f"{r['heldout']['maps']['verdicts']['mass']['below_all'] / 49:.0%}",
            *(
                _g(r["heldout"]["maps"]["grid_mean"]["mass"]["ours"][k])
                for k in ("mean", "lo", "hi")
            ),
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
    # the carried stages' compute (issue 54 item 6), in every mention of the end-to-end wall time
    (
        "docs/paper/README.md",
        "**Ten stages were carried in, not run**: their compute, each the larger of its record's "
        "time and its iteration times over all calls, is {} s ({} h)",
        lambda r: (
            f"{r['ledger']['carried_compute_seconds']:,.0f}",
            f"{r['ledger']['carried_compute_seconds'] / 3600:.1f}",
        ),
    ),
    (
        "README.md",
        "ten stages carried in from an earlier run ({} h of compute, not in the {} h)",
        lambda r: (
            f"{r['ledger']['carried_compute_seconds'] / 3600:.1f}",
            f"{(r['ledger']['wall_seconds']) / 3600:.1f}",
        ),
    ),
    (
        "RESULTS.md",
        "ten recipe stages carried in, whose compute, {} s ({} h), is not in it",
        lambda r: (
            f"{r['ledger']['carried_compute_seconds']:,.0f}",
            f"{r['ledger']['carried_compute_seconds'] / 3600:.1f}",
        ),
    ),
    (
        "docs/reproduce.md",
        "ten recipe stages it carried in from the earlier run ({} h of compute, not in the ledger's",
        lambda r: (f"{r['ledger']['carried_compute_seconds'] / 3600:.1f}",),
    ),
    # the stress tables (issue 54 item 7)
    (
        "docs/paper/README.md",
        "ours is 11-3,600x its floor ({}-{} against 7e-6-0.015), and below DDPG and Meta-Critic in "
        "every column (9 kg: {} against DDPG's {}); TD3 is below ours at 9 kg ({})",
        lambda r: (
            f"{_stress(r, 'stress_mass')[0]:.3g}",
            f"{_stress(r, 'stress_mass')[-1]:.3g}",
            f"{_stress(r, 'stress_mass')[-1]:.3g}",
            f"{_stress(r, 'stress_mass', method='ddpg')[-1]:.3g}",
            f"{_stress(r, 'stress_mass', method='td3')[-1]:.3g}",
        ),
    ),
    (
        "docs/paper/README.md",
        "ours sits at about 2x it from 0.8 m on ({}-{}), above every baseline ({}-{}) from 0.4 m on",
        lambda r: (
            f"{min(_stress(r, 'stress_length')[3:]):.3g}",
            f"{max(_stress(r, 'stress_length')[3:]):.3g}",
            f"{min(min(_stress(r, 'stress_length', method=m)) for m in ('ddpg', 'meta-critic', 'td3')):.3g}",
            f"{max(max(_stress(r, 'stress_length', method=m)) for m in ('ddpg', 'meta-critic', 'td3')):.3g}",
        ),
    ),
    # Table 2's solved-seed count (item 7): not "every column"
    (
        "RESULTS.md",
        "Ours below both baselines in every column of Tables 1-3 for all seeds, and for the seeds "
        "that solved training in {} of {} columns of Table 2",
        lambda r: tuple(
            _find_int(_held(r, 2, "ours below")["reason"], r"(\d+) of (\d+) \(solved seeds\)")
        ),
    ),
    # one definition of the final training error (item 7)
    (
        "RESULTS.md",
        "final training error (mean of the last 10% iterations, 5 seeds): KUKA ours {}, DDPG {}",
        lambda r: (_g(_final(r, "kuka", "ours")), _g(_final(r, "kuka", "ddpg"))),
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
    """docs/paper/README.md's table of the held-out seeds' verdicts (the claims the report judges
    there), each read from results.json."""
    r = _results()
    text = _text("docs/paper/README.md")
    seeds = ", ".join(str(s) for s in r["heldout"]["tables"]["seeds"])
    for start, row in (
        ("Table 1 ({}): ours below", "| Table 1: ours below the baselines | met | {} |"),
        ("Table 1 ({}): ours at the paper", "| Table 1: ours at the paper's values | met | {} |"),
        ("Table 2 ({}): ours below", "| Table 2: ours below the baselines | met | {} |"),
        (
            "Table 2 ({}): ours at the paper",
            "| Table 2: ours at the paper's values | not met | {} |",
        ),
        ("Table 3 ({}): ours below", "| Table 3: ours below the baselines | met | {} |"),
        (
            "Table 3 ({}): ours at the paper",
            "| Table 3: ours at the paper's values | not met | {} |",
        ),
        (
            "Table 1 ({}): ours at the baselines'",
            "| Tables 1-3 at equal environment steps (1.2M each): ours below the baselines | "
            "(not measured) | {} |",
        ),
        ("Figure 4 ({})", "| Figure 4: ours over the reacher's full state space | not met | {} |"),
        ("Figure 5 ({})", "| Figure 5: heavier / lighter links | met (42 of 49 cells) | {} |"),
        ("Figure 6 ({})", "| Figure 6: new link lengths | met (44 of 49 cells) | {} |"),
    ):
        claim = _claim(r, start.format(f"held-out goal seeds {seeds}"))
        assert row.format(claim["verdict"]) in text, start


@pytest.mark.parametrize("robot", ["reacher", "kuka"])
def test_the_budget_readme_quotes_its_sweep(robot):
    """docs/paper/budget/README.md's table rows: each method's chosen budget and errors, read from
    the sweep's JSON (warp-critic budget)."""
    from warp_critic.reproduce.budget import best_scale_at, numeric_keys

    b = json.loads((ROOT / "docs" / "paper" / "budget" / f"{robot}.json").read_text())
    text = _text("docs/paper/budget/README.md")
    labels = {"ours": "L_critic (ours)", "ddpg": "DDPG", "meta-critic": "Meta-Critic", "td3": "TD3"}
    for m, c in b["chosen"].items():
        own = next(
            x
            for x in b["report"][m]["cells"]
            if (x["scale"], x["steps"]) == (c["scale"], c["steps"])
        )
        if m == "ours":
            same = "-"
        else:
            scale, _ = best_scale_at(numeric_keys(b["sweep"]["ours"]["curve"]), c["steps"])
            same = _g(
                next(
                    x["mse_mean"]
                    for x in b["report"]["ours"]["cells"]
                    if (x["scale"], x["steps"]) == (scale, c["steps"])
                )
            )
        row = (
            f"| {labels[m]} | {c['steps']}, x{c['scale']:g} | {_g(c['mse_train'])} | "
            f"{_g(own['mse_mean'])} | {same} |"
        )
        assert row in text, row
