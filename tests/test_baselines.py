"""Baselines (DDPG, Meta-Critic): they learn on a small reacher problem, their Q runs through
meta-test, their run directories resume exactly, and bad input is one line with exit code 2."""

from __future__ import annotations

import json
import math

import pytest
import torch
from conftest import REACHER
from helpers import TINY_BASELINE as TINY
from helpers import reacher_normalizer
from helpers import tiny_baseline_cfg as tiny_cfg

from warp_critic.cli.main import main
from warp_critic.core.errors import UserError
from warp_critic.evaluation.metatest import MetaTestConfig, build_test_critic, meta_test
from warp_critic.learning.networks import Normalizer
from warp_critic.learning.rollout import Trajectory
from warp_critic.methods import method as method_of
from warp_critic.methods import q_networks as baseline_networks
from warp_critic.methods.ddpg import train_ddpg
from warp_critic.methods.meta_critic import MetaCriticConfig, train_meta_critic
from warp_critic.methods.replay import ReplayBuffer, rewards
from warp_critic.physics.load import load_scene
from warp_critic.running.recording import read_entity_paths, read_times
from warp_critic.running.rundir import CHECKPOINT_KIND
from warp_critic.running.task import TaskConfig

TRAIN = {"ddpg": train_ddpg, "meta-critic": train_meta_critic}
# ------------------------------------------------------------------------------------------------
# learning + meta-test
# ------------------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("method", ["ddpg", "meta-critic"])
def test_baseline_learns_and_its_q_runs_through_meta_test(tmp_path, method):
    # the reacher's four default goals, 4 worlds each, a shortened horizon; published DDPG settings
    out = tmp_path / method
    cfg = method_of(method).config(
        scene=REACHER,
        method=method,
        iterations=40,
        horizon=30,
        worlds_per_goal=4,
        device="cpu",
        out=str(out),
        checkpoint_every=20,
        record_every=100,
        seed=0,
    )
    res = TRAIN[method](cfg, progress=False)
    losses = [r["task_loss"] for r in res.metrics]
    assert len(losses) == 40 and all(math.isfinite(x) for x in losses)
    first, last = sum(losses[:3]) / 3, sum(losses[-3:]) / 3
    # the untrained actor (~0 torque) leaves ||q_T - g||^2 = ||g||^2 ~ 1.25; DDPG roughly halves it
    assert last < 0.75 * first, (first, last, losses)
    assert all(len(r["task_loss_per_goal"]) == 4 for r in res.metrics)
    if method == "meta-critic":
        assert all("meta_loss" in r for r in res.metrics[5:])  # the actor trains after the warm-up

    # run directory: same layout as meta-train
    for name in ("config.json", "checkpoint.pt", "metrics.jsonl", "recording.rrd"):
        assert (out / name).is_file(), name
    entities = read_entity_paths(out / "recording.rrd")
    assert "/train/task_loss/goal3" in entities
    assert 39 in read_times(out / "recording.rrd", "/robot/goal0/after/")
    assert "/train/critic/critic_loss" in entities and "/train/actor/actor_loss" in entities
    ckpt = torch.load(out / "checkpoint.pt", weights_only=False)
    assert (
        ckpt["kind"] == CHECKPOINT_KIND and ckpt["method"] == method and ckpt["scene"] == "reacher"
    )
    assert ckpt["iteration"] == 39 and ckpt["dof"] == 2 and ckpt["metrics"]["iteration"] == 39
    tc = TaskConfig.from_dict(ckpt["config"])
    assert (
        tc.horizon == 30 and ckpt["config"]["inner_steps"] == 3 and len(tc.goals) == 4
    )  # the scene's, as ours

    # the meta-test critic is -Q(s - g, a)
    norm = reacher_normalizer(tc.max_torque, tc.qd_scale)
    loss_fn, defaults = build_test_critic(ckpt, norm)
    assert defaults["alpha"] > 0 and defaults["steps"] == 3
    assert defaults["alpha"] == ckpt["metrics"]["alpha"]  # selected by the fresh-policy grid search
    q, qd, tau = torch.randn(5, 2), torch.randn(5, 2), torch.randn(5, 2)
    g = torch.tensor([[1.0, 0.5]]).expand(5, 2)
    assert torch.allclose(loss_fn(q, qd, tau, g), -res.model.q(q, qd, tau, g), atol=1e-6)

    result = meta_test(
        MetaTestConfig(run_dir=str(out), num_goals=2, inits=2, device="cpu"), progress=None
    )
    assert result["method"] == method and math.isfinite(result["mean"])
    assert len(result["final_error_per_goal"]) == 2


