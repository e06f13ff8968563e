"""Benchmark: differentiable iiwa7 rollouts, warp-critic (Newton/Warp) vs the paper's model.

Prints forward+backward world-steps per second for the KUKA iiwa7 at several world counts
(horizon 100), side by side with the same rollout written on the paper's dynamics model
(``differentiable-robot-model``, torch autograd), and the ratio.

The rollout: open-loop joint torques ``tau_t`` (a leaf tensor), semi-implicit Euler with the same
``dt`` in both, joint damping on, gravity on, loss ``sum_t <w_t, q_t>``; one backward pass to the
torques and the initial state. A world-step is one physics step of one world.

Usage: ``python tools/bench_dynamics.py [--worlds 1,64,512] [--horizon 100] [--device cpu]``
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import torch

PROG = "bench_dynamics"


from warp_critic.cli.flags import ToolParser, comma_list  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def bench_newton(
    worlds: int, horizon: int, dt: float, device: str, repeats: int = 2
) -> tuple[float, float]:
    from warp_critic.physics.scene import Variant, load_scene
    from warp_critic.physics.simulator import Simulator

    scene = load_scene(ROOT / "scenes" / "kuka.usda")
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
        ro = sim.begin_rollout()
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
    args = p.parse_args(argv)
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
