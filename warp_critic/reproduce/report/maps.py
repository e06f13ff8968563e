"""The report's Figures 4-6 section: the reacher's goal map and its 2-D mass and length grids,
with their claims."""

from __future__ import annotations

import numpy as np

from warp_critic.reproduce.engine.stages import STAGE_FILE
from warp_critic.reproduce.experiments.settings import METHOD_LABELS, METHODS, present
from warp_critic.reproduce.report import paper as rp
from warp_critic.reproduce.report.departures import departures_line, departures_of
from warp_critic.reproduce.report.heldout_section import judged_on_heldout
from warp_critic.reproduce.report.plots import figure, plot_goal_maps
from warp_critic.reproduce.report.rules import (
    COMPARE_RULE,
    MAP_LEVEL,
    compare_verdict,
    map_reason,
    map_verdict,
)
from warp_critic.reproduce.report.section import Inputs, fmt, part
from warp_critic.reproduce.report.tables import SHOWN_NOT_JUDGED

KINDS = {"mass": "masses", "length": "lengths"}


def maps_compute(inp: Inputs) -> dict:
    """Figures 4-6: reacher generalisation maps; plots the three figures."""
    r = inp.recs.get("maps")
    if r is None:
        return part(None)
    M = r.data["result"]
    figs = inp.figures_dir
    p4, p5, p6 = (
        figs / "fig4_reacher_goals.png",
        figs / "fig5_reacher_mass.png",
        figs / "fig6_reacher_length.png",
    )
    plot_goal_maps(p4, M)
    sv = inp.solved.get("reacher", {})
    rp.plot_grid_2d(p5, M, "mass", figure)
    rp.plot_grid_2d(p6, M, "length", figure)
    gm = {m: M["goals"][m]["mse_mean"] for m in present(M["goals"])}
    frac = {m: float((np.asarray(M["goals"][m]["mse"]) < 0.05).mean()) for m in gm}
    grids, grid_rows = {}, {}
    for kind in ("mass", "length"):
        grids[kind], grid_rows[kind] = rp.grid_summary(M, kind, sv)
    # the figures stay either way; unjudged, their claims are the held-out seeds' (report/heldout.py)
    judged = not judged_on_heldout(inp.recs, "maps")
    claims: list[dict] = []
    figures: list[dict] = []
    verdicts = {"goals": _goal_claim(M, gm, frac, claims)}
    figures.append(_goal_figure(inp, p4, gm, frac))
    for fig_no, kind, png in ((5, "mass", p5), (6, "length", p6)):
        verdicts[kind] = _dynamics_claim(
            fig_no, kind, grids[kind]["means"], grid_rows[kind], claims
        )
        figures.append(_dynamics_figure(inp, fig_no, kind, png, grids[kind]["means"]))
    results = {
        "goals_mse_mean": gm,
        "goals_fraction_below_0.05": frac,
        "mass": M["mass"],
        "length": M["length"],
        "grid_means": {k: g["means"] for k, g in grids.items()},
        "verdicts": verdicts,
        "file": f"{r.dir.name}/{STAGE_FILE}",
        "raw_file": f"{r.dir.name}/{M['raw_file']}",
    }
    goal_rows = rp.method_rows(lambda ci, m: M["goals"][m], 1, sv, None)
    view = {
        "departures": departures_of("reacher", inp.recs),
        "grid": [len(M["axis_q1"]), len(M["axis_q2"])],
        "policy_updates": M["policy_updates"],
        "horizon": M["horizon"],
        "goals_mse_mean": gm,
        "goals_fraction": frac,
        "floor": floor_shares(M),
        "reach": [M.get("reach_iterations"), M.get("reach_lrs")],
        "goal_rows": [[g.label, g.values[0][0] if g.values[0] else None] for g in goal_rows],
        "diverged": M.get("diverged") or 0,
        "grids": grids,
        "judged": judged,
    }
    return part(view, results={"maps": results}, claims=claims if judged else [], figures=figures)


