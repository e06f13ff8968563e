"""The report's section on each method's own meta-test budget: the choice on the training goals,
the curve of error against meta-test steps, and Tables 1-3 and the maps on the held-out goal seeds
with every method at its own budget and ours also at each baseline's number of steps.

Three pure parts: :func:`compute` (stage records -> a JSON-able dict for ``results.json``, the
claims included), :func:`plot` (that dict -> the curve figures, one per robot) and :func:`render`
(that dict -> markdown lines). :func:`budget_compute` and :func:`budget_render` are its section for
:mod:`~warp_critic.reproduce.report.write`. The pooling over seeds and the 95% intervals are the
held-out section's (:func:`~warp_critic.reproduce.report.heldout.pool_tables`,
:func:`~warp_critic.reproduce.report.heldout.pool_maps`); the verdicts its comparative rule
(:func:`~warp_critic.reproduce.report.rules.compare_verdict`), counted on two comparisons:

* **own budgets**: the cells (table columns; map goals and grid cells) where ours at its own budget
  is below every baseline at that baseline's own budget;
* **the baselines' budgets**: the (cell, baseline) pairs where ours, given the baseline's chosen
  number of steps (at ours' best step size there on the training goals), is below that baseline.

Only the stages that are complete count: a baseline enters the held-out comparison once its
reporting stage is complete on every held-out seed ours' is.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from warp_critic.evaluation.seed_uses import HELD_OUT_SEEDS
from warp_critic.reproduce.engine.stages import StageRecord
from warp_critic.reproduce.experiments.budget import (
    at_row,
    envelope,
    numeric_keys,
    with_shared_rows,
)
from warp_critic.reproduce.experiments.naming import BUDGET, stage_name
from warp_critic.reproduce.experiments.settings import ALL_METHODS, METHOD_LABELS, SCENES
from warp_critic.reproduce.report.heldout import COLUMN, TITLES, pool_maps, pool_tables
from warp_critic.reproduce.report.rules import COMPARE_SHARE, compare_verdict, map_verdict
from warp_critic.reproduce.report.section import Inputs, fmt, part

Recs = Mapping[str, StageRecord | None]
KINDS = ("goals", "mass", "length")
BUDGET_RULE = (
    f"rule: met when ours is below in at least {COMPARE_SHARE:.0%} of the compared cells (the "
    "comparative rule of Figures 5-6 and Tables 1-3), each method at its own chosen meta-test "
    "budget; pooled over the held-out goal seeds"
)
MAP_TITLES = {
    "goals": "Figure 4 (goal grid)",
    "mass": "Figure 5 (masses)",
    "length": "Figure 6 (lengths)",
}


# ------------------------------------------------------------------------------------------------
# compute
# ------------------------------------------------------------------------------------------------


def compute(recs: Recs, seeds: tuple[int, ...] = HELD_OUT_SEEDS) -> dict[str, Any]:
    """``{"choice": robot -> method -> {"scale", "steps", "mse_train", "untrained", "at_scale":
    {"N": MSE at the chosen scale}, "envelope": {"N": best MSE}, "stage"}, "tables", "maps", "claims"}``
    from the complete ``budget-*`` stages of ``recs`` (stage name -> record); MSE in rad^2.
    ``tables`` / ``maps`` are ``None`` until ours' reporting stage is complete on a seed."""
    choice: dict[str, dict] = {}
    for scene in SCENES:
        for m in ALL_METHODS:
            rec = recs.get(stage_name(BUDGET, scene, m))
            if rec is None:
                continue
            r, curve = rec.data["result"], numeric_keys(rec.data["result"]["curve"])
            c = r["chosen"]
            choice.setdefault(scene, {})[m] = {
                **c,
                "untrained": r["untrained"],
                # keys as results.json gives them back (strings), so the view round-trips unchanged
                "at_scale": {str(n): v for n, v in curve[float(c["scale"])].items()},
                "envelope": {str(n): v for n, v in envelope(curve).items()},
                "stage": rec.dir.name,
            }
    out: dict[str, Any] = {"choice": choice, "tables": None, "maps": None, "claims": []}
    tables = _reported(recs, "tables", seeds)
    if tables is not None:
        out["tables"] = _tables(*tables)
        out["claims"] += out["tables"].pop("claims")
    maps = _reported(recs, "maps", seeds)
    if maps is not None:
        out["maps"] = _maps(*maps)
        out["claims"] += out["maps"].pop("claims")
    return out


