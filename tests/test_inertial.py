"""The ``inertial`` critic: the nominal inertia it reads, the metric its inner update steps in, and
that the meta-gradient through that update is exact."""

from __future__ import annotations

import pytest
import torch
from conftest import REACHER

from warp_critic.evaluation.metatest import MetaTestConfig, meta_test
from warp_critic.learning.critic import Critic
from warp_critic.learning.inner import critic_gradient
from warp_critic.learning.networks import MLPPolicy, Normalizer, init_policy
from warp_critic.learning.outer import meta_loss
from warp_critic.learning.rollout import Trajectory
from warp_critic.methods import ours as train
from warp_critic.physics.inertia import NominalInertia
from warp_critic.physics.load import load_scene
from warp_critic.physics.scene import Variant
from warp_critic.physics.simulator import Simulator
from warp_critic.running.rundir import load_checkpoint

TORQUE = torch.tensor([20.0, 20.0])


@pytest.fixture(scope="module")
def reacher():
    scene = load_scene(REACHER)
    sim = Simulator(scene, [Variant()] * 2, dt=0.01, substeps=2, device="cpu")
    norm = Normalizer.from_limits(sim.q_lower, sim.q_upper, TORQUE, 5.0, NominalInertia(scene))
    return scene, sim, norm


def reacher_mass_matrix(q2: torch.Tensor) -> torch.Tensor:
    """Two 1 kg, 1 m links, centres of mass at 0.5 m, 0.001 kg m^2 about their own centres."""
    m11 = 2 * 0.001 + 0.25 + 1.0 + 0.25 + torch.cos(q2)
    m12 = 0.001 + 0.25 + 0.5 * torch.cos(q2)
    return torch.stack(
        [torch.stack([m11, m12], -1), torch.stack([m12, torch.full_like(q2, 0.251)], -1)], -2
    )


@pytest.mark.slow
def test_nominal_inertia_is_the_reacher_mass_matrix(reacher):
    _, _, norm = reacher
    q = torch.rand(7, 3, 2) * 6 - 3  # (T, W, dof): any leading shape
    M = norm.inertia(q)
    assert M.shape == (7, 3, 2, 2)
    assert torch.allclose(M, reacher_mass_matrix(q[..., 1]), atol=1e-5)
    assert torch.allclose(norm.inertia.home(), reacher_mass_matrix(torch.tensor(0.0)), atol=1e-5)


def _step_acceleration(critic, q, qd, tau, goal):
    """The joint-acceleration change ``M(q)^-1 P(q) dL/dtau`` one inner step's torque change makes
    (``P`` the identity for a critic without a metric)."""
    tau = tau.clone().requires_grad_(True)
    (dtau,) = torch.autograd.grad(critic(q, qd, tau, goal).sum(), tau)
    P = critic.torque_metric(q)
    step = dtau if P is None else (P @ dtau.unsqueeze(-1)).squeeze(-1)
    return torch.linalg.solve(critic.inertia(q), step.unsqueeze(-1)).squeeze(-1)


@pytest.mark.slow
def test_inertial_critic_moves_every_pose_by_the_same_acceleration(reacher):
    """Two arms at different elbow angles, the same offset from their goals, the same velocity and
    torques that accelerate them alike: the inertial critic scores them alike and its gradient
    changes their accelerations alike. A relative critic's gradient does not."""
    _, _, norm = reacher
    torch.manual_seed(0)
    inertial = Critic(2, norm, inputs="inertial")
    relative = Critic(2, norm, inputs="relative")
    relative.load_state_dict(inertial.state_dict())
    relative.inertia = norm.inertia  # only to measure its acceleration change below
    q = torch.tensor([[0.3, 0.2], [-1.0, 2.6]])  # elbows 0.2 and 2.6 rad
    goal = q + torch.tensor([0.8, -0.5])
    qd = torch.tensor([[1.0, -2.0], [1.0, -2.0]])
    M, M_h = norm.inertia(q), norm.inertia.home()
    x = torch.tensor([4.0, -1.5])  # the torque with this acceleration at home
    tau = M @ torch.linalg.solve(M_h, x)  # (2, dof)
    values = inertial(q, qd, tau, goal).detach()
    assert values[0] == pytest.approx(float(values[1]), rel=1e-5)
    acc = _step_acceleration(inertial, q, qd, tau, goal)
    assert torch.allclose(acc[0], acc[1], rtol=1e-4, atol=1e-7)
    plain = _step_acceleration(relative, q, qd, tau, goal)
    assert not torch.allclose(plain[0], plain[1], rtol=0.1)
    # at the home pose the metric is the identity: the paper's plain gradient step
    home = torch.zeros(1, 2)
    assert torch.allclose(inertial.torque_metric(home)[0], torch.eye(2), atol=1e-5)