def maps_render(v: dict | None) -> list[str]:
    """The Figures 4-6 section's lines (``v``: :func:`maps_compute`'s view)."""
    md = ["## Figures 4-6: reacher generalisation maps", ""]
    if v is None:
        return md + ["Not run (stage `maps`).", ""]
    md += [departures_line("reacher", v["departures"]), ""]
    gm, frac = v["goals_mse_mean"], v["goals_fraction"]
    md += [
        f"Goal grid: {v['grid'][0]} x {v['grid'][1]} goals over the joint limits, "
        f"{v['policy_updates']} policy update(s), horizon {v['horizon']}; mean MSE over the grid "
        "(fraction of the grid's goals below 0.05 MSE): "
        + ", ".join(f"{METHOD_LABELS[m]} {fmt(x)} ({frac[m]:.0%})" for m, x in gm.items())
        + ".",
        "",
    ]
    shares = v["floor"]
    if shares:
        iterations, lrs = v["reach"]
        md += [
            f"Open-loop reachability floor (the best open-loop torques within the policy's bounds "
            f"and horizon, from home; {iterations} Adam steps at each learning rate "
            f"{', '.join(str(x) for x in lrs)}): below 0.05 MSE on "
            f"{shares['goals']:.0%} of the goal grid, {shares['mass']:.0%} of the mass grid's "
            f"cells and {shares['length']:.0%} of the length grid's (mean over the training goals). "
            "A goal or cell whose floor is above 0.05 is out of any controller's reach; a critic's "
            "miss elsewhere is the critic's.",
            "",
        ]
    md += ["| goal grid | mean MSE over the grid |", "|---|---|"]
    md += [f"| {label} | {fmt(x) if x is not None else '—'} |" for label, x in v["goal_rows"]]
    md += [""]
    if v["diverged"]:
        md += [rp.diverged_line(v["diverged"]), ""]
    md += [
        "Dynamics (Figures 5, 6): 2-D grids over both links at the four training goals. Masses: each "
        "link's mass SET at its centre of mass, its inertia about the centre kept (the paper's model "
        "changes the `mass` parameter of a link). Lengths: each link STRETCHED to the length (its "
        "centre of mass and inertia stretched with it; a longer link 1 moves joint 2 out). Assumption: the "
        "paper does not say how it changed a length; a stretched link is a longer link of the same mass.",
        "",
    ]
    for kind in ("mass", "length"):
        md += rp.grid_lines(kind, v["grids"][kind]) + [""]
    if not v["judged"]:
        md += [SHOWN_NOT_JUDGED, ""]
    return md


def _goal_figure(inp: Inputs, png, gm: dict, frac: dict) -> dict:
    """Figure 4's entry: the lowest grid mean and ours' share below 0.05 MSE."""
    best = min(gm, key=gm.__getitem__)
    return inp.figure(
        "Figure 4: reacher new goals",
        png,
        f"Figure 4: MSE per new goal over the reacher's joint space (red crosses: training goals); the "
        f"lowest grid mean is {METHOD_LABELS[best]}'s; ours is below 0.05 MSE on {frac['ours']:.0%} "
        f"of the grid.",
    )


def _goal_claim(M: dict, gm: dict, frac: dict, claims: list[dict]) -> dict:
    """Figure 4's claim (into ``claims``); returns its verdict."""
    v4 = map_verdict(
        M["goals"]["ours"]["mse"],
        {METHOD_LABELS[m]: M["goals"][m]["mse"] for m in METHODS if m != "ours"},
    )
    claims.append(
        {
            "claim": "Figure 4: ours generalises over the full state space of the reacher",
            "paper": "goal map: ours low everywhere, the baselines only near the training goals",
            "ours": "fraction of the 2-D goal grid below 0.05 MSE: "
            + ", ".join(f"{METHOD_LABELS[m]} {frac[m]:.0%}" for m in METHODS)
            + "; grid mean: "
            + ", ".join(f"{METHOD_LABELS[m]} {fmt(gm[m])}" for m in METHODS),
            "verdict": v4["verdict"],
            "reason": map_reason(v4),
        }
    )
    return v4


