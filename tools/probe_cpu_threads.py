"""Probe: can the worlds' Featherstone kernels use both CPU cores, split into two shards in threads?

The question it answers (issue 24's last lever): Warp runs a CPU kernel on one thread, and a
replayed graph (``wp.capture_launch``) is one ctypes call that releases the GIL, so two graphs over
two halves of the worlds could replay on two cores at once. For the KUKA (``scenes/kuka.usda``, its
dt and sub-steps, forward only) it times a ``--steps`` control-step rollout of ``W`` worlds in one
simulator, then in two simulators of ``W/2`` worlds one after the other, then the two in two
threads, and checks each against the one simulator bitwise (``torch.equal``). It does so once with
Featherstone's tile GEMM + Cholesky (what the bridge uses) and once with its dense batched path.
Each case runs in its own process, so a case that crashes is reported by its signal: Warp 1.19's
CPU tile kernels keep the pointer to their shared-memory block in a static that is not thread-local
on x86-64 (``warp/native/tile.h``: "Ideally this would be thread_local, but LLVM's JIT doesn't
support TLS yet"), and both shards' solvers launch the same cached tile kernel.

Usage: ``python tools/probe_cpu_threads.py [--worlds 16,80] [--steps 50] [--repeats 5]``
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

from warp_critic.cli.flags import ToolParser, comma_list

PROG = "probe_cpu_threads"
SCENE = Path(__file__).resolve().parents[1] / "scenes" / "kuka.usda"


def run_case(tile: bool, worlds: int, steps: int, repeats: int) -> dict:
    """Times (s, best of ``repeats``) and bitwise checks of one case, in this process."""
    import threading

    import torch

    from warp_critic.core import runtime
    from warp_critic.physics.bridge import NewtonBridge
    from warp_critic.physics.load import load_scene
    from warp_critic.physics.schema import STANDARD_GRAVITY
    from warp_critic.physics.variants import Variant

    runtime.init_warp()
    scene = load_scene(SCENE)
    d = scene.defaults
    dt, substeps, gravity = d["dt"], d["substeps"], d.get("gravity", STANDARD_GRAVITY)

    def bridge(n: int) -> NewtonBridge:
        model = scene.build_model([Variant()] * n, device="cpu", requires_grad=False)
        model.set_gravity((0.0, 0.0, -gravity))
        return NewtonBridge(model, n, scene.dof, dt, substeps, use_tile_gemm=tile)

    half = worlds // 2
    full, a, b = bridge(worlds), bridge(half), bridge(worlds - half)
    gen = torch.Generator().manual_seed(0)
    q0 = 0.5 * torch.randn(worlds, scene.dof, generator=gen)
    tau = 20.0 * torch.randn(steps, worlds, scene.dof, generator=gen)

    def roll(br: NewtonBridge, sl: slice):
        q, qd = q0[sl].clone(), torch.zeros_like(q0[sl])
        for t in range(steps):
            q, qd = br.step_forward(q, qd, tau[t, sl])
        return torch.cat([q, qd], dim=1)

    lo, hi = slice(0, half), slice(half, worlds)
    for _ in range(2):  # the first call runs directly, the second captures the graph
        roll(full, slice(None)), roll(a, lo), roll(b, hi)

    def serial():
        return torch.cat([roll(a, lo), roll(b, hi)])

    def threaded():
        out: dict = {}
        worker = threading.Thread(target=lambda: out.__setitem__("b", roll(b, hi)))
        worker.start()
        first = roll(a, lo)
        worker.join()
        return torch.cat([first, out["b"]])

    def best(fn):
        times, result = [], None
        for _ in range(repeats):
            t0 = time.perf_counter()
            result = fn()
            times.append(time.perf_counter() - t0)
        return min(times), result

    t_full, ref = best(lambda: roll(full, slice(None)))
    t_serial, r_serial = best(serial)
    t_threads, r_threads = best(threaded)
    return {
        "one": t_full,
        "serial": t_serial,
        "threads": t_threads,
        "serial_bitwise": bool(torch.equal(r_serial, ref)),
        "threads_bitwise": bool(torch.equal(r_threads, ref)),
    }


def in_subprocess(tile: bool, worlds: int, steps: int, repeats: int) -> dict | str:
    """:func:`run_case` in a fresh process: its result, or how the process ended."""
    code = (
        f"import json, runpy; case = runpy.run_path({str(Path(__file__).resolve())!r})['run_case']; "
        f"print('RESULT', json.dumps(case({tile}, {worlds}, {steps}, {repeats})))"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line.removeprefix("RESULT "))
    if proc.returncode < 0:
        return f"crashed ({signal.Signals(-proc.returncode).name})"
    tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
    return f"failed (exit {proc.returncode}: {tail})"


def main(argv: list[str] | None = None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("--worlds", type=comma_list(int), default=[16, 80], help="world counts (>= 2)")
    p.add_argument("--steps", type=int, default=50, help="control steps per rollout")
    p.add_argument("--repeats", type=int, default=5, help="measurements, the best is kept")
    p.add_argument(
        "--paths", type=comma_list(str), default=["tile", "dense"], help="tile, dense or both"
    )
    args = p.parse_args(argv)
    if not args.worlds or min(args.worlds) < 2:
        p.error("--worlds must be integers >= 2")
    if args.steps < 1 or args.repeats < 1:
        p.error("--steps and --repeats must be >= 1")
    if not args.paths or set(args.paths) - {"tile", "dense"}:
        p.error(f"--paths must be tile and/or dense (got {','.join(args.paths)!r})")
    print(f"KUKA forward rollouts of {args.steps} control steps, ms (best of {args.repeats})")
    print("path   worlds   one sim   2 shards serial   2 shards in 2 threads   threads/one")
    for path in args.paths:
        for W in args.worlds:
            r = in_subprocess(path == "tile", W, args.steps, args.repeats)
            if isinstance(r, str):
                print(f"{path:<6} {W:>6}   {r}")
                continue
            mark = {True: "bitwise", False: "DIFFERENT"}
            print(
                f"{path:<6} {W:>6}   {1e3 * r['one']:7.1f}   {1e3 * r['serial']:7.1f} "
                f"({mark[r['serial_bitwise']]})   {1e3 * r['threads']:7.1f} "
                f"({mark[r['threads_bitwise']]})   {r['one'] / r['threads']:.2f}x"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
