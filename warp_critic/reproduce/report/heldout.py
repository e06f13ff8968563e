"""The held-out verdicts: KUKA Tables 1-3 and the reacher maps pooled over the goal seeds that chose
nothing, every number with a 95% bootstrap interval, and ours at the baselines' environment steps.

Goal seed 1 chose ours' settings (:mod:`~warp_critic.evaluation.seed_uses`), so the claims of
Tables 1-3 and Figures 4-6 are judged here, on the held-out seeds, whenever their stages are
complete; the seed-1 sections are then shown, not judged.

Pooling: a cell's value is the mean over the ``S`` meta-training seeds x ``K`` held-out goal
seeds of that pair's mean error (each pair scores the same number of policies). Its interval is a
crossed bootstrap (:func:`crossed_interval`): training seeds and goal seeds are resampled
independently, with replacement, :data:`RESAMPLES` times from a fixed generator, and the 2.5 and
97.5 percentiles of the resampled means are the bounds. Both kinds of seed are resampled because a
critic is trained once per training seed and each goal seed draws new goals and initialisations:
the interval says how much the number would move under other seeds of either kind.

The computations (:func:`pool_tables`, :func:`pool_maps`, :func:`judge_tables`,
:func:`judge_maps`) are pure functions of the stage results; the report's section
(:mod:`~warp_critic.reproduce.report.heldout_section`) gathers and renders them.
"""

from __future__ import annotations

import numpy as np

from warp_critic.evaluation.paper import PAPER_TABLE1, PAPER_TABLE2, PAPER_TABLE3
from warp_critic.reproduce.experiments.heldout import EQUAL_STEPS_ROW
from warp_critic.reproduce.experiments.settings import METHOD_LABELS, METHODS, present
from warp_critic.reproduce.report.rules import (
    COMPARE_RULE,
    PAPER_VALUE_RULE,
    compare_verdict,
    map_reason,
    map_verdict,
    paper_value_verdict,
    table_verdict,
)
from warp_critic.reproduce.report.section import fmt

#: bootstrap resamples per interval, and the generator's seed (the report regenerates identically)
RESAMPLES = 2000
BOOTSTRAP_SEED = 0
PAPER = {"table1": PAPER_TABLE1, "table2": PAPER_TABLE2, "table3": PAPER_TABLE3}
TITLES = {"table1": "Table 1", "table2": "Table 2", "table3": "Table 3"}
COLUMN = {"table1": "std", "table2": "mass", "table3": "length"}
EQUAL_LABEL = "ours at the baselines' environment steps"
KINDS = {"mass": "masses", "length": "lengths"}


def crossed_interval(v: np.ndarray, resamples: int = RESAMPLES) -> tuple[float, float, float]:
    """``(mean, lo, hi)`` of ``v`` ``(S, K)`` (training seed x goal seed): the mean and the 95%
    crossed-bootstrap interval of the mean (module docstring). ``inf`` entries (diverged worlds)
    make every bound ``inf``."""
    v = np.asarray(v, dtype=float)
    if not np.isfinite(v).all():
        return float("inf"), float("inf"), float("inf")
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    s, k = v.shape
    rows = rng.integers(0, s, size=(resamples, s))
    cols = rng.integers(0, k, size=(resamples, k))
    means = np.array([v[r][:, c].mean() for r, c in zip(rows, cols)])
    lo, hi = np.percentile(means, [2.5, 97.5])
    return float(v.mean()), float(lo), float(hi)


def _interval(v: np.ndarray) -> dict:
    mean, lo, hi = crossed_interval(v)
    return {"mean": mean, "lo": lo, "hi": hi}


