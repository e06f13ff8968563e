"""The ``pose-dynamics`` critic: each world's model told to the critic (privileged data).

The descriptor is zero at the nominal model and moves exactly the numbers of what a variant changes;
a live simulator whose variants were redrawn describes its worlds as one built with those variants;
the critic reads the descriptor (its output changes with it), batched seeds evaluate as single
critics, and the critic loss passes the trajectory's descriptor (a run trains, resumes and meta-tests
on a new model through the command line: tests/test_train_variants.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from conftest import REACHER

from warp_critic.physics.descriptor import PER_BODY, PER_JOINT, DynamicsDescriptor
from warp_critic.physics.redraw import set_variants
from warp_critic.physics.scene import load_scene
from warp_critic.physics.variants import Variant


@pytest.fixture(scope="module")
def scene():
    return load_scene(REACHER)


def _sim(scene, variants):
    from warp_critic.physics.simulator import Simulator

    return Simulator(scene, variants, dt=0.01, device="cpu", differentiable=False)


def test_descriptor_moves_what_a_variant_changes(scene):
    """Nominal: all zeros. ``arm2.mass=6:keep``: only the second body's mass number, by the stated
    log ratio. ``arm1.stretch=2``: the first body's COM and inertia and the second joint's offset
    (the elbow moves to 2 m), nothing of the second body."""
    describe = DynamicsDescriptor(scene)
    B, J = len(describe.m0), len(describe.p0)
    assert describe.size == PER_BODY * B + PER_JOINT * J == 20
    nominal = describe.of(scene.world_builder(Variant()), 1)[0]
    assert np.array_equal(nominal, np.zeros(describe.size, np.float32))

    heavy = describe.of(scene.world_builder(Variant(changes="arm2.mass=6:keep")), 1)[0]
    m0 = float(describe.m0[1])
    expect = math.log((6.0 + describe.e_m) / (m0 + describe.e_m))
    assert heavy[PER_BODY] == pytest.approx(expect, rel=1e-6) and expect > 1.5
    assert np.count_nonzero(heavy) == 1

    long = describe.of(scene.world_builder(Variant(changes="arm1.stretch=2")), 1)[0]
    body1, body2 = long[:PER_BODY], long[PER_BODY : 2 * PER_BODY]
    elbow = long[PER_BODY * B + PER_JOINT : PER_BODY * B + 2 * PER_JOINT]
    assert body1[0] == 0.0  # the mass is kept
    assert np.abs(body1[1:]).max() > 0.1 and not body2.any()
    assert np.linalg.norm(elbow) * describe.length == pytest.approx(1.0, rel=1e-5)  # 1 m -> 2 m


def test_redrawn_simulator_describes_its_worlds_as_a_built_one(scene):
    variants = [
        Variant(),
        Variant(changes="arm2.mass=6:keep"),
        Variant(changes="arm1.stretch=2"),
        Variant(changes="arm1.mass=0.25:keep; arm2.stretch=0.5"),
    ]
    live = _sim(scene, [Variant()] * len(variants))
    before = live.dynamics().clone()
    assert live.dynamics_size == 20 and not before.any()
    set_variants(live, variants)
    after = live.dynamics()
    assert torch.equal(after, _sim(scene, variants).dynamics())
    assert after[1:].abs().amax(-1).gt(0.1).all()  # the cache followed the new variants
    set_variants(live, variants[::-1])
    assert torch.equal(live.dynamics(), after.flip(0))


def test_pose_dynamics_critic_reads_the_descriptor():
    from warp_critic.learning.losses import critic_loss
    from warp_critic.learning.networks import Critic, MLPPolicy, Normalizer, StackedCritic
    from warp_critic.learning.rollout import Trajectory

    T, W, dof, K = 4, 3, 2, 5
    gen = torch.Generator().manual_seed(0)
    norm = Normalizer(torch.zeros(dof), torch.full((dof,), 2.0), 5.0, torch.full((dof,), 3.0))
    with pytest.raises(ValueError, match="descriptor size"):
        Critic(dof, norm, inputs="pose-dynamics")
    norm = Normalizer(
        torch.zeros(dof), torch.full((dof,), 2.0), 5.0, torch.full((dof,), 3.0), dynamics_size=K
    )
    torch.manual_seed(1)
    critics = [Critic(dof, norm, hidden=16, inputs="pose-dynamics") for _ in range(2)]
    assert critics[0].uses_dynamics and critics[0].net[0].in_features == 4 * dof + K
    assert not Critic(dof, norm, hidden=16, inputs="pose").uses_dynamics
    relative = Critic(dof, norm, hidden=16, inputs="relative-dynamics")
    assert relative.uses_dynamics and relative.net[0].in_features == 3 * dof + K
    q, qd, tau = (torch.randn(T, W, dof, generator=gen) for _ in range(3))
    g = torch.zeros(T, W, dof)
    d = torch.randn(W, K, generator=gen)
    a = critics[0](q, qd, tau, g, dynamics=d)
    assert a.shape == (T, W)
    assert not torch.allclose(a, critics[0](q, qd, tau, g, dynamics=torch.zeros_like(d)))
    with pytest.raises(ValueError, match="dynamics"):
        critics[0](q, qd, tau, g)
    stacked = StackedCritic(critics)
    assert stacked.uses_dynamics
    both = [torch.cat([x, x], dim=1) for x in (q, qd, tau, g)]
    out = stacked(*both, dynamics=torch.cat([d, d]))
    assert torch.allclose(out[:, :W], a, atol=1e-6)
    assert torch.allclose(out[:, W:], critics[1](q, qd, tau, g, dynamics=d), atol=1e-6)
    assert torch.equal(stacked.critic(1).state_dict()["net.0.weight"], critics[1].net[0].weight)

    policy = MLPPolicy(norm)
    params = policy.init(W, generator=gen)
    qs = torch.randn(2, T + 1, W, dof, generator=gen)
    traj = Trajectory(qs[0], qs[1], tau, d)
    at = traj.q[:-1], traj.qd[:-1]
    expect = critics[0](*at, policy(params, *at), g, dynamics=d)
    assert torch.allclose(critic_loss(critics[0], policy, params, traj, g[0]), expect.sum(0))
    with pytest.raises(ValueError, match="carries none"):
        critic_loss(critics[0], policy, params, Trajectory(traj.q, traj.qd, tau), g[0])


def test_rollout_carries_the_worlds_dynamics(scene):
    from warp_critic.learning.rollout import rollout

    sim = _sim(scene, [Variant(), Variant(changes="arm2.mass=4:keep")])
    q0 = torch.zeros(2, 2)
    traj = rollout(sim, lambda q, qd: torch.zeros_like(q), q0, q0, 3)
    assert traj.dynamics is not None and torch.equal(traj.dynamics, sim.dynamics())
    assert not traj.dynamics[0].any() and traj.dynamics[1].any()
