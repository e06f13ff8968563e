#!/usr/bin/env python
"""A small, documented hyperparameter search for the baselines (DDPG, Meta-Critic) on the training task.

The paper tunes nothing it reports for the baselines; we owe them a fair chance. For each scene and
method this trains ``--configs`` settings drawn (seeded, without repetition) from the grid below plus
the published defaults, each on the scene's training task with ``--seeds`` (seeds OTHER than the
reported 0-4, so the reported runs stay untouched by the choice), for ``--iterations`` iterations,
and scores a setting by its training error: the mean over seeds of the mean ``task_loss``
(``||q_T - g||^2`` of the actor on the training goals, rad^2) over the last quarter of the iterations.
The task (goals, starts, horizon, meta-test updates) is reproduce's (``reproduce/experiments/settings.py``).

Grid (a few values around the published ones, each a factor of 2-10):

* ``noise_std`` 0.1, 0.2 (published), 0.4 -- exploration noise, fraction of the torque bound;
* ``actor_lr`` 1e-4 (published), 1e-3; ``critic_lr`` 3e-4, 1e-3 (published);
* ``updates_per_iteration`` horizon (published: 50), 2 x horizon;
* ``reward_scale`` 1 (published), 10;
* Meta-Critic only, in the one-at-a-time design: ``virtual_lr`` 1e-3, 1e-2 (published: the actor
  lr, 1e-4), the SGD step of the two virtual actor updates whose difference trains ``h_omega``.

Meta-Critic's auxiliary loss can collapse to a constant (every published-setting run does within
a few iterations: the virtual steps of size 1e-4 give a meta-gradient far below ``h_omega``'s weight
decay), after which the run trains as DDPG. Each Meta-Critic row therefore records ``aux_alive``
(:func:`~warp_critic.methods.meta_critic.aux_alive`: the fraction of the last quarter's
iterations in which ``h_omega`` still moved the actor), printed beside its score. It is reported,
not used to choose: one rule for both baselines (:data:`ADOPT_RULE`). An earlier gate that let
only settings with a live ``h_omega`` be adopted for Meta-Critic rejected its better-training
settings while keeping a published setting that collapses just the same.

Prints one line per setting, sorted by score, and the best, and whether it is adopted
(:data:`ADOPT_RULE`: better than the published setting by more than the seed noise); writes everything to ``--out`` as JSON,
rewritten after every setting. The search resumes: a rerun with the same ``--out`` keeps every
setting already scored there (same scene, method, setting, iterations and seeds) and continues an
interrupted training from its last checkpoint (every quarter of the iterations).

Usage::

    nice python bench/tune_baselines.py --scenes reacher --methods ddpg,meta-critic \
        --configs 6 --iterations 120 --seeds 100,101 --out runs/tune/tune.json
    nice python bench/tune_baselines.py --scenes reacher,kuka --design one-at-a-time \
        --iterations 100 --seeds 100,101 --out runs/tune/tune.json
"""

from __future__ import annotations

import itertools
import json
import random
import sys
import time
from pathlib import Path

from warp_critic.cli.flags import ToolParser, comma_list, user_message
from warp_critic.core.errors import UserError

PROG = "tune_baselines"
GRID = {
    "noise_std": [0.1, 0.2, 0.4],
    "actor_lr": [1e-4, 1e-3],
    "critic_lr": [3e-4, 1e-3],
    "updates_per_iteration": [1.0, 2.0],  # x the horizon
    "reward_scale": [1.0, 10.0],
}
METHOD_GRID = {"meta-critic": {"virtual_lr": [1e-3, 1e-2]}}  # published: None (= the actor lr)
PUBLISHED = {
    "noise_std": 0.2,
    "actor_lr": 1e-4,
    "critic_lr": 1e-3,
    "updates_per_iteration": 1.0,
    "reward_scale": 1.0,
}


def one_at_a_time(method: str) -> list[dict]:
    """The published setting, then each single change of one value to another of :data:`GRID`,
    then (Meta-Critic) each of its own :data:`METHOD_GRID` values added to the published setting."""
    out = [dict(PUBLISHED)]
    for key, values in GRID.items():
        out += [{**PUBLISHED, key: v} for v in values if v != PUBLISHED[key]]
    for key, values in METHOD_GRID.get(method, {}).items():
        out += [{**PUBLISHED, key: v} for v in values]
    return out