def pool_tables(results: list[dict], solved: dict[str, list[bool]]) -> dict:
    """Tables 1-3 pooled over the held-out tables stages' ``results`` (one per goal seed, with the
    extra rows merged in): ``table -> {"values", "untrained", "rows": {row: [cell per column]}}``,
    a cell ``{"mean", "lo", "hi"}`` (MSE over the joints, rad^2). A baseline that solved training
    in some seeds (``solved``) also gets a ``"<m>:solved"`` row over those seeds only."""
    out: dict = {}
    first = results[0]
    for table in ("table1", "table2", "table3"):
        values = first["columns"][table]
        per = [
            {(c["column"], c["method"]): c for c in r["cells"] if c["table"] == table}
            for r in results
        ]
        rows: dict[str, list[dict]] = {}
        for m in dict.fromkeys(m for _, m in per[0]):
            # (S, K) per column: training seed x goal seed
            grids = [
                np.array([p[(ci, m)]["mse_per_seed"] for p in per]).T for ci in range(len(values))
            ]
            rows[m] = [_interval(g) for g in grids]
            keep = np.asarray(solved.get(m, []), dtype=bool)
            if m in solved and keep.size == grids[0].shape[0] and keep.any():
                rows[f"{m}:solved"] = [_interval(g[keep]) for g in grids]
        untrained = [
            float(np.mean([p[(ci, "ours")]["untrained_mse_mean"] for p in per]))
            for ci in range(len(values))
        ]
        out[table] = {"values": values, "untrained": untrained, "rows": rows}
    return out


def _wins(rows: dict, ours: str, solved_rows: bool) -> tuple[int, int, int]:
    """(columns where ``ours`` is below every paper baseline, columns comparable, columns where
    ours' interval lies wholly below every baseline's): all seeds, or each baseline's solved-seed
    row where it has one (``solved_rows``)."""
    baselines = [m for m in METHODS if m != "ours" and m in rows]
    if solved_rows:
        baselines = [f"{m}:solved" for m in baselines if f"{m}:solved" in rows]
        if not baselines:
            return 0, 0, 0
    wins = apart = 0
    n = len(rows[ours])
    for ci in range(n):
        o = rows[ours][ci]
        wins += all(o["mean"] < rows[b][ci]["mean"] for b in baselines)
        apart += all(o["hi"] < rows[b][ci]["lo"] for b in baselines)
    return wins, n, apart


def judge_tables(pooled: dict, seeds: list[int]) -> list[dict]:
    """The claims rows of Tables 1-3 on the held-out seeds: ours below the paper's baselines
    (:func:`~warp_critic.reproduce.report.rules.table_verdict`), ours at the paper's values, and,
    where ours at the baselines' environment steps was evaluated, the same comparison for it."""
    where = f"held-out goal seeds {', '.join(str(s) for s in seeds)}"
    claims = []
    for table, t in pooled.items():
        rows, name = t["rows"], f"{TITLES[table]} ({where})"
        for ours, label in (("ours", "ours"), (EQUAL_STEPS_ROW, EQUAL_LABEL)):
            if ours not in rows:
                continue
            wa, ca, apart = _wins(rows, ours, False)
            ws, cs, _ = _wins(rows, ours, True)
            verdict, reason = table_verdict((wa, ca), (ws, cs))
            claims.append(
                {
                    "claim": f"{name}: {label} below DDPG and Meta-Critic"
                    + (" (equal environment steps)" if ours != "ours" else ""),
                    "paper": "ours lowest in every column",
                    "ours": f"{label} below both (all seeds) in {wa} of {ca} columns, its 95% "
                    f"interval wholly below both in {apart} of {ca}",
                    "verdict": verdict,
                    "reason": reason,
                }
            )
        paper = PAPER[table].get("ours", {})
        refs = [paper.get(v) for v in t["values"]]
        v_paper, measured, _ = paper_value_verdict([c["mean"] for c in rows["ours"]], refs)
        claims.append(
            {
                "claim": f"{name}: ours at the paper's values",
                "paper": "the paper's row for ours, mean(std)",
                "ours": measured,
                "verdict": v_paper,
                "reason": PAPER_VALUE_RULE,
            }
        )
    return claims


