"""Stages ``tables`` (KUKA Tables 1-3) and ``maps`` (reacher Figures 4-6), batched meta-test.

Tables (the paper: "the mean squared error between last state and goal over 10 new goals, 5 seeds
and 5 new policy initialization"): every cell pools ``seeds x goals x inits`` final errors of one
method, as ``mean_j (q_T,j - g_j)^2`` (MSE over the joints); ``mean(std)`` over the pooled policies.

* Table 1: per column ``std``, ``num_goals`` goals ``N(g, std^2 I)`` per joint around training goals
  ``around`` (cycled), clipped into 98% of the limits (:func:`warp_critic.evaluation.metatest.sample_goals`).
* Table 2: end-effector mass: ``Variant(ee_mass=m)`` ADDS ``m`` kg at the tip of link 7 (0 = as
  trained); the paper's column is the end-effector mass itself ("training mass is at mass=3.12").
* Table 3: end-effector link length: ``Variant(link_length=L)`` SETS the tip distance of link 7 to
  ``L`` m (as trained: the scene's tip offset).
* Tables 2 and 3 use one set of ``num_goals`` goals drawn as Table 1's at ``dynamics_goal_std``.

Maps (reacher, 2 joints): (a) a ``grid x grid`` goal grid over ``limit_fraction`` of the joint
limits, MSE per goal over ``seeds x inits``; (b) end-effector (link 2) masses added at the tip and
(c) link-2 lengths, each for the four training goals. Link 1 cannot be changed by our
:class:`~warp_critic.physics.scene.Variant` (it changes the end-effector link only).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from warp_critic.physics.scene import Variant
from warp_critic.reproduce.evaluate import Job, default_steps, evaluate, relpath
from warp_critic.reproduce.settings import METHODS
from warp_critic.running.task import inside_limits


def _train_goals_and_limits(run_dir: str):
    from warp_critic.physics.scene import load_scene
    from warp_critic.running.rundir import RunDir

    ckpt = RunDir.open(run_dir).load_checkpoint(require=("config",))
    scene = load_scene(ckpt["config"]["scene"])
    goals = torch.tensor(ckpt["config"]["goals"], dtype=torch.float32)
    lo = torch.as_tensor(scene.q_lower, dtype=torch.float32)
    hi = torch.as_tensor(scene.q_upper, dtype=torch.float32)
    return scene, goals, lo, hi


def _sample(train_goals, lo, hi, num, std, around, noise, seed):
    from warp_critic.evaluation.metatest import sample_goals

    gen = torch.Generator().manual_seed(int(seed))
    return sample_goals(
        train_goals, int(num), float(std), list(around) if around else None, lo, hi, gen, noise
    )


def _pool(errs: list[np.ndarray], dof: int) -> dict:
    """Pool final squared errors (one (G, K) array per seed) into a cell: MSE over joints."""
    mse = np.concatenate([e.ravel() for e in errs]) / dof
    return {
        "mse_mean": float(mse.mean()),
        "mse_std": float(mse.std()),
        "mse_per_seed": [float(e.mean() / dof) for e in errs],
        "n": int(mse.size),
    }


def run_tables_stage(
    d: Path, s: dict, runs: dict[str, list[Path]], device: str, progress: bool = True
) -> dict:
    """``runs``: method -> per-seed run directories (KUKA)."""
    import json

    first = str(runs["ours"][0])
    scene, train_goals, lo, hi = _train_goals_and_limits(first)
    steps = default_steps(first)
    columns = {
        "table1": [float(x) for x in s["stds"]],
        "table2": [float(x) for x in s["masses"]],
        "table3": [float(x) for x in s["lengths"]],
    }
    dyn_goals = _sample(
        train_goals,
        lo,
        hi,
        s["num_goals"],
        s["dynamics_goal_std"],
        s["around"],
        s["goal_noise"],
        s["seed"],
    )
    jobs, goals_used = [], {}
    for table, values in columns.items():
        for ci, v in enumerate(values):
            if table == "table1":
                goals = _sample(
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
                variant = Variant(ee_mass=v) if table == "table2" else Variant(link_length=v)
            goals_used[f"{table}/{ci}"] = goals.tolist()
            for m in METHODS:
                for si, rd in enumerate(runs[m]):
                    jobs.append(Job((table, ci, m, si), str(rd), goals, variant))
    r = evaluate(
        jobs,
        inits=int(s["inits"]),
        steps=steps,
        seed=int(s["seed"]),
        device=device,
        max_worlds=int(s["max_worlds"]),
        progress=progress,
    )
    raw = [
        {
            "table": j.key[0],
            "column": j.key[1],
            "method": j.key[2],
            "run_dir": relpath(j.run_dir, d.parent),
            "final_sq_error": e.tolist(),
            "final_sq_error_untrained": b.tolist(),
        }
        for j, e, b in zip(jobs, r["errors"], r["before"])
    ]
    (d / "errors.json").write_text(json.dumps({"goals": goals_used, "jobs": raw}) + "\n")
    cells = []
    for table, values in columns.items():
        for ci, v in enumerate(values):
            for m in METHODS:
                idx = [k for k, j in enumerate(jobs) if j.key[:3] == (table, ci, m)]
                cell = _pool([r["errors"][k] for k in idx], r["dof"])
                cell.update(
                    table=table,
                    column=ci,
                    value=v,
                    method=m,
                    runs=[relpath(jobs[k].run_dir, d.parent) for k in idx],
                    untrained_mse_mean=float(
                        np.mean([r["before"][k].mean() for k in idx]) / r["dof"]
                    ),
                )
                cells.append(cell)
    return {
        "columns": columns,
        "cells": cells,
        "dof": r["dof"],
        "horizon": r["horizon"],
        "policy_updates": steps,
        "alphas": {relpath(k, d.parent): v for k, v in r["alphas"].items()},
        "worlds": r["worlds"],
        "batches": r["batches"],
        "raw_file": "errors.json",
        "dynamics_goals": dyn_goals.tolist(),
    }


def run_maps_stage(
    d: Path, s: dict, runs: dict[str, list[Path]], device: str, progress: bool = True
) -> dict:
    """``runs``: method -> per-seed run directories (reacher)."""
    import json

    first = str(runs["ours"][0])
    scene, train_goals, lo, hi = _train_goals_and_limits(first)
    steps = default_steps(first)
    n, f = int(s["grid"]), float(s["limit_fraction"])
    (lo0, lo1), (hi0, hi1) = (
        inside_limits(lo.double(), hi.double(), f)[k].tolist() for k in (0, 1)
    )
    ax0 = np.linspace(lo0, hi0, n)
    ax1 = np.linspace(lo1, hi1, n)
    grid = torch.tensor(
        [[a, b] for a in ax0 for b in ax1], dtype=torch.float32
    )  # row-major: q1 major
    masses = [float(x) for x in s["masses"]]
    lengths = [float(x) for x in s["lengths"]]
    jobs = []
    for m in METHODS:
        for si, rd in enumerate(runs[m]):
            jobs.append(Job(("goals", 0, m, si), str(rd), grid, Variant()))
            for ci, v in enumerate(masses):
                jobs.append(Job(("mass", ci, m, si), str(rd), train_goals, Variant(ee_mass=v)))
            for ci, v in enumerate(lengths):
                jobs.append(
                    Job(("length", ci, m, si), str(rd), train_goals, Variant(link_length=v))
                )
    r = evaluate(
        jobs,
        inits=int(s["inits"]),
        steps=steps,
        seed=int(s["seed"]),
        device=device,
        max_worlds=int(s["max_worlds"]),
        progress=progress,
    )
    dof = r["dof"]
    raw = [
        {
            "map": j.key[0],
            "column": j.key[1],
            "method": j.key[2],
            "run_dir": relpath(j.run_dir, d.parent),
            "final_sq_error": e.tolist(),
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
        "dof": dof,
        "horizon": r["horizon"],
        "policy_updates": steps,
        "tip_offset": [float(x) for x in scene.tip_offset],
        "raw_file": "errors.json",
        "goals": {},
        "mass": {},
        "length": {},
    }
    for m in METHODS:
        errs = [r["errors"][k] for k, j in enumerate(jobs) if j.key[0] == "goals" and j.key[2] == m]
        per_goal = (
            np.stack([e.mean(1) for e in errs]).mean(0) / dof
        )  # mean over seeds x inits, per goal
        out["goals"][m] = {"mse": per_goal.reshape(n, n).tolist(), **_pool(errs, dof)}
        for kind, values in (("mass", masses), ("length", lengths)):
            cells = []
            for ci, v in enumerate(values):
                errs = [r["errors"][k] for k, j in enumerate(jobs) if j.key[:3] == (kind, ci, m)]
                cells.append({"value": v, **_pool(errs, dof)})
            out[kind][m] = cells
    return out
