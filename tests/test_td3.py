"""TD3, the third baseline: its update (clipped double Q, target policy smoothing, delayed actor
and targets) by hand, and tiny runs that train, resume exactly and meta-test through the CLI."""

from __future__ import annotations

import json
import math

import pytest
import torch
from conftest import REACHER
from helpers import (
    filled_buffer,
    reacher_normalizer,
    refused_in_one_line,
    straight_and_resumed,
    tiny_baseline_cfg,
)

from warp_critic.cli.main import main
from warp_critic.evaluation.metatest import build_test_critic
from warp_critic.learning.losses import td_loss
from warp_critic.learning.networks import Normalizer
from warp_critic.methods.td3 import TD3Agent, TD3Config, train_td3
from warp_critic.running.methods import method
from warp_critic.running.task import TaskConfig

MAX_TORQUE = torch.tensor([2.0, 0.5])


def agent(**kw) -> TD3Agent:
    torch.manual_seed(0)
    norm = Normalizer.from_limits(
        torch.tensor([-2.0, -2.0]), torch.tensor([2.0, 2.0]), MAX_TORQUE, 5.0
    )
    cfg = TD3Config(scene=REACHER, critic_hidden=16, actor_hidden=8, batch_size=32, **kw)
    return TD3Agent(cfg, 2, norm, "cpu")


def batch(n: int = 32) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(1)
    b = {k: torch.randn(n, 2, generator=g) for k in ("q", "qd", "tau", "goal", "q2", "qd2")}
    b["reward"] = torch.randn(n, generator=g)
    b["done"] = torch.zeros(n)
    return b


def flat(module: torch.nn.Module) -> torch.Tensor:
    return torch.cat([p.detach().flatten() for p in module.parameters()])


def test_the_defaults_are_the_published_settings():
    cfg = TD3Config(scene=REACHER)
    assert (cfg.actor_lr, cfg.critic_lr, cfg.batch_size, cfg.tau) == (3e-4, 3e-4, 256, 5e-3)
    assert (cfg.noise, cfg.noise_std, cfg.policy_noise, cfg.noise_clip) == (
        "gaussian",
        0.1,
        0.2,
        0.5,
    )
    assert cfg.policy_delay == 2 and cfg.method == "td3" and cfg.gamma == 0.99
    entry = method("td3")
    assert entry.config is TD3Config and entry.train is train_td3 and entry.baseline
    assert not entry.reproduced_by_default


def test_target_smoothing_noise_is_clipped_in_units_of_the_action_scale():
    a = agent(policy_noise=100.0, noise_clip=0.5)  # every draw far beyond the clip
    b = batch()
    gen = torch.Generator().manual_seed(3)
    with torch.no_grad():
        mu = a.actor_target(b["q2"], b["qd2"], b["goal"])
        smoothed = a.target_action(b, gen)
    # the actor's target action is near 0 (small last layer), so the action bound never binds here
    assert mu.abs().max() < 0.2 * MAX_TORQUE.min()
    assert torch.allclose((smoothed - mu).abs(), 0.5 * MAX_TORQUE.expand_as(mu), atol=1e-6)
    a = agent(policy_noise=0.0)
    with torch.no_grad():
        assert torch.equal(a.target_action(b, gen), a.actor_target(b["q2"], b["qd2"], b["goal"]))
    a = agent(policy_noise=100.0, noise_clip=50.0)  # a wide clip: the action bound holds
    with torch.no_grad():
        wide = a.target_action(b, gen)
    assert torch.all(wide.abs() <= MAX_TORQUE) and torch.any(wide.abs() == MAX_TORQUE)


def test_the_target_is_the_minimum_of_the_two_target_critics():
    a = agent()
    with torch.no_grad():  # constant critics: Q1 = Q2 = 0, Q1' = 5, Q2' = -3
        for net, bias in ((a.q, 0.0), (a.q2, 0.0), (a.q_target, 5.0), (a.q2_target, -3.0)):
            net.net[-1].weight.zero_()
            net.net[-1].bias.fill_(bias)
    b = batch()
    stats = a.twin_critic_step(b, torch.Generator().manual_seed(0))
    zero = torch.zeros_like(b["reward"])
    low = td_loss(zero, b["reward"], b["done"], torch.full_like(zero, -3.0), a.cfg.gamma)
    high = td_loss(zero, b["reward"], b["done"], torch.full_like(zero, 5.0), a.cfg.gamma)
    assert stats["critic_loss"] == pytest.approx(2 * low.item(), rel=1e-6)  # both Qs on min
    assert stats["critic_loss"] != pytest.approx(2 * high.item(), rel=1e-3)