def _reported(recs: Recs, group: str, seeds: tuple[int, ...]):
    """``(seeds, baselines, [per seed: {method: result}], budgets)`` of the held-out ``group``
    stages at the chosen budgets: the seeds where ours' is complete and the baselines complete on
    all of them; ``budgets``: row -> ``{"steps", "scale"}``. ``None``: ours' on no seed."""
    got = [s for s in seeds if recs.get(stage_name(group, by="ours", heldout=s, budget=True))]
    if not got:
        return None

    def result(m: str, s: int) -> dict | None:
        rec = recs.get(stage_name(group, by=m, heldout=s, budget=True))
        return rec.data["result"] if rec is not None else None

    base = [m for m in ALL_METHODS if m != "ours" and all(result(m, s) for s in got)]
    # each row another stage computed, from it (a baseline whose row is in no complete stage: out)
    per = [
        with_shared_rows({m: r for m in ("ours", *base) if (r := result(m, s)) is not None})
        for s in got
    ]
    base = [m for m in base if all(m in p for p in per)]
    per = [{m: p[m] for m in ("ours", *base)} for p in per]
    budgets: dict[str, dict] = {}
    for r in per[0].values():
        for row, scale in r.get("alpha_scales", {}).items():
            budgets[row] = {"steps": int(r["policy_updates"]), "scale": float(scale)}
        for row, (_, src) in r.get("shared_rows", {}).items():
            budgets[row]["same_as"] = src  # one meta-test, shown in both rows
    return got, base, per, budgets


def _tables(seeds: list[int], base: list[str], per: list[dict], budgets: dict) -> dict:
    """Tables 1-3 pooled over ``seeds`` (every row of every method's stage) and their claims."""
    merged = [
        {"columns": p["ours"]["columns"], "cells": [c for r in p.values() for c in r["cells"]]}
        for p in per
    ]
    pooled = pool_tables(merged, {})
    claims = []
    for table, t in pooled.items():
        rows = t["rows"]
        cells = {row: [c["mean"] for c in v] for row, v in rows.items()}
        name = f"{TITLES[table]} ({_where(seeds)})"
        claims += _claims(name, cells, base, len(t["values"]), "column")
    return {"seeds": seeds, "baselines": base, "budgets": budgets, **pooled, "claims": claims}


def _maps(seeds: list[int], base: list[str], per: list[dict], budgets: dict) -> dict:
    """The reacher maps pooled over ``seeds``, one row at a time (each row's goal grid and 2-D
    grids as :func:`pool_maps` pools ours'), and their claims."""
    rows = ["ours", *[r for m in base for r in (m, at_row(m))]]
    grid_mean: dict[str, dict] = {k: {} for k in KINDS}
    cells: dict[str, dict] = {k: {} for k in KINDS}
    for row in rows:
        owner = row if row in per[0] else next(m for m in base if at_row(m) == row)
        one = [{k: {"ours": p[owner][k][row]} for k in KINDS} for p in per]
        pm = pool_maps(one)
        for k in KINDS:
            grid_mean[k][row] = pm["grid_mean"][k]["ours"]
            cells[k][row] = np.ravel(pm[k]["ours"]).tolist()
    claims = []
    for k in KINDS:
        name = f"{MAP_TITLES[k]} ({_where(seeds)})"
        claims += _claims(name, cells[k], base, len(cells[k]["ours"]), "cell")
    return {
        "seeds": seeds,
        "baselines": base,
        "budgets": budgets,
        "grid_mean": grid_mean,
        "cells": cells,
        "claims": claims,
    }


