"""Each method's own meta-test budget inside ``reproduce``: chosen on the training goals, reported on
the held-out goal seeds (issue 54: Algorithm 3 trains "while not done"; the paper's stages give
every method ours' 3 critic-gradient steps).

1. **Choosing** (``budget-<robot>-<method>``, :func:`run_budget_stage`; reads that method's
   ``metatrain`` stage): every seed's critic trains fresh policies on the run's own training goals
   (``inits`` initialisations per goal from goal seed ``seed`` = :data:`CHOOSE_BUDGET_SEED`, which
   draws nothing else) at each step-size multiple ``s`` of ``alpha_scales`` (the run's own meta-test
   step size times ``s``) for ``max(steps)`` updates, read after each ``N`` of ``steps``
   (:func:`sweep`). The curve is the final MSE over the joints (rad^2), mean over seeds x goals x
   inits, per ``(s, N)``; the choice (:func:`choose`) its lowest finite value (ties: fewer steps,
   then the smaller step).
2. **Reporting** (``budget-<method>-tables-heldout[-<seed>]``, ``budget-<method>-maps-heldout[-<seed>]``):
   the held-out tables and maps stages' settings (:mod:`~warp_critic.reproduce.experiments.heldout`),
   run by the same stage functions with the method's rows at its chosen ``(s, N)`` and, for a
   baseline, ours' rows (``ours-at-<method>``) at the same ``N`` with ours' best step size there
   on the training goals (:func:`best_scale_at`). The budget is read from the choosing stages'
   records when the stage starts (:func:`reporting_kwargs`); their directories are in its hash.
   Ours' row at ``N`` steps depends on ``N`` alone (ours' critics, its best step size there), so
   where ``N`` is ours' own budget or an earlier baseline's (in the plan's order), that stage's
   row is the one meta-test of it: the stage leaves the row out and records where it is
   (``"shared_rows"``), and the report reads it there (:func:`with_shared_rows`). On the reacher
   DDPG and Meta-Critic both chose 300 steps: ours' maps at 300 steps, about an hour of a 2-core
   CPU per goal seed, are computed once instead of twice.

Each method's stages read only its own and ours' meta-training and choice, so ``--baselines td3``
adds TD3's without rerunning the others. A diverged world makes its ``(s, N)`` cell ``inf``: never
chosen.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from warp_critic.core.errors import UserError
from warp_critic.evaluation.seed_uses import CHOOSE_BUDGET_SEED
from warp_critic.reproduce.engine.stage import PROGRESS, Stage
from warp_critic.reproduce.experiments.naming import BUDGET, Outputs, stage_name
from warp_critic.reproduce.experiments.settings import (
    ALL_METHODS,
    BUDGET_SCALES,
    BUDGET_STEPS,
    METHODS,
    SCENES,
    stage_hash,
)

#: the ``warp-critic budget`` defaults (the reproduce settings' ``budget.steps`` / ``alpha_scales``)
BUDGETS, ALPHA_SCALES = BUDGET_STEPS, BUDGET_SCALES
#: the ``--only`` groups: every choice, and the held-out tables / maps at the chosen budgets
BUDGET_GROUPS = (
    BUDGET,
    stage_name("tables", heldout=True, budget=True),
    stage_name("maps", heldout=True, budget=True),
)

__all__ = [
    "ALPHA_SCALES",
    "BUDGETS",
    "BUDGET_GROUPS",
    "CHOOSE_BUDGET_SEED",
    "at_row",
    "best_scale_at",
    "choose",
    "envelope",
    "mean_mse",
    "numeric_keys",
    "owner_row",
    "plan_budget",
    "reporting_kwargs",
    "run_budget_stage",
    "run_reporting_stage",
    "sweep",
    "with_shared_rows",
]


# ------------------------------------------------------------------------------------------------
# the choice (pure)
# ------------------------------------------------------------------------------------------------


def choose(curve: dict[float, dict[int, float]]) -> tuple[float, int, float]:
    """``(scale, N, error)`` of the lowest finite error of ``curve`` (``{scale: {N: error}}``);
    ties: fewer steps, then the smaller scale. Raises :class:`UserError` when every cell diverged."""
    cells = [
        (err, n, s) for s, row in curve.items() for n, err in row.items() if math.isfinite(err)
    ]
    if not cells:
        raise UserError("every step size and budget diverged: no budget to choose")
    err, n, s = min(cells)
    return float(s), int(n), float(err)


def best_scale_at(curve: dict[float, dict[int, float]], n: int) -> tuple[float, float]:
    """``(scale, error)`` of the lowest finite error at budget ``n`` (ties: the smaller scale)."""
    scale, _, err = choose({s: {n: row[n]} for s, row in curve.items() if n in row})
    return scale, err


def envelope(curve: dict[float, dict[int, float]]) -> dict[int, float]:
    """Per budget ``N`` the lowest error over the step sizes (``inf`` when all diverged)."""
    ns = sorted({n for row in curve.values() for n in row})
    return {n: min((row.get(n, math.inf) for row in curve.values()), default=math.inf) for n in ns}


def numeric_keys(curve: dict) -> dict[float, dict[int, Any]]:
    """JSON's string keys back to ``{scale: {N: value}}``."""
    return {float(s): {int(n): v for n, v in row.items()} for s, row in curve.items()}


