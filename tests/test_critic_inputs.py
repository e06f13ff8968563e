"""The critic's input layouts (``learning/critic_inputs.py``): one registry that the critic, the
losses, the scene format and the flag all read."""

from __future__ import annotations

import pytest
import torch

from warp_critic.core.critic_input_names import CRITIC_INPUT_NAMES
from warp_critic.learning.critic import Critic
from warp_critic.learning.critic_inputs import (
    CRITIC_INPUTS,
    DYNAMICS,
    HISTORY,
    TOLD_INPUTS,
    critic_input,
    critic_input_help,
    rollout_kwargs,
)
from warp_critic.learning.networks import Normalizer
from warp_critic.learning.rollout import Trajectory
from warp_critic.physics import schema

T, W, DOF, K = 4, 3, 2, 5


class _Inertia:
    """A pose-dependent ``M(q)``, SPD: ``diag(1 + q^2) + 0.1``."""

    def __call__(self, q):
        return torch.diag_embed(1 + q**2) + 0.1

    def home(self):
        return self(torch.zeros(DOF))


def _norm() -> Normalizer:
    return Normalizer(
        torch.zeros(DOF),
        torch.full((DOF,), 2.0),
        5.0,
        torch.full((DOF,), 3.0),
        inertia=_Inertia(),
        dynamics_size=K,
    )


def _trajectory(gen) -> Trajectory:
    return Trajectory(
        torch.randn(T + 1, W, DOF, generator=gen),
        torch.randn(T + 1, W, DOF, generator=gen),
        torch.randn(T, W, DOF, generator=gen),
        torch.randn(W, K, generator=gen),
    )


def test_the_registry_is_the_names_the_scene_format_knows():
    assert tuple(CRITIC_INPUTS) == CRITIC_INPUT_NAMES
    assert TOLD_INPUTS == ("pose-dynamics", "relative-dynamics")
    assert all(name in schema.RULES["critic_input"] for name in CRITIC_INPUTS)
    attr = schema.attribute("critic_input")
    for name in CRITIC_INPUTS:  # the scene format accepts each, and nothing else
        assert schema.parse(attr, name, [-1.0] * DOF, [1.0] * DOF, ["a", "b"]) == name
    with pytest.raises(schema.RuleError, match="must be one of full, relative"):
        schema.parse(attr, "absolute", [-1.0] * DOF, [1.0] * DOF, ["a", "b"])
    with pytest.raises(ValueError, match="must be one of"):
        critic_input("absolute")
    text = critic_input_help()
    assert [text.index(f"{name} = ") for name in CRITIC_INPUTS] == sorted(
        text.index(f"{name} = ") for name in CRITIC_INPUTS
    )


@pytest.mark.parametrize("name", CRITIC_INPUT_NAMES)
def test_each_layout_s_width_features_and_rollout_data_agree(name):
    """The critic's first layer is the layout's width; the features are that wide for a
    trajectory's steps when the critic is given exactly the rollout data its layout names."""
    gen = torch.Generator().manual_seed(0)
    layout, traj = CRITIC_INPUTS[name], _trajectory(gen)
    torch.manual_seed(0)
    critic = Critic(DOF, _norm(), hidden=8, inputs=name)
    assert critic.net[0].in_features == layout.width(DOF, K)
    assert critic.rollout_data == layout.rollout_data
    assert (HISTORY in layout.rollout_data) == (name == "history")
    assert (DYNAMICS in layout.rollout_data) == (name in TOLD_INPUTS)
    data = rollout_kwargs(critic, traj)
    assert set(data) == {d.key for d in layout.rollout_data}
    q, qd, tau = traj.q[:T], traj.qd[:T], traj.tau
    g = torch.randn(W, DOF, generator=gen).expand(T, W, DOF)
    x = critic.features(q, qd, tau, g, **data)
    assert x.shape == (T, W, layout.width(DOF, K))
    assert torch.isfinite(x).all()
    assert critic(q, qd, tau, g, **data).shape == (T, W)
    metric = critic.torque_metric(q)
    assert (metric is not None) == (name == "inertial")
    for d in layout.rollout_data:  # each named piece is read: without it, a one-line error
        with pytest.raises(
            ValueError, match=f"needs {'history' if d is HISTORY else 'the worlds'}"
        ):
            critic(q, qd, tau, g, **{k: v for k, v in data.items() if k != d.key})


def test_a_plain_callable_reads_no_rollout_data():
    gen = torch.Generator().manual_seed(1)
    assert rollout_kwargs(lambda q, qd, tau, g: q.sum(-1), _trajectory(gen)) == {}
    with pytest.raises(ValueError, match="carries none"):
        rollout_kwargs(
            Critic(DOF, _norm(), hidden=8, inputs="pose-dynamics"),
            Trajectory(
                torch.zeros(T + 1, W, DOF), torch.zeros(T + 1, W, DOF), torch.zeros(T, W, DOF)
            ),
        )
