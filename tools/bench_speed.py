"""Benchmark: seconds per meta-train outer iteration: graph replay vs direct launches, 1 seed vs seeds batched.

Runs the KUKA at the report's settings (preset ``kuka-table1``: 4 goals x 4 worlds, horizon 50 x 4
physics sub-steps, 3 inner steps) for a few iterations with one seed and with ``--seeds`` batched in
one process, each with the simulator's captured-graph replay on and off (``$WARP_CRITIC_GRAPHS``),
side by side in one run (this shared machine's speed swings 2-3x between runs), and prints
s/iteration and the gains. ``--profile`` adds where the time goes (cProfile of extra short runs,
grouped: Warp kernels incl. graph replay, Warp launch overhead, Newton's Python, torch's backward
engine, torch ops, other Python; read as proportions: profiling slows Python-heavy parts more).

Usage: ``python tools/bench_speed.py [--scene scenes/kuka.usda] [--iterations 6] [--seeds 0,1,2,3,4]
[--preset kuka-table1] [--device cpu] [--profile]``. Took 41 s on the 2-core CPU machine (without --profile).
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
import tempfile
import time
from pathlib import Path

from warp_critic.core import runtime

ROOT = Path(__file__).resolve().parents[1]
WARMUP = 2  # iterations not timed


def categorise(stats: pstats.Stats) -> dict[str, float]:
    """Own time (s) grouped by where it is spent."""
    groups = {
        "warp kernels": 0.0,
        "warp launch overhead": 0.0,
        "newton python": 0.0,
        "torch backward engine": 0.0,
        "torch ops": 0.0,
        "other python": 0.0,
    }
    for (filename, _, name), (_, _, tottime, _, _) in stats.stats.items():
        if "warp/" in filename and name in ("invoke", "capture_launch"):
            groups["warp kernels"] += tottime
        elif "warp/" in filename:
            groups["warp launch overhead"] += tottime
        elif "newton/" in filename:
            groups["newton python"] += tottime
        elif "run_backward" in name or "torch/autograd" in filename:
            groups["torch backward engine"] += tottime
        elif filename == "~" and ("torch" in name or "method" in name):
            groups["torch ops"] += tottime
        else:
            groups["other python"] += tottime
    return groups


def run(
    scene: str,
    preset: dict,
    seeds: list[int],
    iterations: int,
    device: str,
    graphs: bool,
    profile: bool,
):
    """Meta-train ``iterations`` outer iterations; returns (s/iteration after the first, wall s, breakdown)."""
    from warp_critic.methods.ours import TrainConfig, meta_train

    os.environ[runtime.GRAPHS_ENV] = "1" if graphs else "0"
    with tempfile.TemporaryDirectory(prefix="bench-speed-") as tmp:
        out = Path(tmp)
        cfg = TrainConfig(
            scene=scene,
            **{**preset, "iterations": iterations},
            device=device,
            out=str(out / "run"),
            seed=seeds[0],
            seeds=seeds if len(seeds) > 1 else None,
            checkpoint_every=10**6,
            record_every=10**6,
        )
        prof = cProfile.Profile() if profile else None
        t0 = time.perf_counter()
        if prof:
            prof.enable()
        result = meta_train(cfg, progress=False, record=False)
        if prof:
            prof.disable()
        wall = time.perf_counter() - t0
        # not timed: the first iteration compiles and allocates, the second captures the graphs
        per_it = [r["seconds"] for r in result.metrics][WARMUP:]
        groups = categorise(pstats.Stats(prof)) if prof else {}
        return sum(per_it) / len(per_it), wall, groups


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default=str(ROOT / "scenes" / "kuka.usda"))
    p.add_argument(
        "--preset", default="kuka-table1", help="training settings (warp_critic.evaluation.presets)"
    )
    p.add_argument(
        "--iterations",
        type=int,
        default=8,
        help=f"iterations per run (the first {WARMUP} are not timed)",
    )
    p.add_argument(
        "--seeds", default="0,1,2,3,4", help="seeds batched in the second run, comma-separated"
    )
    p.add_argument("--device", default="cpu")
    p.add_argument(
        "--profile",
        action="store_true",
        help="also profile each configuration (extra runs) and print where the time goes",
    )
    args = p.parse_args(argv)

    from warp_critic.core.errors import UserError
    from warp_critic.evaluation.presets import preset

    try:
        seeds = [int(x) for x in args.seeds.split(",") if x.strip()]
        if args.iterations <= WARMUP or not seeds:
            raise UserError(f"--iterations must be > {WARMUP} and --seeds non-empty")
        settings = preset(args.preset)
        settings.pop("iterations", None)
        runtime.init()
        configs = [
            (f"1 seed, {mode}", seeds[:1], graphs)
            for graphs, mode in ((False, "direct"), (True, "graphs"))
        ]
        if len(seeds) > 1:
            configs += [
                (f"{len(seeds)} seeds, {mode}", seeds, graphs)
                for graphs, mode in ((False, "direct"), (True, "graphs"))
            ]
        times, groups = {}, {}
        for label, s, graphs in configs:
            per_it, wall, _ = run(
                args.scene, settings, s, args.iterations, args.device, graphs, False
            )
            times[label] = per_it
            print(
                f"{label:>18}: {per_it:.3f} s/iteration ({wall:.1f} s for {args.iterations} iterations)",
                flush=True,
            )
        if args.profile:
            for label, s, graphs in configs:
                groups[label] = run(args.scene, settings, s, WARMUP + 2, args.device, graphs, True)[
                    2
                ]
    except UserError as e:
        print(f"bench_speed: error: {e}", file=sys.stderr)
        return 2
    one_d, one_g = times["1 seed, direct"], times["1 seed, graphs"]
    print(f"\ngraph replay: 1 seed {one_d / one_g:.2f}x faster per iteration")
    if len(seeds) > 1:
        n = len(seeds)
        many_d, many_g = times[f"{n} seeds, direct"], times[f"{n} seeds, graphs"]
        print(f"graph replay: {n} seeds {many_d / many_g:.2f}x faster per iteration")
        print(
            f"{n} seeds batched (graphs): {many_g / one_g:.2f}x the time per iteration of 1 seed, "
            f"{n * one_g / many_g:.2f}x the throughput (seeds x iterations per second)"
        )
        print(
            f"{n} seeds batched (graphs) vs 1 seed direct: {n * one_d / many_g:.2f}x the throughput"
        )
    if groups:
        print("\nbreakdown (cProfile own time, share of each profiled run):")
        labels = list(groups)
        print("| part | " + " | ".join(labels) + " |\n|---|" + "---:|" * len(labels))
        for k in next(iter(groups.values())):
            cells = [f"{100 * g[k] / sum(g.values()):.0f}%" for g in groups.values()]
            print(f"| {k} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
