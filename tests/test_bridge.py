"""The differentiable model f: gradients through long rollouts with large motion are exact.

Reference: the paper's own dynamics model (``differentiable-robot-model``, torch autograd), run with
the same semi-implicit Euler integrator, damping and gravity, in float64 where it matters.
"""

from __future__ import annotations

import functools
from contextlib import nullcontext

import pytest
import torch
from conftest import ROOT
from helpers import drm_robot, drm_step

from warp_critic.core.errors import DivergenceError
from warp_critic.learning.networks import Normalizer, init_policy, policy_action
from warp_critic.learning.rollout import rollout
from warp_critic.physics.load import load_scene
from warp_critic.physics.scene import Variant
from warp_critic.physics.simulator import Simulator


@pytest.fixture(scope="module")
def kuka_sim():
    scene = load_scene(ROOT / "scenes" / "kuka.usda")
    return Simulator(scene, [Variant()] * 2, dt=0.0025, substeps=4, device="cpu")


@pytest.mark.slow
def test_open_loop_gradient_matches_paper_model_on_long_rollout(kuka_sim):
    """60 physics steps, ~1 rad of motion: d loss / d (torques, q0, qd0) vs autograd through DRM."""
    sim, H = kuka_sim, 15
    gen = torch.Generator().manual_seed(0)
    q0 = ((torch.rand(2, 7, generator=gen) - 0.5) * 0.6).requires_grad_()
    qd0 = torch.randn(2, 7, generator=gen).requires_grad_()
    scale = torch.tensor([40.0, 40.0, 20.0, 20.0, 5.0, 3.0, 1.0])
    taus = (torch.randn(H, 2, 7, generator=gen) * scale).requires_grad_()
    wq, wqd = torch.randn(H, 2, 7, generator=gen), torch.randn(H, 2, 7, generator=gen)

    ro = sim.begin_rollout()
    q, qd, loss = q0, qd0, 0.0
    for t in range(H):
        q, qd = ro.step(q, qd, taus[t])
        loss = loss + (q * wq[t]).sum() + 0.1 * (qd * wqd[t]).sum()
    grads = torch.autograd.grad(loss, [taus, q0, qd0])
    motion = (q - q0).abs().max().item()

    robot = drm_robot("kuka")
    qr, qdr, loss_r = q0.double(), qd0.double(), 0.0
    for t in range(H):
        qr, qdr = drm_step(robot, qr, qdr, taus[t], sim.dt, sim.substeps)
        loss_r = loss_r + (qr * wq[t]).sum() + 0.1 * (qdr * wqd[t]).sum()
    ref = torch.autograd.grad(loss_r, [taus, q0, qd0])

    assert motion > 0.5, "the test needs large motion"
    assert torch.allclose(q.double(), qr, atol=1e-3)
    for name, g, r in zip(("tau", "q0", "qd0"), grads, ref):
        rel = ((g.double() - r).norm() / r.norm()).item()
        assert rel < 1e-3, f"gradient w.r.t. {name} off by {rel:.2e}"


@pytest.mark.slow
def test_policy_parameter_gradient_matches_paper_model():
    """Closed loop: gradient of the final error w.r.t. per-world policy parameters (reacher)."""
    scene = load_scene(ROOT / "scenes" / "reacher.usda")
    sim = Simulator(scene, [Variant()] * 3, dt=0.01, substeps=2, device="cpu")
    norm = Normalizer.from_limits(sim.q_lower, sim.q_upper, torch.tensor([4.0, 4.0]), 5.0)
    gen = torch.Generator().manual_seed(1)
    params = {
        k: v.requires_grad_() for k, v in init_policy(3, 4, 2, generator=gen, out_scale=3.0).items()
    }
    goal = torch.tensor([[1.0, 0.5], [-1.0, 0.2], [0.3, -0.8]])
    H = 40
    traj = rollout(
        sim,
        lambda q, qd: policy_action(params, norm, q, qd),
        sim.zeros(),
        sim.zeros(),
        H,
        differentiable=True,
    )
    loss = ((traj.q[-1] - goal) ** 2).sum()
    grads = torch.autograd.grad(loss, list(params.values()))

    robot = drm_robot("reacher")
    q = torch.zeros(3, 2, dtype=torch.float64)
    qd = torch.zeros_like(q)
    for _ in range(H):
        tau = policy_action(params, norm, q.float(), qd.float())
        q, qd = drm_step(robot, q, qd, tau, sim.dt, sim.substeps)
    ref = torch.autograd.grad(((q - goal) ** 2).sum(), list(params.values()))
    assert (traj.q[-1] - traj.q[0]).abs().max() > 0.3
    assert (traj.q.abs() < 2.9).all(), "stay clear of the joint limits (the paper model has none)"
    for g, r in zip(grads, ref):
        assert ((g.double() - r.double()).norm() / r.norm()).item() < 2e-3


