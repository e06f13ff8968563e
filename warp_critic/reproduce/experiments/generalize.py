"""Stages ``tables`` (KUKA Tables 1-3 and two stress tables) and ``maps`` (reacher Figures 4-6).

Tables (the paper: "the mean squared error between last state and goal over 10 new goals, 5 seeds
and 5 new policy initialization"): every cell pools ``seeds x goals x inits`` final errors of one
method, as ``mean_j (q_T,j - g_j)^2`` (MSE over the joints); ``mean(std)`` over the pooled policies.

* Table 1: per column ``std``, ``num_goals`` goals ``N(g, std^2 I)`` per joint around training goals
  ``around`` (cycled), clipped into 98% of the limits (:func:`warp_critic.evaluation.metatest.sample_goals`).
* Table 2 (the paper's reading, "training mass is at mass=3.12"): SET the mass of link 7 (the
  end-effector link, 3.129 kg in the iiwa7 URDF) to each column's kg, its centre of mass and its
  inertia about that centre unchanged (``ee.mass=M:keep``); the training mass is its own column.
* Table 3 (the paper's reading, "training value is at length=0"): ADD each column's metres to the
  massless end-effector frame (the paper model's ``iiwa_link_ee``, 0.045 m out of link 7):
  ``ee.offset+=L``, no mass change; 0 is the training column.
* Stress tables (this project's earlier, harsher variants): ``stress_mass`` ADDS a point mass at the
  tip (``Variant(ee_mass=m)``), ``stress_length`` SETS link 7's length by stretching the link
  (``Variant(link_length=L)``). Each column also gets the open-loop reachability floor
  (:mod:`~warp_critic.reproduce.experiments.reach`): the error the best open-loop torques with the same bounds and horizon reach.
* Tables 2, 3 and the stress tables use one set of ``num_goals`` goals drawn as Table 1's at
  ``dynamics_goal_std``.

Maps (reacher, 2 joints): (a) a ``grid x grid`` goal grid over ``limit_fraction`` of the joint
limits, MSE per goal over ``seeds x inits``; (b) a 2-D grid over the masses (m1, m2) of both links
(SET at the centre of mass, inertia kept) and (c) a 2-D grid over the lengths (l1, l2) of both links
(stretched links: a longer link 1 moves joint 2 out), each at the four training goals. With
``reach_iterations`` > 0, each goal and each cell also gets the open-loop reachability floor (the best
over the Adam learning rates ``reach_lrs``).

Raw final errors go to ``errors.json`` as float32 values in shortest decimal form
(:func:`~warp_critic.reproduce.experiments.records.float32_list`): read them as float32.
"""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path

import numpy as np
import torch

from warp_critic.physics.link_changes import parse_changes
from warp_critic.physics.scene import Variant
from warp_critic.reproduce.engine.stage import PROGRESS
from warp_critic.reproduce.experiments.evaluate import (
    Job,
    default_steps,
    evaluate,
    pool_errors,
    relpath,
)
from warp_critic.reproduce.experiments.records import float32_list
from warp_critic.running.task_inputs import inside_limits


def train_goals_and_limits(run_dir: str):
    """A run's scene, its training goals ``(G, dof)`` rad and its joint limits ``(dof,)`` rad."""
    from warp_critic.running.rundir import RunDir
    from warp_critic.running.scenefile import find_run_scene

    ckpt = RunDir.open(run_dir).load_checkpoint(require=("config",))
    scene = find_run_scene(ckpt, run_dir)
    goals = torch.tensor(ckpt["config"]["goals"], dtype=torch.float32)
    lo = torch.as_tensor(scene.q_lower, dtype=torch.float32)
    hi = torch.as_tensor(scene.q_upper, dtype=torch.float32)
    return scene, goals, lo, hi


def draw_goals(train_goals, lo, hi, num, std, around, noise, seed):
    """``num`` goals ``(num, dof)`` rad drawn around the training goals (or ``around``) with ``std``,
    inside ``[lo, hi]``, from ``seed`` (:func:`~warp_critic.evaluation.metatest.sample_goals`)."""
    from warp_critic.evaluation.metatest import sample_goals

    gen = torch.Generator().manual_seed(int(seed))
    return sample_goals(
        train_goals, int(num), float(std), list(around) if around else None, lo, hi, gen, noise
    )


def table_variant(table: str, v: float) -> Variant:
    """The dynamics variant of one column of a dynamics table (module docstring)."""
    if table == "table2":
        return Variant(changes=parse_changes(f"ee.mass={v!r}:keep"))
    if table == "table3":
        return Variant(changes=parse_changes(f"ee.offset+={v!r}"))
    if table == "stress_mass":
        return Variant(ee_mass=v)
    if table == "stress_length":
        return Variant(link_length=v)
    return Variant()


