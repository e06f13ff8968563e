"""Stage ``tables``: the KUKA's Tables 1-3 and two stress tables.

The paper: "the mean squared error between last state and goal over 10 new goals, 5 seeds and 5 new
policy initialization". Every cell pools ``seeds x goals x inits`` final errors of one method, as
``mean_j (q_T,j - g_j)^2`` (MSE over the joints); ``mean(std)`` over the pooled policies.

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

Raw final errors go to ``errors.json`` (:mod:`.goals`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from warp_critic.physics.link_changes import parse_changes
from warp_critic.physics.scene import Variant
from warp_critic.reproduce.experiments.evaluate import Job, default_steps, pool_errors, relpath
from warp_critic.reproduce.experiments.goals import (
    draw_goals,
    evaluate_stage,
    raw_errors,
    train_goals_and_limits,
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


def _with(values, extra: float) -> list[float]:
    """``values`` as floats with ``extra`` (the training value) added, sorted."""
    return sorted({float(x) for x in values} | {float(extra)})


def _columns(s: dict, scene) -> tuple[dict[str, list[float]], dict[str, float]]:
    """Each table's column values (std rad, kg, m) and each dynamics table's training value."""
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
    return columns, trained


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
    columns, trained = _columns(s, scene)
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
    r = evaluate_stage(d, s, jobs, steps, device, progress)
    raw = raw_errors(jobs, r, d.parent, "table", untrained=True)
    (d / "errors.json").write_text(json.dumps({"goals": goals_used, "jobs": raw}) + "\n")
    return {
        "columns": columns,
        "trained": trained,
        "reach_floor": _stress_floors(first, s, columns, dyn_goals, r["dof"], device),
        "reach_iterations": int(s["reach_iterations"]),
        "cells": _table_cells(columns, runs, jobs, r, d.parent),
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


def _stress_floors(
    first: str, s: dict, columns: dict, dyn_goals, dof: int, device: str
) -> dict[str, list[float]]:
    """Each stress table's open-loop reachability floor per column (MSE over the joints, mean over
    the goals), from ours' first run's scene; none when ``reach_iterations`` is 0."""
    floors: dict[str, list[float]] = {}
    if int(s["reach_iterations"]) <= 0:
        return floors
    from warp_critic.reproduce.experiments.reach import open_loop_floor

    for table in ("stress_mass", "stress_length"):
        best = open_loop_floor(
            first,
            [table_variant(table, v) for v in columns[table]],
            dyn_goals,
            iterations=int(s["reach_iterations"]),
            device=device,
        )
        floors[table] = (best.mean(1) / dof).tolist()
    return floors
