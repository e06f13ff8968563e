"""The report's Figure 3 section: training curves, steps to error levels and the errors at a
common environment-step budget, with the sample-efficiency and seed-sensitivity claims."""

from __future__ import annotations

import numpy as np

from warp_critic.reproduce.engine.stages import STAGE_FILE
from warp_critic.reproduce.experiments.naming import stage_name
from warp_critic.reproduce.experiments.settings import ALL_METHODS, METHOD_LABELS, METHODS, SCENES
from warp_critic.reproduce.report import paper as rp
from warp_critic.reproduce.report.departures import departures_line
from warp_critic.reproduce.report.draft import Draft, fmt
from warp_critic.reproduce.report.plots import plot_metatrain
from warp_critic.reproduce.report.rules import SPREAD_RULE, STEPS_RULE, WINDOW


def metatrain_section(d: Draft) -> None:
    """Figure 3: meta-training of the three methods on both robots."""
    d.md += ["## Figure 3: meta-training (reacher, KUKA)", ""]
    for scene in SCENES:
        got = {
            m: rec
            for m in ALL_METHODS
            if (rec := d.recs.get(stage_name("metatrain", scene, m))) is not None
        }
        if not got:
            d.md += [f"{scene}: not run (stage `metatrain`).", ""]
            continue
        png = d.figs / f"fig3_metatrain_{scene}.png"
        summary = plot_metatrain(png, scene, got)
        _curves_table(d, scene, got, summary)
        lines, levels = rp.steps_table(got)
        budget = min(s["env_steps"] for s in summary.values())
        at_budget = {m: rp.error_at_budget(got[m].data["result"], budget) for m in got}
        d.md += (
            [
                f"Environment steps and wall time to reach each training-error level (rad^2, summed over "
                f"the joints) and stay there: the first iteration after which the running mean over "
                f"{WINDOW} iterations stays at or below it to the end of the run; mean [min, max] over "
                f"the seeds that reach it. "
                f"Training error at the common budget of {budget:.3g} steps, mean(std) over seeds: "
                + ", ".join(
                    f"{METHOD_LABELS[m]} {fmt(float(np.mean(v)))}({fmt(float(np.std(v)))})"
                    for m, v in at_budget.items()
                )
                + ".",
                "",
            ]
            + lines
            + [""]
        )
        d.results["metatrain"][f"{scene}/steps_to_levels"] = {
            m: {str(k): v for k, v in lv.items()} for m, lv in levels.items()
        }
        d.results["metatrain"][f"{scene}/error_at_budget"] = {"budget": budget, **at_budget}
        _scene_claims(d, scene, got, summary, levels, at_budget, budget, png)


def _curves_table(d: Draft, scene: str, got: dict, summary: dict) -> None:
    """The robot's table of iterations, steps and final errors per method, into ``d``."""
    md, results = d.md, d.results
    md += [
        f"### {scene}",
        "",
        departures_line(scene, d.recs),
        "",
        "| method | iterations | env steps | env steps counted | final ||q_T-g||^2 mean(std) over seeds | first iteration |",
        "|---|---|---|---|---|---|",
    ]
    for m, s in summary.items():
        res = got[m].data["result"]
        md.append(
            f"| {METHOD_LABELS[m]} | {s['iterations']} | {s['env_steps']} | {res['env_steps_counted']} | "
            f"{fmt(s['final_mean'])}({fmt(s['final_std'])}) | {fmt(s['first_mean'])} |"
        )
        results["metatrain"][f"{scene}/{m}"] = {
            **s,
            "file": f"{got[m].dir.name}/{STAGE_FILE}",
            "runs": [
                f"{got[m].dir.name}/{v['run_dir']}/metrics.jsonl" for v in res["seeds"].values()
            ],
        }
    md.append("")
    if "meta-critic" in got:
        alive = aux_alive_of(got["meta-critic"])
        bases = aux_alive_bases_of(got["meta-critic"])
        results["metatrain"][f"{scene}/meta-critic"]["aux_alive"] = alive
        results["metatrain"][f"{scene}/meta-critic"]["aux_alive_basis"] = bases
        md += [aux_alive_sentence(alive, bases), ""]