def _link_lengths(scene) -> list[float]:
    """[m] each link's length as trained: its child joint's distance, the tip's for the last."""
    b = scene.world_builder()
    out = []
    for body in range(len(scene.body_names)):
        child = [j for j, parent in enumerate(b.joint_parent) if parent == body]
        end = np.array(b.joint_X_p[child[0]].p) if child else scene.tip_offset
        out.append(round(float(np.linalg.norm(end)), 6))
    return out


def _with(values, extra: float) -> list[float]:
    """``values`` as floats with ``extra`` (the training value) added, sorted."""
    return sorted({float(x) for x in values} | {float(extra)})


def run_tables_stage(
    d: Path,
    s: dict,
    runs: dict[str, list[Path]],
    device: str,
    progress: bool = True,
    only: list[str] | None = None,
    steps: int | None = None,
    scales: dict[str, float] | None = None,
) -> dict:
    """``runs``: method (a row of the tables: ours, the baselines, or a recipe beyond the paper) ->
    per-seed run directories (KUKA); ``runs["ours"]`` sets the scene, goals and policy updates.
    ``only``: the rows evaluated (default: every one of ``runs``). ``steps``: the policy updates
    of every row (default: ours' meta-test's, :func:`default_steps`); ``scales``: row -> its step
    size as a multiple of its run's own (default 1; a meta-test budget,
    :mod:`~warp_critic.reproduce.experiments.budget`)."""
    first = str(runs["ours"][0])
    runs = {m: runs[m] for m in (only if only is not None else runs)}
    scene, train_goals, lo, hi = train_goals_and_limits(first)
    steps = int(steps) if steps is not None else default_steps(first)
    train_mass = round(float(scene.world_builder().body_mass[scene.ee_body]), 6)
    columns = {
        "table1": [float(x) for x in s["stds"]],
        "table2": _with(s["masses"], train_mass),
        "table3": _with(s["lengths"], 0.0),
        "stress_mass": [float(x) for x in s["stress_masses"]],
        "stress_length": [float(x) for x in s["stress_lengths"]],
    }
    trained = {
        "table2": train_mass,
        "table3": 0.0,
        "stress_mass": 0.0,
        "stress_length": float(np.linalg.norm(scene.tip_offset)),
    }
    dyn_goals = draw_goals(
        train_goals,
        lo,
        hi,
        s["num_goals"],
        s["dynamics_goal_std"],
        s["around"],
        s["goal_noise"],
        s["seed"],
    )
    jobs, goals_used = _table_jobs(s, columns, runs, (train_goals, lo, hi), dyn_goals, scales)
    r = evaluate(
        jobs,
        inits=int(s["inits"]),
        steps=steps,
        seed=int(s["seed"]),
        device=device,
        max_worlds=int(s["max_worlds"]),
        progress=progress,
        resume=d / PROGRESS,
    )
    raw = [
        {
            "table": j.key[0],
            "column": j.key[1],
            "method": j.key[2],
            "run_dir": relpath(j.run_dir, d.parent),
            "final_sq_error": float32_list(e),
            "final_sq_error_untrained": float32_list(b),
        }
        for j, e, b in zip(jobs, r["errors"], r["before"])
    ]
    (d / "errors.json").write_text(json.dumps({"goals": goals_used, "jobs": raw}) + "\n")
    cells = _table_cells(columns, runs, jobs, r, d.parent)
    floors = {}
    if int(s["reach_iterations"]) > 0:
        from warp_critic.reproduce.experiments.reach import open_loop_floor

        for table in ("stress_mass", "stress_length"):
            best = open_loop_floor(
                first,
                [table_variant(table, v) for v in columns[table]],
                dyn_goals,
                iterations=int(s["reach_iterations"]),
                device=device,
            )
            floors[table] = (best.mean(1) / r["dof"]).tolist()  # MSE over joints, mean over goals
    return {
        "columns": columns,
        "trained": trained,
        "reach_floor": floors,
        "reach_iterations": int(s["reach_iterations"]),
        "cells": cells,
        "dof": r["dof"],
        "horizon": r["horizon"],
        "policy_updates": steps,
        **({"alpha_scales": dict(scales)} if scales else {}),
        "alphas": {relpath(k, d.parent): v for k, v in r["alphas"].items()},
        "worlds": r["worlds"],
        "batches": r["batches"],
        "diverged": r["diverged"],
        "raw_file": "errors.json",
        "dynamics_goals": dyn_goals.tolist(),
    }


