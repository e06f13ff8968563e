"""SAC, the baseline with a stochastic policy: its squashed-Gaussian log-density against a numerical
one, the temperature moving toward the target entropy, a short run that learns the reacher, runs that
resume exactly and meta-test through the CLI with ``-min(Q1, Q2)``, and bad flags refused in one
line. Also the protocol it plugs into: the renamed ``metatest_alpha`` still read from old runs."""

from __future__ import annotations

import json
import math

import pytest
import torch
from conftest import REACHER
from helpers import filled_buffer, reacher_normalizer, refused_in_one_line, straight_and_resumed

from warp_critic.cli.main import main
from warp_critic.evaluation.metatest import build_test_critic
from warp_critic.learning.networks import Normalizer
from warp_critic.methods import q_networks
from warp_critic.methods.baseline_config import BaselineConfig
from warp_critic.methods.sac import (
    LOG_STD_RANGE,
    SACAgent,
    SACConfig,
    TwinQ,
    squashed_log_prob,
    train_sac,
)
from warp_critic.running.methods import method
from warp_critic.running.task import TaskConfig

MAX_TORQUE = torch.tensor([2.0, 0.5])


def norm() -> Normalizer:
    return Normalizer.from_limits(
        torch.tensor([-2.0, -2.0]), torch.tensor([2.0, 2.0]), MAX_TORQUE, 5.0
    )


def agent(**kw) -> SACAgent:
    torch.manual_seed(0)
    cfg = SACConfig(scene=REACHER, critic_hidden=16, actor_hidden=8, batch_size=32, **kw)
    return SACAgent(cfg, 2, norm(), "cpu")


def test_the_defaults_are_the_published_settings():
    cfg = SACConfig(scene=REACHER)
    assert (cfg.actor_lr, cfg.critic_lr, cfg.temperature_lr) == (3e-4, 3e-4, 3e-4)
    assert (cfg.batch_size, cfg.tau, cfg.gamma, cfg.init_temperature) == (256, 5e-3, 0.99, 1.0)
    assert cfg.target_entropy is None and agent().target_entropy == -2.0  # -dim(A)
    entry = method("sac")
    assert entry.config is SACConfig and entry.train is train_sac and entry.baseline
    assert not entry.reproduced_by_default and entry.preset == {"method": "sac", "iterations": 300}


def test_the_squashed_gaussian_log_prob_is_the_numerical_density():
    """``exp(log pi)`` of ``a = tanh(u)`` equals the derivative of its CDF
    ``P(a <= x) = Phi((atanh(x) - mu) / sigma)``, taken by central differences in float64."""
    mu = torch.tensor([0.3, -1.2, 1.0, 0.0], dtype=torch.float64)
    log_std = torch.tensor([-0.5, 0.4, 0.0, 1.5], dtype=torch.float64)
    normal = torch.distributions.Normal(mu, log_std.exp())
    for a in (-0.9, -0.5, 0.0, 0.3, 0.9, 0.99):
        x = torch.full_like(mu, a)
        h = 1e-6 * (1 - a * a)
        cdf = [normal.cdf(torch.atanh(x + d)) for d in (h, -h)]
        density = (cdf[0] - cdf[1]) / (2 * h)  # per joint
        got = squashed_log_prob(torch.atanh(x).unsqueeze(-1), mu[:, None], log_std[:, None])
        assert torch.allclose(got, density.log(), rtol=1e-5, atol=1e-6), (a, got, density.log())
    # joints are independent: the log-density of a vector sums its joints'
    u = torch.tensor([[0.1, -3.0, 0.7, 1.1]], dtype=torch.float64)
    whole = squashed_log_prob(u, mu, log_std)
    parts = sum(
        squashed_log_prob(u[:, j : j + 1], mu[j : j + 1], log_std[j : j + 1]) for j in range(4)
    )
    assert torch.allclose(whole, parts)
    # finite where tanh(u) rounds to +-1 in float32 (the naive log(1 - tanh^2) is -inf there)
    far = squashed_log_prob(torch.tensor([[30.0]]), torch.tensor([0.0]), torch.tensor([0.0]))
    assert torch.isfinite(far).all()