def test_gradient_matches_finite_differences():
    """Reacher, 20 control steps: directional derivative vs central differences in the torques."""
    scene = load_scene(ROOT / "scenes" / "reacher.usda")
    sim = Simulator(scene, [Variant()], dt=0.01, substeps=2, device="cpu")
    gen = torch.Generator().manual_seed(2)
    taus = torch.randn(20, 1, 2, generator=gen) * 5
    direction = torch.randn(
        taus.shape, generator=gen
    )  # seeded: randn_like draws from the global RNG
    goal = torch.tensor([[0.7, -0.4]])

    def loss_of(t, differentiable):
        step = sim.begin_rollout().step if differentiable else sim.step
        q, qd = sim.zeros(), sim.zeros()
        for k in range(t.shape[0]):
            q, qd = step(q, qd, t[k])
        return ((q - goal) ** 2).sum()

    t = taus.clone().requires_grad_()
    (g,) = torch.autograd.grad(loss_of(t, True), [t])
    eps = 1e-2
    fd = (loss_of(taus + eps * direction, False) - loss_of(taus - eps * direction, False)) / (
        2 * eps
    )
    analytic = (g * direction).sum()
    assert abs(analytic - fd) / abs(fd) < 1e-2


def test_forward_only_matches_differentiable_path(kuka_sim):
    sim = kuka_sim
    tau = torch.randn(2, 7) * 10
    q0 = torch.rand(2, 7) * 0.2
    with torch.no_grad():
        q_a, qd_a = sim.step(q0, torch.zeros(2, 7), tau)
    q_b, qd_b = sim.begin_rollout().step(q0, torch.zeros(2, 7), tau.clone().requires_grad_())
    assert torch.equal(q_a, q_b.detach()) and torch.equal(qd_a, qd_b.detach())


def test_non_finite_state_is_reported_with_world_and_step(kuka_sim):
    sim = kuka_sim
    calls = {"n": 0}

    def policy(q, qd):
        calls["n"] += 1
        tau = torch.zeros(2, 7)
        if calls["n"] == 3:
            tau[1, 0] = float("nan")
        return tau

    with pytest.raises(DivergenceError) as info:
        rollout(sim, policy, sim.zeros(), sim.zeros(), 6)
    assert info.value.world == 1 and info.value.step == 3
    assert "world 1" in str(info.value) and "step 3" in str(info.value)


def test_reused_buffers_refuse_stale_backward(kuka_sim):
    sim = kuka_sim
    tau = torch.ones(2, 7, requires_grad=True)
    old = sim.begin_rollout()
    q, _ = old.step(sim.zeros(), sim.zeros(), tau)
    sim.begin_rollout().step(
        sim.zeros(), sim.zeros(), tau
    )  # a newer rollout overwrites the buffers
    with pytest.raises(RuntimeError, match="reused"):
        q.sum().backward()
    with pytest.raises(RuntimeError, match="newer rollout"):
        old.step(q.detach(), sim.zeros(), tau)


def test_differentiable_step_needs_a_rollout(kuka_sim):
    tau = torch.ones(2, 7, requires_grad=True)
    with pytest.raises(RuntimeError, match="begin_rollout"):
        kuka_sim.step(kuka_sim.zeros(), kuka_sim.zeros(), tau)


