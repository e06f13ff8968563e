#!/usr/bin/env python
"""Benchmark the baselines the way the paper's section 5 does (not run in CI).

For each scene (reacher, kuka) and method (ddpg, meta-critic): train with the reported settings
(presets ``ddpg`` / ``meta-critic`` of :mod:`warp_critic.evaluation.presets`: the published hyperparameters,
300 iterations, the scene's goals/horizon/dt) into ``OUT_ROOT/<scene>-<method>``, then meta-test the
learned Q on new goals sampled around the training goals at std 0.1 / 0.3 / 0.4 (10 goals, 5 fresh
policy initialisations each, meta-test's default number of policy updates) and print a table of the
final joint-space squared error (mean +- std), next to the training numbers. Extra run directories
(e.g. our meta-trained critic, ``--extra runs/kuka-meta``) are meta-tested the same way and added.

A run directory is never deleted or overwritten: a complete run is only meta-tested, an interrupted
one is resumed from its checkpoint, and a directory that holds files but no checkpoint is refused.

Usage::

    python bench/bench_baselines.py                      # reported settings (minutes per run on CPU)
    python bench/bench_baselines.py --quick              # smoke test: 20 iterations, 3 goals x 2 inits
    python bench/bench_baselines.py --scenes reacher --methods ddpg --reuse

Lists are comma-separated (``--stds 0.1,0.4``, ``--extra runs/a,runs/b``). ``--reuse`` meta-tests
existing run directories without training. The results are also written as JSON to
``OUT_ROOT/bench_baselines.json``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from warp_critic.cli.flags import ToolParser, comma_list, user_message  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PROG = "bench_baselines"


def parse_args(argv=None):
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--scenes",
        type=comma_list(str),
        default=["reacher", "kuka"],
        help="comma-separated scene names under scenes/",
    )
    p.add_argument(
        "--methods",
        type=comma_list(str),
        default=["ddpg", "meta-critic"],
        help="comma-separated: ddpg, meta-critic",
    )
    p.add_argument(
        "--iterations",
        type=int,
        default=None,
        help="training iterations (default: the preset's, 300)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--stds",
        type=comma_list(float),
        default=[0.1, 0.3, 0.4],
        help="meta-test goal stds (rad), e.g. 0.1,0.4",
    )
    p.add_argument(
        "--goal-noise",
        default="per-joint",
        help="how goals are sampled around the training goals: per-joint or distance (see warp_critic.evaluation.metatest.sample_goals)",
    )
    p.add_argument("--num-goals", type=int, default=10)
    p.add_argument("--inits", type=int, default=5)
    p.add_argument(
        "--around",
        type=comma_list(int),
        default=[0, 1],
        help="training goals to sample around, e.g. 0,1 (the paper: two of the four); '' = all",
    )
    p.add_argument("--device", default="auto")
    p.add_argument(
        "--out-root",
        type=Path,
        default=None,
        help="where the run directories go (default runs/bench, runs/bench-quick with --quick)",
    )
    p.add_argument(
        "--extra",
        type=comma_list(str),
        default=[],
        help="other run directories to meta-test (e.g. ours), comma-separated",
    )
    p.add_argument(
        "--reuse", action="store_true", help="meta-test existing run directories, do not train"
    )
    p.add_argument(
        "--quick", action="store_true", help="smoke test: 20 iterations, 3 goals x 2 inits"
    )
    args = p.parse_args(argv)
    if args.out_root is None:
        args.out_root = Path("runs/bench-quick" if args.quick else "runs/bench")
    if args.quick:
        args.iterations = args.iterations or 20
        args.num_goals, args.inits = 3, 2
    return args


def _summary(run_dir: Path, seconds: float | None = None) -> dict:
    """Training numbers from ``metrics.jsonl``: first and last task loss, the last fresh-policy loss."""
    path = run_dir / "metrics.jsonl"
    try:
        rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    except (OSError, ValueError):
        return {}
    if not rows:
        return {}
    checked = [r for r in rows if "fresh_policy_loss" in r]
    last_check = checked[-1] if checked else {}
    return {
        "train_seconds": seconds
        if seconds is not None
        else sum(r.get("seconds", 0.0) for r in rows),
        "iterations": len(rows),
        "task_loss": rows[-1]["task_loss"],
        "task_loss_first": rows[0]["task_loss"],
        "fresh_policy_loss": last_check.get("fresh_policy_loss"),
        "alpha": last_check.get("alpha"),
    }


def _checkpoint(run_dir: Path) -> dict:
    """``RUN_DIR/checkpoint.pt`` as a dict, or a one-line UserError."""
    import torch

    from warp_critic.core.errors import UserError

    path = Path(run_dir) / "checkpoint.pt"
    if not Path(run_dir).is_dir():
        raise UserError(f"{run_dir}: run directory not found")
    if not path.is_file():
        raise UserError(f"{run_dir}: no checkpoint.pt in this run directory")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as e:  # corrupt / not a torch file
        raise UserError(f"{path}: cannot read checkpoint ({type(e).__name__})") from None
    if not isinstance(ckpt, dict) or "iteration" not in ckpt:
        raise UserError(f"{path}: not a warp-critic checkpoint")
    return ckpt


def plan_run(run_dir: Path, method: str, iterations: int) -> str:
    """``train``, ``resume`` or ``complete`` for ``run_dir``; a directory that is not such a run of
    ``method`` raises UserError: runs are never deleted or overwritten."""
    from warp_critic.core.errors import UserError

    if not run_dir.exists() or (run_dir.is_dir() and not any(run_dir.iterdir())):
        return "train"
    if not (run_dir / "checkpoint.pt").is_file():
        raise UserError(
            f"{run_dir}: exists but holds no checkpoint.pt; move it away or choose another --out-root "
            f"(runs are never deleted)"
        )
    ckpt = _checkpoint(run_dir)
    if ckpt.get("method") != method:
        raise UserError(
            f"{run_dir}: holds a {ckpt.get('method', 'ours')} run, not {method}; "
            f"move it away or choose another --out-root"
        )
    return "complete" if ckpt["iteration"] + 1 >= iterations else "resume"


def main(argv=None) -> int:
    args = parse_args(argv)
    from warp_critic.core import runtime
    from warp_critic.core.errors import UserError

    try:
        runtime.init()
        rows = run(args)
    except UserError as e:
        print(f"{PROG}: error: {user_message(e)}", file=sys.stderr)
        return 2
    stds = args.stds
    (args.out_root / "bench_baselines.json").write_text(json.dumps(rows, indent=2))
    print_table(rows, stds)
    print(f"\nresults: {args.out_root / 'bench_baselines.json'}")
    return 0


def run(args) -> list[dict]:
    from warp_critic.core.errors import FieldError
    from warp_critic.evaluation.metatest import MetaTestConfig, meta_test
    from warp_critic.evaluation.presets import preset
    from warp_critic.evaluation.protocol import ProtocolConfig, check_settings
    from warp_critic.methods import method as method_of
    from warp_critic.methods.baseline_config import BaselineConfig
    from warp_critic.methods.ddpg import train_ddpg
    from warp_critic.methods.meta_critic import train_meta_critic

    train = {"ddpg": train_ddpg, "meta-critic": train_meta_critic}
    # every setting is checked before any training
    check_settings(
        ProtocolConfig(
            stds=args.stds,
            goal_noise=[args.goal_noise],
            around=args.around or None,
            num_goals=args.num_goals,
            inits=args.inits,
        )
    )
    for m in args.methods:
        if m not in train:
            raise FieldError("methods", f"must be some of {', '.join(train)} (got {m!r})")
    for s in args.scenes:
        if not (ROOT / "scenes" / f"{s}.usda").is_file():
            raise FieldError("scenes", f"no scene {s!r} (scenes/{s}.usda not found)")
    around = args.around or None
    jobs: list[tuple[str, Path, BaselineConfig | None, str]] = []  # (label, run dir, config, plan)
    for scene in args.scenes:
        for method in args.methods:
            run_dir = args.out_root / f"{scene}-{method}"
            if args.reuse:
                _checkpoint(run_dir)  # a one-line error now rather than after the other runs
                jobs.append((f"{scene}-{method}", run_dir, None, "complete"))
                continue
            cfg = method_of(method).config(
                scene=str(ROOT / "scenes" / f"{scene}.usda"),
                seed=args.seed,
                device=args.device,
                out=str(run_dir),
                **preset(method),
            )
            if args.iterations:
                cfg.iterations = args.iterations
            jobs.append(
                (f"{scene}-{method}", run_dir, cfg, plan_run(run_dir, method, cfg.iterations))
            )
    for extra in args.extra:
        _checkpoint(Path(extra))
        jobs.append((Path(extra).name, Path(extra), None, "complete"))

    runs: list[tuple[str, Path, dict]] = []  # (label, run dir, training summary)
    for label, run_dir, cfg, plan in jobs:
        seconds = None
        if cfg is not None and plan != "complete":
            cfg.resume = plan == "resume"
            print(
                f"== {'resume' if cfg.resume else 'train'} {cfg.method} on {Path(cfg.scene).stem}: "
                f"{cfg.iterations} iterations",
                flush=True,
            )
            t0 = time.perf_counter()
            train[cfg.method](cfg)
            seconds = time.perf_counter() - t0
        elif cfg is not None:
            print(f"== {label}: {run_dir} is complete, meta-test only", flush=True)
        runs.append(
            (label, run_dir, _summary(run_dir, seconds) if cfg is not None or args.reuse else {})
        )

    rows = []
    for label, run_dir, summary in runs:
        row = {"run": label, "run_dir": str(run_dir), **summary, "meta_test": {}}
        for std in args.stds:
            suffix = "" if args.goal_noise == "per-joint" else f"-{args.goal_noise}"
            tc = MetaTestConfig(
                run_dir=str(run_dir),
                num_goals=args.num_goals,
                goal_std=std,
                around=around,
                goal_noise=args.goal_noise,
                inits=args.inits,
                device=args.device,
                seed=1,
                out=str(run_dir / f"metatest_std{std}{suffix}.json"),
            )
            r = meta_test(tc, progress=None)
            row["method"], row["scene"] = r["method"], r["scene"]
            row["meta_test"][str(std)] = {
                "mean": r["mean"],
                "std": r["std"],
                "before": r["mean_before"],
                "mse": r["mse_mean"],
                "alpha": r["alpha"],
                "policy_steps": r["policy_steps"],
            }
        rows.append(row)
    args.out_root.mkdir(parents=True, exist_ok=True)
    return rows


def print_table(rows: list[dict], stds: list[float]) -> None:
    head = f"{'run':<24} {'train first':>11} {'train last':>10} {'fresh(-Q)':>9} {'alpha':>8}"
    head += "".join(
        f" {'std ' + str(s) + ' sq. error (mean+-std / untrained; MSE)':>52}" for s in stds
    )
    print("\n" + head)
    print("-" * len(head))

    def num(x, fmt="{:.4f}"):
        return fmt.format(x) if isinstance(x, (int, float)) else "-"

    for row in rows:
        line = (
            f"{row['run']:<24} {num(row.get('task_loss_first')):>11} {num(row.get('task_loss')):>10} "
            f"{num(row.get('fresh_policy_loss')):>9} {num(next(iter(row['meta_test'].values()))['alpha'], '{:.2g}'):>8}"
        )
        for s in stds:
            m = row["meta_test"][str(s)]
            cell = "{:.4f} +- {:.4f} / {:.4f}; {:.4f}".format(
                m["mean"], m["std"], m["before"], m["mse"]
            )
            line += f" {cell:>52}"
        print(line)


if __name__ == "__main__":
    sys.exit(main())