def test_samples_are_squashed_torques_with_their_log_prob():
    a = agent()
    q, qd, g = torch.randn(64, 2), torch.randn(64, 2), torch.zeros(64, 2)
    gen = torch.Generator().manual_seed(5)
    tau, logp = a.actor.sample(q, qd, g, gen)
    assert tau.shape == (64, 2) and logp.shape == (64,)
    assert torch.all(tau.abs() < MAX_TORQUE)
    mu, log_std = a.actor.gaussian(q, qd, g)
    assert torch.all(log_std >= LOG_STD_RANGE[0]) and torch.all(log_std <= LOG_STD_RANGE[1])
    u = torch.atanh((tau / MAX_TORQUE).double()).float()
    assert torch.allclose(logp, squashed_log_prob(u, mu, log_std), atol=1e-3)
    # the evaluation policy is the mean action; exploring draws from the generator only
    assert torch.equal(a.actor(q, qd, g), MAX_TORQUE * torch.tanh(mu))
    one = a.explore(q, qd, g, torch.Generator().manual_seed(9))
    assert torch.equal(one, a.explore(q, qd, g, torch.Generator().manual_seed(9)))
    assert not torch.equal(one, a.explore(q, qd, g, torch.Generator().manual_seed(10)))


@pytest.mark.parametrize("target, direction", [(5.0, 1), (-20.0, -1)])
def test_the_temperature_moves_toward_the_target_entropy(target, direction):
    """Above the policy's entropy the temperature grows (more entropy is rewarded), below it
    shrinks; the critics and targets learn on every update, the actor only after the warm-up."""
    a = agent(target_entropy=target, temperature_lr=1e-2)
    buf, gen = filled_buffer(), torch.Generator().manual_seed(4)
    stats = a.update(buf, gen)
    assert direction * (stats["temperature"] - 1.0) > 0
    assert (stats["entropy"] - target) * direction < 0  # the policy is on the other side
    temps = [a.update(buf, gen)["temperature"] for _ in range(5)]
    assert all(direction * (t1 - t0) > 0 for t0, t1 in zip([stats["temperature"], *temps], temps))
    actor, temp, q1 = (
        [p.clone() for p in a.actor.parameters()],
        a.temperature,
        a.q.q1.net[0].weight.clone(),
    )
    stats = a.update(buf, gen, train_actor=False)  # warming up: only the Qs (and their targets)
    assert "actor_loss" not in stats and a.temperature == temp
    assert all(torch.equal(p, x) for p, x in zip(a.actor.parameters(), actor))
    assert not torch.equal(a.q.q1.net[0].weight, q1)


def test_the_critic_target_is_the_soft_minimum_of_the_twin_targets():
    a = agent(init_temperature=2.0)
    with torch.no_grad():  # constant critics: Q1 = Q2 = 0, Q1' = 5, Q2' = -3
        for net, bias in (
            (a.q.q1, 0.0),
            (a.q.q2, 0.0),
            (a.q_target.q1, 5.0),
            (a.q_target.q2, -3.0),
        ):
            net.net[-1].weight.zero_()
            net.net[-1].bias.fill_(bias)
    buf = filled_buffer()
    b = buf.sample(32, torch.Generator().manual_seed(0))
    stats = a.critic_step(b, torch.Generator().manual_seed(1))
    _, logp2 = a.actor.sample(b["q2"], b["qd2"], b["goal"], torch.Generator().manual_seed(1))
    y = b["reward"] + a.cfg.gamma * (1 - b["done"]) * (-3.0 - 2.0 * logp2.detach())
    assert stats["critic_loss"] == pytest.approx(2 * (y.square().mean()).item(), rel=1e-5)


@pytest.mark.slow
def test_sac_learns_the_reacher(tmp_path):
    # the reacher's four default goals, 4 worlds each, a shortened horizon, SAC's settings but a
    # smaller minibatch (for time); after the 5 warm-up iterations the actor starts
    cfg = SACConfig(
        scene=REACHER,
        iterations=20,
        horizon=30,
        worlds_per_goal=4,
        batch_size=64,
        device="cpu",
        out=str(tmp_path / "run"),
        checkpoint_every=20,
        record_every=100,
        seed=0,
    )
    rows = train_sac(cfg, progress=False, record=False).metrics
    losses = [r["task_loss"] for r in rows]
    assert len(losses) == 20 and all(math.isfinite(x) for x in losses)
    first, last = sum(losses[:3]) / 3, sum(losses[-3:]) / 3
    # the untrained actor (~0 torque) leaves ||q_T - g||^2 = ||g||^2 ~ 1.25
    assert last < 0.75 * first, (first, last, losses)
    assert all("temperature" in r and "entropy" in r for r in rows[5:])
    assert not any("temperature" in r for r in rows[:5])  # the warm-up trains only the Qs


