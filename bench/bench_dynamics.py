"""Benchmark: differentiable iiwa7 rollouts, warp-critic (Newton/Warp) vs the paper's model.

Prints forward+backward world-steps per second for the KUKA iiwa7 at several world counts
(horizon 100), side by side with the same rollout written on the paper's dynamics model
(``differentiable-robot-model``, torch autograd), and the ratio.

The rollout: open-loop joint torques ``tau_t`` (a leaf tensor), semi-implicit Euler with the same
``dt`` in both, joint damping on, gravity on, loss ``sum_t <w_t, q_t>``; one backward pass to the
torques and the initial state. A world-step is one physics step of one world.

``--against COMMIT`` adds the same Newton rollout on another commit's checkout, side by side in one
run (interleaved, each measurement a fresh process, the best of ``--repeats``; see
``bench/bench_speed.py``'s ``other_checkout``).

Usage: ``python bench/bench_dynamics.py [--worlds 1,64,512] [--horizon 100] [--device cpu]
[--against COMMIT] [--repeats 1]``
"""

from __future__ import annotations

import argparse
import contextlib
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

PROG = "bench_dynamics"

try:
    from warp_critic.cli.flags import ToolParser, comma_list
except ImportError:  # run as --worker on a checkout before the layer folders (e.g. 4268102)
    from warp_critic.flags import ToolParser, comma_list

ROOT = Path(__file__).resolve().parents[1]


def bench_newton(
    worlds: int, horizon: int, dt: float, device: str, repeats: int = 2, root: Path = ROOT
) -> tuple[float, float]:
    """(fwd+bwd, fwd) world-steps/s of the checkout whose ``warp_critic`` is imported."""
    try:
        from warp_critic.physics.scene import Variant
        from warp_critic.physics.simulator import Simulator

        try:
            from warp_critic.physics.load import load_scene
        except ImportError:  # before physics/load.py (e.g. 11105f8)
            from warp_critic.physics.scene import load_scene
    except ImportError:  # before the layer folders (e.g. 4268102)
        from warp_critic.scene import Variant, load_scene
        from warp_critic.simulator import Simulator

    scene = load_scene(Path(root) / "scenes" / "kuka.usda")
    sim = Simulator(
        scene, [Variant()] * worlds, dt=dt, substeps=1, device=device, differentiable=True
    )
    dev = sim.torch_device
    gen = torch.Generator().manual_seed(0)
    tau = (torch.randn(horizon, worlds, 7, generator=gen) * 5).to(dev).requires_grad_()
    w = torch.randn(horizon, worlds, 7, generator=gen).to(dev)
    q0 = torch.zeros(worlds, 7, device=dev, requires_grad=True)
    qd0 = torch.zeros(worlds, 7, device=dev)

    def run():
        ro = sim.begin_rollout() or sim  # older checkouts: hidden rollout state, sim.step
        q, qd, loss = q0, qd0, 0.0
        for t in range(horizon):
            q, qd = ro.step(q, qd, tau[t])
            loss = loss + (w[t] * q).sum()
        loss.backward()
        if dev.type == "cuda":
            torch.cuda.synchronize()
        return float(loss.detach())

    run()  # warm-up: kernel compilation, buffer allocation
    run()  # the simulator captures its Warp graphs on the second rollout (replayed from then on)
    best_fb = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        run()
        best_fb = min(best_fb, time.perf_counter() - t0)
    # forward only, for reference (its first two steps run direct and capture)
    with torch.no_grad():
        q, qd = q0.detach(), qd0
        for t in range(2):
            q, qd = sim.step(q, qd, tau[t].detach())
        t0 = time.perf_counter()
        q, qd = q0.detach(), qd0
        for t in range(horizon):
            q, qd = sim.step(q, qd, tau[t].detach())
        if dev.type == "cuda":
            torch.cuda.synchronize()
        fwd = time.perf_counter() - t0
    return worlds * horizon / best_fb, worlds * horizon / fwd


def bench_drm(worlds: int, horizon: int, dt: float) -> float:
    import contextlib
    import io

    import differentiable_robot_model as drm_pkg
    from differentiable_robot_model.robot_model import DifferentiableRobotModel

    urdf = (
        Path(drm_pkg.__file__).resolve().parents[1]
        / "diff_robot_data"
        / "kuka_iiwa"
        / "urdf"
        / "iiwa7.urdf"
    )
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        robot = DifferentiableRobotModel(
            str(urdf), "iiwa7", device="cpu"
        )  # its URDF parser is chatty
    gen = torch.Generator().manual_seed(0)
    tau = (torch.randn(horizon, worlds, 7, generator=gen) * 5).requires_grad_()
    w = torch.randn(horizon, worlds, 7, generator=gen)
    q0 = torch.zeros(worlds, 7, requires_grad=True)
    t0 = time.perf_counter()
    q, qd, loss = q0, torch.zeros(worlds, 7), 0.0
    for t in range(horizon):
        qdd = robot.compute_forward_dynamics(
            q, qd, tau[t] * 1.0, include_gravity=True, use_damping=True
        )
        qd = qd + dt * qdd
        q = q + dt * qd
        loss = loss + (w[t] * q).sum()
    loss.backward()
    return worlds * horizon / (time.perf_counter() - t0)


