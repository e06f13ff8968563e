"""The GPU check: one call that says what works and what is fast on a machine's CUDA device.

Runs, within a time budget (default 8 minutes), and writes one JSON file plus a printed table:

1. ``tests/test_cuda.py`` (CUDA against CPU gradients, graph replay against direct launches); on a
   machine without CUDA every test there is skipped and the table says so;
2. ``bench/bench_dynamics.py``'s differentiable KUKA rollout at 1 to 16,384 worlds on the device and
   on this machine's CPU, side by side (forward+backward world-steps per second);
3. ``bench/bench_speed.py``'s meta-training iteration (KUKA, Table 1 preset, 1 seed; the reacher
   in ``--tiny``) on the device
   with graph replay and with direct launches, and on the CPU with graph replay.

Each measurement runs in a fresh process (the benchmarks' own workers). Sizes that would not fit in
what is left of the budget are skipped and listed as skipped, never silently dropped.

``--device cpu`` runs the same table on the CPU alone (a machine without a GPU; the CUDA columns are
then the CPU's); ``--tiny`` is the seconds-long version CI runs so that this script cannot rot.

Usage: ``python tools/gpu_check.py [--device auto|cuda|cpu] [--tiny] [--budget 480] [--out F]``
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROG = "gpu_check"
FULL_WORLDS = (1, 16, 256, 1024, 4096, 16384)
TINY_WORLDS = (1, 4)
KIND = "warp-critic/gpu-check-v1"  # the "kind" of the JSON written; an earlier one may be replaced


def _tool(name: str):
    """A benchmark of ``bench/`` as a module (loaded by path, so the import search path stays as it is)."""
    spec = importlib.util.spec_from_file_location(f"_{PROG}_{name}", ROOT / "bench" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def cuda_available() -> bool:
    """Whether Warp and torch both see a CUDA device (a fresh process: this one stays light)."""
    code = "import torch, warp as wp; wp.config.quiet = True; print(bool(wp.is_cuda_available() and torch.cuda.is_available()))"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    return proc.returncode == 0 and proc.stdout.strip().endswith("True")


def run_cuda_tests(timeout: float) -> dict:
    """``pytest tests/test_cuda.py``: exit code, the closing summary line, seconds."""
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/test_cuda.py"],
            capture_output=True,
            text=True,
            cwd=ROOT,
            timeout=max(timeout, 1.0),
        )
    except subprocess.TimeoutExpired:
        return {"exit": None, "summary": f"timed out after {timeout:.0f} s", "seconds": timeout}
    lines = [ln for ln in proc.stdout.splitlines() if ln.strip()]
    return {
        "exit": proc.returncode,
        "summary": lines[-1].strip("= ") if lines else proc.stderr.strip()[-300:],
        "seconds": time.perf_counter() - t0,
    }


class Budget:
    """Seconds left of the whole call; a measurement is started only if its estimate fits."""

    def __init__(self, seconds: float):
        self.end = time.perf_counter() + seconds

    def left(self) -> float:
        return self.end - time.perf_counter()


def _failure(e: RuntimeError) -> str:
    """One line for a failed measurement: the worker's last error line, or how it was ended."""
    lines = [ln for ln in str(e).strip().splitlines() if ln.strip()]
    if len(lines) > 1:
        return lines[-1][:300]
    if "exit -9)" in lines[0]:
        return "killed (SIGKILL: out of memory on this machine)"
    return lines[0][:300]


def bench_rollouts(
    devices: list[str], worlds: tuple[int, ...], horizon: int, budget: Budget, reserve: float
) -> list[dict]:
    """Forward+backward world-steps/s of the KUKA rollout per world count and device. A world count
    is measured only if its estimate (the previous count's seconds, scaled by the square root of the
    world ratio: start-up dominates small counts, the work large ones) fits in what is left of the
    budget less ``reserve`` seconds kept for the iteration benchmark; otherwise it is skipped."""
    dyn = _tool("bench_dynamics")
    rows: list[dict] = []
    last: tuple[int, float] | None = None
    for n in worlds:
        row: dict = {"worlds": n}
        estimate = 0.0 if last is None else last[1] * (n / last[0]) ** 0.5
        if estimate > budget.left() - reserve:
            rows.append({**row, **{dev: None for dev in devices}})
            continue
        t0 = time.perf_counter()
        for dev in devices:
            try:
                fb, fw = dyn.newton_in(sys.executable, ROOT, n, horizon, 0.0025, dev)
                row[dev] = {"fwd_bwd": fb, "fwd": fw}
            except RuntimeError as e:
                row[dev] = {"error": _failure(e)}
        last = (n, time.perf_counter() - t0)
        rows.append(row)
    return rows


def bench_iterations(
    devices: list[str], iterations: int, budget: Budget, robot: tuple[str, str]
) -> list[dict]:
    """Seconds per meta-training iteration of ``robot`` = (preset, scene file), seed 0: each device
    with graph replay, and a CUDA device also with direct launches (measured slower than the CPU on
    an H200 before graph capture worked on CUDA)."""
    speed = _tool("bench_speed")
    plan = [(dev, True) for dev in devices] + [(d, False) for d in devices if d.startswith("cuda")]
    rows = []
    for dev, graphs in plan:
        row = {"device": dev, "mode": "graphs" if graphs else "direct", "per_it": None}
        if budget.left() < 30:
            row["skipped"] = "budget"
            rows.append(row)
            continue
        job = {
            "preset": robot[0],
            "iterations": iterations,
            "device": dev,
            "method": "ours",
            "worlds_per_goal": None,
            "seeds": [0],
            "graphs": graphs,
            "profile": False,
            "scene": str(ROOT / "scenes" / robot[1]),
        }
        try:
            row["per_it"] = speed.run_job(sys.executable, job)["per_it"]
        except RuntimeError as e:
            row["error"] = _failure(e)
        rows.append(row)
    return rows


