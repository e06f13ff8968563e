"""Benchmark: seconds per meta-train outer iteration (KUKA, preset ``kuka-table1``), side by side.

Runs the KUKA at the report's settings (preset ``kuka-table1``: 4 goals x 4 worlds, horizon 50 x 4
physics sub-steps, 3 inner steps) for a few iterations with one seed and with ``--seeds`` batched in
one process, with the simulator's captured-graph replay on and off (``$WARP_CRITIC_GRAPHS``), and
prints s/iteration and the gains. Every measurement is a fresh process; the configurations are
interleaved and each is measured ``--repeats`` times, keeping the fastest (this shared machine's
speed swings 2-3x between runs: compare only numbers of one run).

``--against COMMIT`` measures the same configurations (graph replay on) on another commit too, in
the same run, interleaved: a temporary ``git worktree`` of COMMIT gets a temporary virtual
environment that shares this interpreter's packages but imports that checkout's package (see
:func:`other_checkout`); the same measuring code runs there. Both are removed after.

``--method ddpg`` or ``--method meta-critic`` measures a baseline's training iteration instead
(published settings on the same task: one exploration episode in every world, the minibatch
updates, the noise-free evaluation; one random-action warm-up iteration and a fixed meta-test alpha,
so no alpha search is timed); graph replay is then left on.

``--profile`` adds where the time of the steady-state iterations goes (cProfile own time of the
iterations after the untimed ones, grouped: Warp kernels incl. graph replay, the rest of Warp's
Python, Newton's Python, torch's backward engine, torch ops, other Python; plus the functions in
``warp/`` with the most own time). Read as proportions: profiling slows Python-heavy parts more.

Usage: ``python bench/bench_speed.py [--scene scenes/kuka.usda] [--iterations 8] [--seeds 0,1,2,3,4]
[--preset kuka-table1] [--method ours] [--device cpu] [--worlds-per-goal N] [--repeats 1]
[--against COMMIT]
[--profile]``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WARMUP = 2  # iterations not timed: the first compiles and allocates, the second captures graphs
GRAPHS_ENV = "WARP_CRITIC_GRAPHS"


# -- the measuring side: runs in a fresh process, on whichever checkout its interpreter imports ----
def _imports():
    """``(runtime, preset, TrainConfig, meta_train)`` of the layered package or the older flat one."""
    try:
        from warp_critic.core import runtime
        from warp_critic.evaluation.presets import preset
        from warp_critic.methods.ours import TrainConfig, meta_train
    except ImportError:  # before the layer folders (e.g. 4268102)
        from warp_critic import runtime
        from warp_critic.presets import preset
        from warp_critic.train import TrainConfig, meta_train
    return runtime, preset, TrainConfig, meta_train


def categorise(stats) -> tuple[dict[str, float], list[tuple[str, float]]]:
    """Own time (s) grouped by where it is spent, and the top functions inside ``warp/``."""
    groups = dict.fromkeys(
        (
            "warp kernels",
            "warp python",
            "newton python",
            "torch backward engine",
            "torch ops",
            "other python",
        ),
        0.0,
    )
    in_warp = []
    for (filename, line, name), (_, _, tottime, _, _) in stats.stats.items():
        if "warp/" in filename and name in ("invoke", "capture_launch"):
            groups["warp kernels"] += tottime
        elif "warp/" in filename:
            groups["warp python"] += tottime
            in_warp.append((f"{filename.split('warp/')[-1]}:{line}({name})", tottime))
        elif "newton/" in filename:
            groups["newton python"] += tottime
        elif "run_backward" in name or "torch/autograd" in filename:
            groups["torch backward engine"] += tottime
        elif filename == "~" and ("torch" in name or "method" in name):
            groups["torch ops"] += tottime
        else:
            groups["other python"] += tottime
    return groups, sorted(in_warp, key=lambda x: -x[1])[:8]


def measure(job: dict) -> dict:
    """Meta-train ``job['iterations']`` iterations; s/iteration after the untimed ones."""
    import cProfile

    os.environ[GRAPHS_ENV] = "1" if job["graphs"] else "0"
    runtime, preset, TrainConfig, meta_train = _imports()
    import warp_critic

    runtime.init()
    settings = preset(job["preset"])
    settings.pop("iterations", None)
    seeds = job["seeds"]
    prof = cProfile.Profile() if job["profile"] else None

    def start_profile(info) -> None:  # after the untimed iterations
        if prof is not None and info.iteration == WARMUP - 1:
            prof.enable()

    with tempfile.TemporaryDirectory(prefix="bench-speed-") as tmp:
        if job.get("method", "ours") != "ours":
            t0 = time.perf_counter()
            result = _train_baseline(job, Path(tmp) / "run", start_profile)
            return _result(result, time.perf_counter() - t0, prof, warp_critic.__file__)
        if job.get("worlds_per_goal"):
            settings["worlds_per_goal"] = job["worlds_per_goal"]
        cfg = TrainConfig(
            scene=job["scene"],
            **{**settings, "iterations": job["iterations"]},
            device=job["device"],
            out=str(Path(tmp) / "run"),
            seed=seeds[0],
            seeds=seeds if len(seeds) > 1 else None,
            checkpoint_every=10**6,
            record_every=10**6,
        )
        t0 = time.perf_counter()
        result = meta_train(cfg, callbacks=[start_profile], progress=False, record=False)
        wall = time.perf_counter() - t0
    return _result(result, wall, prof, warp_critic.__file__)


def _result(result, wall: float, prof, package: str) -> dict:
    import pstats

    if prof is not None:
        prof.disable()
    per_it = [r["seconds"] for r in result.metrics][WARMUP:]
    out = {"per_it": sum(per_it) / len(per_it), "wall": wall, "package": package}
    if prof is not None:
        out["groups"], out["in_warp"] = categorise(pstats.Stats(prof))
    return out


def _train_baseline(job: dict, out: Path, callback):
    """A baseline's ``job['iterations']`` iterations (published settings, fixed alpha)."""
    from warp_critic.methods import method

    seeds = job["seeds"]
    entry = method(job["method"])
    cfg = entry.config(
        scene=job["scene"],
        method=job["method"],
        iterations=job["iterations"],
        device=job["device"],
        out=str(out),
        seed=seeds[0],
        seeds=seeds if len(seeds) > 1 else None,
        checkpoint_every=10**6,
        record_every=10**6,
        warmup_iterations=1,
        metatest_alpha=1e-3,
    )
    return entry.train(cfg, callbacks=[callback], progress=False, record=False)


