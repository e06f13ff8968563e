"""Critic input layouts and task-loss terms (pure functions, no simulator)."""

from __future__ import annotations

import math

import pytest
import torch

from warp_critic.learning.critic import Critic
from warp_critic.learning.losses import task_loss
from warp_critic.learning.networks import Normalizer
from warp_critic.learning.rollout import Trajectory


def _norm(dof=3):
    return Normalizer.from_limits(
        -2 * torch.ones(dof), 2 * torch.ones(dof), 5 * torch.ones(dof), 4.0
    )


def _batch(dof=3, n=16, seed=0):
    g = torch.Generator().manual_seed(seed)
    return [torch.randn(n, dof, generator=g) for _ in range(4)]  # q, qd, tau, goal


def test_relative_critic_is_equivariant_to_moving_goal_and_state_together():
    torch.manual_seed(0)
    q, qd, tau, goal = _batch()
    shift = torch.tensor([0.3, -0.7, 0.2])
    rel, full = (
        Critic(3, _norm(), hidden=32, inputs="relative"),
        Critic(3, _norm(), hidden=32, inputs="full"),
    )
    assert torch.allclose(rel(q + shift, qd, tau, goal + shift), rel(q, qd, tau, goal), atol=1e-6)
    # the full layout sees q and g themselves, so the same shift changes its value
    assert not torch.allclose(
        full(q + shift, qd, tau, goal + shift), full(q, qd, tau, goal), atol=1e-3
    )
    # ... and the relative one still depends on the goal
    assert not torch.allclose(rel(q, qd, tau, goal + shift), rel(q, qd, tau, goal), atol=1e-3)


def test_pose_critic_sees_the_goal_only_relative_to_the_state_and_the_state_itself():
    """``pose``: ``[q - g, qd, a, q]``: its features are the relative layout's plus the normalised
    ``q``, so shifting state and goal together changes it (it sees where the arm is), and the goal
    enters through ``q - g`` only."""
    torch.manual_seed(0)
    q, qd, tau, goal = _batch()
    norm = _norm()
    rel, pose = (
        Critic(3, norm, hidden=32, inputs="relative"),
        Critic(3, norm, hidden=32, inputs="pose"),
    )
    f = pose.features(q, qd, tau, goal)
    assert f.shape == (16, 12)
    assert torch.equal(f[:, :9], rel.features(q, qd, tau, goal))
    assert torch.allclose(f[:, 9:], norm.q(q))
    shift = torch.tensor([0.3, -0.7, 0.2])
    assert torch.equal(pose.features(q, qd, tau, goal + shift)[:, 9:], f[:, 9:])
    assert not torch.allclose(
        pose(q + shift, qd, tau, goal + shift), pose(q, qd, tau, goal), atol=1e-3
    )


def test_pose_trig_critic_sees_the_pose_through_its_sine_and_cosine():
    """``pose-trig``: ``[q - g, qd, a, sin q, cos q]``: the relative layout's features plus the
    joint angles' sine and cosine, so a full turn of the state alone changes nothing, while the
    ``pose`` critic, which sees ``q`` itself, tells the two apart."""
    torch.manual_seed(0)
    q, qd, tau, goal = _batch()
    norm = _norm()
    rel, trig, pose = (
        Critic(3, norm, hidden=32, inputs=i) for i in ("relative", "pose-trig", "pose")
    )
    f = trig.features(q, qd, tau, goal)
    assert f.shape == (16, 15)
    assert torch.equal(f[:, :9], rel.features(q, qd, tau, goal))
    assert torch.equal(f[:, 9:12], torch.sin(q)) and torch.equal(f[:, 12:], torch.cos(q))
    turn = torch.tensor([2 * math.pi, 0.0, 0.0])
    # q and g turned together: q - g unchanged, sin/cos of q unchanged (to rounding)
    assert torch.allclose(trig(q + turn, qd, tau, goal + turn), trig(q, qd, tau, goal), atol=1e-5)
    assert not torch.allclose(
        pose(q + turn, qd, tau, goal + turn), pose(q, qd, tau, goal), atol=1e-3
    )
    shift = torch.tensor([0.3, -0.7, 0.2])
    assert not torch.allclose(
        trig(q + shift, qd, tau, goal + shift), trig(q, qd, tau, goal), atol=1e-3
    )


def test_critic_rejects_unknown_input_layout():
    with pytest.raises(ValueError, match="relative"):
        Critic(3, _norm(), inputs="absolute")


def test_task_loss_terms():
    T, W, dof = 5, 4, 3
    g = torch.Generator().manual_seed(1)
    traj = Trajectory(
        torch.randn(T + 1, W, dof, generator=g),
        torch.randn(T + 1, W, dof, generator=g),
        torch.randn(T, W, dof, generator=g),
    )
    goal = torch.randn(W, dof, generator=g)
    final = ((traj.q[-1] - goal) ** 2).sum(-1)
    assert torch.allclose(task_loss(traj, goal), final)
    running = ((traj.q[1:] - goal) ** 2).sum(-1).mean(0)
    assert torch.allclose(task_loss(traj, goal, running_weight=0.5), final + 0.5 * running)
    velocity = (traj.qd[-1] ** 2).sum(-1)
    assert torch.allclose(task_loss(traj, goal, velocity_weight=0.1), final + 0.1 * velocity)


def test_goal_noise_readings_of_the_papers_protocol():
    from warp_critic.core.errors import UserError
    from warp_critic.evaluation.metatest import sample_goals

    centres = torch.zeros(2, 7)
    lo, hi = -3 * torch.ones(7), 3 * torch.ones(7)
    gen = torch.Generator().manual_seed(0)
    per_joint = sample_goals(centres, 4000, 0.1, [0, 1], lo, hi, gen)
    distance = sample_goals(centres, 4000, 0.1, [0, 1], lo, hi, gen, noise="distance")
    # per joint: E||offset||^2 = 7 std^2; along a random direction: E||offset||^2 = std^2
    assert (per_joint**2).sum(1).mean().item() == pytest.approx(0.07, rel=0.05)
    assert (distance**2).sum(1).mean().item() == pytest.approx(0.01, rel=0.08)
    # ... and the direction is isotropic: every joint gets the same share
    assert torch.allclose((distance**2).mean(0), torch.full((7,), 0.01 / 7), rtol=0.2)
    with pytest.raises(UserError, match="goal_noise"):
        sample_goals(centres, 1, 0.1, None, lo, hi, gen, noise="sphere")
