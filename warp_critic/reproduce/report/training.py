"""The report's Figure 3 section: training curves, steps to error levels and the errors at a
common environment-step budget, with the sample-efficiency and seed-sensitivity claims."""

from __future__ import annotations

import numpy as np

from warp_critic.reproduce.engine.stages import STAGE_FILE
from warp_critic.reproduce.experiments.naming import stage_name
from warp_critic.reproduce.experiments.settings import ALL_METHODS, METHOD_LABELS, METHODS, SCENES
from warp_critic.reproduce.report import paper as rp
from warp_critic.reproduce.report.departures import departures_line, departures_of
from warp_critic.reproduce.report.plots import plot_metatrain
from warp_critic.reproduce.report.rules import SPREAD_RULE, WINDOW, steps_rule
from warp_critic.reproduce.report.section import Inputs, fmt, part


def metatrain_compute(inp: Inputs) -> dict:
    """Figure 3: meta-training of the methods on both robots; plots each robot's curves."""
    views: list[dict] = []
    results: dict = {}
    claims: list[dict] = []
    figures: list[dict] = []
    for scene in SCENES:
        got = {
            m: rec
            for m in ALL_METHODS
            if (rec := inp.recs.get(stage_name("metatrain", scene, m))) is not None
        }
        if not got:
            views.append({"scene": scene, "run": False})
            continue
        png = inp.figures_dir / f"fig3_metatrain_{scene}.png"
        summary = plot_metatrain(png, scene, got)
        view = _curves(inp, scene, got, summary, results)
        levels = {m: rec_levels(got[m].data["result"]) for m in got}
        budget = min(s["env_steps"] for s in summary.values())
        at_budget = {m: rp.error_at_budget(got[m].data["result"], budget) for m in got}
        results[f"{scene}/steps_to_levels"] = levels
        results[f"{scene}/error_at_budget"] = {"budget": budget} | at_budget
        views.append({**view, "levels": levels, "budget": budget, "at_budget": at_budget})
        scene_claims, sentence = _scene_claims(scene, got, summary, levels, at_budget, budget)
        claims += scene_claims
        figures.append(inp.figure(f"Figure 3: meta-training {scene}", png, sentence))
    return part(views, results={"metatrain": results}, claims=claims, figures=figures)


def rec_levels(res: dict) -> dict[str, dict]:
    """:func:`~.paper.steps_to_levels` of a stage result, keyed by the level's string."""
    return {str(k): v for k, v in rp.steps_to_levels(res).items()}


def _curves(inp: Inputs, scene: str, got: dict, summary: dict, results: dict) -> dict:
    """The robot's iterations, steps and final errors per method (its view), and their
    ``metatrain`` entries of ``results.json`` (into ``results``)."""
    rows = []
    for m, s in summary.items():
        res = got[m].data["result"]
        rows.append({"method": m, **s, "env_steps_counted": res["env_steps_counted"]})
        results[f"{scene}/{m}"] = {
            **s,
            "file": f"{got[m].dir.name}/{STAGE_FILE}",
            "runs": [
                f"{got[m].dir.name}/{v['run_dir']}/metrics.jsonl" for v in res["seeds"].values()
            ],
        }
    aux: dict | None = None
    if "meta-critic" in got:
        alive, basis = aux_alive_of(got["meta-critic"]), aux_alive_bases_of(got["meta-critic"])
        results[f"{scene}/meta-critic"]["aux_alive"] = alive
        results[f"{scene}/meta-critic"]["aux_alive_basis"] = basis
        aux = {"alive": alive, "basis": basis}
    view = {"scene": scene, "run": True, "departures": departures_of(scene, inp.recs)}
    return {**view, "rows": rows, "aux": aux}