def at_row(method: str) -> str:
    """The row of ours' critics at ``method``'s chosen number of steps."""
    return f"ours-at-{method}"


def owner_row(method: str) -> str:
    """The row of ``method``'s reporting stage that holds ours at its number of steps: ours' own
    row in ours' stage, :func:`at_row` in a baseline's."""
    return "ours" if method == "ours" else at_row(method)


def with_shared_rows(per: dict[str, dict]) -> dict[str, dict]:
    """``per`` (method -> its reporting stage's result on one goal seed) with every result's shared
    rows (``"shared_rows"``: row -> ``[method, that method's row]``, module docstring) filled in
    from the result that holds them (itself filled in first, where its row is lent too): a
    table's cells (renamed) or a map's rows, and the row's step size. A method whose rows are in
    no result of ``per`` is left out."""
    done: dict[str, dict] = {}
    left = dict(per)
    while True:
        ready = [m for m, r in left.items()
                 if all(o in done for o, _ in r.get("shared_rows", {}).values())]  # fmt: skip
        if not ready:
            return {m: done[m] for m in per if m in done}
        for m in ready:
            done[m] = _lend(left.pop(m), done)


def _lend(r: dict, done: dict[str, dict]) -> dict:
    """``r`` with its shared rows copied from the complete results ``done``."""
    r = {**r, "alpha_scales": dict(r.get("alpha_scales", {}))}
    for row, (owner, src) in r.get("shared_rows", {}).items():
        o = done[owner]
        r["alpha_scales"][row] = o["alpha_scales"][src]
        if "cells" in r:  # tables: one cell per (table, column, row)
            r["cells"] = [
                *r["cells"],
                *({**c, "method": row} for c in o["cells"] if c["method"] == src),
            ]
        else:  # maps: row -> cells, per kind
            for k in ("goals", "mass", "length"):
                r[k] = {**r[k], row: o[k][src]}
    return r


# ------------------------------------------------------------------------------------------------
# the sweep
# ------------------------------------------------------------------------------------------------


def mean_mse(errs: list[np.ndarray], dof: int) -> float:
    """Mean over the pooled worlds of ``||q_T - g||^2 / dof`` (``inf`` if any diverged)."""
    v = np.concatenate([e.ravel() for e in errs]) / dof
    return float(v.mean()) if np.isfinite(v).all() else math.inf


