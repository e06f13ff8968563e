"""Meta-training (Algorithm 2) and meta-test (Algorithm 3) end to end on tiny problems."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from conftest import KUKA, REACHER
from helpers import TINY_TRAIN as TINY
from helpers import tiny_cfg

from warp_critic.cli.main import main
from warp_critic.core.errors import UserError
from warp_critic.evaluation.metatest import MetaTestConfig, meta_test
from warp_critic.methods import ours as train
from warp_critic.physics import bridge
from warp_critic.physics.load import load_scene
from warp_critic.running.recording import read_entity_paths, read_times
from warp_critic.running.rundir import load_checkpoint


@pytest.mark.slow
def test_meta_train_cli_writes_run_directory_and_resumes(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["meta-train", REACHER, *TINY, "--iterations", "3", "--out", str(out)]) == 0
    for name in ("config.json", "checkpoint.pt", "metrics.jsonl", "recording.rrd"):
        assert (out / name).is_file(), name
    rows = [json.loads(x) for x in (out / "metrics.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [0, 1, 2]
    assert all(len(r["task_loss_per_goal"]) == 2 for r in rows)
    entities = read_entity_paths(out / "recording.rrd")
    assert "/train/task_loss/goal0" in entities and "/train/task_loss/goal1" in entities
    # the arm before and after the inner update, on the iteration timeline: the first and last
    assert read_times(out / "recording.rrd", "/robot/goal0/before/") == {0, 2}
    assert read_times(out / "recording.rrd", "/robot/goal1/after/") == {0, 2}
    assert "/robot/goal1/target/tip" in entities  # the goal, drawn
    assert read_times(out / "recording.rrd", "/train/policy/update_norm") == {0, 1, 2}

    # an existing run is never overwritten without --resume
    assert main(["meta-train", REACHER, *TINY, "--iterations", "3", "--out", str(out)]) == 2
    assert "--resume" in capsys.readouterr().err

    assert (
        main(
            [
                "meta-train",
                REACHER,
                "--iterations",
                "5",
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
    assert [r["iteration"] for r in rows] == [0, 1, 2, 3, 4]
    assert torch.load(out / "checkpoint.pt", weights_only=False)["iteration"] == 4
    assert "/train/task_loss/mean" in read_entity_paths(out / "recording.rrd")

    # a moved run directory resumes and records where it now is
    moved = tmp_path / "moved"
    out.rename(moved)
    assert (
        main(
            [
                "meta-train",
                REACHER,
                "--iterations",
                "6",
                "--out",
                str(moved),
                "--resume",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    assert json.loads((moved / "config.json").read_text())["out"] == str(moved)
    assert torch.load(moved / "checkpoint.pt", weights_only=False)["config"]["out"] == str(moved)


@pytest.mark.slow
@pytest.mark.parametrize("extra", [{}, {"policy_lifetime": 3, "start_std": 0.2}])
def test_interrupted_run_resumes_exactly_on_cpu(tmp_path, extra):
    straight = train.meta_train(tiny_cfg(tmp_path / "a", iterations=4, **extra), progress=False)

    def interrupt(info):
        if info.iteration == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train.meta_train(
            tiny_cfg(tmp_path / "b", iterations=4, **extra), callbacks=[interrupt], progress=False
        )
    assert torch.load(tmp_path / "b" / "checkpoint.pt", weights_only=False)["iteration"] == 1
    resumed = train.meta_train(
        tiny_cfg(tmp_path / "b", iterations=4, resume=True, **extra), progress=False
    )
    a = [r["task_loss"] for r in straight.metrics]
    b = [r["task_loss"] for r in resumed.metrics]
    assert a == pytest.approx(b, rel=1e-5)
    again = train.meta_train(tiny_cfg(tmp_path / "c", iterations=4, **extra), progress=False)
    assert [r["task_loss"] for r in again.metrics] == a  # same seed, same numbers


def test_outer_gradient_reaches_the_critic_through_model_and_inner_update(tmp_path):
    """The critic gradient is second order: it exists only through theta_new(phi) and the model."""
    from warp_critic.learning.critic import Critic
    from warp_critic.learning.networks import MLPPolicy, Normalizer, init_policy
    from warp_critic.learning.outer import meta_loss
    from warp_critic.physics.load import load_scene
    from warp_critic.physics.scene import Variant
    from warp_critic.physics.simulator import Simulator

    scene = load_scene(REACHER)
    sim = Simulator(scene, [Variant()] * 2, dt=0.01, substeps=2, device="cpu")
    norm = Normalizer.from_limits(sim.q_lower, sim.q_upper, torch.tensor([20.0, 20.0]), 5.0)
    critic = Critic(2, norm)
    params = {
        k: v.requires_grad_()
        for k, v in init_policy(2, 4, 2, generator=torch.Generator().manual_seed(0)).items()
    }
    goal = torch.tensor([[0.5, 0.3], [0.5, 0.3]])
    res = meta_loss(
        critic, MLPPolicy(norm), params, sim, sim.zeros(), sim.zeros(), goal, horizon=8, alpha=1e-3
    )
    grads = torch.autograd.grad(res.loss, list(critic.parameters()), allow_unused=True)
    # a constant offset of the critic cannot change the policy update: no path from the output bias
    assert grads[-1] is None
    assert all(torch.isfinite(g).all() for g in grads[:-1])
    assert sum(float(g.abs().sum()) for g in grads[:-1]) > 0

    # finite differences on the critic's output weights, through the whole bi-level graph
    w = critic.net[-1].weight
    (g_w,) = torch.autograd.grad(
        meta_loss(
            critic,
            MLPPolicy(norm),
            params,
            sim,
            sim.zeros(),
            sim.zeros(),
            goal,
            horizon=8,
            alpha=1e-3,
        ).loss,
        [w],
    )
    direction = torch.randn_like(w)
    eps = 1e-2

    def loss_at(shift):
        with torch.no_grad():
            w.add_(shift * direction)
        value = meta_loss(
            critic,
            MLPPolicy(norm),
            params,
            sim,
            sim.zeros(),
            sim.zeros(),
            goal,
            horizon=8,
            alpha=1e-3,
        ).loss.item()
        with torch.no_grad():
            w.sub_(shift * direction)
        return value

    lp, lm = loss_at(eps), loss_at(-eps)
    fd = (lp - lm) / (2 * eps)
    assert float((g_w * direction).sum()) == pytest.approx(fd, rel=0.05, abs=1e-6)


@pytest.mark.slow
def test_meta_test_uses_no_model_gradient(tmp_path, monkeypatch, capsys):
    out = tmp_path / "run"
    train.meta_train(tiny_cfg(out, iterations=2), progress=False)

    def forbidden(*a, **k):
        raise AssertionError("meta-test took a model gradient")

    monkeypatch.setattr(bridge.NewtonBridge, "_forward_taped", forbidden)
    monkeypatch.setattr(bridge.NewtonBridge, "begin_rollout", forbidden)
    built = []
    real_init = bridge.NewtonBridge.__init__

    def spy(self, model, *a, **k):
        built.append(model.requires_grad)
        real_init(self, model, *a, **k)

    monkeypatch.setattr(bridge.NewtonBridge, "__init__", spy)
    res = meta_test(
        MetaTestConfig(run_dir=str(out), num_goals=3, inits=2, goal_std=0.2, device="cpu"),
        progress=None,
    )
    assert built == [False]  # the test-time model has no gradient buffers at all
    assert len(res["final_error_per_goal"]) == 3 and res["mean"] >= 0
    # the paper's "mean squared error" averages over the joints; ours sums (the task loss)
    dof = len(res["goals"][0])
    all_err = np.asarray(res["final_error_all"])
    np.testing.assert_allclose(res["mse_per_goal"], all_err.mean(1) / dof, rtol=1e-6)
    assert res["mse_mean"] == pytest.approx(all_err.mean() / dof) and res[
        "mse_std"
    ] == pytest.approx(all_err.std() / dof)
    assert (out / "metatest.json").is_file()

    assert (
        main(
            [
                "meta-test",
                str(out),
                "--num-goals",
                "2",
                "--inits",
                "1",
                "--ee-mass",
                "0.5",
                "--link-scale",
                "1.2",
                "--device",
                "cpu",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "mean" in text and "goal  1" in text and "MSE" in text


def test_meta_test_records_each_goal_before_and_after_and_its_errors(
    finished_run, tmp_path, capsys
):
    """meta-test writes OUT.rrd beside its results (--no-recording: none); the results are the same."""
    import json

    run = str(finished_run)
    argv = ["meta-test", run, "--num-goals", "2", "--inits", "2", "--policy-steps", "2"]
    assert main([*argv, "--device", "cpu", "--out", str(tmp_path / "a.json")]) == 0
    rrd = tmp_path / "a.rrd"
    assert f"recording: rerun {rrd}\n" in capsys.readouterr().out
    paths = read_entity_paths(rrd)
    for g in range(2):
        for part in ("target", "before", "after"):
            assert any(p.startswith(f"/robot/goal{g}/{part}/") for p in paths), (g, part)
        assert f"/metatest/error/goal{g}" in paths
    assert {"/metatest/final_error", "/metatest/error/mean"} <= paths
    assert read_times(rrd, "/metatest/error", "policy_step") == {0, 1, 2}
    assert (
        main([*argv, "--device", "cpu", "--out", str(tmp_path / "b.json"), "--no-recording"]) == 0
    )
    assert "recording" not in capsys.readouterr().out and not (tmp_path / "b.rrd").exists()
    a, b = (json.loads((tmp_path / f"{k}.json").read_text()) for k in "ab")
    assert a == b and "recording" not in a


@pytest.mark.slow
def test_divergence_stops_with_iteration_and_keeps_last_good_checkpoint(
    tmp_path, monkeypatch, capsys
):
    real = train.meta_loss
    calls = {"n": 0}

    def sometimes_nan(*a, **k):
        res = real(*a, **k)
        calls["n"] += 1
        if calls["n"] == 3:
            res.loss, res.losses = res.loss * float("nan"), res.losses * float("nan")
        return res

    monkeypatch.setattr(train, "meta_loss", sometimes_nan)
    out = tmp_path / "run"
    code = main(
        [
            "meta-train",
            REACHER,
            *TINY,
            "--iterations",
            "5",
            "--checkpoint-every",
            "1",
            "--out",
            str(out),
        ]
    )
    err = [
        line for line in capsys.readouterr().err.splitlines() if not line.startswith("[")
    ]  # minus progress
    assert code == 1 and len(err) == 1 and "iteration 2" in err[0], err
    assert torch.load(out / "checkpoint.pt", weights_only=False)["iteration"] == 1


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["meta-train", REACHER, "--goals", "0.1,0.2,0.3"], "needs 2 joint values"),
        (["meta-train", REACHER, "--goals", "5.0,0.0"], "outside the joint limits"),
        (["meta-train", REACHER, "--horizon", "0"], "--horizon must be > 0"),
        (["meta-train", REACHER, "--lr", "-1"], "--lr must be > 0"),
        (["meta-train", REACHER, "--alpha", "0"], "--alpha must be > 0"),
        (["meta-train", REACHER, "--ee-mass", "-1"], "--ee-mass"),
        (["meta-train", REACHER, "--link-length", "-0.5"], "--link-length"),
        (["meta-train", REACHER, "--horizon", "abc"], "invalid int value"),
        (["meta-train", "nope/missing.usda"], "missing.usda"),
        (["meta-train", REACHER, "--policy-init", "weird"], "--policy-init"),
        (["meta-train", REACHER, "--critic-input", "absolute"], "--critic-input"),
        (["meta-train", REACHER, "--velocity-weight", "-1"], "--velocity-weight"),
        (
            ["meta-train", REACHER, "--policy-lifetime", "3", "--policy-init", "fixed"],
            "--policy-lifetime",
        ),
        (["meta-train", REACHER, "--policy-lifetime", "0"], "--policy-lifetime"),
        (["meta-train", REACHER, "--goals", "goals_missing.json"], "goals_missing.json"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, fragment):
    try:
        code = main([*argv, "--out", str(tmp_path / "run"), "--device", "cpu", "--iterations", "1"])
    except SystemExit as e:  # argparse's own errors exit from the parser
        code = e.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and fragment in err[0], err
    assert not (tmp_path / "run" / "checkpoint.pt").exists()


def test_meta_test_bad_run_dirs(tmp_path, capsys, finished_run, copy_of):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["meta-test", str(empty)]) == 2
    assert "no checkpoint" in capsys.readouterr().err
    assert main(["meta-test", str(tmp_path / "nothing")]) == 2
    assert "not found" in capsys.readouterr().err

    out = copy_of(finished_run)
    ckpt = torch.load(out / "checkpoint.pt", weights_only=False)
    # a checkpoint that names another scene, by path and content (the scene is found by content)
    ckpt["config"]["scene"] = ckpt["scene_file"] = KUKA
    ckpt["scene_hash"] = load_scene(KUKA).content_hash
    torch.save(ckpt, out / "checkpoint.pt")
    assert main(["meta-test", str(out), "--device", "cpu"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scene" in err[0]
    assert main(["meta-test", str(empty), "--inits", "0"]) == 2


def test_help_and_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and "warp-critic" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["meta-train", "--help"])
    text = capsys.readouterr().out
    for flag in (
        "--goals",
        "--iterations",
        "--horizon",
        "--dt",
        "--lr",
        "--alpha",
        "--inner-steps",
        "--worlds-per-goal",
        "--seed",
        "--device",
        "--out",
        "--resume",
        "--policy-init",
    ):
        assert flag in text


@pytest.mark.slow
def test_relative_critic_run_meta_tests_from_its_checkpoint(tmp_path):
    out = tmp_path / "rel"
    train.meta_train(
        tiny_cfg(out, iterations=2, critic_input="relative", velocity_weight=0.01), progress=False
    )
    ckpt = load_checkpoint(out)
    assert ckpt["critic_input"] == "relative" and ckpt["config"]["velocity_weight"] == 0.01
    res = meta_test(
        MetaTestConfig(run_dir=str(out), num_goals=2, inits=1, device="cpu"), progress=None
    )
    assert res["mean"] >= 0


@pytest.mark.slow
def test_staggered_policy_lifetime_continues_each_policy_until_it_is_replaced(tmp_path):
    """lifetime 2, 2 worlds per goal: slot 0 is fresh at even iterations, slot 1 at odd ones."""
    seen = []
    train.meta_train(
        tiny_cfg(tmp_path / "s", iterations=3, policy_lifetime=2),
        callbacks=[lambda info: seen.append((info.result.before.q, info.result.after.q))],
        progress=False,
    )
    (_, after0), (before1, _), (before2, _) = seen
    # world 0 (goal 0, slot 0) is not replaced at iteration 1: it starts from its updated policy ...
    assert torch.allclose(before1[:, 0], after0[:, 0], atol=1e-6)
    # ... world 1 (slot 1) is: a fresh policy, not the updated one; at iteration 2 the other way round
    assert not torch.allclose(before1[:, 1], after0[:, 1], atol=1e-3)
    assert not torch.allclose(before2[:, 0], seen[1][1][:, 0], atol=1e-3)
    assert torch.allclose(before2[:, 1], seen[1][1][:, 1], atol=1e-6)
    ckpt = load_checkpoint(tmp_path / "s")
    res = meta_test(
        MetaTestConfig(run_dir=str(tmp_path / "s"), num_goals=1, inits=1, device="cpu"),
        progress=None,
    )
    assert res["policy_steps"] == ckpt["config"]["inner_steps"] * 2


@pytest.mark.slow
def test_home_starts_keep_some_worlds_at_the_home_pose(tmp_path, capsys):
    seen = []
    train.meta_train(
        tiny_cfg(tmp_path / "h", iterations=2, start_std=0.3, home_starts=1),
        callbacks=[lambda info: seen.append(info.result.before.q[0])],
        progress=False,
    )
    for (
        q0
    ) in seen:  # worlds are goal-major: (goal 0, slot 0), (goal 0, slot 1), (goal 1, slot 0), ...
        assert torch.all(q0[0::2] == 0) and torch.all(q0[1::2].abs().sum(1) > 0)
    assert (
        main(
            [
                "meta-train",
                REACHER,
                *TINY,
                "--start-std",
                "0.3",
                "--home-starts",
                "3",
                "--out",
                str(tmp_path / "bad"),
            ]
        )
        == 2
    )
    assert "--home-starts" in capsys.readouterr().err and not (tmp_path / "bad").exists()


@pytest.mark.slow
def test_seeds_batched_in_one_process_equal_single_seed_runs(tmp_path):
    # three seeds share one simulator and one stacked critic; each seed's run directory holds what a
    # run of that seed alone holds (random starts and two inner steps exercise every random draw)
    extra = dict(iterations=3, inner_steps=2, start_std=0.2, home_starts=1)
    batched = train.meta_train(tiny_cfg(tmp_path / "b", seeds=[0, 2, 5], **extra), progress=False)
    assert [r.run_dir for r in batched.seeds] == [tmp_path / "b" / f"seed{s}" for s in (0, 2, 5)]
    single = train.meta_train(tiny_cfg(tmp_path / "s2", seed=2, **extra), progress=False)
    b, s = batched.seeds[1].metrics, single.metrics
    for key in ("task_loss", "task_loss_before", "grad_norm"):
        assert [r[key] for r in b] == pytest.approx([r[key] for r in s], rel=1e-5), key
    ckb, cks = load_checkpoint(tmp_path / "b" / "seed2"), load_checkpoint(tmp_path / "s2")
    assert ckb["config"]["seed"] == 2 and ckb["config"]["seeds"] is None
    for k, v in cks["critic_state"].items():
        assert torch.allclose(ckb["critic_state"][k], v, atol=1e-6), k
    for k, v in cks["optimizer_state"]["state"].items():
        assert torch.allclose(
            ckb["optimizer_state"]["state"][k]["exp_avg_sq"], v["exp_avg_sq"], atol=1e-9
        )
    assert torch.equal(ckb["rng_state"], cks["rng_state"]) and torch.equal(
        ckb["torch_rng_state"], cks["torch_rng_state"]
    )
    # a seed of a batched run resumes on its own, and the batch resumes as a batch
    alone = train.meta_train(
        tiny_cfg(tmp_path / "b" / "seed2", seed=2, resume=True, **{**extra, "iterations": 4}),
        progress=False,
    )
    assert [r["iteration"] for r in alone.metrics] == [0, 1, 2, 3]
    with pytest.raises(UserError, match="different iterations"):
        train.meta_train(
            tiny_cfg(tmp_path / "b", seeds=[0, 2, 5], resume=True, **{**extra, "iterations": 5}),
            progress=False,
        )
    again = train.meta_train(
        tiny_cfg(tmp_path / "b", seeds=[0, 5], resume=True, **{**extra, "iterations": 4}),
        progress=False,
    )
    assert [r["iteration"] for r in again.seeds[1].metrics] == [0, 1, 2, 3]