def _dynamics_figure(inp: Inputs, fig_no: int, kind: str, png, grid_means: dict) -> dict:
    """Figure 5 (``kind`` mass) or 6 (length)'s entry: each row's grid mean MSE (rad^2)."""
    return inp.figure(
        f"Figure {fig_no}: reacher {kind}",
        png,
        f"Figure {fig_no}: MSE at the training goals over the {KINDS[kind]} of both links (red cross: "
        f"as trained; one colour scale); grid mean: "
        + ", ".join(f"{rp.shown(k)} {fmt(v)}" for k, v in grid_means.items())
        + ".",
    )


def _dynamics_claim(
    fig_no: int, kind: str, grid_means: dict, grid_rows: list[rp.Row], claims: list[dict]
) -> dict:
    """Figure 5 (``kind`` mass) or 6 (length)'s claim (into ``claims``); returns its verdict. The
    rows are found by their method's registry name; a row's label (``this run: ...``) is only shown."""
    # the claims compare ours with the paper's baselines (an extra one is shown only)
    claimed = [r for r in grid_rows if r.method in METHODS]
    means = {r.label: grid_means[r.label] for r in claimed if r.label in grid_means}
    ours = next([c[0] for c in r.values] for r in claimed if r.method == "ours")
    cells = {
        rp.shown(r.label): [c[0] for c in r.values]
        for r in claimed
        if r.method != "ours" and all(c is not None for c in r.values)
    }
    v = map_verdict(ours, cells)
    # the claim is comparative ("better than the baselines"): judged cell by cell
    v["verdict"], share = compare_verdict(v["below_all"], v["cells"])
    v["rule"] = "comparative"
    solved_row = any(r.method != "ours" and r.label in means and r.solved_only for r in claimed)
    claims.append(
        {
            "claim": f"Figure {fig_no}: ours generalises to "
            + ("heavier / lighter links" if kind == "mass" else "new link lengths")
            + " better than the baselines",
            "paper": f"2-D map over the {KINDS[kind]} of both links; ours lowest",
            "ours": "grid mean MSE: "
            + ", ".join(f"{rp.shown(k)} {fmt(v)}" for k, v in means.items()),
            "verdict": v["verdict"],
            "reason": f"{share}; lowest grid mean: "
            f"{'ours' if v['lowest'] == 'ours' else v['lowest']}; ours below "
            f"{MAP_LEVEL:g} MSE on {v['share']:.1%} of the cells. {COMPARE_RULE}"
            + ("" if solved_row else "; no baseline seed solved training"),
        }
    )
    return v


def elbow_bent(res: dict) -> np.ndarray:
    """``(n * n,)`` bool over the maps' goal grid (row-major, ``q1`` major): the goals whose second
    joint is bent past a right angle, ``|q2| > pi/2``. There the arm arrives with ``cos q2 < 0``,
    so the inertia's coupling ``M12 = I2 + m2 lc2 (lc2 + l1 cos q2)`` is below ``M22 = I2 + m2
    lc2^2``, as at no arrival of the training goals (``|q2| <= 1`` rad) under any masses or
    lengths (RESULTS.md, "The goal grid's far half")."""
    q2 = np.asarray(res["axis_q2"], dtype=float)
    return np.tile(np.abs(q2) > np.pi / 2, len(res["axis_q1"]))


def floor_shares(maps: dict, level: float = 0.05) -> dict[str, float] | None:
    """The share of the goal grid's goals and of each 2-D map's cells whose open-loop reachability
    floor is below ``level`` MSE (``None``: the maps stage computed no floor)."""
    floor = maps.get("reach_floor")
    if not floor:
        return None
    return {k: float((np.asarray(floor[k]) < level).mean()) for k in ("goals", "mass", "length")}