def _table_jobs(
    s: dict, columns: dict, runs: dict, train: tuple, dyn_goals, scales: dict | None = None
) -> tuple[list, dict]:
    """Every (table, column, method, seed) job of the tables, and the goals of each column
    (``table/column`` -> goals). ``train``: the training goals and the joint limits (rad);
    ``scales``: method -> its step-size multiple (default 1)."""
    train_goals, lo, hi = train
    jobs, goals_used = [], {}
    for table, values in columns.items():
        for ci, v in enumerate(values):
            if table == "table1":
                goals = draw_goals(
                    train_goals,
                    lo,
                    hi,
                    s["num_goals"],
                    v,
                    s["around"],
                    s["goal_noise"],
                    int(s["seed"]) + ci,
                )
                variant = Variant()
            else:
                goals = dyn_goals
                variant = table_variant(table, v)
            goals_used[f"{table}/{ci}"] = goals.tolist()
            for m in runs:
                for si, rd in enumerate(runs[m]):
                    scale = float((scales or {}).get(m, 1.0))
                    jobs.append(Job((table, ci, m, si), str(rd), goals, variant, scale))
    return jobs, goals_used


def _table_cells(columns: dict, runs: dict, jobs: list, r: dict, base: Path) -> list[dict]:
    """One cell per table, column and method: its errors pooled over seeds (``pool_errors``)."""
    cells = []
    for table, values in columns.items():
        for ci, v in enumerate(values):
            for m in runs:
                idx = [k for k, j in enumerate(jobs) if j.key[:3] == (table, ci, m)]
                cell = pool_errors([r["errors"][k] for k in idx], r["dof"])
                cell.update(
                    table=table,
                    column=ci,
                    value=v,
                    method=m,
                    runs=[relpath(jobs[k].run_dir, base) for k in idx],
                    untrained_mse_mean=float(
                        np.mean([r["before"][k].mean() for k in idx]) / r["dof"]
                    ),
                )
                cells.append(cell)
    return cells


def goal_grid(
    lower: torch.Tensor, upper: torch.Tensor, n: int, fraction: float
) -> tuple[torch.Tensor, tuple[np.ndarray, np.ndarray]]:
    """The maps' goal grid: ``(n * n, 2)`` joint angles (rad), float32, row-major with ``q1``
    major, and its two axes ``(n,)`` (float64): ``n`` evenly spaced angles per joint over the
    middle ``fraction`` of its limits ``lower, upper (2,)`` (rad)."""
    (lo0, lo1), (hi0, hi1) = (
        inside_limits(lower.double(), upper.double(), fraction)[k].tolist() for k in (0, 1)
    )
    ax0, ax1 = np.linspace(lo0, hi0, n), np.linspace(lo1, hi1, n)
    grid = torch.tensor([[a, b] for a in ax0 for b in ax1], dtype=torch.float32)
    return grid, (ax0, ax1)


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
    ``steps``, ``scales``: the meta-test budget, as :func:`run_tables_stage`'s.

    ``floors_from``: a complete maps stage directory next to ``d`` that computed the reachability
    floors of the same grids from the same nominal runs (:func:`~warp_critic.reproduce.experiments.units.paper_maps_floors`); its
    floors are taken instead of computed again (``reach_floor_from`` names it)."""
    first = str(runs["ours"][0])
    runs = {m: runs[m] for m in (only if only is not None else runs)}
    scene, train_goals, lo, hi = train_goals_and_limits(first)
    steps = int(steps) if steps is not None else default_steps(first)
    n = int(s["grid"])
    grid, (ax0, ax1) = goal_grid(lo, hi, n, float(s["limit_fraction"]))
    masses = [float(x) for x in s["masses"]]
    lengths = [float(x) for x in s["lengths"]]
    links = list(scene.body_names)  # the two links, in chain order (arm1, arm2)
    pairs = {
        "mass": [(a, b) for a in masses for b in masses],  # row-major: link 1 major
        "length": [(a, b) for a in lengths for b in lengths],
    }
    variant = partial(_map_variant, links)
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
    r = evaluate(
        jobs,
        inits=int(s["inits"]),
        steps=steps,
        seed=int(s["seed"]),
        device=device,
        max_worlds=int(s["max_worlds"]),
        progress=progress,
        resume=d / PROGRESS,
    )
    dof = r["dof"]
    raw = [
        {
            "map": j.key[0],
            "column": j.key[1],
            "method": j.key[2],
            "run_dir": relpath(j.run_dir, d.parent),
            "final_sq_error": float32_list(e),
        }
        for j, e in zip(jobs, r["errors"])
    ]
    (d / "errors.json").write_text(json.dumps({"jobs": raw}) + "\n")
    out = {
        "axis_q1": ax0.tolist(),
        "axis_q2": ax1.tolist(),
        "train_goals": train_goals.tolist(),
        "masses": masses,
        "lengths": lengths,
        "links": links,
        "trained_mass": [round(float(x), 6) for x in scene.world_builder().body_mass],
        "trained_length": _link_lengths(scene),
        "grid_2d": True,
        "dof": dof,
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
        _map_results(out, m, jobs, r["errors"], pairs, n, dof)
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