def test_model_free_simulator_has_no_gradient_path():
    scene = load_scene(ROOT / "scenes" / "reacher.usda")
    sim = Simulator(scene, [Variant()], dt=0.01, substeps=1, device="cpu", differentiable=False)
    with pytest.raises(RuntimeError, match="requires_grad"):
        sim.begin_rollout()


def test_tip_kernel_matches_link_geometry():
    """Reacher tip = planar 2-link forward kinematics (links 1 m); a longer link moves it."""
    import math

    scene = load_scene(ROOT / "scenes" / "reacher.usda")
    sim = Simulator(
        scene, [Variant(), Variant(link_scale=1.5)], dt=0.01, device="cpu", differentiable=False
    )
    q = torch.tensor([[0.3, -0.7], [0.3, -0.7]])
    tips = sim.tip_positions(q)
    for w, l2 in ((0, 1.0), (1, 1.5)):
        x = math.cos(0.3) + l2 * math.cos(0.3 - 0.7)
        y = math.sin(0.3) + l2 * math.sin(0.3 - 0.7)
        assert tips[w, 0] == pytest.approx(x, abs=1e-5) and tips[w, 1] == pytest.approx(y, abs=1e-5)


def test_gravity_setting_is_per_simulator():
    """gravity=0 is the gravity-compensated robot: at rest with zero torque it stays at rest."""
    scene = load_scene(ROOT / "scenes" / "kuka.usda")
    q0 = torch.tensor([[0.0, 0.5, 0.0, -0.5, 0.0, 0.3, 0.0]])
    moved = {}
    for g in (0.0, 9.81):
        sim = Simulator(
            scene, [Variant()], dt=0.0025, substeps=4, device="cpu", differentiable=False, gravity=g
        )
        q, qd = q0.clone(), torch.zeros(1, 7)
        for _ in range(10):
            q, qd = sim.step(q, qd, torch.zeros(1, 7))
        moved[g] = float((q - q0).abs().max())
    assert moved[0.0] < 1e-6 and moved[9.81] > 1e-2


@pytest.mark.slow
def test_graph_replay_is_bitwise_the_direct_path():
    """Captured-graph replay (forward, taped forward, backward, zeroing) equals issuing every launch.

    Several rollouts of changing length, so that steps run direct (first use), get captured (second)
    and replay (later), forward-only steps interleaved, gradients through all of them.
    """
    scene = load_scene(ROOT / "scenes" / "kuka.usda")
    sims = [
        Simulator(scene, [Variant()] * 3, dt=0.0025, substeps=2, device="cpu", graphs=g)
        for g in (False, True)
    ]
    assert not sims[0].bridge.graphs and sims[1].bridge.graphs
    gen = torch.Generator().manual_seed(3)
    cases = [
        (
            torch.rand(3, 7, generator=gen) * 0.4,
            torch.randn(3, 7, generator=gen),
            torch.randn(h, 3, 7, generator=gen) * 8,
        )
        for h in (4, 6, 3, 6, 6)
    ]
    results = []
    for sim in sims:
        out = []
        for q0, qd0, taus in cases:
            with torch.no_grad():
                q_fw, qd_fw = q0, qd0
                for t in range(len(taus)):
                    q_fw, qd_fw = sim.step(q_fw, qd_fw, taus[t])
            q0g, taus_g = q0.clone().requires_grad_(), taus.clone().requires_grad_()
            q, qd = q0g, qd0
            with sim.begin_rollout() as ro:
                for t in range(len(taus)):
                    q, qd = ro.step(q, qd, taus_g[t])
            ((q**2).sum() + (qd**3).sum()).backward()
            out += [q_fw, qd_fw, q.detach(), qd.detach(), q0g.grad, taus_g.grad]
        results.append(out)
    assert (
        sims[1].bridge._fw_run.graph is not None
        and sims[1].bridge._controls[0].backward.graph is not None
    )
    for a, b in zip(*results):
        assert torch.equal(a, b)


