"""The report's section on the held-out goal seeds: Tables 1-3 and Figures 4-6 pooled over the goal
seeds that chose nothing (:mod:`~warp_critic.reproduce.report.heldout`) with their claims, and ours
meta-trained at the baselines' environment steps; a pure compute and render
(:mod:`~warp_critic.reproduce.report.section`)."""

from __future__ import annotations

from collections.abc import Mapping

from warp_critic.reproduce.experiments.heldout import EQUAL_STEPS_ROW
from warp_critic.reproduce.experiments.naming import BUDGET, stage_name
from warp_critic.reproduce.experiments.settings import METHOD_LABELS, METHODS, SCENES
from warp_critic.reproduce.report.heldout import (
    COLUMN,
    RESAMPLES,
    TITLES,
    ci_text,
    judge_maps,
    judge_tables,
    pool_maps,
    pool_tables,
    row_label,
)
from warp_critic.reproduce.report.section import Inputs, fmt, part


def heldout_records(recs: Mapping, group: str) -> tuple[list[int], list[dict]]:
    """The held-out seeds whose ``group`` stage (tables or maps) is complete in ``recs`` (stage
    name -> record or None), and their results (the extra rows merged in), in seed order."""
    from warp_critic.evaluation.seed_uses import HELD_OUT_SEEDS

    seeds, results = [], []
    for seed in HELD_OUT_SEEDS:
        rec = recs.get(stage_name(group, heldout=seed))
        if rec is not None:
            seeds.append(seed)
            results.append(rec.data["result"])
    return seeds, results


def judged_on_heldout(recs: Mapping, group: str) -> bool:
    """Whether the claims of ``group`` (tables, maps) are judged on the held-out seeds (some
    held-out stage of it is complete): the seed-1 section then shows its numbers, unjudged."""
    return bool(heldout_records(recs, group)[0])


def heldout_compute(inp: Inputs) -> dict:
    """The pooled held-out tables and maps with their intervals, and their claims."""
    seeds, tables = heldout_records(inp.recs, "tables")
    mseeds, maps = heldout_records(inp.recs, "maps")
    if not tables and not maps:
        return part(None)
    out: dict = {}
    own = any(inp.recs.get(stage_name(BUDGET, s, "ours")) is not None for s in SCENES)
    view: dict = {
        "equal_steps": equal_steps(inp.recs),
        "tables": None,
        "maps": None,
        "own_budgets": own,  # the report's own-budget section is there
    }
    claims: list[dict] = []
    if tables:
        pooled = pool_tables(tables, inp.solved.get("kuka", {}))
        out["tables"] = view["tables"] = {"seeds": seeds, **pooled}
        claims += judge_tables(pooled, seeds)
    if maps:
        pm = pool_maps(maps, inp.solved.get("reacher", {}))
        map_claims, verdicts = judge_maps(pm, mseeds)
        out["maps"] = {
            "seeds": mseeds,
            "grid_mean": pm["grid_mean"],
            "goals_fraction_below_0.05": pm["goals_fraction_below_0.05"],
            "verdicts": verdicts,
        }
        view["maps"] = {"seeds": mseeds, "grid_mean": pm["grid_mean"]}
        claims += map_claims
    return part(view, results={"heldout": out}, claims=claims)


