"""Benchmark: meta-train the critic and meta-test it with the paper's protocol; prints the figures.

A thin script over :mod:`warp_critic.evaluation.presets` (the settings of the reported runs) and
:mod:`warp_critic.evaluation.protocol` (the meta-test protocol, pooled over seeds):

* reacher (preset ``reacher``): 4 training goals; meta-train error; meta-test on 10 unseen goals
  (std 0.3 around the training goals), 5 fresh policy initialisations each. Targets: <= 0.01 rad^2 /
  <= 0.05 rad^2.
* kuka (preset ``kuka-table1``): meta-test as in the paper's Table 1 at std 0.1 and 0.4 (10 new goals
  around two of the four training goals, 5 fresh inits, pooled over the meta-train ``--seeds``; the
  paper used 5). Paper: 0.02 and 0.07 -- its "mean squared error", the MSE rows (mean over the
  joints); the summed error ``||q_T - g||^2`` is 7x that. Both readings of the paper's goal sampling
  are printed (see :func:`warp_critic.evaluation.metatest.sample_goals`).

Wall time per outer iteration and in total is printed for every run.

Usage: ``python bench/bench_metatrain.py [--scenes reacher,kuka] [--seeds 0,1,2,3,4] [--iterations N]
[--device cpu] [--quick]``. Run directories go to ``runs/bench-<scene>[-seed<s>]`` (an existing one is
resumed, a finished one is only meta-tested).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from warp_critic.cli.flags import ToolParser, comma_list, user_message  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PROG = "bench_metatrain"


# scene -> the preset (warp_critic.evaluation.presets) its numbers are reported with
SCENE_PRESETS = {"reacher": "reacher", "kuka": "kuka-table1"}


def run_dir(runs: Path, name: str, seed: int, quick: bool) -> Path:
    return runs / (f"bench-{name}{'-quick' if quick else ''}" + (f"-seed{seed}" if seed else ""))


def train_scene(
    name: str, seed: int, iterations: int | None, device: str, quick: bool, runs: Path
) -> str:
    from warp_critic.evaluation.presets import preset
    from warp_critic.methods.ours import TrainConfig, meta_train

    out = run_dir(runs, name, seed, quick)
    settings = preset(SCENE_PRESETS[name])
    if iterations is not None:
        settings["iterations"] = iterations
    cfg = TrainConfig(
        scene=str(ROOT / "scenes" / f"{name}.usda"),
        device=device,
        out=str(out),
        seed=seed,
        resume=(out / "checkpoint.pt").exists(),
        **settings,
    )
    if quick:
        cfg.horizon, cfg.worlds_per_goal = 10, 1
        cfg.home_starts = min(cfg.home_starts or 0, cfg.worlds_per_goal)
    t0 = time.perf_counter()
    res = meta_train(cfg, progress=True)
    total = time.perf_counter() - t0
    rows = res.metrics
    last = rows[-10:] if len(rows) >= 10 else rows
    train_err = sum(r["task_loss"] for r in last) / max(len(last), 1)
    per_it = sum(r["seconds"] for r in rows) / max(len(rows), 1)
    return (
        f"{name} seed {seed}: meta-train {len(rows)} iterations, {per_it:.2f} s/iteration, "
        f"{per_it * len(rows):.0f} s in all ({total:.0f} s this call); final task loss "
        f"||q_T - g||^2 (mean of last {len(last)} iterations) {train_err:.4f} rad^2"
    )


def main(argv: list[str] | None = None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--scenes",
        type=comma_list(str),
        default=["reacher", "kuka"],
        help=f"comma-separated, of {', '.join(SCENE_PRESETS)}",
    )
    p.add_argument(
        "--seeds",
        type=comma_list(int),
        default=[0],
        help="meta-train seeds, pooled at meta-test, e.g. 0,1,2",
    )
    p.add_argument("--iterations", type=int, default=None, help="override the preset's iterations")
    p.add_argument("--device", default="auto")
    p.add_argument("--quick", action="store_true", help="tiny smoke version")
    p.add_argument(
        "--runs-dir", type=Path, default=ROOT / "runs", help="where the run directories go"
    )
    args = p.parse_args(argv)
    unknown = [s for s in args.scenes if s not in SCENE_PRESETS]
    if unknown or not args.scenes:
        p.error(
            f"--scenes: expected some of {', '.join(SCENE_PRESETS)} (got {','.join(args.scenes) or 'none'})"
        )
    if not args.seeds:
        p.error("--seeds: give one or more seeds, e.g. 0,1,2")

    from warp_critic.core import runtime
    from warp_critic.core.errors import UserError
    from warp_critic.evaluation.presets import evaluation
    from warp_critic.evaluation.protocol import ProtocolConfig, format_table, run_protocol

    lines = []
    try:
        runtime.init()  # Warp start, one torch thread (small networks next to Warp's CPU kernels)
        for name in args.scenes:
            lines += [
                train_scene(name, s, args.iterations, args.device, args.quick, args.runs_dir)
                for s in args.seeds
            ]
            pc = ProtocolConfig(
                run_dirs=[str(run_dir(args.runs_dir, name, s, args.quick)) for s in args.seeds],
                device=args.device,
                **evaluation(SCENE_PRESETS[name]),
            )
            if args.quick:
                pc.num_goals, pc.inits = 2, 1
            table = run_protocol(pc)
            lines.append(
                f"{name}: meta-test, {len(pc.run_dirs)} seed(s) x {pc.num_goals} goals x {pc.inits} inits "
                f"per cell (final error, mean(std))"
            )
            lines += format_table(table, paper="ours" if name == "kuka" else None)
    except UserError as e:
        print("\n".join(lines))
        print(f"{PROG}: error: {user_message(e)}", file=sys.stderr)
        return 2
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
