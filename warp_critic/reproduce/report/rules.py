"""The verdict rules of the report's claims table: one function and one quoted sentence per rule.

Each rule is as strict as the claim it judges, and the report prints the rule's sentence next to
its verdict:

* **maps** (Figures 4, 5 and 6, one rule): ours below :data:`MAP_LEVEL` MSE on at least
  :data:`MAP_SHARE` of the grid's cells *and* the lowest grid mean of every row shown; the
  cell-by-cell count (ours below every baseline row in N of the grid's cells) is shown beside it.
* **tables** (Tables 1-3): ours below every baseline row (all seeds and solved seeds) in every
  column *and* at or below the paper's own value for ours in every column the paper gives.
* **steps to a level** (Figure 3): a seed reaches a level at the first iteration after which the
  running mean of its training error over :data:`WINDOW` iterations stays at or below the level
  (not the first crossing, which favours noisy curves).
* **budgets** (Figure 3): the curves are compared within the common budget, the fewest
  environment steps any method ran; a level reached by some method counts against ours unless
  ours reaches it within the common budget, in every seed, in the fewest mean steps.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

#: iterations of the trailing running mean that must stay at or below a level (Figure 3)
WINDOW = 20
#: a map cell is "low" below this MSE (rad^2), and ours must be low on this share of the grid
MAP_LEVEL = 0.05
MAP_SHARE = 0.9

MAP_RULE = (
    f"rule (Figures 4-6 alike): met when ours is below {MAP_LEVEL:g} MSE on >= {MAP_SHARE:.0%} of "
    "the grid's cells and has the lowest grid mean of every row shown"
)
TABLE_RULE = (
    "rule (Tables 1-3 alike): met when ours is below every baseline row (all seeds and solved "
    "seeds) in every column and at or below the paper's own value for ours in every column the "
    "paper gives"
)
STEPS_RULE = (
    f"rule: a seed reaches a level at the first iteration after which the running mean of its "
    f"training error over {WINDOW} iterations stays at or below the level; met when, at every "
    "level some method reaches in all seeds, ours reaches it in all seeds within the common budget "
    "(the fewest env steps any method ran) and in the fewest mean env steps"
)

SPREAD_RULE = (
    "rule: met when ours has the smallest std over seeds of the training error at the common "
    "budget (the fewest env steps any method ran)"
)
LANDSCAPE_RULE = (
    "rule: met when, in the paper's setting, descent on L_critic reaches theta* of the unseen goals "
    "from a larger share of the grid than descent on Q_sup"
)


def settled_index(loss, level: float, window: int = WINDOW) -> int | None:
    """The first iteration after which the trailing running mean of ``loss`` over ``window``
    iterations (fewer at the start) stays at or below ``level`` to the end; ``None`` if it does
    not end there."""
    x = np.asarray(loss, dtype=float)
    if x.size == 0:
        return None
    c = np.concatenate([[0.0], np.cumsum(x)])
    k = np.arange(x.size)
    lo = np.maximum(k - window + 1, 0)
    running = (c[k + 1] - c[lo]) / (k + 1 - lo)
    above = np.nonzero(~(running <= level))[0]  # NaN counts as above
    if above.size == 0:
        return 0
    last = int(above[-1])
    return None if last == x.size - 1 else last + 1


def map_verdict(ours, baselines: Mapping[str, Any]) -> dict:
    """The maps' rule on per-cell MSEs: ``ours`` ``(cells,)``, ``baselines`` label -> ``(cells,)``.

    Returns verdict, share (ours' cells below :data:`MAP_LEVEL`), lowest (the label with the
    lowest grid mean, ``"ours"`` for ours), below_all (cells where ours is below every baseline),
    cells, worst (ours' worst cell) and worst_baseline (the worst cell of any baseline)."""
    o = np.asarray(ours, dtype=float)
    rows = {k: np.asarray(v, dtype=float) for k, v in baselines.items()}
    share = float((o < MAP_LEVEL).mean())
    means = {"ours": float(o.mean()), **{k: float(v.mean()) for k, v in rows.items()}}
    lowest = min(means, key=means.__getitem__)
    below = np.ones(o.shape, dtype=bool)
    for v in rows.values():
        below &= o < v
    lowest_ours = all(means["ours"] < m for k, m in means.items() if k != "ours")
    met = share >= MAP_SHARE and lowest_ours
    return {
        "verdict": "met" if met else "not met",
        "share": share,
        "lowest": lowest if not lowest_ours else "ours",
        "below_all": int(below.sum()),
        "cells": int(o.size),
        "worst": float(o.max()),
        "worst_baseline": max((float(v.max()) for v in rows.values()), default=float("nan")),
    }


def map_reason(v: dict) -> str:
    """The claims row's 'why' for :func:`map_verdict`'s result."""
    return (
        f"ours below {MAP_LEVEL:g} on {v['share']:.1%} of the cells; lowest grid mean: "
        f"{'ours' if v['lowest'] == 'ours' else v['lowest']}; ours below every baseline row in "
        f"{v['below_all']} of {v['cells']} cells; ours' worst cell {v['worst']:.3g} (the baselines' "
        f"worst {v['worst_baseline']:.3g}). {MAP_RULE}"
    )


def table_verdict(
    wins_all: tuple[int, int], wins_solved: tuple[int, int], paper: tuple[int, int]
) -> tuple[str, str]:
    """(verdict, reason) of a paper table: ``wins_*`` = (columns where ours is below every
    baseline row of that kind, comparable columns); ``paper`` = (columns where ours is at or below
    the paper's own value, columns the paper gives)."""
    (wa, ca), (ws, cs), (hp, cp) = wins_all, wins_solved, paper
    if ca == 0:
        return "not comparable", f"no column with every row. {TABLE_RULE}"
    below = wa == ca and (cs == 0 or ws == cs)
    at_paper = cp == 0 or hp == cp
    parts = [
        f"ours below both baselines in {wa} of {ca} columns (all seeds)"
        + (f", {ws} of {cs} (solved seeds)" if cs else "; no baseline seed solved training"),
        f"at or below the paper's value for ours in {hp} of {cp} columns",
    ]
    return ("met" if below and at_paper else "not met"), "; ".join(parts) + f". {TABLE_RULE}"


def sample_efficiency(full: dict, within: dict) -> tuple[str, str]:
    """(verdict, measurement) under :data:`STEPS_RULE`: ``full`` and ``within`` map method ->
    level -> {steps, never, ...} (:func:`~warp_critic.reproduce.report.paper.steps_to_levels` on the whole curves and
    on the curves cut at the common budget)."""
    from warp_critic.reproduce.experiments.settings import METHOD_LABELS

    def mean(t: dict, level: float) -> float:
        return float(np.mean(t[level]["steps"])) if t[level]["never"] == 0 else np.inf

    levels = sorted({lv for t in full.values() for lv in t}, reverse=True)
    parts, won, considered = [], 0, 0
    for level in levels:
        if all(np.isinf(mean(t, level)) for t in full.values()):
            continue
        considered += 1
        at = {m: mean(t, level) for m, t in within.items()}
        best = min(at.values())
        won += "ours" in at and np.isfinite(at["ours"]) and at["ours"] == best
        parts.append(
            f"{level:g}: "
            + ", ".join(
                f"{METHOD_LABELS[m]} {f'{v:.3g}' if np.isfinite(v) else 'not all seeds'}"
                for m, v in at.items()
            )
        )
    text = "mean env steps to stay below " + "; ".join(parts) if parts else "no level reached"
    if "ours" not in full or len(full) < 2:
        return "not comparable", text + " (a method missing)"
    if considered == 0:
        return "not comparable", text + " by any method"
    return ("met" if won == considered else "not met"), text + (
        f" (ours first at {won} of {considered} levels)"
    )
