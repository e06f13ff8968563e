"""The report's Figures 4-6 section: the reacher's goal map and its 2-D mass and length grids,
with their claims."""

from __future__ import annotations

import numpy as np

from warp_critic.reproduce.engine.stages import STAGE_FILE
from warp_critic.reproduce.experiments.settings import METHOD_LABELS, METHODS, present
from warp_critic.reproduce.report import paper as rp
from warp_critic.reproduce.report.departures import departures_line
from warp_critic.reproduce.report.draft import Draft, fmt
from warp_critic.reproduce.report.heldout import judged_on_heldout
from warp_critic.reproduce.report.plots import figure, plot_goal_maps
from warp_critic.reproduce.report.rules import (
    COMPARE_RULE,
    MAP_LEVEL,
    compare_verdict,
    map_reason,
    map_verdict,
)
from warp_critic.reproduce.report.tables import SHOWN_NOT_JUDGED


def maps_section(d: Draft) -> None:
    """Figures 4-6: reacher generalisation maps."""
    d.md += ["## Figures 4-6: reacher generalisation maps", ""]
    r = d.recs.get("maps")
    if r is None:
        d.md += ["Not run (stage `maps`).", ""]
        return
    M = r.data["result"]
    p4, p5, p6 = (
        d.figs / "fig4_reacher_goals.png",
        d.figs / "fig5_reacher_mass.png",
        d.figs / "fig6_reacher_length.png",
    )
    plot_goal_maps(p4, M)
    sv = d.solved.get("reacher", {})
    rp.plot_grid_2d(p5, M, "mass", figure)
    rp.plot_grid_2d(p6, M, "length", figure)
    gm = {m: M["goals"][m]["mse_mean"] for m in present(M["goals"])}
    frac = {m: float((np.asarray(M["goals"][m]["mse"]) < 0.05).mean()) for m in gm}
    _goal_grid_lines(d, M, gm, frac, sv)
    grid_means, grid_rows = {}, {}
    for kind in ("mass", "length"):
        lines, g = rp.grid_summary(M, kind, sv)
        grid_means[kind], grid_rows[kind] = g["means"], g["rows"]
        d.md += lines + [""]
    judged = not judged_on_heldout(d, "maps")
    if not judged:
        d.md += [SHOWN_NOT_JUDGED, ""]
    # the figures stay either way; unjudged, their claims are the held-out seeds' (report/heldout.py)
    verdicts = {"goals": _goal_claim(d, M, gm, frac, p4, judged)}
    for fig_no, kind, png in ((5, "mass", p5), (6, "length", p6)):
        verdicts[kind] = _dynamics_claim(
            d, fig_no, kind, png, grid_means[kind], grid_rows[kind], judged
        )
    d.results["maps"] = {
        "goals_mse_mean": gm,
        "goals_fraction_below_0.05": frac,
        "mass": M["mass"],
        "length": M["length"],
        "grid_means": grid_means,
        "verdicts": verdicts,
        "file": f"{r.dir.name}/{STAGE_FILE}",
        "raw_file": f"{r.dir.name}/{M['raw_file']}",
    }


