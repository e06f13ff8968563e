"""Stage ``maps``: the reacher's Figures 4-6 (2 joints).

(a) a ``grid x grid`` goal grid over ``limit_fraction`` of the joint limits, MSE per goal over
``seeds x inits``; (b) a 2-D grid over the masses (m1, m2) of both links (SET at the centre of mass,
inertia kept) and (c) a 2-D grid over the lengths (l1, l2) of both links (stretched links: a longer
link 1 moves joint 2 out), each at the four training goals. With ``reach_iterations`` > 0, each goal
and each cell also gets the open-loop reachability floor (the best over the Adam learning rates
``reach_lrs``).

Raw final errors go to ``errors.json`` (:mod:`.goals`).
"""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path

import numpy as np

from warp_critic.physics.link_changes import parse_changes
from warp_critic.physics.scene import Variant
from warp_critic.reproduce.experiments.evaluate import Job, default_steps, pool_errors
from warp_critic.reproduce.experiments.goals import (
    evaluate_stage,
    goal_grid,
    raw_errors,
    train_goals_and_limits,
)


def run_maps_stage(
    d: Path,
    s: dict,
    runs: dict[str, list[Path]],
    device: str,
    progress: bool = True,
    floors_from: str | None = None,
    only: list[str] | None = None,
    steps: int | None = None,
    scales: dict[str, float] | None = None,
) -> dict:
    """``runs``: method (ours, the baselines, or a recipe) -> per-seed run directories (reacher);
    ``only``: the rows evaluated (default: every one of ``runs``; ours' runs set the grids);
    ``steps``, ``scales``: the meta-test budget, as
    :func:`~warp_critic.reproduce.experiments.tables.run_tables_stage`'s.

    ``floors_from``: a complete maps stage directory next to ``d`` that computed the reachability
    floors of the same grids from the same nominal runs (:func:`~warp_critic.reproduce.experiments.units.paper_maps_floors`); its
    floors are taken instead of computed again (``reach_floor_from`` names it)."""
    first = str(runs["ours"][0])
    runs = {m: runs[m] for m in (only if only is not None else runs)}
    scene, train_goals, lo, hi = train_goals_and_limits(first)
    steps = int(steps) if steps is not None else default_steps(first)
    n = int(s["grid"])
    grid, axes = goal_grid(lo, hi, n, float(s["limit_fraction"]))
    links = list(scene.body_names)  # the two links, in chain order (arm1, arm2)
    masses, lengths = [float(x) for x in s["masses"]], [float(x) for x in s["lengths"]]
    pairs = {
        "mass": [(a, b) for a in masses for b in masses],  # row-major: link 1 major
        "length": [(a, b) for a in lengths for b in lengths],
    }
    variant = partial(_map_variant, links)
    jobs = _map_jobs(runs, grid, train_goals, pairs, variant, scales)
    r = evaluate_stage(d, s, jobs, steps, device, progress)
    raw = raw_errors(jobs, r, d.parent, "map", untrained=False)
    (d / "errors.json").write_text(json.dumps({"jobs": raw}) + "\n")
    out = {
        "axis_q1": axes[0].tolist(),
        "axis_q2": axes[1].tolist(),
        "train_goals": train_goals.tolist(),
        "masses": masses,
        "lengths": lengths,
        "links": links,
        "trained_mass": [round(float(x), 6) for x in scene.world_builder().body_mass],
        "trained_length": _link_lengths(scene),
        "grid_2d": True,
        "dof": r["dof"],
        "horizon": r["horizon"],
        "policy_updates": steps,
        **({"alpha_scales": dict(scales)} if scales else {}),
        "diverged": r["diverged"],
        "tip_offset": [float(x) for x in scene.tip_offset],
        "raw_file": "errors.json",
        "goals": {},
        "mass": {},
        "length": {},
    }
    if int(s["reach_iterations"]) > 0:
        from warp_critic.reproduce.experiments.reach import maps_floor, taken_floors

        if floors_from is not None:
            out.update(taken_floors(d.parent, floors_from))
        else:
            out.update(
                maps_floor(first, s, grid.view(n, n, 2), train_goals, pairs, variant, device)
            )
    for m in runs:
        _map_results(out, m, jobs, r["errors"], pairs, n, r["dof"])
    return out


def _map_jobs(
    runs: dict, grid, train_goals, pairs: dict, variant, scales: dict | None
) -> list[Job]:
    """Per method and seed: the goal grid's job, then one job per 2-D cell of each of ``pairs``
    (``kind -> [(a, b)]``) at the training goals; ``scales``: method -> its step-size multiple."""
    jobs = []
    for m in runs:
        x = float((scales or {}).get(m, 1.0))  # the row's step-size multiple
        for si, rd in enumerate(runs[m]):
            jobs.append(Job(("goals", 0, m, si), str(rd), grid, Variant(), x))
            for kind, values in pairs.items():
                for ci, (a, b) in enumerate(values):
                    jobs.append(
                        Job((kind, ci, m, si), str(rd), train_goals, variant(kind, a, b), x)
                    )
    return jobs


def _link_lengths(scene) -> list[float]:
    """[m] each link's length as trained: its child joint's distance, the tip's for the last."""
    b = scene.world_builder()
    out = []
    for body in range(len(scene.body_names)):
        child = [j for j, parent in enumerate(b.joint_parent) if parent == body]
        end = np.array(b.joint_X_p[child[0]].p) if child else scene.tip_offset
        out.append(round(float(np.linalg.norm(end)), 6))
    return out


def _map_variant(links: list[str], kind: str, a: float, b: float) -> Variant:
    """The maps' dynamics variant of one 2-D cell: ``kind`` mass SETS the masses (kg) of the two
    ``links`` at their centres of mass, inertia kept; length stretches them by ``a``, ``b``."""
    if kind == "mass":
        return Variant(
            changes=parse_changes(f"{links[0]}.mass={a!r}:keep; {links[1]}.mass={b!r}:keep")
        )
    return Variant(changes=parse_changes(f"{links[0]}.stretch={a!r}; {links[1]}.stretch={b!r}"))


def _map_results(out: dict, m: str, jobs: list, errors: list, pairs: dict, n: int, dof: int):
    """Method ``m``'s goal map ``(n, n)`` MSE and its 2-D maps' cells into ``out``."""
    errs = [errors[k] for k, j in enumerate(jobs) if j.key[0] == "goals" and j.key[2] == m]
    per_goal = (
        np.stack([e.mean(1) for e in errs]).mean(0) / dof
    )  # mean over seeds x inits, per goal
    out["goals"][m] = {"mse": per_goal.reshape(n, n).tolist(), **pool_errors(errs, dof)}
    for kind, values in pairs.items():
        cells = []
        for ci, v in enumerate(values):
            errs = [errors[k] for k, j in enumerate(jobs) if j.key[:3] == (kind, ci, m)]
            cells.append({"value": list(v), **pool_errors(errs, dof)})
        out[kind][m] = cells