# ------------------------------------------------------------------------------------------------
# pieces
# ------------------------------------------------------------------------------------------------


def test_rewards_dense_and_sparse():
    q = torch.tensor([[[0.0, 0.0]], [[1.0, 0.0]], [[1.0, 1.0]]])  # (T+1=3, W=1, 2)
    traj = Trajectory(q, torch.zeros_like(q), torch.zeros(2, 1, 2))
    goal = torch.tensor([[1.0, 1.0]])
    r, done = rewards(traj, goal, "dense", 2.0)
    assert r.squeeze(1).tolist() == [-2.0, 0.0] and done.sum() == 0
    traj.q[-1] = torch.tensor([[3.0, 1.0]])
    r, done = rewards(traj, goal, "sparse", 1.0)
    assert r.squeeze(1).tolist() == [0.0, -4.0] and done.squeeze(1).tolist() == [0.0, 1.0]


def test_replay_buffer_ring_and_state_dict():
    buf = ReplayBuffer(5, 1, "cpu")
    rows = torch.arange(7.0).unsqueeze(1).expand(7, buf.data.shape[1]).clone()
    buf._add_rows(rows[:3])
    buf._add_rows(rows[3:])
    assert buf.size == 5 and buf.ptr == 2
    kept = buf.state_dict()["rows"][:, 0].tolist()
    assert kept == [2.0, 3.0, 4.0, 5.0, 6.0]  # oldest first
    small = ReplayBuffer(3, 1, "cpu")
    small.load_state_dict(buf.state_dict())
    assert small.state_dict()["rows"][:, 0].tolist() == [4.0, 5.0, 6.0]
    batch = buf.sample(16, torch.Generator().manual_seed(0))
    assert batch["q"].shape == (16, 1) and batch["reward"].shape == (16,)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["ddpg", "meta-critic"])
def test_resume_is_exact_on_cpu(tmp_path, method):
    straight = TRAIN[method](
        tiny_cfg(tmp_path / "a", method, iterations=4), progress=False, record=False
    )
    TRAIN[method](tiny_cfg(tmp_path / "b", method, iterations=2), progress=False, record=False)
    resumed = TRAIN[method](
        tiny_cfg(tmp_path / "b", method, iterations=4, resume=True), progress=False, record=False
    )
    a = [(r["task_loss"], r.get("critic_loss")) for r in straight.metrics]
    b = [(r["task_loss"], r.get("critic_loss")) for r in resumed.metrics]
    assert a == b


def test_actor_features_are_its_last_hidden_layer_and_forward_is_their_final_layer():
    norm = Normalizer.from_limits(
        torch.tensor([-2.0, -2.0]), torch.tensor([2.0, 2.0]), torch.tensor([5.0, 3.0]), 4.0
    )
    actor = baseline_networks.Actor(2, norm, hidden=16)
    q, qd, g = torch.randn(7, 2), torch.randn(7, 2), torch.randn(7, 2)
    feats = actor.features(q, qd, g)
    assert feats.shape == (7, 16) and bool((feats.abs() <= 1).all())  # after a tanh
    assert torch.equal(actor.head(feats), actor(q, qd, g))