# -- the driving side ------------------------------------------------------------------------------
def run_job(python: str, job: dict) -> dict:
    """One measurement in a fresh process of ``python`` (its own checkout's package)."""
    proc = subprocess.run(
        [python, str(Path(__file__).resolve()), "--worker", json.dumps(job)],
        capture_output=True,
        text=True,
        cwd=tempfile.gettempdir(),  # never import a package from the current directory
    )
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(
            f"measurement failed ({python}, exit {proc.returncode}):\n{proc.stderr[-3000:]}"
        )
    return json.loads(lines[-1])


@contextlib.contextmanager
def other_checkout(commit: str):
    """``(python, root)``: a temporary checkout of ``commit`` importable as ``warp_critic``.

    A virtual environment of this interpreter whose site-packages list the checkout, then this
    interpreter's package directories (torch, warp, newton ...). A plain path line adds a directory
    without running the ``.pth`` files in it, so this checkout's editable install stays out. The
    checkout's ``[tool.setuptools.package-dir]`` entries (``warp_critic.kernels`` = ``kernels``)
    become links inside its package, as an editable install would map them (``pip install -e``
    needs the ``wheel`` package without build isolation, which a reused environment may lack).
    """
    import sysconfig

    import tomllib

    git = ["git", "-C", str(ROOT)]
    with tempfile.TemporaryDirectory(prefix="bench-against-") as tmp:
        root, venv = Path(tmp) / "checkout", Path(tmp) / "venv"
        subprocess.run(git + ["worktree", "add", "--detach", str(root), commit], check=True,
                       capture_output=True)  # fmt: skip
        try:
            subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
            python = str(venv / "bin" / "python")
            site = subprocess.run(
                [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                check=True,
                capture_output=True,
                text=True,
            ).stdout.strip()
            # the checkout first, then this interpreter's package directory and what its .pth
            # files add, except this checkout's own editable install
            ours = Path(sysconfig.get_paths()["purelib"])
            lines = [str(root), str(ours)]
            for pth in sorted(ours.glob("*.pth")):
                if "warp_critic" not in pth.name:
                    lines += pth.read_text().splitlines()
            Path(site, "zz_checkout.pth").write_text("\n".join(lines) + "\n")
            meta = tomllib.loads((root / "pyproject.toml").read_text())
            package_dir = meta.get("tool", {}).get("setuptools", {}).get("package-dir", {})
            for name, folder in package_dir.items():
                parts = name.split(".")
                if len(parts) == 2 and parts[0] == "warp_critic":
                    link = root / "warp_critic" / parts[1]
                    if not link.exists():
                        link.symlink_to(root / folder, target_is_directory=True)
            yield python, root
        finally:
            subprocess.run(git + ["worktree", "remove", "--force", str(root)], capture_output=True)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", default="scenes/kuka.usda", help="relative to each checkout's root")
    p.add_argument("--preset", default="kuka-table1", help="training settings (presets)")
    p.add_argument("--method", default="ours", choices=("ours", "ddpg", "meta-critic"),
                   help="whose training iteration to time (the baselines: published settings)")  # fmt: skip
    p.add_argument("--iterations", type=int, default=8,
                   help=f"iterations per run (the first {WARMUP} are not timed)")  # fmt: skip
    p.add_argument("--seeds", default="0,1,2,3,4", help="seeds batched in the second run")
    p.add_argument("--device", default="cpu", help="cpu or cuda (default cpu)")
    p.add_argument("--worlds-per-goal", type=int, default=None,
                   help="worlds per goal instead of the preset's (ours only; e.g. 64 on a GPU)")  # fmt: skip
    p.add_argument("--repeats", type=int, default=1, help="measurements per configuration")
    p.add_argument("--against", metavar="COMMIT", help="also measure this commit, side by side")
    p.add_argument("--profile", action="store_true", help="also profile (extra runs)")
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        print(json.dumps(measure(json.loads(args.worker))), flush=True)
        return 0
    try:
        seeds = [int(x) for x in args.seeds.split(",") if x.strip()]
    except ValueError:
        seeds = []
    if args.iterations <= WARMUP or not seeds or args.repeats < 1:
        print(f"bench_speed: error: --iterations must be > {WARMUP}, --seeds non-empty integers, "
              "--repeats >= 1", file=sys.stderr)  # fmt: skip
        return 2
    if args.worlds_per_goal is not None and (args.worlds_per_goal < 1 or args.method != "ours"):
        print("bench_speed: error: --worlds-per-goal must be >= 1, and times ours only",
              file=sys.stderr)  # fmt: skip
        return 2
    configs = [("1 seed", seeds[:1])] + ([(f"{len(seeds)} seeds", seeds)] if len(seeds) > 1 else [])
    base = {"preset": args.preset, "iterations": args.iterations, "device": args.device,
            "method": args.method, "worlds_per_goal": args.worlds_per_goal}  # fmt: skip
    with contextlib.ExitStack() as stack:
        sides = [("this", sys.executable, ROOT)]
        if args.against or args.method != "ours":
            modes = [(True, "graphs")]
        else:
            modes = [(False, "direct"), (True, "graphs")]
        if args.against:
            try:
                python, root = stack.enter_context(other_checkout(args.against))
            except subprocess.CalledProcessError as e:
                err = (e.stderr or b"").decode(errors="replace").strip().splitlines()
                print(f"bench_speed: error: --against {args.against}: {err[-1] if err else e}",
                      file=sys.stderr)  # fmt: skip
                return 2
            sides.append((args.against, python, root))
        times: dict[tuple, float] = {}
        for rep in range(args.repeats):
            for label, s in configs:
                for graphs, mode in modes:
                    for side, python, root in sides:
                        job = {**base, "seeds": s, "graphs": graphs, "profile": False,
                               "scene": str(root / args.scene)}  # fmt: skip
                        r = run_job(python, job)
                        key = (label, mode, side)
                        times[key] = min(times.get(key, float("inf")), r["per_it"])
                        print(f"[{rep + 1}/{args.repeats}] {label:>8}, {mode:>6}, {side:>8}: "
                              f"{r['per_it']:.3f} s/iteration ({r['wall']:.1f} s for "
                              f"{args.iterations} iterations; {r['package']})", flush=True)  # fmt: skip
        print(f"\nfastest of {args.repeats} (s/iteration):")
        for key, t in times.items():
            print(f"  {', '.join(key)}: {t:.3f}")
        print()
        for label, _ in configs:
            if not args.against and args.method != "ours":
                continue
            if not args.against:
                d, g = times[(label, "direct", "this")], times[(label, "graphs", "this")]
                print(f"graph replay: {label} {d / g:.2f}x faster per iteration")
            else:
                t, o = times[(label, "graphs", "this")], times[(label, "graphs", args.against)]
                print(f"{label}: {o / t:.2f}x faster per iteration than {args.against}")
        if len(seeds) > 1:
            n, one = len(seeds), times[("1 seed", "graphs", "this")]
            many = times[(f"{n} seeds", "graphs", "this")]
            print(f"{n} seeds batched (graphs): {n * one / many:.2f}x the throughput of 1 seed")
        if args.profile:
            print("\nbreakdown (cProfile own time of the timed iterations, share of each run):")
            profiles = {}
            for label, s in configs:
                for side, python, root in sides:
                    job = {**base, "seeds": s, "graphs": True, "profile": True,
                           "scene": str(root / args.scene), "iterations": WARMUP + 3}  # fmt: skip
                    profiles[f"{label}, {side}"] = run_job(python, job)
            print("| part | " + " | ".join(profiles) + " |\n|---|" + "---:|" * len(profiles))
            for k in next(iter(profiles.values()))["groups"]:
                cells = [f"{100 * r['groups'][k] / sum(r['groups'].values()):.0f}%"
                         for r in profiles.values()]  # fmt: skip
                print(f"| {k} | " + " | ".join(cells) + " |")
            for name, r in profiles.items():
                total = sum(r["groups"].values())
                print(f"\nPython in warp/ with the most own time ({name}):")
                for fn, t in r["in_warp"]:
                    print(f"  {100 * t / total:5.1f}%  {fn}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