@pytest.mark.slow
def test_sac_resumes_exactly_and_meta_tests_min_q_through_the_cli(tmp_path, capsys):
    straight, rows = straight_and_resumed(tmp_path, "sac")
    part = tmp_path / "part"
    assert [r["iteration"] for r in rows[1]] == [0, 1, 2]
    drop = ("seconds",)
    assert [{k: v for k, v in r.items() if k not in drop} for r in rows[0]] == [
        {k: v for k, v in r.items() if k not in drop} for r in rows[1]
    ]
    assert "temperature" in rows[0][-1] and "temperature" not in rows[0][0]  # after the warm-up
    ckpts = [torch.load(d / "checkpoint.pt", weights_only=False) for d in (straight, part)]
    for key in ("actor", "q", "q_target"):
        for k, v in ckpts[0]["agent_state"][key].items():
            assert torch.equal(v, ckpts[1]["agent_state"][key][k]), (key, k)
    assert torch.equal(*(c["agent_state"]["log_temperature"] for c in ckpts))
    ckpt = ckpts[0]
    assert ckpt["method"] == "sac" and ckpt["config"]["target_entropy"] is None

    # meta-test descends -min(Q1, Q2) of the checkpoint
    tc = TaskConfig.from_dict(ckpt["config"])
    n = reacher_normalizer(tc.max_torque)
    loss_fn, defaults = build_test_critic(ckpt, n)
    assert defaults["alpha"] == ckpt["selected_alpha"] > 0
    twin = TwinQ(2, n, int(ckpt["critic_hidden"]))
    twin.load_state_dict(ckpt["agent_state"]["q"])
    q, qd, tau = torch.randn(7, 2), torch.randn(7, 2), torch.randn(7, 2)
    g = torch.tensor([[0.5, 0.3]]).expand(7, 2)
    with torch.no_grad():
        want = -torch.minimum(twin.q1(q, qd, tau, g), twin.q2(q, qd, tau, g))
        assert torch.equal(loss_fn(q, qd, tau, g), want)
    # both critics of the checkpoint, not Q1 alone (as TD3's)
    assert isinstance(loss_fn.q, TwinQ)
    for k, v in ckpt["agent_state"]["q"].items():
        assert torch.equal(loss_fn.q.state_dict()[k], v), k
    assert any(k.startswith("q2.") for k in loss_fn.q.state_dict())
    capsys.readouterr()
    out = tmp_path / "mt.json"
    cmd = ["meta-test", str(straight), "--num-goals", "2", "--inits", "2", "--out", str(out)]
    assert main([*cmd, "--device", "cpu"]) == 0
    result = json.loads(out.read_text())
    assert result["method"] == "sac" and math.isfinite(result["mse_mean"])


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["baseline", "sac", REACHER, "--noise", "ou"], "--noise"),
        (["baseline", "sac", REACHER, "--init-temperature", "0"], "--init-temperature must be > 0"),
        (["baseline", "sac", REACHER, "--target-entropy", "nan"], "--target-entropy"),
        (["baseline", "sac", REACHER, "--temperature-lr=-1"], "--temperature-lr"),
        (["baseline", "sac", REACHER, "--noise-std", "0.3"], "--noise-std: SAC adds no"),
        (["baseline", "sac", REACHER, "--ou-theta", "0.5"], "--ou-theta: SAC adds no"),
        (["baseline", "ddpg", REACHER, "--init-temperature", "0.5"], "--init-temperature"),
    ],
)
def test_bad_sac_input_is_one_line_and_exit_2(tmp_path, capsys, argv, fragment):
    refused_in_one_line(tmp_path, capsys, argv, fragment)  # TD3's check: exit 2, no run folder


def test_a_run_saved_with_the_old_alpha_key_keeps_its_metatest_step():
    """``BaselineConfig.metatest_alpha`` was ``alpha``: an old run's config and checkpoint still
    give meta-test the step size it was trained with."""
    old = {"scene": REACHER, "method": "ddpg", "alpha": 0.02, "iterations": 7}
    cfg = BaselineConfig.from_dict(old)
    assert cfg.metatest_alpha == 0.02 and cfg.iterations == 7
    assert SACConfig.from_dict({**old, "method": "sac"}).metatest_alpha == 0.02
    assert BaselineConfig.from_dict({**old, "metatest_alpha": 0.5}).metatest_alpha == 0.5
    torch.manual_seed(0)
    agent_q = TwinQ(2, norm(), 8)
    ckpt = {
        "method": "sac",
        "dof": 2,
        "critic_hidden": 8,
        "q_state": agent_q.state_dict(),
        "config": {"alpha": 0.02, "inner_steps": 4},
        "selected_alpha": 1e-3,
    }
    _, defaults = q_networks.test_critic_from_checkpoint(ckpt, norm(), make_q=TwinQ)
    assert defaults == {"alpha": 0.02, "steps": 4}
    ckpt["config"] = {"metatest_alpha": None, "inner_steps": 4}  # not given: the search's choice
    assert q_networks.test_critic_from_checkpoint(ckpt, norm(), make_q=TwinQ)[1]["alpha"] == 1e-3