def test_the_actor_and_targets_move_only_every_policy_delay_critic_updates():
    a = agent(policy_delay=2)
    buf, gen = filled_buffer(), torch.Generator().manual_seed(4)
    nets = (a.actor, a.actor_target, a.q_target, a.q2_target)
    before = [flat(n) for n in nets]
    q_before, q2_before = flat(a.q), flat(a.q2)
    stats = a.update(buf, gen)  # critic update 1: not delayed
    assert "actor_loss" not in stats
    assert all(torch.equal(flat(n), x) for n, x in zip(nets, before))
    assert not torch.equal(flat(a.q), q_before) and not torch.equal(flat(a.q2), q2_before)
    stats = a.update(buf, gen)  # critic update 2: the actor and every target move
    assert "actor_loss" in stats
    assert all(not torch.equal(flat(n), x) for n, x in zip(nets, before))
    # warming up (train_actor=False): on the delayed update only the targets move
    actor = flat(a.actor)
    a.update(buf, gen, train_actor=False)
    target = flat(a.q_target)
    a.update(buf, gen, train_actor=False)
    assert torch.equal(flat(a.actor), actor) and not torch.equal(flat(a.q_target), target)
    assert a.updates == 4 and a.state_dict()["updates"] == 4


@pytest.mark.slow
def test_td3_trains_resumes_exactly_and_meta_tests_through_the_cli(tmp_path, capsys):
    straight, rows = straight_and_resumed(tmp_path, "td3")
    assert [r["iteration"] for r in rows[1]] == [0, 1, 2]
    keys = ("task_loss", "critic_loss", "actor_loss", "q_mean")
    assert [[r.get(k) for k in keys] for r in rows[0]] == [
        [r.get(k) for k in keys] for r in rows[1]
    ]
    assert "actor_loss" in rows[0][-1] and "actor_loss" not in rows[0][0]  # after the warm-up
    ckpt = torch.load(straight / "checkpoint.pt", weights_only=False)
    assert ckpt["method"] == "td3" and ckpt["config"]["policy_delay"] == 2
    assert ckpt["agent_state"]["updates"] == 9  # 3 iterations x 3 critic updates

    # meta-test descends -Q1: the checkpoint's first critic, not the second
    tc = TaskConfig.from_dict(ckpt["config"])
    norm = reacher_normalizer(tc.max_torque)
    loss_fn, defaults = build_test_critic(ckpt, norm)
    assert defaults["alpha"] == ckpt["selected_alpha"] > 0
    state = ckpt["agent_state"]
    assert all(torch.equal(loss_fn.q.state_dict()[k], v) for k, v in state["q"].items())
    assert not all(torch.equal(loss_fn.q.state_dict()[k], v) for k, v in state["q2"].items())
    capsys.readouterr()
    out = tmp_path / "mt.json"
    cmd = ["meta-test", str(straight), "--num-goals", "2", "--inits", "2", "--out", str(out)]
    assert main([*cmd, "--device", "cpu"]) == 0
    result = json.loads(out.read_text())
    assert result["method"] == "td3" and math.isfinite(result["mse_mean"])
    assert "meta-test td3 on reacher" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["baseline", "td3", REACHER, "--policy-delay", "0"], "--policy-delay must be > 0"),
        (["baseline", "td3", REACHER, "--noise-clip=-1"], "--noise-clip"),
        (["baseline", "ddpg", REACHER, "--policy-noise", "0.1"], "--policy-noise"),
    ],
)
def test_bad_td3_input_is_one_line_and_exit_2(tmp_path, capsys, argv, fragment):
    refused_in_one_line(tmp_path, capsys, argv, fragment)


def test_the_reported_actor_loss_is_the_mean_over_the_delayed_updates(tmp_path, monkeypatch):
    seen: list[float] = []
    update = TD3Agent.update

    def spy(self, buffer, gen, train_actor=True):
        stats = update(self, buffer, gen, train_actor)
        if "actor_loss" in stats:
            seen.append(stats["actor_loss"])
        return stats

    monkeypatch.setattr(TD3Agent, "update", spy)
    cfg = tiny_baseline_cfg(
        tmp_path / "run",
        "td3",
        iterations=2,
        critic_hidden=16,
        actor_hidden=8,
        updates_per_iteration=4,
    )
    rows = train_td3(cfg, progress=False, record=False).metrics
    assert len(seen) == 2  # iteration 1: 4 critic updates, the actor on the 2nd and the 4th
    assert rows[1]["actor_loss"] == pytest.approx(sum(seen) / 2, rel=1e-6)