@pytest.mark.slow
def test_inertial_critic_gradient_is_a_metric_step_on_the_same_loss(reacher):
    """``J^T P dL/dtau`` per world, against the same product assembled by hand."""
    _, sim, norm = reacher
    critic = Critic(2, norm, inputs="inertial")
    policy = MLPPolicy(norm)
    params = {k: v.requires_grad_() for k, v in policy.init(2).items()}
    q = torch.rand(5, 2, 2) * 2 - 1
    traj = Trajectory(q, torch.rand(5, 2, 2), torch.zeros(4, 2, 2))
    goal = torch.tensor([[0.5, 0.3], [-0.4, 0.2]])
    grads = critic_gradient(critic, policy, params, traj, goal, create_graph=False)
    tau = policy(params, q[:-1], traj.qd[:-1])
    (dtau,) = torch.autograd.grad(
        critic(q[:-1], traj.qd[:-1], tau, goal.expand(4, 2, 2)).sum(), tau
    )
    P = critic.torque_metric(q[:-1])
    assert torch.linalg.eigvalsh(P).min() > 0  # a descent direction of the same loss
    step = (P @ dtau.unsqueeze(-1)).squeeze(-1)
    tau = policy(params, q[:-1], traj.qd[:-1])
    expected = torch.autograd.grad(tau, list(params.values()), grad_outputs=step)
    for g, e in zip(grads, expected):
        assert torch.allclose(g, e, rtol=1e-5, atol=1e-8)
    plain = critic_gradient(
        Critic(2, norm, inputs="relative"), policy, params, traj, goal, create_graph=False
    )
    assert not all(torch.allclose(g, p) for g, p in zip(grads, plain))


@pytest.mark.slow
def test_inertial_meta_gradient_matches_finite_differences(reacher):
    """Two inner steps: the second step's metric and features depend on the first step's states,
    which are data; the outer gradient through both must still be the exact derivative."""
    _, sim, norm = reacher
    torch.manual_seed(1)
    critic = Critic(2, norm, inputs="inertial")
    params = {
        k: v.requires_grad_()
        for k, v in init_policy(2, 4, 2, generator=torch.Generator().manual_seed(0)).items()
    }
    goal = torch.tensor([[0.5, 0.3], [-0.9, 1.7]])
    start = torch.tensor([[0.0, 0.0], [0.4, 2.0]])

    def loss():
        return meta_loss(
            critic,
            MLPPolicy(norm),
            params,
            sim,
            start,
            sim.zeros(),
            goal,
            horizon=8,
            alpha=1e-3,
            inner_steps=2,
        ).loss

    w = critic.net[-1].weight
    (g_w,) = torch.autograd.grad(loss(), [w])
    direction = torch.randn_like(w)
    eps = 1e-2

    def loss_at(shift):
        with torch.no_grad():
            w.add_(shift * direction)
        value = loss().item()
        with torch.no_grad():
            w.sub_(shift * direction)
        return value

    fd = (loss_at(eps) - loss_at(-eps)) / (2 * eps)
    assert float((g_w * direction).sum()) == pytest.approx(fd, rel=0.05, abs=1e-6)


@pytest.mark.slow
def test_inertial_critic_run_meta_tests_from_its_checkpoint(tmp_path):
    from helpers import tiny_cfg

    out = tmp_path / "inertial"
    train.meta_train(tiny_cfg(out, iterations=2, critic_input="inertial"), progress=False)
    assert load_checkpoint(out)["critic_input"] == "inertial"
    res = meta_test(
        MetaTestConfig(run_dir=str(out), num_goals=2, inits=1, device="cpu"), progress=None
    )
    assert res["mean"] >= 0
