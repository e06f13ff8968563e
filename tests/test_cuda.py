"""On a GPU: the CUDA path computes what the CPU path computes.

Every test here is skipped where Warp or torch sees no CUDA device (CI has none); on a machine with
one they run with the rest (``pytest tests/test_cuda.py``). The CPU path is the one checked against
the paper's own model (``tests/test_bridge.py``), so agreement with it carries that check over.
The tolerances are float32's: the GPU's kernels sum in another order (tile GEMM, fused multiply-add).
"""

from __future__ import annotations

import pytest
import torch
from conftest import KUKA, REACHER

from warp_critic.physics.load import load_scene
from warp_critic.physics.scene import Variant
from warp_critic.physics.simulator import AUTO_PICKS_CUDA, Simulator, resolve_device


def _has_cuda() -> bool:
    try:
        import warp as wp

        return bool(wp.is_cuda_available() and torch.cuda.is_available())
    except Exception:  # noqa: BLE001 - no driver, no CUDA build: no GPU to test
        return False


pytestmark = [
    pytest.mark.gpu,
    pytest.mark.skipif(not _has_cuda(), reason="no CUDA device (Warp and torch)"),
]


def _rel(a: torch.Tensor, b: torch.Tensor) -> float:
    return float((a.double().cpu() - b.double().cpu()).norm() / b.double().cpu().norm())


def _kuka_rollout(device: str, graphs: bool = True, worlds: int = 3, horizon: int = 15):
    """A 60-physics-step open-loop KUKA rollout with large motion; its end state and the loss's
    gradients w.r.t. the torques and the start state, on ``device``."""
    sim = Simulator(
        load_scene(KUKA), [Variant()] * worlds, dt=0.0025, substeps=4, device=device, graphs=graphs
    )
    gen = torch.Generator().manual_seed(0)
    dev = sim.torch_device
    q0 = ((torch.rand(worlds, 7, generator=gen) - 0.5) * 0.6).to(dev).requires_grad_()
    qd0 = torch.randn(worlds, 7, generator=gen).to(dev).requires_grad_()
    scale = torch.tensor([40.0, 40.0, 20.0, 20.0, 5.0, 3.0, 1.0])
    taus = (torch.randn(horizon, worlds, 7, generator=gen) * scale).to(dev).requires_grad_()
    wq = torch.randn(horizon, worlds, 7, generator=gen).to(dev)
    results = []
    for _ in range(3):  # direct, captured, replayed
        q, qd, loss = q0, qd0, 0.0
        with sim.begin_rollout() as ro:
            for t in range(horizon):
                q, qd = ro.step(q, qd, taus[t])
                loss = loss + (q * wq[t]).sum() + 0.1 * (qd**2).sum()
        grads = torch.autograd.grad(loss, [taus, q0, qd0])
        results.append([q.detach(), qd.detach(), *grads])
    motion = float((results[-1][0] - q0.detach()).abs().max())
    return sim, results, motion


def test_cuda_device_tensors_live_there():
    # ``auto`` stays on the CPU until the GPU check has measured CUDA faster (AUTO_PICKS_CUDA)
    assert resolve_device("auto") == ("cuda" if AUTO_PICKS_CUDA else "cpu")
    sim = Simulator(load_scene(REACHER), [Variant()] * 2, dt=0.01, substeps=2, device="cuda")
    assert sim.torch_device.type == "cuda" and str(sim.bridge.device).startswith("cuda")
    q, qd = sim.step(sim.zeros(), sim.zeros(), torch.ones(2, 2, device=sim.torch_device))
    assert q.device.type == "cuda" and torch.isfinite(q).all() and float(qd.abs().max()) > 0


def test_cuda_rollout_and_gradients_match_cpu():
    """The end state and every gradient agree with the CPU path to float32 precision."""
    _, cpu, motion = _kuka_rollout("cpu")
    sim, gpu, _ = _kuka_rollout("cuda")
    assert sim.torch_device.type == "cuda"
    assert motion > 0.5, "the test needs large motion"
    for name, g, c in zip(("q", "qd", "d/dtau", "d/dq0", "d/dqd0"), gpu[-1], cpu[-1]):
        assert g.device.type == "cuda"
        assert _rel(g, c) < 1e-4, f"{name}: CUDA off the CPU by {_rel(g, c):.2e}"


def test_cuda_graph_replay_matches_direct_launches():
    """CUDA graphs (captured on torch's stream) replay what direct launches compute."""
    sim, replay, _ = _kuka_rollout("cuda", graphs=True)
    _, direct, _ = _kuka_rollout("cuda", graphs=False)
    assert sim.bridge.graphs and sim.bridge._controls[0].backward.graph is not None
    for name, r, d in zip(("q", "qd", "d/dtau", "d/dq0", "d/dqd0"), replay[-1], direct[-1]):
        assert _rel(r, d) < 1e-6, f"{name}: replay off the direct path by {_rel(r, d):.2e}"
    # the third (replayed) rollout equals the first (direct) one of the same simulator
    for r, d in zip(replay[-1], replay[0]):
        assert _rel(r, d) < 1e-6


def test_cuda_meta_training_follows_the_cpu(tmp_path):
    """Three reacher meta-train iterations: the same task losses and critic on both devices."""
    from warp_critic.methods.ours import TrainConfig, meta_train

    runs = {}
    for device in ("cpu", "cuda"):
        runs[device] = meta_train(
            TrainConfig(
                scene=REACHER,
                goals=[[0.5, 0.3], [-0.4, 0.2]],
                worlds_per_goal=2,
                horizon=10,
                iterations=3,
                device=device,
                out=str(tmp_path / device),
            ),
            progress=False,
            record=False,
        )
    for mc, mg in zip(runs["cpu"].metrics, runs["cuda"].metrics):
        for key in ("task_loss_before", "task_loss"):
            assert mg[key] == pytest.approx(mc[key], rel=1e-3), (mc["iteration"], key)
    pc = torch.cat([p.detach().flatten() for p in runs["cpu"].model.parameters()])
    pg = torch.cat([p.detach().flatten().cpu() for p in runs["cuda"].model.parameters()])
    assert next(runs["cuda"].model.parameters()).device.type == "cuda"
    assert _rel(pg, pc) < 1e-3