@pytest.mark.slow
def test_meta_critic_features_input_sees_the_actors_features_and_the_stored_action(tmp_path):
    from warp_critic.methods.meta_critic import MetaCriticAgent

    cfg = tiny_cfg(tmp_path / "f", "meta-critic", aux_input="features", actor_hidden=16)
    res = train_meta_critic(cfg, progress=False, record=False)
    agent = res.model
    assert isinstance(agent, MetaCriticAgent)
    assert agent.aux.net[0].in_features == 16 + 3 * 2
    ratios = [r["aux_grad_ratio"] for r in res.metrics if "aux_grad_ratio" in r]
    assert len(ratios) == 2 and all(r > 1e-6 for r in ratios), ratios
    # h_omega reads the features (its only path to the actor's parameters)
    b = {k: torch.randn(5, 2) for k in ("q", "qd", "tau", "goal")}
    feats = agent.actor.features(b["q"], b["qd"], b["goal"])
    h = agent.aux.of_features(feats, b["q"], b["qd"], b["tau"], b["goal"])
    assert not torch.equal(
        h, agent.aux.of_features(feats + 0.1, b["q"], b["qd"], b["tau"], b["goal"])
    )
    # a run saved with one input resumes with it
    again = train_meta_critic(
        tiny_cfg(tmp_path / "f", "meta-critic", iterations=4, resume=True),
        progress=False,
        record=False,
    )
    assert again.model.aux.net[0].in_features == 16 + 3 * 2


def test_aux_grad_ratio_and_aux_alive_by_hand():
    from warp_critic.methods.meta_critic import aux_alive, aux_grad_ratio

    g_main = (torch.tensor([3.0, 0.0]), torch.tensor([[4.0]]))  # norm 5
    g_aux = (torch.tensor([0.0, 0.6]), torch.tensor([[0.8]]))  # norm 1
    assert aux_grad_ratio(g_main, g_aux, 2.0) == pytest.approx(0.4)
    assert aux_grad_ratio(g_main, tuple(torch.zeros_like(g) for g in g_aux), 1.0) == 0.0
    warmup = [{"task_loss": 1.0}] * 4  # no actor updates yet: not counted
    rows = [{"aux_loss": 0.7, "aux_grad_ratio": r} for r in [1, 1, 1, 1, 1, 1, 1e-6, 1e-7]]
    assert aux_alive(warmup + rows) == 0.5  # the last quarter of the 8 actor iterations
    assert aux_alive(warmup + rows[:-1] + [{"aux_loss": 0.7, "aux_grad_ratio": 0.0}]) == 0.5
    old = [{"aux_loss": 0.69, "meta_improvement": m} for m in [1e-3, 2e-4, 0.0, 0.0]]
    assert aux_alive(old) == 0.0  # written before the ratio: judged by meta_improvement
    assert aux_alive(old[:2] + old[:1] + old[1:2]) == 1.0
    assert aux_alive(warmup) is None


@pytest.mark.slow
def test_meta_critic_logs_the_aux_ratio_and_warns_when_h_omega_no_longer_moves_the_actor(
    tmp_path, capsys
):
    live = train_meta_critic(tiny_cfg(tmp_path / "a", "meta-critic"), progress=False, record=False)
    ratios = [r["aux_grad_ratio"] for r in live.metrics if "aux_grad_ratio" in r]
    assert len(ratios) == 2 and all(r > 1e-6 for r in ratios), ratios  # a fresh h_omega moves it
    assert "trained as DDPG" not in capsys.readouterr().err
    # aux weight 0: h_omega is still trained, but its gradient never reaches the actor
    dead = train_meta_critic(
        tiny_cfg(tmp_path / "b", "meta-critic", aux_weight=0.0), progress=False, record=False
    )
    assert all(r["aux_grad_ratio"] == 0.0 for r in dead.metrics if "aux_loss" in r)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(tmp_path / "b") in err[0] and "trained as DDPG" in err[0], err


