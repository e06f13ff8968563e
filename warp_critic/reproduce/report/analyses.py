"""The report's sections on the analyses: the 1-D toy (section 4.1) and the landscapes
(section 4.2, Figures 1-2), each a pure compute and render (:mod:`~.section`)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from warp_critic.reproduce.engine.stages import STAGE_FILE
from warp_critic.reproduce.report.rules import LANDSCAPE_RULE
from warp_critic.reproduce.report.section import Inputs, part

TOY_METHODS = ("supervised", "ours", "meta_critic")


def toy_compute(inp: Inputs) -> dict:
    """Section 4.1 / Appendix A: the toy's closed forms against its loops; copies its figures."""
    r = inp.recs.get("toy")
    if r is None:
        return part(None)
    t = r.data["result"]
    figures = []
    for m in TOY_METHODS:
        dst = shutil.copyfile(r.dir / t["files"][m], inp.figures_dir / f"appendix_toy_{m}.png")
        num, closed = t["numerical"][m], t["closed_form"][m]
        sentence = (
            f"Appendix figure ({m}): the learned critic and its policy gradient over theta; the fitted "
            f"critic's gradient vanishes at theta = {num:.3g}, the paper's closed form gives {closed:g} "
            f"({'equal' if abs(num - closed) < 1e-2 else 'NOT equal'} to 0.01)."
        )
        figures.append(inp.figure(f"Appendix: toy {m}", Path(dst), sentence))
    toy = {"numerical": t["numerical"], "closed_form": t["closed_form"]}
    return part(
        {**toy, "table_markdown": t["table_markdown"]},
        results={"toy": {**toy, "file": f"{r.dir.name}/{STAGE_FILE}"}},
        figures=figures,
    )


def toy_render(v: dict | None) -> list[str]:
    """The toy section's lines (``v``: :func:`toy_compute`'s view)."""
    md = ["## Section 4.1 / Appendix A: the 1-D toy (closed forms vs learning loops)", ""]
    if v is None:
        return md + ["Not run (stage `toy`).", ""]
    num, closed = v["numerical"], v["closed_form"]
    return md + [
        v["table_markdown"],
        "",
        f"The paper derives theta = 3 (optimal) for ours and theta = 4 for supervised Q learning and the "
        f"Meta-Critic. Our loops converge to: ours {num['ours']:.4g}, supervised "
        f"{num['supervised']:.4g}, Meta-Critic {num['meta_critic']:.4g} (closed forms "
        f"{closed['ours']:g}, {closed['supervised']:g}, {closed['meta_critic']:g}).",
        "",
    ]


def _descent(L: dict) -> dict:
    """The numbers of one landscape run's descent-success table."""
    return {k: L[k] for k in ("goal_names", "goals", "optima", "fractions")}


def _descent_table(L: dict) -> list[str]:
    """The markdown descent-success table of one landscape run (goal, theta*, one column per method)."""
    md = ["| goal | theta* | Q_true | Q_sup | L_critic |", "|---|---|---|---|---|"]
    for gi, gname in enumerate(L["goal_names"]):
        fr = L["fractions"][gi]
        md.append(
            f"| {gname} ({L['goals'][gi][0]:g},{L['goals'][gi][1]:g}) | "
            f"({L['optima'][gi][0]:.2f},{L['optima'][gi][1]:.2f}) | {fr['Q_true']:.2f} | {fr['Q_sup']:.2f} | "
            f"{fr['L_critic']:.2f} |"
        )
    return md + [""]


def _unseen(L: dict, method: str) -> float:
    """Mean descent success of ``method`` over the unseen goals (nan without any)."""
    return (
        float(np.mean([f[method] for f in L["fractions"][1:]]))
        if len(L["fractions"]) > 1
        else float("nan")
    )


def landscape_compute(inp: Inputs) -> dict:
    """Section 4.2: the landscapes (Figures 1, 2) and Figure 1's claim; copies the figures."""
    r = inp.recs.get("landscape")
    if r is None:
        return part(None)
    L = r.data["result"]
    G = L.get("generalising")
    ours_new, sup_new = _unseen(L, "L_critic"), _unseen(L, "Q_sup")
    gen = _generalising(r, G, ours_new) if G is not None else None
    view = {"table": _descent(L), "ours": ours_new, "sup": sup_new, "generalising": gen}
    landscape = {
        "fractions": L["fractions"],
        "goal_names": L["goal_names"],
        "generalising": (
            {k: G[k] for k in ("fractions", "goal_names", "overrides")} if G is not None else None
        ),
        "file": f"{r.dir.name}/{STAGE_FILE}",
    }
    return part(
        view,
        results={"landscape": landscape},
        claims=[_landscape_claim(ours_new, sup_new, gen)],
        figures=_landscape_figures(inp, r, G, gen, (ours_new, sup_new)),
    )


