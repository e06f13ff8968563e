"""The claims table's verdict rules (warp_critic/reproduce/report/rules.py), each on small synthetic stage
data where the earlier, more lenient rule said "met" and the rule now applied says "not met"."""

from __future__ import annotations

import numpy as np

from warp_critic.evaluation.paper import PAPER_TABLE2
from warp_critic.reproduce.report import paper as rp
from warp_critic.reproduce.report import rules
from warp_critic.reproduce.report.tables import BASELINE_MARK, MARK, table_markdown
from warp_critic.reproduce.report.training import budget_sentence


class _Rec:
    def __init__(self, result):
        self.data = {"result": result}


def _train(curves: dict[str, list[float]], per: int = 100) -> _Rec:
    return _Rec(
        {
            "env_steps_per_iteration": per,
            "seeds": {
                s: {"task_loss": c, "seconds_each": [1.0] * len(c)} for s, c in curves.items()
            },
        }
    )


# -- rule 1: one rule for Figures 4-6 ---------------------------------------------------------------


def _maps(ours: np.ndarray, base: np.ndarray) -> dict:
    """A 3 x 3 mass grid of a maps stage: ours and two baselines (per-cell means, two seeds)."""

    def cells(v):
        return [
            {"mse_mean": float(x), "mse_std": 0.0, "mse_per_seed": [float(x)] * 2}
            for x in v.ravel()
        ]

    return {
        "masses": [0.5, 1.0, 2.0],
        "trained_mass": [1.0, 1.0],
        "mass": {"ours": cells(ours), "ddpg": cells(base), "meta-critic": cells(base * 1.1)},
    }


def test_maps_rule_needs_the_share_below_005_not_only_the_lowest_mean():
    ours = np.array([0.01, 0.3, 0.3, 0.3, 0.001, 0.3, 0.3, 0.3, 0.3])
    base = np.full(9, 0.35)
    base[0] = 0.005  # a baseline below ours in one cell
    M = _maps(ours, base)
    _, g = rp.grid_summary(M, "mass", {})
    means = g["means"]
    ours_mean = next(v for k, v in means.items() if "(ours)" in k)
    # the earlier Figures 5-6 rule: ours has the lowest grid mean -> met
    assert all(ours_mean < v for k, v in means.items() if "(ours)" not in k)
    cells = {
        lab: [c[0] for c in vals]
        for lab, _m, vals in g["rows"]
        if all(c is not None for c in vals)  # no solved rows: no seed flags given
    }
    ours_cells = cells.pop(next(k for k in cells if "(ours)" in k))
    v = rules.map_verdict(ours_cells, cells)
    assert v["verdict"] == "not met"
    assert v["share"] == 2 / 9 and v["lowest"] == "ours"
    assert v["below_all"] == 8 and v["cells"] == 9
    assert "8 of 9 cells" in rules.map_reason(v) and rules.MAP_RULE in rules.map_reason(v)
    # the same rule is met where ours is low nearly everywhere and lowest
    good = rules.map_verdict(np.full(9, 0.01), {"DDPG": np.full(9, 0.2)})
    assert good["verdict"] == "met" and good["below_all"] == 9


# -- rule 2: the tables also need the paper's own values ------------------------------------------


def _tables(ours: list[float]) -> dict:
    cols = sorted(PAPER_TABLE2["ours"])
    cells = []
    for m, vals in (
        ("ours", ours),
        ("ddpg", [0.2] * len(cols)),
        ("meta-critic", [0.3] * len(cols)),
    ):
        for ci, x in enumerate(vals):
            cells.append(
                {
                    "table": "table2",
                    "column": ci,
                    "method": m,
                    "mse_mean": x,
                    "mse_std": 0.01,
                    "mse_per_seed": [x, x],
                    "n": 4,
                    "runs": ["run/seed0", "run/seed1"],
                }
            )
    return {"columns": {"table2": cols}, "trained": {"table2": 3.0}, "cells": cells}