def settings(n: int, seed: int) -> list[dict]:
    """The published setting first, then ``n - 1`` others drawn from :data:`GRID` without repetition."""
    keys = list(GRID)
    others = [dict(zip(keys, v)) for v in itertools.product(*GRID.values())]
    others = [s for s in others if s != PUBLISHED]
    random.Random(seed).shuffle(others)
    return [dict(PUBLISHED)] + others[: max(0, n - 1)]


def train_one(scene: str, method: str, setting: dict, args, out: Path) -> dict:
    from warp_critic.methods.ddpg import train_ddpg
    from warp_critic.methods.meta_critic import aux_alive, train_meta_critic
    from warp_critic.reproduce.experiments.metatrain import make_config
    from warp_critic.reproduce.experiments.settings import default_settings

    base = dict(default_settings(False, 1)["metatrain"][scene][method])
    horizon = horizon_of(scene, method)
    values = {k: v for k, v in setting.items() if k != "updates_per_iteration"}
    # one fixed meta-test alpha: the score is the training error, so skip the alpha search
    base.update(
        values,
        iterations=args.iterations,
        checkpoint_every=max(1, args.iterations // 4),
        metatest_alpha=1e-3,
    )
    resume = all((out / f"seed{s}" / "checkpoint.pt").is_file() for s in args.seeds)
    cfg = make_config(scene, method, base, args.seeds, out, args.device, resume)
    cfg.updates_per_iteration = int(round(setting["updates_per_iteration"] * horizon))
    t0 = time.perf_counter()
    train = train_ddpg if method == "ddpg" else train_meta_critic
    result = train(cfg, progress=False, record=False)
    seconds = time.perf_counter() - t0
    scores = []
    for r in result.seeds or [result]:
        losses = [float(x["task_loss"]) for x in r.metrics]
        tail = losses[-max(1, len(losses) // 4) :]
        scores.append(sum(tail) / len(tail))
    extra = {}
    if method == "meta-critic":
        extra["aux_alive"] = [aux_alive(r.metrics) for r in result.seeds or [result]]
    return {
        "scene": scene,
        "method": method,
        "iterations": args.iterations,
        "seeds": list(args.seeds),
        "setting": setting,
        "updates_per_iteration": cfg.updates_per_iteration,
        "score": sum(scores) / len(scores),
        "per_seed": scores,
        "seconds": seconds,
        **extra,
    }


def main(argv=None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("--scenes", type=comma_list(str), default=["reacher"])
    p.add_argument("--methods", type=comma_list(str), default=["ddpg", "meta-critic"])
    p.add_argument(
        "--configs", type=int, default=6, help="settings per scene and method (--design draw)"
    )
    p.add_argument(
        "--design",
        choices=("draw", "one-at-a-time"),
        default="draw",
        help="draw: the published setting and --configs - 1 seeded draws from the grid; "
        "one-at-a-time: the published setting and each single change of one value (7 settings; "
        "9 for Meta-Critic, with its virtual step)",
    )
    p.add_argument("--iterations", type=int, default=120)
    p.add_argument("--seeds", type=comma_list(int), default=[100, 101])
    p.add_argument("--draw-seed", type=int, default=0, help="seed of the draw from the grid")
    p.add_argument("--device", default="cpu")
    p.add_argument("--out", default="runs/tune/tune.json")
    args = p.parse_args(argv)
    for s in args.scenes:
        if s not in ("reacher", "kuka"):
            p.error(f"--scenes: unknown scene {s!r} (reacher, kuka)")
    for m in args.methods:
        if m not in ("ddpg", "meta-critic"):
            p.error(f"--methods: unknown method {m!r} (ddpg, meta-critic)")
    if args.configs < 1 or args.iterations < 4 or not args.seeds:
        p.error("--configs >= 1, --iterations >= 4 and at least one seed")
    if any(s < 5 for s in args.seeds):
        p.error("--seeds: use seeds other than the reported 0-4")
    out = Path(args.out)
    try:
        rows = _done_rows(out)
        _backfill_alive(out, rows)
        for scene in args.scenes:
            for method in args.methods:
                chosen = (
                    one_at_a_time(method)
                    if args.design == "one-at-a-time"
                    else settings(args.configs, args.draw_seed)
                )
                for k, setting in enumerate(chosen):
                    key = (scene, method, setting, args.iterations, list(args.seeds))
                    if any(_key(r) == key for r in rows):
                        continue  # scored by an earlier call
                    run = _run_dir(out, scene, method, args.iterations, setting)
                    row = train_one(scene, method, setting, args, run)
                    rows.append(row)
                    _write(out, args, rows, {})
                    print(
                        f"{scene} {method} #{k} {setting}: score {row['score']:.4f} "
                        f"(per seed {', '.join(f'{x:.4f}' for x in row['per_seed'])}; "
                        f"{row['seconds']:.0f} s)",
                        flush=True,
                    )
    except UserError as e:  # a user mistake (bad path, ...) as one line
        p.exit(2, f"{PROG}: error: {user_message(e)}\n")
    best = {}
    for scene in args.scenes:
        for method in args.methods:
            mine = sorted(
                (
                    r
                    for r in rows
                    if r["scene"] == scene
                    and r["method"] == method
                    and r["iterations"] == args.iterations
                    and r["seeds"] == list(args.seeds)
                ),
                key=lambda r: r["score"],
            )
            if not mine:
                continue
            published = next((r for r in mine if r["setting"] == PUBLISHED), None)
            if published is None:
                print(f"\n{scene} {method}: the published setting is not scored yet")
                continue
            top = mine[0]
            adopt = adopted(top, published)
            best[f"{scene}/{method}"] = {"best": top, "published": published, "adopt": adopt}
            print(f"\n{scene} {method}: sorted by score (rad^2, lower is better)")
            for r in mine:
                alive = r.get("aux_alive")
                note = "" if alive is None else f"  h_omega alive {_mean(alive):.0%}"
                print(f"  {r['score']:.4f}  {r['setting']}{note}")
            print(
                f"  best {top['setting']} {top['score']:.4f} vs published "
                f"{published['score']:.4f}: adopt {'the best' if adopt else 'the published'} "
                f"setting (rule: {ADOPT_RULE})"
            )
    _write(out, args, rows, best)
    return 0


ADOPT_RULE = (
    "a setting replaces the published one when its score is lower by more than half the spread "
    "of the published setting's per-seed scores; the same for both baselines (whether "
    "Meta-Critic's h_omega stayed alive is reported beside the score, not used to choose)"
)


def horizon_of(scene: str, method: str) -> int:
    """The rollout length a search's ``updates_per_iteration`` multiplies (its unit is the horizon):
    the stage's own setting, else the scene's default."""
    from warp_critic.physics.load import load_scene
    from warp_critic.reproduce.experiments.metatrain import scene_file
    from warp_critic.reproduce.experiments.settings import default_settings

    base = default_settings(False, 1)["metatrain"][scene][method]
    return int(base.get("horizon") or load_scene(scene_file(scene)).defaults.get("horizon", 50))


def _mean(xs: list) -> float:
    vals = [float(x) for x in xs if x is not None]
    return sum(vals) / len(vals) if vals else float("nan")


def _run_dir(out: Path, scene: str, method: str, iterations: int, setting: dict) -> Path:
    return out.parent / (
        f"{scene}-{method}-{iterations}it-" + "-".join(f"{v:g}" for v in setting.values())
    )


def _backfill_alive(out: Path, rows: list[dict]) -> None:
    """Give Meta-Critic rows scored before ``aux_alive`` was recorded their value, read from
    their runs' metrics where those are still on disk."""
    from warp_critic.methods.meta_critic import aux_alive

    for r in rows:
        if r["method"] != "meta-critic" or "aux_alive" in r:
            continue
        run = _run_dir(out, r["scene"], r["method"], r["iterations"], r["setting"])
        files = [run / f"seed{s}" / "metrics.jsonl" for s in r["seeds"]]
        if all(f.is_file() for f in files):
            r["aux_alive"] = [
                aux_alive([json.loads(line) for line in f.read_text().splitlines() if line])
                for f in files
            ]


def adopted(best: dict, published: dict) -> bool:
    """Whether ``best`` beats ``published`` by more than the seed noise (:data:`ADOPT_RULE`)."""
    if best["setting"] == published["setting"]:
        return False
    spread = max(published["per_seed"]) - min(published["per_seed"])
    return published["score"] - best["score"] > spread / 2


def _key(row: dict) -> tuple:
    return (row["scene"], row["method"], row["setting"], row.get("iterations"), row.get("seeds"))


def _done_rows(out: Path) -> list[dict]:
    """The settings an earlier call scored into ``out`` (none when it does not exist yet)."""
    if not out.is_file():
        return []
    try:
        rows = json.loads(out.read_text())["rows"]
        for r in rows:
            _key(r)
    except (ValueError, KeyError, TypeError):
        raise UserError(f"{out}: not a {PROG} result file; choose another --out") from None
    return rows


def _write(out: Path, args, rows: list[dict], best: dict) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps({"args": vars(args), "rows": rows, "best": best}, indent=1) + "\n")
    tmp.replace(out)  # never a half-written file


if __name__ == "__main__":
    sys.exit(main())
