"""Benchmark: seconds per meta-train outer iteration, one seed vs seeds batched, with a breakdown.

Runs the KUKA at the report's settings (preset ``kuka-table1``: 4 goals x 4 worlds, horizon 50 x 4
physics sub-steps, 3 inner steps) for a few iterations with one seed and with ``--seeds`` batched in
one process, side by side in one run (this shared machine's speed swings 2-3x between runs), and
prints s/iteration, the batch's throughput gain and where the time goes (cProfile of each run,
grouped: Warp kernels, Warp launch overhead, Newton's Python, torch's backward engine, torch ops,
other Python; read as proportions: profiling slows Python-heavy parts more than kernels).

Usage: ``python tools/bench_speed.py [--scene scenes/kuka.usda] [--iterations 6] [--seeds 0,1,2,3,4]
[--preset kuka-table1] [--device cpu] [--no-profile]``
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def categorise(stats: pstats.Stats) -> dict[str, float]:
    """Own time (s) grouped by where it is spent."""
    groups = {"warp kernels": 0.0, "warp launch overhead": 0.0, "newton python": 0.0,
              "torch backward engine": 0.0, "torch ops": 0.0, "other python": 0.0}
    for (filename, _, name), (_, _, tottime, _, _) in stats.stats.items():
        if "warp/" in filename and name == "invoke":
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


def run(scene: str, preset: dict, seeds: list[int], iterations: int, device: str, profile: bool):
    from warp_critic.train import TrainConfig, meta_train

    with tempfile.TemporaryDirectory(prefix="bench-speed-") as tmp:
        out = Path(tmp)
        cfg = TrainConfig(scene=scene, **{**preset, "iterations": iterations}, device=device, out=str(out / "run"),
                          seed=seeds[0], seeds=seeds if len(seeds) > 1 else None,
                          checkpoint_every=10**6, record_every=10**6)
        prof = cProfile.Profile() if profile else None
        t0 = time.perf_counter()
        if prof:
            prof.enable()
        result = meta_train(cfg, progress=False, record=False)
        if prof:
            prof.disable()
        wall = time.perf_counter() - t0
        per_it = [r["seconds"] for r in result.metrics][1:]  # the first iteration compiles/allocates
        groups = categorise(pstats.Stats(prof)) if prof else {}
        return sum(per_it) / len(per_it), wall, groups


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default=str(ROOT / "scenes" / "kuka.usda"))
    p.add_argument("--preset", default="kuka-table1", help="training settings (warp_critic.presets)")
    p.add_argument("--iterations", type=int, default=6, help="iterations per run (the first is not timed)")
    p.add_argument("--seeds", default="0,1,2,3,4", help="seeds batched in the second run, comma-separated")
    p.add_argument("--device", default="cpu")
    p.add_argument("--no-profile", action="store_true", help="time only (no cProfile breakdown)")
    args = p.parse_args(argv)

    from warp_critic import runtime
    from warp_critic.errors import UserError
    from warp_critic.presets import preset

    try:
        seeds = [int(x) for x in args.seeds.split(",") if x.strip()]
        if args.iterations < 2 or not seeds:
            raise UserError("--iterations must be >= 2 and --seeds non-empty")
        settings = preset(args.preset)
        settings.pop("iterations", None)
        runtime.init()
        rows = []
        for label, s in (("1 seed", seeds[:1]), (f"{len(seeds)} seeds batched", seeds)):
            per_it, wall, groups = run(args.scene, settings, s, args.iterations, args.device, not args.no_profile)
            rows.append((label, len(s), per_it, wall, groups))
            print(f"{label:>18}: {per_it:.3f} s/iteration ({wall:.1f} s for {args.iterations} iterations)", flush=True)
    except UserError as e:
        print(f"bench_speed: error: {e}", file=sys.stderr)
        return 2
    (_, _, one, _, g1), (label, n, many, _, gn) = rows
    print(f"\n{label}: {many / one:.2f}x the time per iteration of 1 seed, {n * one / many:.2f}x the throughput "
          f"(seeds x iterations per second)")
    if g1:
        print("\nbreakdown (cProfile own time, share of the profiled run):")
        print(f"| part | 1 seed | {label} |\n|---|---:|---:|")
        t1, tn = sum(g1.values()), sum(gn.values())
        for k in g1:
            print(f"| {k} | {100 * g1[k] / t1:.0f}% | {100 * gn[k] / tn:.0f}% |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
