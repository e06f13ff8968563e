"""Meta-training over worlds that diverge: ``--on-divergence drop`` leaves them out, exactly."""

from __future__ import annotations

import json
import math

import pytest
import torch
from conftest import REACHER

from warp_critic.cli.main import main
from warp_critic.core.errors import DivergenceError
from warp_critic.learning.critic import Critic
from warp_critic.learning.networks import MLPPolicy, Normalizer, init_policy
from warp_critic.learning.outer import meta_loss
from warp_critic.learning.rollout import DIVERGED, settled_worlds
from warp_critic.physics.load import load_scene
from warp_critic.physics.scene import Variant
from warp_critic.physics.simulator import Simulator

GOAL = [0.5, 0.3]


def _setup(worlds: int):
    sim = Simulator(load_scene(REACHER), [Variant()] * worlds, dt=0.01, substeps=2, device="cpu")
    norm = Normalizer.from_limits(sim.q_lower, sim.q_upper, torch.tensor([20.0, 20.0]), 5.0)
    torch.manual_seed(0)
    critic = Critic(2, norm, hidden=32)
    params = init_policy(worlds, 4, 2, generator=torch.Generator().manual_seed(0))
    return sim, norm, critic, params


def _meta(critic, norm, sim, params, q0, qd0, drop: bool):
    goal = torch.tensor([GOAL] * q0.shape[0])
    p = {k: v.detach().clone().requires_grad_() for k, v in params.items()}
    res = meta_loss(
        critic, MLPPolicy(norm), p, sim, q0, qd0, goal, horizon=6, alpha=1e-3,
        inner_steps=2, drop_diverged=drop,
    )  # fmt: skip
    grads = torch.autograd.grad(res.loss, list(critic.parameters())[:-1])
    return res, grads


def test_dropped_worlds_get_no_gradient_and_the_others_are_unchanged():
    """Worlds 1 (a non-finite start) and 2 (a start far beyond the bound) diverge. Dropped, the loss
    and the critic's meta-gradient are those of the two settled worlds alone."""
    sim4, norm, critic, params = _setup(4)
    q0 = torch.tensor([[0.1, -0.2], [math.nan, 0.0], [0.0, 0.0], [-0.3, 0.4]])
    qd0 = torch.zeros(4, 2)
    qd0[2, 1] = 10 * DIVERGED
    with pytest.raises(DivergenceError):
        _meta(critic, norm, sim4, params, q0, qd0, drop=False)
    res, grads = _meta(critic, norm, sim4, params, q0, qd0, drop=True)
    assert res.settled.tolist() == [True, False, False, True]
    assert torch.isfinite(res.loss) and all(torch.isfinite(g).all() for g in grads)
    assert res.losses[1].item() == 0.0 and res.losses[2].item() == 0.0

    keep = [0, 3]
    sim2, _, _, _ = _setup(2)
    sub = {k: v[keep] for k, v in params.items()}
    ref, ref_grads = _meta(critic, norm, sim2, sub, q0[keep], qd0[keep], drop=False)
    assert torch.allclose(res.loss, ref.loss, rtol=1e-6, atol=0)
    assert torch.equal(res.per_world[keep], ref.per_world)  # the worlds are independent
    for g, r in zip(grads, ref_grads):
        assert torch.allclose(g, r, rtol=1e-4, atol=1e-7)
    assert sum(float(g.abs().sum()) for g in grads) > 0


def test_guard_leaves_settled_rollouts_bitwise():
    """With nothing diverging, dropping changes no value and no gradient (the paper's runs)."""
    sim, norm, critic, params = _setup(2)
    q0, qd0 = torch.tensor([[0.1, -0.2], [-0.3, 0.4]]), torch.zeros(2, 2)
    a, ga = _meta(critic, norm, sim, params, q0, qd0, drop=False)
    b, gb = _meta(critic, norm, sim, params, q0, qd0, drop=True)
    assert torch.equal(a.loss, b.loss) and b.settled.all()
    assert all(torch.equal(x, y) for x, y in zip(ga, gb))
    assert settled_worlds(b.after).all()


@pytest.mark.slow
def test_cli_drop_counts_diverged_worlds(tmp_path, capsys):
    """Training over second links as light as 10 g, where saturated torques drive the integrator
    out of range: ``stop`` is refused up front (exit 2, naming the value the probe of
    physics/stability finds stable), nothing written; ``drop`` trains on the others and counts the
    diverged worlds in the metrics."""
    args = [
        "meta-train", REACHER, "--goals", "0.5,0.3;-0.4,0.2", "--worlds-per-goal", "4",
        "--horizon", "20", "--iterations", "2", "--device", "cpu", "--critic-hidden", "16",
        "--alpha", "1e3", "--seed", "1", "--train-variants", "arm2.mass=0.01..1:keep",
    ]  # fmt: skip
    capsys.readouterr()
    assert main([*args, "--out", str(tmp_path / "stop")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warp-critic: error: --train-variants:"), err
    assert "arm2.mass=0.01:keep" in err[0] and "it holds from about arm2.mass=" in err[0], err
    assert not (tmp_path / "stop").exists()
    out = tmp_path / "drop"
    code = main([*args, "--on-divergence", "drop", "--out", str(out)])
    rows = [json.loads(x) for x in (out / "metrics.jsonl").read_text().splitlines()]
    assert code == 0 and [r["iteration"] for r in rows] == [0, 1]
    assert rows[0]["diverged_worlds"] > 0, rows
    assert all(r["diverged_worlds"] < 8 and math.isfinite(r["task_loss"]) for r in rows), rows