def pool_maps(results: list[dict], solved: dict[str, list[bool]] | None = None) -> dict:
    """The reacher maps pooled over the held-out maps stages' ``results``: per method, the goal
    grid's per-goal MSE and each 2-D grid's per-cell MSE averaged over the goal seeds, and every
    grid's mean with its crossed-bootstrap interval (``"grid_mean": kind -> method -> cell``). A
    baseline that solved training in some seeds (``solved``) also gets a ``"<m>:solved"`` row of
    each 2-D grid over those seeds only, as the seed-1 maps compare."""
    first = results[0]
    methods = present(first["goals"])
    goals = {m: np.mean([r["goals"][m]["mse"] for r in results], axis=0).tolist() for m in methods}
    out: dict = {
        "goals": goals,
        "goals_fraction_below_0.05": {
            m: float((np.asarray(g) < 0.05).mean()) for m, g in goals.items()
        },
        "grid_mean": {"goals": {}},
    }
    for m in methods:
        out["grid_mean"]["goals"][m] = _interval(
            np.array([r["goals"][m]["mse_per_seed"] for r in results]).T
        )
    for kind in ("mass", "length"):
        kinds = present(first[kind])
        out[kind] = {
            m: np.mean([[c["mse_mean"] for c in r[kind][m]] for r in results], axis=0).tolist()
            for m in kinds
        }
        for m, ok in (solved or {}).items():
            keep = np.asarray(ok, dtype=bool)
            if m in kinds and keep.any() and keep.size == len(first[kind][m][0]["mse_per_seed"]):
                out[kind][f"{m}:solved"] = np.mean(
                    [
                        [np.asarray(c["mse_per_seed"])[keep].mean() for c in r[kind][m]]
                        for r in results
                    ],
                    axis=0,
                ).tolist()
        # (S, K): each (training seed, goal seed) pair's mean over the grid's cells
        out["grid_mean"][kind] = {
            m: _interval(
                np.array(
                    [np.mean([c["mse_per_seed"] for c in r[kind][m]], axis=0) for r in results]
                ).T
            )
            for m in kinds
        }
    return out


def judge_maps(pooled: dict, seeds: list[int]) -> tuple[list[dict], dict]:
    """The claims rows of Figures 4-6 on the held-out seeds, under the same rules as on seed 1:
    Figure 4's absolute map rule, Figures 5-6 comparative cell by cell; and the verdicts' numbers
    (``goals`` / ``mass`` / ``length`` -> :func:`~warp_critic.reproduce.report.rules.map_verdict`)."""
    where = f"held-out goal seeds {', '.join(str(s) for s in seeds)}"
    base = [m for m in METHODS if m != "ours"]
    claims = []
    g = pooled["goals"]
    v4 = map_verdict(g["ours"], {METHOD_LABELS[m]: g[m] for m in base if m in g})
    verdicts = {"goals": v4}
    claims.append(
        {
            "claim": f"Figure 4 ({where}): ours generalises over the full state space of the reacher",
            "paper": "goal map: ours low everywhere, the baselines only near the training goals",
            "ours": _grid_means(pooled, "goals"),
            "verdict": v4["verdict"],
            "reason": map_reason(v4),
        }
    )
    for fig_no, kind in ((5, "mass"), (6, "length")):
        cells = pooled[kind]
        rows = [m for m in base if m in cells] + [
            f"{m}:solved" for m in base if f"{m}:solved" in cells
        ]
        v = map_verdict(cells["ours"], {row_label(m): cells[m] for m in rows})
        verdict, share = compare_verdict(v["below_all"], v["cells"])
        v["verdict"], v["rule"] = verdict, "comparative"
        verdicts[kind] = v
        claims.append(
            {
                "claim": f"Figure {fig_no} ({where}): ours generalises to "
                + ("heavier / lighter links" if kind == "mass" else "new link lengths")
                + " better than the baselines",
                "paper": f"2-D map over the {KINDS[kind]} of both links; ours lowest",
                "ours": _grid_means(pooled, kind),
                "verdict": verdict,
                "reason": f"{share} (every baseline row: all seeds and the seeds that solved "
                f"training). {COMPARE_RULE}",
            }
        )
    return claims, verdicts


def _grid_means(pooled: dict, kind: str) -> str:
    return "grid mean MSE [95% interval]: " + ", ".join(
        f"{METHOD_LABELS[m]} {ci_text(c)}" for m, c in pooled["grid_mean"][kind].items()
    )


def ci_text(c: dict) -> str:
    return f"{fmt(c['mean'])} [{fmt(c['lo'])}, {fmt(c['hi'])}]"


def row_label(row: str) -> str:
    if row == EQUAL_STEPS_ROW:
        return f"{METHOD_LABELS['ours']}, trained on the baselines' environment steps"
    m, _, solved = row.partition(":")
    return METHOD_LABELS.get(m, m) + (", seeds that solved training" if solved else "")


__all__ = [
    "crossed_interval",
    "judge_maps",
    "judge_tables",
    "pool_maps",
    "pool_tables",
]