def metatrain_render(views: list[dict]) -> list[str]:
    """The Figure 3 section's lines (``views``: :func:`metatrain_compute`'s, one per robot)."""
    md = ["## Figure 3: meta-training (reacher, KUKA)", ""]
    for v in views:
        if not v["run"]:
            md += [f"{v['scene']}: not run (stage `metatrain`).", ""]
            continue
        md += [
            f"### {v['scene']}",
            "",
            departures_line(v["scene"], v["departures"]),
            "",
            "| method | iterations | env steps | env steps counted | final training error ||q_T-g||^2 (mean of the last 10% iterations), mean(std) over seeds | first iteration |",
            "|---|---|---|---|---|---|",
        ]
        md += [
            f"| {METHOD_LABELS[r['method']]} | {r['iterations']} | {r['env_steps']} | "
            f"{r['env_steps_counted']} | {fmt(r['final_mean'])}({fmt(r['final_std'])}) | "
            f"{fmt(r['first_mean'])} |"
            for r in v["rows"]
        ] + [""]
        if v["aux"] is not None:
            md += [aux_alive_sentence(v["aux"]["alive"], v["aux"]["basis"]), ""]
        md += [
            f"Environment steps and wall time to reach each training-error level (rad^2, summed over "
            f"the joints) and stay there: the first iteration after which the running mean over "
            f"{WINDOW} iterations stays at or below it to the end of the run; mean [min, max] over "
            f"the seeds that reach it. "
            f"Training error at the common budget of {v['budget']:.3g} steps (the running mean over the "
            f"{WINDOW} iterations up to it), mean(std) over seeds: "
            + ", ".join(
                f"{METHOD_LABELS[m]} {fmt(float(np.mean(e)))}({fmt(float(np.std(e)))})"
                for m, e in v["at_budget"].items()
            )
            + ".",
            "",
        ]
        md += rp.steps_lines(v["levels"]) + [""]
    return md


def _scene_claims(
    scene: str, got: dict, summary: dict, levels: dict, at_budget: dict, budget
) -> tuple[list[dict], str]:
    """The robot's sample-efficiency and seed-sensitivity claims, and Figure 3's sentence."""
    # the paper's claims compare ours with the paper's baselines (an extra one is shown only)
    claimed = [m for m in got if m in METHODS]
    within = {m: rp.steps_to_levels(got[m].data["result"], budget) for m in claimed}
    verdict, measured = rp.sample_efficiency_verdict(
        {m: {float(k): e for k, e in v.items()} for m, v in levels.items() if m in METHODS},
        within,
    )
    # the paper's text: "fewer iterations"; environment steps as a second row
    iters = {m: rp.per_iteration(got[m].data["result"]) for m in claimed}
    it_budget = min(s["iterations"] for m, s in summary.items() if m in claimed)
    it_verdict, it_measured = rp.sample_efficiency_verdict(
        {m: rp.steps_to_levels(iters[m]) for m in claimed},
        {m: rp.steps_to_levels(iters[m], it_budget) for m in claimed},
        unit="iterations",
    )
    its = {m: s["iterations"] for m, s in summary.items() if m in METHODS}
    claims = [
        {
            "claim": f"Figure 3 ({scene}): ours solves training in fewer iterations",
            "paper": "training curves over iterations; ours falls fastest",
            "ours": it_measured + f" (within the common budget of {it_budget} iterations)",
            "verdict": it_verdict,
            "reason": ("Equal iterations" if len(set(its.values())) <= 1 else "Unequal iterations")
            + " ("
            + ", ".join(f"{METHOD_LABELS[m]} {v}" for m, v in its.items())
            + f"). {steps_rule('iterations')}",
        },
        {
            "claim": f"Figure 3 ({scene}): ours solves training in fewer environment steps",
            "paper": "training curves over iterations; ours falls fastest (read in env steps)",
            "ours": measured + f" (within the common budget of {budget:.3g} env steps)",
            "verdict": verdict,
            "reason": budget_sentence(
                {m: s["env_steps"] for m, s in summary.items() if m in METHODS}
            )
            + f" {steps_rule('env steps')}",
        },
    ]
    spread: dict[str, float] = {m: float(np.std(v)) for m, v in at_budget.items() if m in METHODS}
    if "ours" not in spread or len(spread) <= 1:
        return claims, f"Figure 3 ({scene}): training curves of the methods that ran."
    least = min(spread, key=spread.__getitem__)
    claims.append(
        {
            "claim": f"Figure 3 ({scene}): ours is the least sensitive to the seed",
            "paper": "narrowest band over seeds",
            "ours": f"std over seeds of the training error ({WINDOW}-iteration running "
            f"mean) at {budget:.3g} steps: "
            + ", ".join(f"{METHOD_LABELS[m]} {fmt(v)}" for m, v in spread.items()),
            "verdict": "met" if least == "ours" else "not met",
            "reason": f"smallest spread: {METHOD_LABELS[least]}. {SPREAD_RULE}",
        }
    )
    return claims, (
        f"Figure 3 ({scene}): training error vs iterations and environment steps. At the common "
        f"budget of {budget:.3g} steps the lowest mean error is "
        f"{METHOD_LABELS[min(at_budget, key=lambda m: np.mean(at_budget[m]))]}'s and the smallest "
        f"spread over seeds {METHOD_LABELS[least]}'s; fewer iterations: {it_verdict}; fewer env steps: {verdict}."
    )


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