def _goal_grid_lines(d: Draft, M: dict, gm: dict, frac: dict, sv: dict) -> None:
    """The goal grid's sentences and table, the reachability floor, and the dynamics' preamble."""
    md = d.md
    md += [departures_line("reacher", d.recs), ""]
    md += [
        f"Goal grid: {len(M['axis_q1'])} x {len(M['axis_q2'])} goals over the joint limits, "
        f"{M['policy_updates']} policy update(s), horizon {M['horizon']}; mean MSE over the grid "
        "(fraction of the grid's goals below 0.05 MSE): "
        + ", ".join(f"{METHOD_LABELS[m]} {fmt(v)} ({frac[m]:.0%})" for m, v in gm.items())
        + ".",
        "",
    ]
    shares = floor_shares(M)
    if shares:
        md += [
            f"Open-loop reachability floor (the best open-loop torques within the policy's bounds "
            f"and horizon, from home; {M['reach_iterations']} Adam steps at each learning rate "
            f"{', '.join(str(x) for x in M['reach_lrs'])}): below 0.05 MSE on "
            f"{shares['goals']:.0%} of the goal grid, {shares['mass']:.0%} of the mass grid's "
            f"cells and {shares['length']:.0%} of the length grid's (mean over the training goals). "
            "A goal or cell whose floor is above 0.05 is out of any controller's reach; a critic's "
            "miss elsewhere is the critic's.",
            "",
        ]
    goal_rows = rp.method_rows(lambda ci, m: M["goals"][m], 1, sv, None)
    md += ["| goal grid | mean MSE over the grid |", "|---|---|"]
    md += [f"| {r.label} | {fmt(r.values[0][0]) if r.values[0] else '—'} |" for r in goal_rows]
    md += [""]
    if M.get("diverged"):
        md += [rp.diverged_line(M["diverged"]), ""]
    md += [
        "Dynamics (Figures 5, 6): 2-D grids over both links at the four training goals. Masses: each "
        "link's mass SET at its centre of mass, its inertia about the centre kept (the paper's model "
        "changes the `mass` parameter of a link). Lengths: each link STRETCHED to the length (its "
        "centre of mass and inertia stretched with it; a longer link 1 moves joint 2 out). Assumption: the "
        "paper does not say how it changed a length; a stretched link is a longer link of the same mass.",
        "",
    ]


def _goal_claim(d: Draft, M: dict, gm: dict, frac: dict, png, judged: bool) -> dict:
    """Figure 4 and (``judged``) its claim; returns its verdict."""
    best = min(gm, key=gm.__getitem__)
    v4 = map_verdict(
        M["goals"]["ours"]["mse"],
        {METHOD_LABELS[m]: M["goals"][m]["mse"] for m in METHODS if m != "ours"},
    )
    d.figures.append(
        (
            "Figure 4: reacher new goals",
            png,
            f"Figure 4: MSE per new goal over the reacher's joint space (red crosses: training goals); the "
            f"lowest grid mean is {METHOD_LABELS[best]}'s; ours is below 0.05 MSE on {frac['ours']:.0%} "
            f"of the grid.",
        )
    )
    claim = {
        "claim": "Figure 4: ours generalises over the full state space of the reacher",
        "paper": "goal map: ours low everywhere, the baselines only near the training goals",
        "ours": "fraction of the 2-D goal grid below 0.05 MSE: "
        + ", ".join(f"{METHOD_LABELS[m]} {frac[m]:.0%}" for m in METHODS)
        + "; grid mean: "
        + ", ".join(f"{METHOD_LABELS[m]} {fmt(gm[m])}" for m in METHODS),
        "verdict": v4["verdict"],
        "reason": map_reason(v4),
    }
    if judged:
        d.claims.append(claim)
    return v4


def _dynamics_claim(
    d: Draft,
    fig_no: int,
    kind: str,
    png,
    grid_means: dict,
    grid_rows: list[rp.Row],
    judged: bool,
) -> dict:
    """Figure 5 (``kind`` mass) or 6 (length) and (``judged``) its claim; returns its verdict. The rows are
    found by their method's registry name; a row's label (``this run: ...``) is only shown."""
    kinds = {"mass": "masses", "length": "lengths"}[kind]
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
    d.figures.append(
        (
            f"Figure {fig_no}: reacher {kind}",
            png,
            f"Figure {fig_no}: MSE at the training goals over the {kinds} of both links (red cross: "
            f"as trained; one colour scale); grid mean: "
            + ", ".join(f"{rp.shown(k)} {fmt(v)}" for k, v in grid_means.items())
            + ".",
        )
    )
    claim = {
        "claim": f"Figure {fig_no}: ours generalises to "
        + ("heavier / lighter links" if kind == "mass" else "new link lengths")
        + " better than the baselines",
        "paper": f"2-D map over the {kinds} of both links; ours lowest",
        "ours": "grid mean MSE: " + ", ".join(f"{rp.shown(k)} {fmt(v)}" for k, v in means.items()),
        "verdict": v["verdict"],
        "reason": f"{share}; lowest grid mean: "
        f"{'ours' if v['lowest'] == 'ours' else v['lowest']}; ours below "
        f"{MAP_LEVEL:g} MSE on {v['share']:.1%} of the cells. {COMPARE_RULE}"
        + ("" if solved_row else "; no baseline seed solved training"),
    }
    if judged:
        d.claims.append(claim)
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