def table(result: dict) -> str:
    """The printed summary of one check's JSON."""
    out = [
        f"GPU check on {result['machine']} (device {result['device']}, "
        f"{result['seconds']:.0f} s{', tiny' if result['tiny'] else ''})",
        f"tests/test_cuda.py: {result['cuda_tests']['summary']} (exit {result['cuda_tests']['exit']})",
        "",
        f"KUKA rollout, forward+backward world-steps/s (horizon {result['horizon']}, dt 2.5 ms):",
    ]
    devs = result["devices"]
    out.append("| worlds | " + " | ".join(devs) + " |")
    out.append("|---:|" + "---:|" * len(devs))
    for row in result["rollouts"]:
        cells = []
        for d in devs:
            v = row.get(d)
            cells.append(
                "skipped (budget)"
                if v is None
                else (f"error: {v['error']}" if "error" in v else f"{v['fwd_bwd']:,.0f}")
            )
        out.append(f"| {row['worlds']:,} | " + " | ".join(cells) + " |")
    out += ["", f"meta-training iteration ({result['preset']} preset, 1 seed), s/iteration:"]
    out.append("| device | mode | s/iteration |")
    out.append("|---|---|---:|")
    for row in result["iterations"]:
        v = (
            f"{row['per_it']:.3f}"
            if row["per_it"] is not None
            else ("skipped (budget)" if row.get("skipped") else f"error: {row.get('error')}")
        )
        out.append(f"| {row['device']} | {row['mode']} | {v} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="auto", choices=("auto", "cuda", "cpu"),
                   help="the device to check; auto: cuda where Warp and torch see one, else cpu")  # fmt: skip
    p.add_argument("--tiny", action="store_true",
                   help="seconds-long sizes (1 and 4 worlds, horizon 5, 3 reacher iterations): CI's version")  # fmt: skip
    p.add_argument("--budget", type=float, default=480.0,
                   help="seconds for the whole call (default 480, 8 minutes)")  # fmt: skip
    p.add_argument(
        "--out", default="gpu_check.json", help="the JSON file written (default ./gpu_check.json)"
    )
    args = p.parse_args(argv)
    if not args.budget > 0:
        print(f"{PROG}: error: --budget must be > 0 seconds (got {args.budget})", file=sys.stderr)
        return 2
    out = Path(args.out)
    if out.is_dir() or not out.parent.is_dir():
        print(f"{PROG}: error: --out {out}: not a file in an existing folder", file=sys.stderr)
        return 2
    from warp_critic.cli.flags import user_message
    from warp_critic.core.errors import UserError
    from warp_critic.running.files import atomic_write_text, check_output_file, check_replaceable
    from warp_critic.running.locks import check_not_owned

    try:  # the one rule of every writer: replace only an earlier GPU check's file
        check_output_file(out, "--out")
        check_not_owned(out, "--out")
        check_replaceable(out, "out", KIND, lambda old: None)
    except UserError as e:
        print(f"{PROG}: error: {user_message(e)}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    budget = Budget(args.budget)
    device = args.device
    if device != "cpu" and not cuda_available():
        if device == "cuda":
            print(f"{PROG}: error: --device cuda: no CUDA device is visible to both Warp and torch",
                  file=sys.stderr)  # fmt: skip
            return 2
        device = "cpu"
    devices = [device] if device == "cpu" else [device, "cpu"]
    horizon = 5 if args.tiny else 100
    worlds = TINY_WORLDS if args.tiny else FULL_WORLDS
    print(f"{PROG}: device {device}; tests/test_cuda.py ...", flush=True)
    result: dict = {
        "kind": KIND,
        "machine": f"{platform.node()} ({platform.machine()}, {platform.system()})",
        "device": device,
        "devices": devices,
        "tiny": args.tiny,
        "horizon": horizon,
        "budget_s": args.budget,
        "cuda_tests": run_cuda_tests(min(150.0, budget.left() / 3)),
    }
    print(f"{PROG}: rollouts at {', '.join(map(str, worlds))} worlds ...", flush=True)
    # the iteration benchmark's share: about a minute a device and mode (less in the tiny version)
    reserve = (20.0 if args.tiny else 60.0) * (2 * len(devices) - 1)
    result["rollouts"] = bench_rollouts(devices, worlds, horizon, budget, reserve)
    robot = ("reacher", "reacher.usda") if args.tiny else ("kuka-table1", "kuka.usda")
    result["preset"] = robot[0]
    print(f"{PROG}: meta-training iterations ({robot[0]}) ...", flush=True)
    result["iterations"] = bench_iterations(devices, 3 if args.tiny else 6, budget, robot)
    result["seconds"] = time.perf_counter() - t0
    atomic_write_text(out, json.dumps(result, indent=1) + "\n")
    print(table(result))
    print(f"\n{PROG}: wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