def sweep(
    dirs: list[str],
    *,
    budgets: list[int],
    scales: list[float],
    inits: int,
    seed: int,
    device: str,
    max_worlds: int,
    progress: bool = False,
    resume: Path | None = None,
) -> dict[str, Any]:
    """Step 1 of the module docstring for one method's per-seed run directories ``dirs``:
    ``{"curve": {scale: {N: MSE}}, "per_seed": {scale: {N: [MSE per seed]}}, "untrained": MSE,
    "alphas", "diverged", "worlds", "seconds"}`` (MSE in rad^2)."""
    from warp_critic.physics.scene import Variant
    from warp_critic.reproduce.experiments.evaluate import Job, evaluate
    from warp_critic.reproduce.experiments.goals import train_goals_and_limits

    t = time.perf_counter()
    jobs = []
    for rd in dirs:
        _, goals, _, _ = train_goals_and_limits(rd)
        jobs += [Job((rd, s), rd, goals, Variant(), alpha_scale=s) for s in scales]
    r = evaluate(
        jobs,
        inits=inits,
        steps=max(budgets),
        seed=seed,
        device=device,
        max_worlds=max_worlds,
        progress=progress,
        at=tuple(budgets),
        resume=resume,
    )
    dof = r["dof"]
    curve: dict[float, dict[int, float]] = {}
    per_seed: dict[float, dict[int, list[float]]] = {}
    for s in scales:
        idx = [k for k, j in enumerate(jobs) if j.alpha_scale == s]
        curve[s] = {n: mean_mse([r["errors_at"][n][k] for k in idx], dof) for n in budgets}
        per_seed[s] = {n: [mean_mse([r["errors_at"][n][k]], dof) for k in idx] for n in budgets}
    return {
        "curve": curve,
        "per_seed": per_seed,
        # every scale of a run starts from the same policies: the first scale's jobs, one per run
        "untrained": mean_mse([r["before"][k] for k in range(0, len(jobs), len(scales))], dof),
        "alphas": r["alphas"],
        "diverged": r["diverged"],
        "worlds": r["worlds"],
        "seconds": time.perf_counter() - t,
    }


def run_budget_stage(
    d: Path, s: dict, runs: dict[str, list[Path]], device: str, progress: bool = True
) -> dict:
    """The choosing stage ``budget-<robot>-<method>``: ``runs`` holds that one method's per-seed
    run directories; its result is :func:`sweep`'s with ``"method"`` and ``"chosen"``
    (``{"scale", "steps", "mse_train"}``)."""
    from warp_critic.reproduce.experiments.evaluate import relpath

    ((method, dirs),) = runs.items()
    r = sweep(
        [str(p) for p in dirs],
        budgets=[int(n) for n in s["steps"]],
        scales=[float(x) for x in s["alpha_scales"]],
        inits=int(s["inits"]),
        seed=int(s["seed"]),
        device=device,
        max_worlds=int(s["max_worlds"]),
        progress=progress,
        resume=d / PROGRESS,
    )
    scale, steps, err = choose(r["curve"])
    r["alphas"] = {relpath(k, d.parent): v for k, v in r["alphas"].items()}
    return {
        **r,
        "method": method,
        "chosen": {"scale": scale, "steps": steps, "mse_train": err},
        "runs": [relpath(p, d.parent) for p in dirs],
    }


# ------------------------------------------------------------------------------------------------
# the plan, and the reporting stages' inputs
# ------------------------------------------------------------------------------------------------