@pytest.mark.slow
def test_policy_rollout_replay_is_bitwise_the_direct_path():
    """A 50-step closed-loop KUKA rollout (the paper's policy MLP): values, and gradients w.r.t. the
    policy parameters and the start state, equal with graph replay and with direct launches.

    Equality, not a tolerance: replay runs the same kernels on the same memory in the same order,
    and the policy stays in torch (no change of floating-point order). The third rollout of each
    kind is compared: the first runs direct, the second captures, the third replays.
    """
    scene = load_scene(ROOT / "scenes" / "kuka.usda")
    gen = torch.Generator().manual_seed(4)
    params = init_policy(2, 14, 7, generator=gen, out_scale=2.0)
    limit = torch.tensor([40.0, 40.0, 20.0, 20.0, 5.0, 3.0, 1.0])
    q0 = (torch.rand(2, 7, generator=gen) - 0.5) * 0.6
    results = []
    for graphs in (False, True):
        sim = Simulator(scene, [Variant()] * 2, dt=0.0025, substeps=4, device="cpu", graphs=graphs)
        norm = Normalizer.from_limits(sim.q_lower, sim.q_upper, limit, 5.0)
        for _ in range(3):
            p = {k: v.clone().requires_grad_() for k, v in params.items()}
            q0g = q0.clone().requires_grad_()
            policy = functools.partial(policy_action, p, norm)
            fw = rollout(sim, policy, q0, sim.zeros(), 50)
            traj = rollout(sim, policy, q0g, sim.zeros(), 50, differentiable=True)
            loss = (traj.q[-1] ** 2).sum() + (traj.qd**2).mean()
            grads = torch.autograd.grad(loss, [q0g, *p.values()])
        assert (traj.q[-1] - traj.q[0]).abs().max() > 0.1, "the test needs motion"
        results.append([fw.q, fw.qd, fw.tau, traj.q.detach(), traj.qd.detach(), *grads])
    for a, b in zip(*results):
        assert torch.equal(a, b)


def test_failed_capture_falls_back_to_direct_launches(monkeypatch):
    """A graph capture that cannot begin (on CUDA: a stream Warp cannot capture) warns once per
    replay and runs the direct launches: the same results as a simulator without graphs."""
    import warp_critic.physics.replay as replay

    def refuse(*args, **kwargs):
        raise RuntimeError("Warp error: unknown stream")

    scene = load_scene(ROOT / "scenes" / "kuka.usda")
    gen = torch.Generator().manual_seed(5)
    q0, taus = torch.rand(2, 7, generator=gen) * 0.4, torch.randn(4, 2, 7, generator=gen) * 8
    results = []
    for graphs in (False, True):
        sim = Simulator(scene, [Variant()] * 2, dt=0.0025, substeps=2, device="cpu", graphs=graphs)
        with monkeypatch.context() as m:
            m.setattr(replay.wp, "capture_begin", refuse)
            with pytest.warns(RuntimeWarning, match="unknown stream") if graphs else nullcontext():
                for _ in range(3):  # direct, (failed) capture, then direct again
                    tg = taus.clone().requires_grad_()
                    q, qd = q0, sim.zeros()
                    with sim.begin_rollout() as ro:
                        for t in range(len(tg)):
                            q, qd = ro.step(q, qd, tg[t])
                    ((q**2).sum() + (qd**2).sum()).backward()
        assert sim.bridge._controls[0].forward.graph is None
        assert not sim.bridge._controls[0].forward.enabled
        results.append([q.detach(), qd.detach(), tg.grad])
    for a, b in zip(*results):
        assert torch.equal(a, b)


def test_a_capture_that_fails_midway_is_discarded_and_runs_direct():
    """An error inside the captured work (nothing of it ran) leaves the capture ended and discarded,
    warns, and runs the direct work from then on, each call once."""
    from warp_critic.physics.replay import Replay

    calls: list[str] = []

    def captured():
        calls.append("captured")
        raise RuntimeError("operation not permitted when stream is capturing")

    replay = Replay("cpu", lambda: calls.append("direct"), captured)
    replay()
    with pytest.warns(RuntimeWarning, match="not permitted"):
        replay()
    replay()
    assert calls == ["direct", "captured", "direct", "direct"]
    assert replay.graph is None and not replay.enabled
    import warp as wp

    wp.capture_begin(device="cpu")  # no capture was left open on the device
    wp.capture_end(device="cpu")