def _claims(name: str, cells: dict, base: list[str], n: int, unit: str) -> list[dict]:
    """The two comparative claims of one table or map (module docstring): ``cells`` row -> mean
    MSE per cell (``n`` cells, each a ``unit``)."""
    if not base:
        return []
    own = map_verdict(cells["ours"], {m: cells[m] for m in base})["below_all"]
    pairs = sum(map_verdict(cells[at_row(m)], {m: cells[m]})["below_all"] for m in base)
    out = []
    for what, below, total, of in (
        ("each method at its own meta-test budget: ours below every baseline", own, n, f"{unit}s"),
        (
            "at each baseline's own number of meta-test steps: ours below that baseline",
            pairs,
            n * len(base),
            f"({unit}, baseline) pairs",
        ),
    ):
        verdict, _ = compare_verdict(below, total)
        out.append(
            {
                "claim": f"{name}: {what}",
                "paper": "ours lowest (the paper: Algorithm 3 meta-tests 'while not done')",
                "ours": f"ours below in {below} of {total} {of} ({below / total:.0%})",
                "verdict": verdict,
                "reason": BUDGET_RULE,
            }
        )
    return out


def _where(seeds: list[int]) -> str:
    return f"held-out goal seeds {', '.join(map(str, seeds))}"


# ------------------------------------------------------------------------------------------------
# plot
# ------------------------------------------------------------------------------------------------