def test_table_rule_needs_ours_at_or_below_the_papers_value():
    ours = [0.15] + [0.05] * 9  # below both baselines everywhere, 2.3x the paper at 0 kg
    solved = {"ddpg": [True, True], "meta-critic": [True, False]}
    lines, _, summary, wins = table_markdown("table2", _tables(ours), "x/stage.json", solved)
    (wa, ca), (ws, cs) = wins["all"], wins["solved"]
    # the earlier rule: ours below both baselines in every column -> met
    assert wa == ca == 10 and ws == cs == 10
    assert wins["paper"] == (9, 10)
    verdict, reason = rules.table_verdict(wins["all"], wins["solved"], wins["paper"])
    assert verdict == "not met"
    assert "9 of 10 columns" in reason and rules.TABLE_RULE in reason
    assert rules.table_verdict(wins["all"], wins["solved"], (10, 10))[0] == "met"
    # rule 3: a baseline's mark says the paper's gap is not reproduced, apart from ours' mark
    ours_line = next(line for line in lines if line.startswith("| this run: L_critic"))
    assert f" {MARK} " in ours_line and BASELINE_MARK not in ours_line
    ddpg = next(line for line in lines if line.startswith("| this run: DDPG, all seeds"))
    assert BASELINE_MARK in ddpg  # 0.2 is below the paper's DDPG (3.7 at 0 kg)
    assert f" {MARK} " not in ddpg and not ddpg.endswith(f" {MARK} |")
    assert any("the paper's gap not reproduced" in s for s in summary)


# -- rule 4: steps to a level: the running mean stays below, not the first crossing --------------


def test_steps_rule_needs_the_running_mean_to_stay_below_the_level():
    n = 60
    ours = [1.0, 0.02] + [0.5] * (n - 2)  # one lucky dip, then far above every level
    base = list(np.linspace(1.0, 0.2, n // 2)) + [0.01] * (n // 2)  # falls and stays low
    got = {"ours": _train({"0": ours, "1": ours}), "ddpg": _train({"0": base, "1": base})}
    # the earlier rule: the first crossing -> ours first at every level -> met
    first = {
        m: {lv: min(np.nonzero(np.asarray(c) <= lv)[0]) for lv in rp.LEVELS}
        for m, c in (("ours", ours), ("ddpg", base))
    }
    assert all(first["ours"][lv] < first["ddpg"][lv] for lv in rp.LEVELS)
    _, data = rp.steps_table(got)
    assert data["ours"][0.03]["never"] == 2 and data["ddpg"][0.03]["never"] == 0
    verdict, text = rp.sample_efficiency_verdict(data)
    assert verdict == "not met" and "ours first at 0 of 3 levels" in text
    assert rules.settled_index([1.0, 0.02, 0.5, 0.01, 0.01], 0.1, window=1) == 3
    assert rules.settled_index([0.01, 0.5], 0.1, window=1) is None


# -- rule 5: unequal budgets are compared within the common budget ---------------------------------


def test_budget_rule_compares_within_the_common_budget():
    # ours runs 40 iterations (4,000 steps) and settles below 0.3 only after 2,000; the baseline
    # runs 20 iterations (2,000 steps) and stays at 0.35
    ours = [1.0] * 25 + [0.2] * 15
    base = [0.35] * 20
    got = {"ours": _train({"0": ours}), "ddpg": _train({"0": base})}
    full = {m: rp.steps_to_levels(r.data["result"], window=1) for m, r in got.items()}
    # the earlier rule (whole curves): ours reaches 0.3, the baseline never -> met
    assert rp.sample_efficiency_verdict(full, full)[0] == "met"
    budget = 2000
    within = {m: rp.steps_to_levels(r.data["result"], budget, window=1) for m, r in got.items()}
    verdict, text = rp.sample_efficiency_verdict(full, within)
    assert verdict == "not met" and "0 of 1 levels" in text
    s = budget_sentence({"ours": 4000, "ddpg": 2000})
    assert "Unequal budgets" in s and "2x" in s and "common 2e+03" in s
    assert budget_sentence({"ours": 10, "ddpg": 10}).startswith("Equal budgets")