# ------------------------------------------------------------------------------------------------
# command line
# ------------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_baseline_cli_writes_run_directory_and_resumes(tmp_path, capsys):
    out = tmp_path / "run"
    assert (
        main(["baseline", "meta-critic", REACHER, *TINY, "--iterations", "2", "--out", str(out)])
        == 0
    )
    printed = capsys.readouterr().out
    assert "final task loss" in printed and str(out) in printed
    rows = [json.loads(x) for x in (out / "metrics.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [0, 1]
    assert json.loads((out / "config.json").read_text())["method"] == "meta-critic"

    # never overwrite an existing run without --resume; never resume a run of another method
    assert (
        main(["baseline", "meta-critic", REACHER, *TINY, "--iterations", "2", "--out", str(out)])
        == 2
    )
    assert "--resume" in capsys.readouterr().err
    assert (
        main(["baseline", "ddpg", REACHER, "--iterations", "3", "--out", str(out), "--resume"]) == 2
    )
    assert "meta-critic" in capsys.readouterr().err

    assert (
        main(
            [
                "baseline",
                "meta-critic",
                REACHER,
                "--iterations",
                "3",
                "--out",
                str(out),
                "--resume",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    rows = [json.loads(x) for x in (out / "metrics.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [0, 1, 2]
    assert torch.load(out / "checkpoint.pt", weights_only=False)["iteration"] == 2


def test_default_out_directory():
    cfg = MetaCriticConfig(scene=REACHER)
    filled = cfg.fill_defaults(load_scene(REACHER))
    assert filled.out == "runs/reacher-meta-critic" and filled.horizon is not None and filled.goals
    assert (
        cfg.out is None and cfg.horizon is None and cfg.goals is None
    )  # a new config: cfg as it was


@pytest.mark.slow
@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["baseline", "ppo", REACHER], "invalid choice"),
        (["baseline", "ddpg", REACHER, "--gamma", "1.5"], "--gamma must be in (0, 1]"),
        (["baseline", "ddpg", REACHER, "--gamma", "0"], "--gamma must be in (0, 1]"),
        (["baseline", "meta-critic", REACHER, "--tau", "0"], "--tau must be in (0, 1]"),
        (["baseline", "ddpg", REACHER, "--tau", "2"], "--tau must be in (0, 1]"),
        (["baseline", "ddpg", REACHER, "--actor-lr=-1e-4"], "--actor-lr must be > 0"),
        (["baseline", "ddpg", REACHER, "--critic-lr", "0"], "--critic-lr must be > 0"),
        (["baseline", "meta-critic", REACHER, "--aux-lr", "0"], "--aux-lr must be > 0"),
        (["baseline", "ddpg", REACHER, "--batch-size", "0"], "--batch-size must be > 0"),
        (["baseline", "ddpg", REACHER, "--horizon", "0"], "--horizon must be > 0"),
        (["baseline", "ddpg", REACHER, "--buffer-size=-5"], "--buffer-size must be > 0"),
        (["baseline", "ddpg", REACHER, "--noise", "pink"], "--noise"),
        (["baseline", "ddpg", REACHER, "--reward", "shaped"], "--reward"),
        (["baseline", "ddpg", REACHER, "--noise-std=-0.1"], "--noise-std"),
        (["baseline", "ddpg", REACHER, "--batch-size", "abc"], "invalid int value"),
        (["baseline", "ddpg", REACHER, "--goals", "0.1,0.2,0.3"], "needs 2 joint values"),
        (["baseline", "ddpg", "nope/missing.usda"], "missing.usda"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, fragment):
    try:
        code = main([*argv, "--out", str(tmp_path / "run"), "--device", "cpu", "--iterations", "1"])
    except SystemExit as e:  # argparse's own errors (choices, types) exit from the parser
        code = e.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and fragment in err[0], err
    assert not (tmp_path / "run" / "checkpoint.pt").exists()


def test_test_critic_rejects_broken_checkpoints():
    norm = Normalizer.from_limits(-torch.ones(2), torch.ones(2), torch.ones(2), 1.0)
    with pytest.raises(UserError, match="no usable Q"):
        baseline_networks.test_critic_from_checkpoint({"method": "ddpg", "dof": 2}, norm)


@pytest.mark.slow
def test_baseline_seeds_batched_equal_single_seed_runs(tmp_path):
    # seeds' episodes share one simulator; each seed's agent, buffer and noise draw from its own seed
    kw = dict(iterations=3, start_std=0.2, home_starts=1)
    batched = train_ddpg(tiny_cfg(tmp_path / "b", "ddpg", seeds=[4, 1], **kw), progress=False)
    single = train_ddpg(tiny_cfg(tmp_path / "s", "ddpg", seed=1, **kw), progress=False)
    b, s = batched.seeds[1].metrics, single.metrics
    for key in ("task_loss", "task_loss_explore", "critic_loss", "fresh_policy_loss", "alpha"):
        assert [r.get(key) for r in b] == pytest.approx([r.get(key) for r in s], rel=1e-5), key
    assert json.loads((tmp_path / "b" / "seed1" / "config.json").read_text())["seed"] == 1