def _generalising(r, G: dict, ours_new: float) -> dict:
    """The closest setting that generalises: the numbers of its table and sentence."""
    stage_settings = r.data.get("settings") or {}
    changed = {k: v for k, v in G["overrides"].items() if stage_settings.get(k) != v}
    g_ours = _unseen(G, "L_critic")
    return {
        "over": ", ".join(f"{k} = {v}" for k, v in (changed or G["overrides"]).items()),
        "landscapes": f"{r.dir.name}/{Path(G['files']['landscape'])}",
        "table": _descent(G),
        "ours": g_ours,
        "sup": _unseen(G, "Q_sup"),
        "better": bool(g_ours > ours_new),
    }


def landscape_render(v: dict | None) -> list[str]:
    """The landscape section's lines (``v``: :func:`landscape_compute`'s view)."""
    md = ["## Section 4.2: optimisation landscapes (Figures 1, 2)", ""]
    if v is None:
        return md + ["Not run (stage `landscape`).", ""]
    md += [
        "Descent success (normalised-gradient descent from every grid point ends within the tolerance of "
        "theta*), the paper's setting (one training goal, two fixed initial states, L_critic sees the goal "
        "as an absolute input):",
        "",
    ] + _descent_table(v["table"])
    g = v["generalising"]
    if g is None:
        return md
    verdict = (
        "so it generalises"
        if g["better"]
        else "no better than the paper's setting here (too few iterations to learn it?)"
    )
    md += [
        f"The closest setting that generalises, the same with {g['over']} (landscapes in "
        f"`{g['landscapes']}`):",
        "",
    ] + _descent_table(g["table"])
    return md + [
        f"In the paper's setting the critic's goal input never varies during training and it only sees "
        f"rollouts from two fixed initial states, so nothing ties its landscape to the goal: on the unseen "
        f"goals L_critic's field leads to theta* from {v['ours']:.0%} of the grid (Q_sup {v['sup']:.0%}). "
        f"Feeding the goal relative to the state (q - g: the critic is then translation-equivariant, as "
        f"the point mass is) and training from random initial states (a continuum of relative starts "
        f"q_0 - g, so that the critic has to learn how theta* depends on g - q_0 instead of "
        f"memorising two tasks) gives {g['ours']:.0%} on the unseen goals (Q_sup {g['sup']:.0%}), "
        f'{verdict}; docs/landscape.md, "Generalisation to unseen goals", has the measurements.',
        "",
    ]


def _landscape_claim(ours_new: float, sup_new: float, gen: dict | None) -> dict:
    """Figure 1's claim, from the shares of the grid that reach theta* of the unseen goals."""
    return {
        "claim": "Figure 1: the meta-learned critic generalises to unseen goals, a supervised Q does not",
        "paper": "landscapes: L_critic's gradient field leads to theta* for the unseen goals, Q_sup's does not",
        "ours": f"paper setting: descent from {ours_new:.0%} of the grid reaches theta* of the unseen "
        f"goals with L_critic vs {sup_new:.0%} with Q_sup"
        + (
            f"; relative goal input and random starts: {gen['ours']:.0%} vs {gen['sup']:.0%}"
            if gen is not None
            else ""
        ),
        "verdict": "met" if ours_new > sup_new else "not met",
        "reason": (
            "L_critic above Q_sup on the unseen goals"
            if ours_new > sup_new
            else "L_critic not above Q_sup on the unseen goals in the paper's setting"
        )
        + f". {LANDSCAPE_RULE}",
    }


def _landscape_figures(inp: Inputs, r, G: dict | None, gen: dict | None, unseen) -> list[dict]:
    """Figures 1 (and its generalising setting's) and 2, copied from the stage's directory."""
    ours_new, sup_new = unseen
    claim = (
        "the paper's claim is met here"
        if ours_new > sup_new
        else "the paper's claim is NOT met here (L_critic does not beat Q_sup)"
    )
    figs = inp.figures_dir
    d1 = shutil.copyfile(r.dir / "landscape.png", figs / "fig1_landscape.png")
    d2 = shutil.copyfile(r.dir / "exploration.png", figs / "fig2_exploration.png")
    figures = [
        inp.figure(
            "Figure 1: landscapes",
            Path(d1),
            f"Figure 1: Q_true, Q_sup and L_critic over the policy parameters for the training goal and two "
            f"unseen goals; on the unseen goals L_critic's field leads to theta* from {ours_new:.0%} of the "
            f"grid vs Q_sup's {sup_new:.0%}, {claim}.",
        )
    ]
    if G is not None and gen is not None:
        d1g = shutil.copyfile(
            r.dir / G["files"]["landscape"], figs / "fig1_landscape_generalising.png"
        )
        figures.append(
            inp.figure(
                "Figure 1: landscapes, generalising setting",
                Path(d1g),
                f"Figure 1 in the closest setting that generalises ({gen['over']}): on the unseen goals "
                f"L_critic's field leads to theta* from {gen['ours']:.0%} of the grid vs Q_sup's "
                f"{gen['sup']:.0%}.",
            )
        )
    figures.append(
        inp.figure(
            "Figure 2: exploration",
            Path(d2),
            "Figure 2: the updated policy parameters theta_new visited during meta-training (dark to light "
            "over the iterations), the paper's 'sampling the parameter space' figure.",
        )
    )
    return figures
