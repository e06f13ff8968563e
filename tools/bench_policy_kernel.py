"""Benchmark: the per-world policy MLP as a Warp kernel (replayed graph) vs torch, per control step.

The question it answers: would a forward-only inner rollout pay for evaluating its policy inside
the captured Warp work (so that the whole rollout replays as one graph)? It times the paper's policy
(``2 * dof -> 64 -> 64 -> dof``, tanh, one weight set per world) for ``W`` worlds, 50 evaluations
per measurement, three ways: torch (``networks.policy_forward``, batched einsum: what the rollouts
use), a Warp kernel with one thread per world (scalar loops), and a Warp tile kernel
(``wp.tile_matmul`` per world). Both Warp kernels run as a replayed graph of 50 launches, i.e. with
no Python per evaluation at all. Prints microseconds per evaluation (best of ``--repeats``) and
the largest relative difference to torch (the float order differs).

Usage: ``python tools/bench_policy_kernel.py [--worlds 16,80] [--repeats 5]``
"""

from __future__ import annotations

import sys
import time

import torch
import warp as wp

from warp_critic.cli.flags import ToolParser, comma_list
from warp_critic.core import runtime
from warp_critic.learning.networks import init_policy, policy_forward

PROG = "bench_policy_kernel"
OBS, HID, ACT, EVALS = 14, 64, 7, 50  # the KUKA: 7 joints, observation (q, qd)


@wp.kernel
def mlp_scalar(
    obs: wp.array2d[float],
    w1: wp.array3d[float],
    b1: wp.array2d[float],
    w2: wp.array3d[float],
    b2: wp.array2d[float],
    w3: wp.array3d[float],
    b3: wp.array2d[float],
    h1: wp.array2d[float],
    h2: wp.array2d[float],
    out: wp.array2d[float],
):
    w = wp.tid()
    for i in range(w1.shape[1]):
        s = b1[w, i]
        for j in range(w1.shape[2]):
            s += w1[w, i, j] * obs[w, j]
        h1[w, i] = wp.tanh(s)
    for i in range(w2.shape[1]):
        s = b2[w, i]
        for j in range(w2.shape[2]):
            s += w2[w, i, j] * h1[w, j]
        h2[w, i] = wp.tanh(s)
    for i in range(w3.shape[1]):
        s = b3[w, i]
        for j in range(w3.shape[2]):
            s += w3[w, i, j] * h2[w, j]
        out[w, i] = s


@wp.kernel
def mlp_tile(
    obs: wp.array3d[float],
    w1: wp.array3d[float],
    b1: wp.array3d[float],
    w2: wp.array3d[float],
    b2: wp.array3d[float],
    w3: wp.array3d[float],
    b3: wp.array3d[float],
    out: wp.array3d[float],
):
    w = wp.tid()
    x = wp.tile_load(obs[w], shape=(OBS, 1))
    a = wp.tile_matmul(wp.tile_load(w1[w], shape=(HID, OBS)), x)
    h = wp.tile_map(wp.tanh, a + wp.tile_load(b1[w], shape=(HID, 1)))
    a = wp.tile_matmul(wp.tile_load(w2[w], shape=(HID, HID)), h)
    h = wp.tile_map(wp.tanh, a + wp.tile_load(b2[w], shape=(HID, 1)))
    y = wp.tile_matmul(wp.tile_load(w3[w], shape=(ACT, HID)), h)
    wp.tile_store(out[w], y + wp.tile_load(b3[w], shape=(ACT, 1)))


def replayed(launch) -> wp.Graph:
    launch()  # loads the module
    wp.capture_begin(device="cpu", force_module_load=False)
    try:
        for _ in range(EVALS):
            launch()
    finally:
        graph = wp.capture_end(device="cpu")
    return graph


def best_us(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e6 * min(times) / EVALS


def measure(W: int, repeats: int, gen: torch.Generator) -> tuple[float, float, float, float]:
    """(torch, warp scalar, warp tile) us per evaluation and the largest relative difference."""
    params = init_policy(W, OBS, ACT, generator=gen)
    obs = torch.randn(W, OBS, generator=gen)
    ref = policy_forward(params, obs)
    names = ("w1", "b1", "w2", "b2", "w3", "b3")
    flat = {k: wp.from_torch(v.contiguous()) for k, v in params.items()}
    col = {k: wp.from_torch(v.unsqueeze(-1).contiguous()) for k, v in params.items()}
    out2, out3 = wp.zeros((W, ACT)), wp.zeros((W, ACT, 1))
    h1, h2 = wp.zeros((W, HID)), wp.zeros((W, HID))
    scalar_args = [wp.from_torch(obs), *(flat[n] for n in names), h1, h2, out2]
    tile_args = [wp.from_torch(obs.unsqueeze(-1).contiguous())]
    tile_args += [flat[n] if n.startswith("w") else col[n] for n in names] + [out3]
    g_scalar = replayed(lambda: wp.launch(mlp_scalar, dim=W, inputs=scalar_args))
    g_tile = replayed(lambda: wp.launch_tiled(mlp_tile, dim=W, inputs=tile_args, block_dim=1))

    def torch_evals():
        with torch.no_grad():
            for _ in range(EVALS):
                policy_forward(params, obs)

    t_torch = best_us(torch_evals, repeats)
    t_scalar = best_us(lambda: wp.capture_launch(g_scalar), repeats)
    t_tile = best_us(lambda: wp.capture_launch(g_tile), repeats)
    diff = max(
        float((wp.to_torch(o).reshape(W, ACT) - ref).abs().max() / ref.abs().max())
        for o in (out2, out3)
    )
    return t_torch, t_scalar, t_tile, diff


def main(argv: list[str] | None = None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("--worlds", type=comma_list(int), default=[16, 80], help="world counts")
    p.add_argument("--repeats", type=int, default=5, help="measurements, the best is kept")
    args = p.parse_args(argv)
    if not args.worlds or min(args.worlds) < 1 or args.repeats < 1:
        p.error("--worlds must be positive integers and --repeats >= 1")
    runtime.init()
    gen = torch.Generator().manual_seed(0)
    print(f"policy {OBS}-{HID}-{HID}-{ACT} tanh, us per evaluation of all worlds (best of "
          f"{args.repeats}; torch threads: {torch.get_num_threads()})")  # fmt: skip
    print(f"{'worlds':>7} | {'torch':>7} | {'warp scalar':>11} | {'warp tile':>9} | max rel diff")
    for W in args.worlds:
        t_torch, t_scalar, t_tile, diff = measure(W, args.repeats, gen)
        print(f"{W:>7} | {t_torch:>7.0f} | {t_scalar:>11.0f} | {t_tile:>9.0f} | {diff:.1e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
