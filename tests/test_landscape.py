"""Tests of the 2-D landscape analysis (section 4.2, Figure 1): small end-to-end run, analytic optimum,
descent check, recording contents, CLI errors."""

from __future__ import annotations

import numpy as np
import pytest

from warp_critic.analysis.landscape.fields import METHODS, descent_fraction
from warp_critic.analysis.landscape.problem import AXIS_MASS, analytic_gain, analytic_optimum
from warp_critic.analysis.landscape.run import LandscapeConfig, run_landscape
from warp_critic.running.recording import read_entity_paths

GOAL, TEST_GOALS, INITS = (1.0, 1.0), ((-1.5, 0.5), (0.5, -1.5)), ((0.0, 0.0), (-0.5, 0.5))


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    from warp_critic.core import runtime

    runtime.init()  # one torch thread, Warp started quietly: what the CLI does
    out = tmp_path_factory.mktemp("landscape")
    cfg = LandscapeConfig(
        out=out,
        iterations=4,
        grid=9,
        inits_per_state=2,
        sup_fit_steps=2,
        quiet=True,
        goal=GOAL,
        test_goals=TEST_GOALS,
        init_states=INITS,
    )
    return run_landscape(cfg)


def test_analytic_gain_semi_implicit_euler():
    # N steps of constant force from rest: qd_k = k dt a, q_N = dt^2 a (1 + ... + N) = a dt^2 N (N+1)/2
    dt, T = 0.05, 20
    a = 1.0 / np.array(AXIS_MASS)
    q, qd = np.zeros(2), np.zeros(2)
    for _ in range(T):
        qd = qd + dt * a
        q = q + dt * qd
    assert np.allclose(analytic_gain(dt, T), q)
    assert np.allclose(analytic_gain(dt, T), dt * dt * T * (T + 1) / 2 / np.array([1.001, 1.0]))
    assert np.allclose(
        analytic_gain(0.025, 10, substeps=2), 0.025**2 * 20 * 21 / 2 / np.array(AXIS_MASS)
    )


@pytest.mark.slow
def test_shapes_and_finite(result):
    n, G = 9, 3
    assert result["values"].shape == (G, 3, n, n)
    assert result["grads"].shape == (G, 3, n, n, 2)
    assert np.isfinite(result["values"]).all() and np.isfinite(result["grads"]).all()
    assert result["trace_new"].shape == (4, 4, 2) and np.isfinite(result["trace_new"]).all()
    assert len(result["fractions"]) == G and all(
        set(f) == set(METHODS) for f in result["fractions"]
    )


@pytest.mark.slow
def test_q_true_matches_newton_and_analytic_optimum(result):
    axis, values, grads, goals = result["axis"], result["values"], result["grads"], result["goals"]
    gain = analytic_gain(0.05, 20)
    t1, t2 = np.meshgrid(axis, axis, indexing="ij")
    theta = np.stack([t1, t2], -1)
    q0 = np.array(INITS[0])
    for gi, g in enumerate(goals):
        err = q0 + theta * gain - g
        # the Newton rollout agrees with the closed form q_T = q0 + theta dt^2 T(T+1)/(2m) ...
        np.testing.assert_allclose(values[gi, 0], (err**2).sum(-1), rtol=2e-3, atol=2e-4)
        # ... and so does its gradient through the differentiable model
        np.testing.assert_allclose(grads[gi, 0], 2 * err * gain, rtol=2e-3, atol=2e-4)
        opt = analytic_optimum(g, q0, 0.05, 20)
        np.testing.assert_allclose(result["optima"][gi], opt)
        np.testing.assert_allclose(q0 + opt * gain, g, atol=1e-12)
        i1, i2 = np.unravel_index(np.argmin(values[gi, 0]), values[gi, 0].shape)
        assert (i1, i2) == (np.argmin(abs(axis - opt[0])), np.argmin(abs(axis - opt[1])))
        assert result["fractions"][gi]["Q_true"] == 1.0


def test_descent_fraction_can_fail():
    axis = np.linspace(-5, 5, 21)
    t1, t2 = np.meshgrid(axis, axis, indexing="ij")
    opt = np.array([1.9, -2.3])
    bowl = np.stack([t1 - opt[0], t2 - opt[1]], -1)
    assert descent_fraction(bowl, axis, opt, 0.5) == 1.0
    assert descent_fraction(-bowl, axis, opt, 0.5) == 0.0  # ascent field: nobody arrives
    shifted = np.stack([t1 - 0.0, t2 - 0.0], -1)  # minimum in the wrong place
    assert descent_fraction(shifted, axis, opt, 0.5) == 0.0


