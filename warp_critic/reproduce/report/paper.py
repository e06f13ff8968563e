"""The report's reading of the paper's protocol: steps to error levels (Figure 3 at equal budgets),
"seeds that solved the training task" rows for the baselines, 2-D reacher maps (Figures 5-6), stress
tables with reachability floors, and the claims table whose verdicts are computed from the numbers.

Definitions (stated in the report):

* **steps to a level**: the first iteration after which the running mean of the training error
  ``||q_T - g||^2`` (rad^2, summed over the joints; the curve of Figure 3) over
  :data:`~warp_critic.reproduce.report.rules.WINDOW` iterations stays at or below the level (:mod:`~warp_critic.reproduce.report.rules`), as environment steps
  ``(iteration + 1) x steps per iteration`` and as wall time (the sum of the iteration times up to
  it); mean and min-max over the seeds that reach it, and the count that never does.
* **solved the training task** (the paper: "for our baselines, we selected seeds that solved the
  task during training"): a seed whose final training error (mean of its last 10% iterations) is at
  or below :data:`SOLVED` of its robot.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from warp_critic.methods import method
from warp_critic.reproduce.experiments.settings import ALL_METHODS, METHOD_LABELS, METHODS, present
from warp_critic.reproduce.report.plots import diverged_cmap, log_limits
from warp_critic.reproduce.report.rules import (
    WINDOW,
    final_training_error,
    sample_efficiency,
    settled_index,
)

LEVELS = (0.3, 0.1, 0.03)
#: rad^2 (summed over the joints): a baseline seed "solved the training task" at or below this final
#: training error -- about the error band our method trains to on each robot (reacher ~0.01,
#: KUKA ~0.2), so that the comparison is between methods that learned the training task.
SOLVED = {"reacher": 0.1, "kuka": 0.3}
#: the paper's baselines: the claims ("ours below both") compare ours with these
BASELINES = tuple(m for m in METHODS if method(m).baseline)
#: every registered baseline: each gets its rows wherever its stages exist
ALL_BASELINES = tuple(m for m in ALL_METHODS if method(m).baseline)


def _fmt(x: float) -> str:
    return f"{x:.3g}"


# -- Figure 3: steps to error levels ----------------------------------------------------------------


def seed_curves(res: dict) -> dict[str, dict]:
    """seed -> {loss (iterations,), steps (iterations,), seconds (iterations,) or None}."""
    out = {}
    per = res["env_steps_per_iteration"]
    for seed, v in sorted(res["seeds"].items(), key=lambda kv: int(kv[0])):
        loss = np.asarray(v["task_loss"], dtype=float)
        sec = v.get("seconds_each")
        out[seed] = {
            "loss": loss,
            "steps": (np.arange(len(loss)) + 1) * per,
            "seconds": np.cumsum(sec) if sec else None,
        }
    return out


def solved_seeds(res: dict, scene: str) -> list[bool]:
    """Per seed (seed order): did it solve the training task (:data:`SOLVED`)?"""
    return [final_training_error(c["loss"]) <= SOLVED[scene] for c in seed_curves(res).values()]


def steps_to_levels(
    res: dict, budget: float | None = None, window: int = WINDOW
) -> dict[float, dict]:
    """level -> {steps: [per reaching seed], seconds: [...], never: int, seeds: int}: a seed reaches
    a level at :func:`~warp_critic.reproduce.report.rules.settled_index` (the running mean over ``window`` iterations stays at
    or below it to the end of the curve, the curve cut at ``budget`` env steps when given)."""
    curves = seed_curves(res)
    out = {}
    for level in LEVELS:
        steps, secs, never = [], [], 0
        for c in curves.values():
            n = len(c["loss"]) if budget is None else int(np.sum(c["steps"] <= budget))
            k = settled_index(c["loss"][:n], level, window)
            if k is None:
                never += 1
                continue
            steps.append(int(c["steps"][k]))
            if c["seconds"] is not None:
                secs.append(float(c["seconds"][k]))
        out[level] = {"steps": steps, "seconds": secs, "never": never, "seeds": len(curves)}
    return out


def error_at_budget(res: dict, budget: float, window: int = WINDOW) -> list[float]:
    """Per seed: the training error at ``budget`` environment steps, the running mean over the
    ``window`` iterations up to the last iteration within it (the steps rule's smoothing)."""
    out = []
    for c in seed_curves(res).values():
        k = max(int(np.searchsorted(c["steps"], budget, side="right")) - 1, 0)
        out.append(float(np.mean(c["loss"][max(k + 1 - window, 0) : k + 1])))
    return out


def per_iteration(res: dict) -> dict:
    """The stage result with one "step" per iteration: steps-to-level and budgets in iterations."""
    return {**res, "env_steps_per_iteration": 1}


def steps_lines(levels: dict[str, dict]) -> list[str]:
    """Markdown rows of one robot's steps-to-level table: ``levels`` is method -> level (a number
    or its string, as ``results.json`` keys it) -> :func:`steps_to_levels`'s entry."""
    lines = [
        "| method | level (rad^2) | env steps to reach: mean [min, max] | seeds never reaching | wall time to reach (s): mean [min, max] |",
        "|---|---|---|---|---|",
    ]
    for m, t in levels.items():
        for level, v in t.items():
            st = (
                f"{np.mean(v['steps']):.3g} [{min(v['steps']):.3g}, {max(v['steps']):.3g}]"
                if v["steps"]
                else "—"
            )
            wt = (
                f"{np.mean(v['seconds']):.0f} [{min(v['seconds']):.0f}, {max(v['seconds']):.0f}]"
                if v["seconds"]
                else "—"
            )
            lines.append(
                f"| {METHOD_LABELS[m]} | {float(level):g} | {st} | {v['never']} of {v['seeds']} | {wt} |"
            )
    return lines


def sample_efficiency_verdict(
    data: dict, within: dict | None = None, unit: str = "env steps"
) -> tuple[str, str]:
    """(verdict, measurement) for 'ours reaches the training error levels in fewer steps', under
    :func:`~.rules.steps_rule`: ``data`` from the whole curves, ``within`` from the curves cut at
    the common budget (the same when the budgets are equal); counted in ``unit``."""
    return sample_efficiency(data, data if within is None else within, unit)


# -- two rows per baseline -------------------------------------------------------------------------


def solved_cell(cell: dict, solved: list[bool]) -> tuple[float, float] | None:
    """(mean, std) of a cell over the solved seeds only (pooled, equal policies per seed)."""
    means = np.asarray(cell["mse_per_seed"], dtype=float)
    if len(solved) != len(means) or not any(solved):
        return None
    keep = np.asarray(solved)
    mean = float(means[keep].mean())
    stds = cell.get("mse_std_per_seed")
    if stds is None:
        return mean, float("nan")
    var = np.mean(np.asarray(stds, dtype=float)[keep] ** 2 + means[keep] ** 2) - mean**2
    return mean, float(np.sqrt(max(var, 0.0)))


#: the start of the label of a row of this run's numbers (beside the paper's own rows)
THIS_RUN = "this run: "


def shown(label: str) -> str:
    """A row's label as a sentence names it: without :data:`THIS_RUN`."""
    return label.removeprefix(THIS_RUN)


class Row(NamedTuple):
    """One row of this run's numbers: its shown label, its method's registry name, ``(mean, std)``
    or ``None`` per column, and whether it holds only the seeds that solved training."""

    label: str
    method: str
    values: list
    solved_only: bool = False


def method_rows(
    cells_of, n_cols: int, solved: dict[str, list[bool]], fmt_cell, shown=METHODS
) -> list[Row]:
    """Rows: ours, then each baseline with all seeds and with its solved seeds; ``shown``: the
    methods with numbers (default the paper's)."""
    rows: list[Row] = []
    for m in shown:
        rows.append(
            Row(
                f"{THIS_RUN}{METHOD_LABELS[m]}" + (", all seeds" if m != "ours" else ""),
                m,
                [(c["mse_mean"], c["mse_std"]) for c in (cells_of(ci, m) for ci in range(n_cols))],
            )
        )
        if m in ALL_BASELINES:
            ok = solved.get(m, [])
            label = (
                f"{THIS_RUN}{METHOD_LABELS[m]}, seeds that solved training ({sum(ok)} of {len(ok)})"
            )
            vals = [solved_cell(cells_of(ci, m), ok) for ci in range(n_cols)]
            rows.append(Row(label, m, vals, solved_only=True))
    return rows


def beats_baselines(rows: list[Row], n_cols: int, which: str) -> tuple[int, int]:
    """(columns where ours is below every baseline row of ``which`` ('all' / 'solved'), comparable)."""
    ours = next(r for r in rows if r.method == "ours").values
    pick = [r for r in rows if r.method in BASELINES and r.solved_only == (which == "solved")]
    wins = comparable = 0
    for ci in range(n_cols):
        others = [r.values[ci] for r in pick if r.values[ci] is not None]
        if not others or len(others) < len(pick):
            continue
        comparable += 1
        wins += all(ours[ci][0] < o[0] for o in others)
    return wins, comparable


def diverged_line(n: int) -> str:
    """The report's sentence for ``n`` evaluated worlds whose state went non-finite."""
    return (
        f"{n} evaluated world(s) went non-finite: the scene's dt is unstable for that variant under "
        "that policy's torques (`tools/probe_variants.py` shows which variants are). Each counts as an "
        "infinite error: its cell's mean is inf (black in the figures) and it is never below a threshold."
    )


# -- Figures 5-6: 2-D maps --------------------------------------------------------------------------


def plot_grid_2d(path: Path, M: dict, kind: str, figure) -> None:
    """One panel per method over (link 1, link 2) values, one log colour scale for all three."""
    from matplotlib.colors import LogNorm

    values = M["masses"] if kind == "mass" else M["lengths"]
    n = len(values)
    shown = present(M[kind])
    grids = {
        m: np.ma.masked_invalid(np.array([c["mse_mean"] for c in M[kind][m]]).reshape(n, n))
        for m in shown
    }
    lo, hi = log_limits(grids.values())
    trained = M["trained_mass"] if kind == "mass" else M["trained_length"]
    fig = figure(13 * len(shown) / 3, 4.2)
    axes = fig.subplots(1, len(shown))
    im = None
    for ax, m in zip(axes, shown):
        im = ax.imshow(
            grids[m].T, origin="lower", cmap=diverged_cmap(), norm=LogNorm(vmin=lo, vmax=hi)
        )
        ti = [int(np.argmin(np.abs(np.asarray(values) - t))) for t in trained]
        ax.plot(ti[0], ti[1], "x", color="red", markersize=12, mew=2.5, label="as trained")
        ax.set_xticks(range(n), [f"{v:g}" for v in values], fontsize=7)
        ax.set_yticks(range(n), [f"{v:g}" for v in values], fontsize=7)
        unit = "kg" if kind == "mass" else "m"
        ax.set_xlabel(f"link 1 {kind} ({unit})")
        ax.set_ylabel(f"link 2 {kind} ({unit})")
        bad = int(np.ma.count_masked(grids[m]))
        mean = f"{grids[m].filled(np.inf).mean():.3g}"
        ax.set_title(
            f"{METHOD_LABELS[m]}: mean MSE {mean}" + (f" ({bad} diverged, black)" if bad else ""),
            fontsize=9,
        )
    axes[0].legend(fontsize=7, loc="upper right")
    fig.subplots_adjust(left=0.05, right=0.84, bottom=0.15, top=0.9, wspace=0.3)
    cax = fig.add_axes([0.86, 0.15, 0.012, 0.75])  # one colour bar for the three panels
    fig.colorbar(im, cax=cax, label="MSE at the training goals (rad^2)")
    fig.savefig(path, dpi=90)


def grid_summary(M: dict, kind: str, solved: dict[str, list[bool]]) -> tuple[dict, list[Row]]:
    """The numbers of a 2-D grid's table (:func:`grid_lines`): its size ``n`` and per row (two per
    baseline) its ``label``, ``method``, mean MSE over the grid, MSE at the trained pair and worst
    cell (``None`` where a cell is missing), with ``means`` (label -> mean); and the rows."""
    values = M["masses"] if kind == "mass" else M["lengths"]
    trained = M["trained_mass"] if kind == "mass" else M["trained_length"]
    n = len(values)
    ti = [int(np.argmin(np.abs(np.asarray(values) - t))) for t in trained]
    k = ti[0] * n + ti[1]
    cells = M[kind]
    rows = method_rows(lambda ci, m: cells[m][ci], n * n, solved, None, present(cells))
    out: list[dict] = []
    means = {}
    for label, m, vals, _solved in rows:
        if any(v is None for v in vals):
            out.append({"label": label, "method": m, "mean": None})
            continue
        mu = [v[0] for v in vals]
        means[label] = float(np.mean(mu))
        out.append(
            {
                "label": label,
                "method": m,
                "mean": means[label],
                "at_trained": mu[k],
                "worst": max(mu),
            }
        )
    return {"n": n, "rows": out, "means": means}, rows


def grid_lines(kind: str, g: dict) -> list[str]:
    """Markdown rows of :func:`grid_summary`'s numbers ``g`` for ``kind`` (mass, length)."""
    n = g["n"]
    lines = [
        f"| {kind} grid ({n} x {n}) | mean MSE over the grid | MSE at the trained pair | worst cell |",
        "|---|---|---|---|",
    ]
    for r in g["rows"]:
        if r["mean"] is None:
            lines.append(f"| {r['label']} | — | — | — |")
            continue
        lines.append(
            f"| {r['label']} | {_fmt(r['mean'])} | {_fmt(r['at_trained'])} | {_fmt(r['worst'])} |"
        )
    return lines