def heldout_render(v: dict | None) -> list[str]:
    """The held-out section's lines (``v``: :func:`heldout_compute`'s view)."""
    md = ["## The claims on the held-out goal seeds (Tables 1-3, Figures 4-6)", ""]
    if v is None:
        return md + ["Not run (stages `tables-heldout`, `maps-heldout`).", ""]
    md += [
        "Goal seed 1 chose ours' settings, so the claims of Tables 1-3 and Figures 4-6 are judged "
        "here, on goal seeds that chose nothing (`warp_critic/evaluation/seed_uses.py`). Each "
        "number is the mean over the meta-training seeds x held-out goal seeds; in brackets its "
        f"95% crossed-bootstrap interval ({RESAMPLES} resamples of both kinds of seed; "
        "`warp_critic/reproduce/report/heldout.py`). Every method gets the same "
        "critic-gradient steps as on seed 1 "
        + (
            "(the section 'Each method at its own meta-test budget' gives each method the steps "
            "and step size chosen on its training goals)."
            if v.get("own_budgets")
            else "(each method's own meta-test budget: `warp-critic budget`, or `reproduce "
            "--beyond`)."
        ),
        "",
    ]
    if v["equal_steps"]:
        md += [" ".join(_equal_steps_sentence(e) for e in v["equal_steps"]), ""]
    if v["tables"] is not None:
        md += _tables_lines(v["tables"])
    if v["maps"] is not None:
        grid = v["maps"]["grid_mean"]
        md += [
            f"### Figures 4-6, held-out goal seeds {', '.join(map(str, v['maps']['seeds']))}",
            "",
        ]
        md += ["| grid mean MSE [95% interval] | goal grid | mass grid | length grid |"]
        md += ["|---|---|---|---|"]
        for m in grid["goals"]:
            cells = [grid[k].get(m) for k in ("goals", "mass", "length")]
            md.append(
                f"| {row_label(m)} | " + " | ".join(ci_text(c) if c else "—" for c in cells) + " |"
            )
        md.append("")
    return md


def equal_steps(recs: Mapping) -> list[dict]:
    """Per robot where it ran, ours' meta-training at the baselines' environment steps: its
    iterations, steps per iteration and stage folder, and each paper method's full-run steps
    (``others``), read from the meta-training stages' records."""
    from warp_critic.reproduce.experiments.settings import SCENES

    out = []
    for scene in SCENES:
        eq = recs.get(stage_name("metatrain", scene, "ours", equal_steps=True))
        if eq is None:
            continue
        r = eq.data["result"]
        other = {}
        for m in METHODS:
            rec = recs.get(stage_name("metatrain", scene, m))
            if rec is not None:
                res = rec.data["result"]
                other[m] = res["iterations"] * res["env_steps_per_iteration"]
        out.append(
            {
                "scene": scene,
                "iterations": r["iterations"],
                "per_iteration": r["env_steps_per_iteration"],
                "dir": eq.dir.name,
                "others": other,
            }
        )
    return out


def _equal_steps_sentence(e: dict) -> str:
    """The sentence on ours' meta-training at the baselines' environment steps on one robot."""
    steps = e["iterations"] * e["per_iteration"]
    return (
        f"Equal budgets ({e['scene']}): the row '{row_label(EQUAL_STEPS_ROW)}' is ours meta-trained "
        f"anew, with its settings, for {e['iterations']} iterations x "
        f"{e['per_iteration']} environment steps = {steps:,} steps (its learning-rate "
        "schedule over those iterations; stage "
        f"`{e['dir']}`); the full run: "
        + ", ".join(f"{METHOD_LABELS[m]} {v:,}" for m, v in e["others"].items())
        + " steps."
    )


def _tables_lines(pooled: dict) -> list[str]:
    """The pooled Tables 1-3 (``pooled``: :func:`pool_tables`'s tables and ``seeds``)."""
    md: list[str] = []
    seeds = ", ".join(map(str, pooled["seeds"]))
    for table in TITLES:
        if table not in pooled:
            continue
        t = pooled[table]
        md += [f"### {TITLES[table]}, held-out goal seeds {seeds}", ""]
        md += ["| Method | " + " | ".join(f"{COLUMN[table]}={v:g}" for v in t["values"]) + " |"]
        md += ["|---" * (len(t["values"]) + 1) + "|"]
        md += [
            "| untrained policies (no update) | "
            + " | ".join(fmt(u) for u in t["untrained"])
            + " |"
        ]
        for row, cells in t["rows"].items():
            md.append(f"| {row_label(row)} | " + " | ".join(ci_text(c) for c in cells) + " |")
        md.append("")
    return md