def newton_in(python: str, root: Path, worlds: int, horizon: int, dt: float, device: str):
    """:func:`bench_newton` in a fresh process of ``python`` (its own checkout's package)."""
    job = json.dumps([worlds, horizon, dt, device, str(root)])
    proc = subprocess.run(
        [python, str(Path(__file__).resolve()), "--worker", job],
        capture_output=True,
        text=True,
        cwd=tempfile.gettempdir(),
    )
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("[")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(
            f"measurement failed ({python}, exit {proc.returncode}):\n{proc.stderr[-3000:]}"
        )
    return json.loads(lines[-1])


def compare(args) -> int:
    """This checkout's Newton rollout next to ``args.against``'s, interleaved."""
    from bench_speed import other_checkout

    print(
        f"iiwa7, horizon {args.horizon}, dt {args.dt} s, world-steps/s, best of {args.repeats} "
        f"(newton device: {args.device})"
    )
    with contextlib.ExitStack() as stack:
        python, root = stack.enter_context(other_checkout(args.against))
        sides = [("this", sys.executable, ROOT), (args.against, python, root)]
        print(
            f"{'worlds':>7} | {'fwd+bwd this':>13} | {'fwd+bwd ' + args.against:>16} | {'gain':>5} | "
            f"{'fwd this':>10} | {'fwd ' + args.against:>12} | {'gain':>5}"
        )
        for n in args.worlds:
            best = {side: [0.0, 0.0] for side, _, _ in sides}
            for _ in range(args.repeats):
                for side, py, r in sides:
                    fb, fw = newton_in(py, r, n, args.horizon, args.dt, args.device)
                    best[side] = [max(best[side][0], fb), max(best[side][1], fw)]
            (tb, tf), (ob, of) = best["this"], best[args.against]
            print(
                f"{n:>7} | {tb:>13,.0f} | {ob:>16,.0f} | {tb / ob:>4.2f}x | "
                f"{tf:>10,.0f} | {of:>12,.0f} | {tf / of:>4.2f}x",
                flush=True,
            )
    return 0


def main(argv: list[str] | None = None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--worlds", type=comma_list(int), default=[1, 64, 512], help="world counts, e.g. 1,64,512"
    )
    p.add_argument("--horizon", type=int, default=100, help="physics steps per rollout")
    p.add_argument("--dt", type=float, default=0.0025, help="time step (s)")
    p.add_argument(
        "--device", default="cpu", help="cpu or cuda for Newton (the paper's model runs on CPU)"
    )
    p.add_argument(
        "--no-reference",
        action="store_true",
        help="skip the paper's model (e.g. for 4096 worlds on GPU)",
    )
    p.add_argument("--against", metavar="COMMIT", help="also measure this commit, side by side")
    p.add_argument("--repeats", type=int, default=1, help="measurements per side (with --against)")
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        worlds, horizon, dt, device, root = json.loads(args.worker)
        try:
            from warp_critic.core import runtime
        except ImportError:
            from warp_critic import runtime
        runtime.init(threads=0)
        print(json.dumps(bench_newton(worlds, horizon, dt, device, root=Path(root))), flush=True)
        return 0
    if args.against:
        return compare(args)
    from warp_critic.core import runtime
    from warp_critic.core.errors import UserError

    # torch's default thread count: the paper's model (torch autograd) is the reference here
    runtime.init(threads=0)
    import logging

    logging.getLogger().setLevel(logging.ERROR)

    print(
        f"iiwa7, horizon {args.horizon}, dt {args.dt} s, fwd+bwd world-steps/s "
        f"(torch threads: {torch.get_num_threads()}, newton device: {args.device})"
    )
    print(
        f"{'worlds':>7} | {'warp-critic fwd+bwd':>20} | {'warp-critic fwd':>16} | {'paper model fwd+bwd':>20} | {'ratio':>6}"
    )
    for n in args.worlds:
        try:
            fb, fw = bench_newton(n, args.horizon, args.dt, args.device)
        except UserError as e:
            print(f"{PROG}: error: {e}", file=sys.stderr)
            return 2
        if args.no_reference:
            print(f"{n:>7} | {fb:>20,.0f} | {fw:>16,.0f} | {'-':>20} | {'-':>6}")
        else:
            ref = bench_drm(n, args.horizon, args.dt)
            print(f"{n:>7} | {fb:>20,.0f} | {fw:>16,.0f} | {ref:>20,.0f} | {fb / ref:>5.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