def plot_curves(per: dict[str, dict], path: Path, title: str, xlabel: str) -> Path:
    """Error against meta-test steps, one line per method of ``per`` (method -> ``{"curve": {N:
    MSE}, "untrained", "steps", "mse_train"}``): the curve (solid), the chosen budget (a ring), the
    untrained policies (dotted); log-log, MSE in rad^2."""
    from warp_critic.reproduce.report.plots import COLORS, figure, save

    fig = figure(6.5, 4.2)
    ax = fig.subplots()
    for m, c in per.items():
        points = sorted((int(n), v) for n, v in c["curve"].items())
        colour = COLORS.get(m)
        ns, ys = [n for n, _ in points], [v for _, v in points]
        ax.plot(ns, ys, "o-", color=colour, label=METHOD_LABELS.get(m, m))
        ax.axhline(c["untrained"], color=colour, ls=":", lw=1)
        ax.plot([c["steps"]], [c["mse_train"]], "o", ms=13, mfc="none", color=colour)
    ax.plot([], [], ":", color="grey", label="untrained policies")
    ax.plot([], [], "o", ms=13, mfc="none", color="grey", label="chosen (step size, N)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("final MSE on the training goals (rad$^2$)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    return save(fig, path)


def plot(computed: dict, figs: Path) -> list[tuple[str, Path, str]]:
    """One curve figure per robot of ``computed["choice"]`` under ``figs``: ``[(title, png,
    sentence)]``."""
    out = []
    for scene, per in computed["choice"].items():
        title = f"Meta-test budget ({scene}): error against critic-gradient steps"
        curves = {m: {**c, "curve": c["at_scale"]} for m, c in per.items()}
        png = plot_curves(
            curves,
            figs / f"budget_{scene}.png",
            title,
            "meta-test critic-gradient steps N (at each method's chosen step size)",
        )
        out.append(
            (
                title,
                png,
                "Each method's final MSE on its training goals after N critic-gradient steps at "
                "its chosen step size (goal seed 2000's initialisations); the ring marks the "
                "chosen budget, the dotted line the untrained policies.",
            )
        )
    return out


# ------------------------------------------------------------------------------------------------
# render
# ------------------------------------------------------------------------------------------------


def _label(row: str, budgets: dict) -> str:
    m = next((x for x in ALL_METHODS if row == at_row(x)), None)
    name = f"ours at {METHOD_LABELS[m]}'s steps" if m else METHOD_LABELS.get(row, row)
    b = budgets.get(row)
    return f"{name} ({b['steps']} steps, x{b['scale']:g})" if b else name


def _shared(budgets: dict) -> list[str]:
    """The sentence on rows that are another row's meta-test (the same steps and step size)."""
    same = [
        f"{_label(row, budgets)} is {_label(b['same_as'], budgets)}"
        for row, b in budgets.items()
        if "same_as" in b
    ]
    if not same:
        return []
    return [
        "The same meta-test shown in two rows (ours' row depends only on the number of steps "
        "and the step size: "
        "`warp_critic/reproduce/experiments/budget.py`): " + "; ".join(same) + ".",
        "",
    ]


def _ci(c: dict) -> str:
    return f"{fmt(c['mean'])} [{fmt(c['lo'])}, {fmt(c['hi'])}]"


def render(computed: dict) -> list[str]:
    """The section's markdown lines from :func:`compute`'s dict."""
    md = ["## Each method at its own meta-test budget", ""]
    if not computed["choice"]:
        return md + ["Not run (stages `budget-*`; `reproduce --beyond`).", ""]
    md += [
        "The paper's tables give every method ours' 3 critic-gradient steps; Algorithm 3 trains "
        "'while not done'. Here each method's budget (step size x its run's own, and number of "
        "steps) is chosen on its own training goals (initialisations from goal seed 2000, which "
        "chose nothing else), at the lowest mean final MSE of the sweep "
        "(`warp_critic/reproduce/experiments/budget.py`); the held-out tables and maps then "
        "give each method its own budget, and ours also each baseline's number of steps.",
        "",
    ]
    for scene, per in computed["choice"].items():
        ns = sorted({int(n) for c in per.values() for n in c["at_scale"]})
        md += [f"### Chosen budgets ({scene})", ""]
        md += [
            "| method | steps | x step size | MSE at the choice | untrained | "
            + " | ".join(f"N={n}" for n in ns)
            + " | stage |"
        ]
        md += ["|---" * (6 + len(ns)) + "|"]
        for m, c in per.items():
            curve = " | ".join(fmt(c["at_scale"].get(str(n), float("nan"))) for n in ns)
            md.append(
                f"| {METHOD_LABELS.get(m, m)} | {c['steps']} | {c['scale']:g} | "
                f"{fmt(c['mse_train'])} | {fmt(c['untrained'])} | {curve} | `{c['stage']}` |"
            )
        md += ["", "(N=...: the MSE after N steps at the chosen step size.)", ""]
    md += _render_tables(computed["tables"]) + _render_maps(computed["maps"])
    if computed["claims"]:
        md += [f"The verdicts ({BUDGET_RULE}):", ""]
    for c in computed["claims"]:
        md.append(f"- {c['claim']}: {c['ours']}: **{c['verdict']}**")
    return md + [""]


def _render_tables(t: dict | None) -> list[str]:
    if t is None:
        return ["Tables 1-3 at the chosen budgets: not run (`budget-*-tables-heldout`).", ""]
    md = []
    for table in ("table1", "table2", "table3"):
        p = t[table]
        md += [f"### {TITLES[table]} at the chosen budgets, {_where(t['seeds'])}", ""]
        md += ["| Method | " + " | ".join(f"{COLUMN[table]}={v:g}" for v in p["values"]) + " |"]
        md += ["|---" * (len(p["values"]) + 1) + "|"]
        md += ["| untrained policies | " + " | ".join(fmt(u) for u in p["untrained"]) + " |"]
        for row, cells in p["rows"].items():
            md.append(f"| {_label(row, t['budgets'])} | " + " | ".join(map(_ci, cells)) + " |")
        md.append("")
    return md + _shared(t["budgets"])


def _render_maps(m: dict | None) -> list[str]:
    if m is None:
        return ["The maps at the chosen budgets: not run (`budget-*-maps-heldout`).", ""]
    md = [f"### Figures 4-6 at the chosen budgets, {_where(m['seeds'])}", ""]
    md += [
        "| grid mean MSE [95% interval] | goal grid | mass grid | length grid |",
        "|---|---|---|---|",
    ]
    for row in m["grid_mean"]["goals"]:
        cells = " | ".join(_ci(m["grid_mean"][k][row]) for k in KINDS)
        md.append(f"| {_label(row, m['budgets'])} | {cells} |")
    return md + [""] + _shared(m["budgets"])


def budget_compute(inp: Inputs) -> dict:
    """The section's part of ``results.json`` (:func:`compute`; the curve figures written by
    :func:`plot`); its view is ``None`` when no ``budget-*`` stage is complete."""
    computed = compute(inp.recs)
    if not computed["choice"]:
        return part(None)
    figures = [inp.figure(t, png, s) for t, png, s in plot(computed, inp.figures_dir)]
    return part(computed, results={"budget": computed}, claims=computed["claims"], figures=figures)


def budget_render(view: dict | None) -> list[str]:
    """The section's markdown (:func:`render`); nothing when no budget stage is complete."""
    return [] if view is None else render(view)


__all__ = ["budget_compute", "budget_render", "compute", "plot", "plot_curves", "render"]