def _scene_claims(
    d: Draft, scene: str, got: dict, summary: dict, levels: dict, at_budget: dict, budget, png
) -> None:
    """The robot's sample-efficiency and seed-sensitivity claims, and Figure 3's sentence."""
    # the paper's claims compare ours with the paper's baselines (an extra one is shown only)
    claimed = [m for m in got if m in METHODS]
    within = {m: rp.steps_to_levels(got[m].data["result"], budget) for m in claimed}
    verdict, measured = rp.sample_efficiency_verdict(
        {m: v for m, v in levels.items() if m in METHODS}, within
    )
    d.claims.append(
        {
            "claim": f"Figure 3 ({scene}): ours is more sample efficient (fewer steps to solve training)",
            "paper": "training curves over iterations; ours falls fastest",
            "ours": measured + f" (within the common budget of {budget:.3g} env steps)",
            "verdict": verdict,
            "reason": budget_sentence(
                {m: s["env_steps"] for m, s in summary.items() if m in METHODS}
            )
            + f" {STEPS_RULE}",
        }
    )
    spread: dict[str, float] = {m: float(np.std(v)) for m, v in at_budget.items() if m in METHODS}
    if "ours" in spread and len(spread) > 1:
        least = min(spread, key=spread.__getitem__)
        d.claims.append(
            {
                "claim": f"Figure 3 ({scene}): ours is the least sensitive to the seed",
                "paper": "narrowest band over seeds",
                "ours": f"std over seeds of the training error at {budget:.3g} steps: "
                + ", ".join(f"{METHOD_LABELS[m]} {fmt(v)}" for m, v in spread.items()),
                "verdict": "met" if least == "ours" else "not met",
                "reason": f"smallest spread: {METHOD_LABELS[least]}. {SPREAD_RULE}",
            }
        )
        sentence = (
            f"Figure 3 ({scene}): training error vs iterations and environment steps. At the common "
            f"budget of {budget:.3g} steps the lowest mean error is "
            f"{METHOD_LABELS[min(at_budget, key=lambda m: np.mean(at_budget[m]))]}'s and the smallest "
            f"spread over seeds {METHOD_LABELS[least]}'s; sample efficiency (steps to levels): {verdict}."
        )
    else:
        sentence = f"Figure 3 ({scene}): training curves of the methods that ran."
    d.figures.append((f"Figure 3: meta-training {scene}", png, sentence))


def budget_sentence(env_steps: dict[str, int]) -> str:
    """The claims row's statement of the methods' budgets (env steps per method)."""
    each = ", ".join(f"{METHOD_LABELS[m]} {v:.3g}" for m, v in env_steps.items())
    if len(set(env_steps.values())) <= 1:
        return f"Equal budgets ({each} env steps)."
    low = min(env_steps.values())
    return (
        f"Unequal budgets ({each} env steps): the stages ran a fixed number of iterations each, and "
        f"the shorter ones were not extended (matching the longest budget would take "
        f"{max(env_steps.values()) / low:.0f}x their iterations and hours). The "
        f"verdict is taken within the common {low:.3g} steps: a level ours reaches only after it "
        f"counts as not reached, and the std over seeds is read at {low:.3g} steps."
    )


def aux_alive_of(rec) -> list[float | None]:
    """Per seed, the fraction of the last quarter's iterations in which Meta-Critic's ``h_omega``
    still moved the actor (:func:`~warp_critic.methods.meta_critic.aux_alive`): from the stage
    record, else from the seed's ``metrics.jsonl`` where the run directory is still there (records
    written before 2026-12-03 do not hold it), else ``None``."""
    import json

    from warp_critic.methods.meta_critic import aux_alive

    out: list[float | None] = []
    for _, v in sorted(rec.data["result"]["seeds"].items(), key=lambda kv: int(kv[0])):
        if "aux_alive" in v:
            out.append(v["aux_alive"])
            continue
        f = rec.dir / v["run_dir"] / "metrics.jsonl"
        rows = (
            [json.loads(line) for line in f.read_text().splitlines() if line] if f.is_file() else []
        )
        out.append(aux_alive(rows) if rows else None)
    return out


def aux_alive_bases_of(rec) -> list[str | None]:
    """Per seed, what :func:`aux_alive_of`'s share was judged by
    (:func:`~warp_critic.methods.meta_critic.aux_alive_basis`): the stage record's note, else the
    seed's ``metrics.jsonl``, else ``None`` (a stage record without a note, or nothing to read)."""
    import json

    from warp_critic.methods.meta_critic import aux_alive_basis

    out: list[str | None] = []
    for _, v in sorted(rec.data["result"]["seeds"].items(), key=lambda kv: int(kv[0])):
        f = rec.dir / v["run_dir"] / "metrics.jsonl"
        if "aux_alive_basis" in v or "aux_alive" in v or not f.is_file():
            out.append(v.get("aux_alive_basis"))
            continue
        out.append(
            aux_alive_basis([json.loads(line) for line in f.read_text().splitlines() if line])
        )
    return out


def aux_alive_sentence(alive: list[float | None], bases: list[str | None] | None = None) -> str:
    """One line on whether the Meta-Critic rows are Meta-Critic or, with ``h_omega`` collapsed, DDPG."""
    known = [a for a in alive if a is not None]
    if not known:
        return (
            "Meta-Critic's auxiliary loss: not recorded for these seeds (stage record and run "
            "directories without it)."
        )
    from warp_critic.methods.meta_critic import ALIVE_SHARE

    dead = sum(a < ALIVE_SHARE for a in known)
    per = ", ".join("not recorded" if a is None else f"{a:.0%}" for a in alive)
    named = sorted({b for b in bases or [] if b is not None})
    how = f"judged by {' / '.join(named)} in the metrics" if named else "the stage's record"
    if named == ["meta_improvement != 0"]:
        how += ", which predate the aux_grad_ratio log"
    return (
        f"Meta-Critic's auxiliary loss h_omega moved the actor ({how}) in this share "
        f"of the last quarter's iterations, per seed: {per}. "
        + (
            f"In {dead} of {len(known)} recorded seeds it had collapsed to a constant, so those "
            "seeds trained as DDPG with their own draws (docs/paper/README.md: the baselines' search)."
            if dead
            else "It stayed alive in every recorded seed."
        )
    )
