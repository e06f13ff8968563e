"""Stage ``metatrain`` (Figure 3): ours, DDPG and Meta-Critic on the reacher and the KUKA, every seed.

One sub-stage per (scene, method), ``metatrain-<scene>-<method>-<hash>``; its seeds train at once
(``seeds=``, one process and one simulator), each seed in ``run/seed<k>``. An interrupted sub-stage is
resumed (``resume=True``) from its checkpoints; a finished run is never overwritten.

Training curves: the final squared error ``||q_T - g||^2`` (``task_loss``: ours of the updated
policies, the baselines of their noise-free actor) against outer iterations and against simulated
environment steps. What counts as an environment step (one control step of one world):

* ours: every rollout of an iteration through the simulator, ``(inner_steps + 1) x worlds x horizon``
  (the ``inner_steps`` forward rollouts of the inner loop and the differentiable rollout of the updated
  policies for the task loss);
* DDPG / Meta-Critic: the exploration episodes that fill the replay buffer, ``worlds x horizon`` per
  iteration (their noise-free evaluation rollout and the alpha search at checkpoints only measure and
  are not counted).

``worlds`` is one seed's worlds, ``goals x worlds_per_goal``.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import fields
from pathlib import Path
from typing import TYPE_CHECKING

from warp_critic.core.errors import UserError
from warp_critic.methods import method as method_of
from warp_critic.methods import methods
from warp_critic.reproduce.experiments.settings import METHODS

if TYPE_CHECKING:
    from warp_critic.running.loop import TrainResult

#: how each method's environment steps are counted (the method registry's words)
STEPS_COUNTED = {m.name: m.samples_text for m in methods()}


def config_class(method_name: str):
    return method_of(method_name).config


def check_fields_known(method: str, values: dict, where: str) -> None:
    names = {f.name for f in fields(config_class(method))}
    unknown = sorted(set(values) - names)
    if unknown:
        raise UserError(f"{where}: unknown {method} setting(s) {', '.join(unknown)}")


def scene_file(scene: str) -> Path:
    from warp_critic.analysis import scene_path

    return scene_path(f"{scene}.usda")


def make_config(
    scene: str, method: str, values: dict, seeds: list[int], out: Path, device: str, resume: bool
):
    cls = config_class(method)
    kw = dict(values)
    if method_of(method).baseline:
        kw["method"] = method
    return cls(
        scene=str(scene_file(scene)),
        seeds=list(seeds),
        out=str(out),
        device=device,
        resume=resume,
        **kw,
    )


def clear_unstarted(run: Path, seeds: list[int]) -> bool:
    """Remove seed directories of this stage that hold no checkpoint (a run killed before its first
    checkpoint); returns whether every seed has a checkpoint (resume) -- none may be half-way."""
    have = [(run / f"seed{s}" / "checkpoint.pt").is_file() for s in seeds]
    if any(have) and not all(have):
        missing = [f"seed{s}" for s, h in zip(seeds, have) if not h]
        raise UserError(
            f"{run}: {', '.join(missing)} have no checkpoint while other seeds do; "
            "remove this stage directory to retrain it"
        )
    if not any(have):
        from warp_critic.running.locks import holder

        for s in seeds:
            p = run / f"seed{s}"
            if p.is_dir():
                owner = holder(p)
                if owner is not None:  # never remove what a live process works in
                    raise UserError(f"{p}: in use by process {owner.get('pid')}; not removing it")
                shutil.rmtree(p)
    return all(have)


def run_metatrain_stage(
    d: Path,
    scene: str,
    method: str,
    values: dict,
    seeds: list[int],
    device: str,
    progress: bool = True,
) -> dict:
    from warp_critic.running.config import filled

    run = d / "run"
    resume = clear_unstarted(run, seeds)
    values = dict(values)
    identify = values.pop("identify", None)  # a recipe's model identifier, after training
    record = True
    cfg = make_config(scene, method, values, seeds, run, device, resume)
    train: Callable[..., TrainResult] = method_of(method).train
    result = train(cfg, progress=progress, record=record)
    per_seed = {}
    steps_per_it = None
    for seed, r in zip(seeds, result.seeds):
        c = r.config
        assert c is not None  # a run returns its config
        worlds = len(filled(c.goals, "goals")) * c.worlds_per_goal
        mult = method_of(method).samples_per_iteration(c)
        steps_per_it = mult * worlds * filled(c.horizon, "horizon")
        rows = r.metrics
        per_seed[str(seed)] = {
            "run_dir": str(Path(r.run_dir).relative_to(d)),
            "iteration": [int(x["iteration"]) for x in rows],
            "task_loss": [float(x["task_loss"]) for x in rows],
            "fresh_policy_loss": [
                [int(x["iteration"]), float(x["fresh_policy_loss"])]
                for x in rows
                if x.get("fresh_policy_loss") is not None
            ],
            "seconds": float(sum(x.get("seconds", 0.0) for x in rows)),
            # per iteration (s): the wall time to reach an error level (the seeds run batched, so
            # each is the whole batch's time for that iteration)
            "seconds_each": [float(x.get("seconds", 0.0)) for x in rows],
        }
        summary = method_of(method).run_summary
        if summary is not None:  # e.g. Meta-Critic: whether h_omega still moved the actor
            per_seed[str(seed)].update(summary(rows))
    if identify is not None:
        for seed, r in zip(seeds, result.seeds):
            per_seed[str(seed)]["identified"] = identify_seed(
                d, Path(r.run_dir), seed, identify, device, progress
            )
    first = result.seeds[0].config
    assert first is not None
    return {
        "scene": scene,
        "method": method,
        "seeds": per_seed,
        "env_steps_per_iteration": steps_per_it,
        "env_steps_counted": STEPS_COUNTED[method],
        "horizon": first.horizon,
        "goals": first.goals,
        "worlds_per_goal": first.worlds_per_goal,
        "inner_steps": getattr(first, "inner_steps", 1),
        "iterations": first.iterations,
    }


def identify_seed(
    d: Path, run_dir: Path, seed: int, settings: dict, device: str, progress: bool
) -> dict:
    """A model identifier for one seed's told critic, in ``<run_dir>-identified`` (a complete one is
    kept: a resumed stage redoes at most the seed it was stopped in); returns its summary and
    ``run_dir`` (relative to the stage directory ``d``)."""
    from warp_critic.methods.identify import identified, train_identifier
    from warp_critic.running.locks import holder

    out = run_dir.with_name(f"{run_dir.name}-identified")
    summary = identified(out)
    if summary is None:
        if out.exists():  # stopped half-way: nothing of it is used
            owner = holder(out)
            if owner is not None:
                raise UserError(f"{out}: in use by process {owner.get('pid')}; not removing it")
            shutil.rmtree(out)
        if progress:
            print(f"identifying the model for seed {seed}'s critic ({out.name})", flush=True)
        summary = train_identifier(  # a stopped regression continues from its last 100 steps
            str(run_dir),
            str(out),
            seed=seed,
            device=device,
            resume_file=out.with_name(f"{out.name}.progress.pt"),
            **settings,
        )
    return {"run_dir": str(out.relative_to(d)), **summary}


def identified_run_dirs(d: Path, data: dict) -> list[Path]:
    """The per-seed identified run directories of a complete metatrain sub-stage whose recipe
    identifies the model (``identify``), in seed order; ``[]`` for any other."""
    seeds = sorted(data["result"]["seeds"].items(), key=lambda kv: int(kv[0]))
    if not all(isinstance(v.get("identified"), dict) for _, v in seeds):
        return []
    return [d / v["identified"]["run_dir"] for _, v in seeds]


def run_dirs(d: Path, data: dict) -> list[Path]:
    """The per-seed run directories of a complete metatrain sub-stage, in seed order."""
    return [
        d / v["run_dir"]
        for _, v in sorted(data["result"]["seeds"].items(), key=lambda kv: int(kv[0]))
    ]


__all__ = [
    "METHODS",
    "run_metatrain_stage",
    "run_dirs",
    "identified_run_dirs",
    "make_config",
    "check_fields_known",
    "scene_file",
]