def plan_budget(settings: dict, p: dict[str, Stage], extra: tuple[str, ...]) -> None:
    """Add to ``p`` (which holds the meta-trainings and the held-out stages) every method's choice
    on each robot, and the held-out tables and maps at the chosen budgets (module docstring)."""
    from warp_critic.reproduce.experiments.heldout import HELDOUT_EVALUATIONS

    s, methods = settings[BUDGET], (*METHODS, *extra)
    for scene in SCENES:
        for m in methods:
            train = stage_name("metatrain", scene, m)
            dep = {train: p[train].dir_name}
            name = stage_name(BUDGET, scene, m)
            o = Outputs(scene=scene, method=m, part_of=BUDGET)
            p[name] = Stage(name, BUDGET, s, dep, stage_hash(name, s, dep), o)
    for group, scene, _ in HELDOUT_EVALUATIONS:
        for seed in (int(x) for x in settings["heldout"]["seeds"]):
            held = p[stage_name(group, heldout=seed)].settings
            for i, m in enumerate(methods):
                reads = [
                    stage_name(k, scene, x) for k in ("metatrain", BUDGET) for x in ("ours", m)
                ]
                # the earlier baselines' choices: ours' row at a number of steps one of them chose
                # is its stage's (module docstring); the first baseline reads none
                if m != "ours":
                    reads += [stage_name(BUDGET, scene, x) for x in methods[:i] if x != "ours"]
                dep = {n: p[n].dir_name for n in dict.fromkeys(reads)}
                name = stage_name(group, by=m, heldout=seed, budget=True)
                rows = (m,) if m == "ours" else (m, at_row(m))
                part_of = stage_name(group, heldout=True, budget=True)
                o = Outputs(scene=scene, rows=rows, part_of=part_of, budget_of=m)
                p[name] = Stage(name, group, held, dep, stage_hash(name, held, dep), o)


def reporting_kwargs(st: Stage, out: Path) -> dict:
    """The tables / maps stage function's ``runs``, ``only``, ``steps`` and ``scales`` of the
    reporting stage ``st``, from the complete meta-training and choosing stages it reads under
    ``out`` (run directories relative to ``out``)."""
    from warp_critic.reproduce.engine.stages import read_stage
    from warp_critic.reproduce.experiments.metatrain import run_dirs

    o = st.outputs
    m, scene = o.budget_of, o.scene

    def record(kind: str, method: str) -> dict:
        name = stage_name(kind, scene, method)
        data = read_stage(out / st.depends[name])
        if data is None:
            raise UserError(
                f"{out / st.depends[name]}: the stage {name} this one needs is not complete"
            )
        return data

    def dirs(method: str) -> list[str]:
        d = out / st.depends[stage_name("metatrain", scene, method)]
        return [str(p.relative_to(out)) for p in run_dirs(d, record("metatrain", method))]

    chosen = record(BUDGET, m)["result"]["chosen"]
    steps = int(chosen["steps"])
    runs, scales = {"ours": dirs("ours"), m: dirs(m)}, {m: float(chosen["scale"])}
    only, shared = list(o.rows), {}
    if m != "ours":
        curve = numeric_keys(record(BUDGET, "ours")["result"]["curve"])
        runs[at_row(m)] = runs["ours"]
        scales[at_row(m)] = best_scale_at(curve, steps)[0]

        # ours' stage, then each earlier baseline's (those whose choice this stage reads): the
        # first that runs ours at the same steps and step size
        def ours_there(x: str) -> tuple[int, float]:
            c = record(BUDGET, x)["result"]["chosen"]
            n = int(c["steps"])
            return n, float(c["scale"]) if x == "ours" else best_scale_at(curve, n)[0]

        mine = (steps, scales[at_row(m)])
        earlier = [x for x in ALL_METHODS if x != m and stage_name(BUDGET, scene, x) in st.depends]
        owner = next((x for x in earlier if ours_there(x) == mine), None)
        if owner is not None:
            only = [r for r in only if r != at_row(m)]
            shared = {at_row(m): [owner, owner_row(owner)]}
    return {"runs": runs, "only": only, "steps": steps, "scales": scales, "shared": shared}


def run_reporting_stage(d: Path, s: dict, group: str, shared: dict, **kwargs) -> dict:
    """A held-out tables or maps stage at a method's chosen budget (``group``, with
    :func:`reporting_kwargs`' inputs): the stage function's result, with ``"shared_rows"`` when a
    row is another stage's (module docstring)."""
    from warp_critic.reproduce.experiments.maps import run_maps_stage
    from warp_critic.reproduce.experiments.tables import run_tables_stage

    if group == "tables":
        r = run_tables_stage(d, s, **kwargs)
    else:
        r = run_maps_stage(d, s, **kwargs)
    return {**r, "shared_rows": shared} if shared else r