@pytest.mark.slow
def test_outputs(result):
    out = result["out"]
    for name in ("landscape.rrd", "landscape.png", "exploration.png"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0
    paths = read_entity_paths(out / "landscape.rrd")
    for gn in ("train", "test1", "test2"):
        for m in METHODS:
            for leaf in ("value", "descent_direction", "optimum"):
                assert f"/landscape/{gn}/{m}/{leaf}" in paths, (gn, m, leaf, sorted(paths)[:20])
    assert "/trace/theta_new" in paths
    assert "/train/ours_task_loss" in paths


@pytest.mark.parametrize(
    "argv,flag",
    [
        (["--grid", "2"], "--grid"),
        (["--iterations", "0"], "--iterations"),
        (["--range", "-1"], "--range"),
        (["--goal", "1"], "--goal"),
        (["--test-goals", "a,b"], "--test-goals"),
        (["--tolerance", "nan"], "--tolerance"),
        (["--dt", "inf"], "--dt"),
        (["--seed", "-1"], "--seed"),
        (["--init-states", "0,0;1"], "--init-states"),
        (["--grid", "100000"], "--grid"),
        (["--iterations", "1000000000000"], "--iterations"),
    ],
)
def test_cli_errors_name_the_flag(argv, flag, capsys, tmp_path):
    from warp_critic.cli.main import main

    code = main(["analyze", "landscape", "--out", str(tmp_path / "x"), *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and flag in err[0] and "error" in err[0]
    assert not (tmp_path / "x").exists()  # refused before any work


def test_huge_grid_is_refused_with_its_memory_estimate(capsys, tmp_path):
    from warp_critic.cli.main import main

    assert main(["analyze", "landscape", "--out", str(tmp_path / "x"), "--grid", "100000"]) == 2
    (err,) = capsys.readouterr().err.strip().splitlines()
    assert "--grid" in err and "needs about" in err and "available" in err


@pytest.mark.slow
def test_default_scene_is_found_from_any_directory(tmp_path, monkeypatch, capsys):
    from warp_critic.cli.main import main

    monkeypatch.chdir(tmp_path)  # no scenes/ here: the scene comes from the installed package
    assert LandscapeConfig().scene.is_file()
    code = main(
        [
            "analyze",
            "landscape",
            "--out",
            "o",
            "--iterations",
            "1",
            "--grid",
            "3",
            "--horizon",
            "3",
            "--inits-per-state",
            "1",
            "--sup-fit-steps",
            "1",
        ]
    )
    assert code == 0, capsys.readouterr().err
    assert (tmp_path / "o" / "landscape.npz").is_file()


# ---------------------------------------------------------------------------------------------------
# the training-task distribution: --train-goals, --goal-std, --start-std (docs/landscape.md,
# "Generalisation to unseen goals")
# ---------------------------------------------------------------------------------------------------
def test_sample_tasks_paper_setting_is_fixed_and_draws_nothing():
    import torch

    from warp_critic.analysis.landscape.training import sample_tasks, varied_tasks

    cfg = LandscapeConfig()
    assert (
        not varied_tasks(cfg) and cfg.train_goals == () and cfg.goal_std == 0 and cfg.start_std == 0
    )
    q0 = torch.tensor([[0.0, 0.0], [0.0, 0.0], [-0.5, 0.5], [-0.5, 0.5]])
    goal = torch.tensor([[1.0, 1.0]])
    gen = torch.Generator().manual_seed(3)
    state = gen.get_state()
    q, g = sample_tasks(cfg, q0, goal, gen)
    assert torch.equal(q, q0) and torch.equal(g, goal.expand(4, -1))
    assert torch.equal(gen.get_state(), state)  # the paper's runs keep their random stream


def test_sample_tasks_draws_goals_and_starts_per_world():
    import torch

    from warp_critic.analysis.landscape.training import sample_tasks, varied_tasks

    q0 = torch.zeros(4000, 2)
    goal = torch.tensor([[1.0, 1.0]])
    gen = torch.Generator().manual_seed(0)
    cfg = LandscapeConfig(start_std=0.5)
    assert varied_tasks(cfg)
    q, g = sample_tasks(cfg, q0, goal, gen)
    assert torch.equal(g, goal.expand(4000, -1))
    assert abs(float(q.mean())) < 0.03 and abs(float(q.std()) - 0.5) < 0.03
    q2, _ = sample_tasks(cfg, q0, goal, gen)
    assert not torch.equal(q, q2)  # anew every iteration
    cfg = LandscapeConfig(train_goals=((-1.0, 1.0), (1.0, -1.0)))
    q, g = sample_tasks(cfg, q0, goal, gen)
    assert torch.equal(q, q0)
    pool = {(1.0, 1.0), (-1.0, 1.0), (1.0, -1.0)}
    drawn = {tuple(map(float, r)) for r in g}
    assert drawn == pool  # every goal of {goal} + train_goals is drawn, nothing else
    cfg = LandscapeConfig(goal_std=1.0)
    _, g = sample_tasks(cfg, q0, goal, gen)
    assert abs(float(g.mean()) - 1.0) < 0.05 and abs(float(g.std()) - 1.0) < 0.05


@pytest.mark.slow
def test_task_distribution_flags_run(tmp_path, capsys):
    from warp_critic.cli.main import main

    code = main(
        [
            "analyze",
            "landscape",
            "--out",
            str(tmp_path / "o"),
            "--iterations",
            "2",
            "--grid",
            "3",
            "--horizon",
            "3",
            "--inits-per-state",
            "1",
            "--sup-fit-steps",
            "1",
            "--ours-goal-input",
            "relative",
            "--train-goals=-1,1;1,-1",
            "--goal-std",
            "0.2",
            "--start-std",
            "0.5",
        ]
    )
    assert code == 0, capsys.readouterr().err
    z = np.load(tmp_path / "o" / "landscape.npz")
    assert np.isfinite(z["grads"]).all() and z["trace_new"].shape == (2, 2, 2)


def test_task_distribution_flags_reach_the_config():
    import argparse

    from warp_critic.analysis.landscape.command import add_arguments, config_from_args

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    cfg = config_from_args(parser.parse_args([]))
    assert (cfg.train_goals, cfg.goal_std, cfg.start_std) == (
        (),
        0.0,
        0.0,
    )  # the paper's setting by default
    cfg = config_from_args(
        parser.parse_args(["--train-goals=-1,1;0.5,2", "--goal-std", "0.3", "--start-std", "1"])
    )
    assert (cfg.train_goals, cfg.goal_std, cfg.start_std) == (((-1.0, 1.0), (0.5, 2.0)), 0.3, 1.0)


@pytest.mark.parametrize(
    "argv,flag",
    [
        (["--goal-std", "-0.1"], "--goal-std"),
        (["--start-std", "nan"], "--start-std"),
        (["--train-goals", "a,b"], "--train-goals"),
        (["--train-goals=1,2;3"], "--train-goals"),
    ],
)
def test_task_distribution_flag_errors(argv, flag, capsys, tmp_path):
    from warp_critic.cli.main import main

    code = main(["analyze", "landscape", "--out", str(tmp_path / "x"), *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and flag in err[0] and "error" in err[0]
    assert not (tmp_path / "x").exists()


def test_reproduce_stage_runs_the_paper_setting_and_the_generalising_one(tmp_path):
    from warp_critic.reproduce.experiments.analyses import GENERALISING_DIR, landscape_configs
    from warp_critic.reproduce.experiments.settings import default_settings

    s = default_settings(quick=False, seeds=1)["landscape"]
    paper, gen = landscape_configs(tmp_path, s, "cpu")
    d = LandscapeConfig()
    skip = {"out", "quiet", "scene"}
    for f in d.__dataclass_fields__:
        if f not in skip:
            assert getattr(paper, f) == getattr(d, f), (
                f
            )  # the paper's setting = the analysis defaults
    assert paper.out == tmp_path and gen.out == tmp_path / GENERALISING_DIR
    assert (
        gen.ours_goal_input == "relative" and gen.start_std > 0
    )  # the closest setting that generalises
    changed = {
        f for f in d.__dataclass_fields__ if f not in skip and getattr(gen, f) != getattr(paper, f)
    }
    assert changed == {"ours_goal_input", "start_std"}
    q = default_settings(quick=True, seeds=1)["landscape"]
    qp, qg = landscape_configs(tmp_path, q, "cpu")
    assert qp.iterations == qg.iterations <= 12 and qp.grid == qg.grid <= 7  # --quick stays tiny
