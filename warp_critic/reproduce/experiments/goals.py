"""What the ``tables`` and ``maps`` stages share (:mod:`.tables`, :mod:`.maps`): a run's training
goals and limits, the goals they draw or lay out, and one evaluation of a stage's jobs with its raw
errors kept.

Raw final errors go to the stage's ``errors.json`` as float32 values in shortest decimal form
(:func:`~warp_critic.reproduce.experiments.records.float32_list`): read them as float32.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from warp_critic.reproduce.engine.stage import PROGRESS
from warp_critic.reproduce.experiments.evaluate import Job, evaluate, relpath
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


def evaluate_stage(
    d: Path, s: dict, jobs: list[Job], steps: int, device: str, progress: bool
) -> dict:
    """:func:`~warp_critic.reproduce.experiments.evaluate.evaluate` of a stage's ``jobs`` with its
    settings ``s`` (``inits``, ``seed``, ``max_worlds``), ``steps`` policy updates each, resuming
    from the stage directory ``d``'s progress folder."""
    return evaluate(
        jobs,
        inits=int(s["inits"]),
        steps=steps,
        seed=int(s["seed"]),
        device=device,
        max_worlds=int(s["max_worlds"]),
        progress=progress,
        resume=d / PROGRESS,
    )


def raw_errors(jobs: list[Job], r: dict, base: Path, first: str, untrained: bool) -> list[dict]:
    """One row per job for ``errors.json``: its key (``first``, e.g. ``table`` or ``map``, then
    ``column`` and ``method``), its run directory relative to ``base`` and its final squared
    errors (``untrained``: those of the policies before any update too)."""
    rows = []
    for k, j in enumerate(jobs):
        row = {first: j.key[0], "column": j.key[1], "method": j.key[2]}
        row.update(run_dir=relpath(j.run_dir, base), final_sq_error=float32_list(r["errors"][k]))
        if untrained:
            row["final_sq_error_untrained"] = float32_list(r["before"][k])
        rows.append(row)
    return rows
