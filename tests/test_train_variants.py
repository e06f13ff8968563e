"""Dynamics-randomised meta-training (``--train-variants``): the range text, the seeded per-world and
per-iteration draws, the in-place variant change of a live simulator (bitwise a simulator built with
those variants), the draws in the metrics, resume, and bad input (one line, exit 2)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import REACHER
from helpers import variants_train_argv

from warp_critic.core.errors import FieldError
from warp_critic.physics.load import load_scene
from warp_critic.physics.redraw import BODY_FIELDS, DERIVED_FIELDS, JOINT_FIELDS, set_variants
from warp_critic.physics.variant_draws import (
    draw,
    format_ranges,
    groups,
    parse_ranges,
    with_draws,
)
from warp_critic.physics.variants import Variant

RANGES = "arm1.mass=0.25..6; arm2.stretch=0.5..2; ee.point-mass+=0..1@0.1,0,0"


def test_range_text_round_trips_and_fixed_values():
    ranges = parse_ranges(RANGES)
    assert [(r.lo, r.hi) for r in ranges] == [(0.25, 6.0), (0.5, 2.0), (0.0, 1.0)]
    assert parse_ranges(format_ranges(ranges)) == ranges
    (fixed,) = parse_ranges("arm1.mass*=2:scale")
    assert fixed.lo == fixed.hi == 2.0 and fixed.change.mode == "scale"
    assert parse_ranges(None) == () and parse_ranges("  ") == ()


@pytest.mark.parametrize(
    "text, words",
    [
        ("arm1.mass=5..1", "the range 5..1 is empty"),
        ("arm1.mass=a..2", "'a' is not a number"),
        ("arm1.mass=-3..2", "must be >= 0"),
        ("arm1.mass=0..inf", "must be finite"),
        ("ee.point-mass+=-1..2", "a point mass is added"),
        ("arm1.mass=1..2;;arm2.mass=1", "an empty item"),
        ("arm1.mass", "expected LINK.WHAT=LO..HI"),
        ("arm1.mass=1..2 | ", "an empty group"),
        ("| arm1.mass=1..2", "an empty group"),
    ],
)
def test_bad_range_text_is_one_field_error(text, words):
    with pytest.raises(FieldError) as err:
        parse_ranges(text)
    assert err.value.field == "train_variants"
    assert words in str(err.value) and "\n" not in str(err.value)


def test_draws_are_seeded_per_world_and_per_iteration():
    ranges = parse_ranges(RANGES)
    a = draw(ranges, 16, seed=3, iteration=7)
    assert a.shape == (16, 3)
    for k, r in enumerate(ranges):
        assert (a[:, k] >= r.lo).all() and (a[:, k] <= r.hi).all()
    assert np.array_equal(a, draw(ranges, 16, seed=3, iteration=7))  # a function of (seed, it)
    assert not np.array_equal(a, draw(ranges, 16, seed=3, iteration=8))
    assert not np.array_equal(a, draw(ranges, 16, seed=4, iteration=7))
    assert len(np.unique(a[:, 0])) == 16  # every world its own draw
    # uniform: 20000 draws of U(0.25, 6) have the mean and spread of U(0.25, 6)
    many = draw(parse_ranges("arm1.mass=0.25..6"), 20000, seed=0, iteration=0)[:, 0]
    assert abs(many.mean() - 3.125) < 0.05 and abs(many.std() - 5.75 / 12**0.5) < 0.05
    v = with_draws(Variant(changes="arm1.mass=2"), ranges, a[0])
    assert len(v.changes) == 4 and v.changes[0].value == 2.0 and v.changes[1].value == a[0, 0]


def test_groups_are_alternatives_one_per_world_in_turn():
    """'A | B': world w at iteration it takes group (w + it) mod 2 only; the other group's values
    are NaN and left out of its variant; the draws of one group equal a flat draw's."""
    text = "arm1.mass=0.25..6; arm2.mass=0.25..6 | arm1.stretch=0.5..2"
    ranges = parse_ranges(text)
    assert groups(ranges) == 2 and [r.group for r in ranges] == [0, 0, 1]
    assert format_ranges(ranges).count(" | ") == 1
    assert parse_ranges(format_ranges(ranges)) == ranges
    flat = parse_ranges(text.replace("|", ";"))
    assert groups(flat) == 1
    for it in (0, 1, 6):
        a = draw(ranges, 8, seed=2, iteration=it)
        b = draw(flat, 8, seed=2, iteration=it)  # the same stream, masked
        for w in range(8):
            g = (w + it) % 2
            member = np.array([r.group == g for r in ranges])
            assert np.array_equal(a[w, member], b[w, member])
            assert np.isnan(a[w, ~member]).all()
            v = with_draws(Variant(), ranges, a[w])
            assert [c.what for c in v.changes] == (["mass", "mass"] if g == 0 else ["stretch"])
    assert not np.isnan(draw(flat, 8, seed=2, iteration=0)).any()


@pytest.mark.slow
def test_grouped_draws_train_with_nulls_in_the_metrics(tmp_path):
    from warp_critic.cli.main import main

    text = "arm1.mass=0.25..6 | arm2.stretch=0.7..2"
    out = tmp_path / "run"
    assert main(variants_train_argv(out, "--seed", "1", ranges=text, iterations=2)) == 0
    rows = _rows(out)
    ranges = parse_ranges(text)
    for it, row in enumerate(rows):
        values = row["train_variant_values"]
        expect = draw(ranges, 8, seed=1, iteration=it)
        for w, world in enumerate(values):
            assert [v is None for v in world] == list(np.isnan(expect[w]))
            assert [v for v in world if v is not None] == list(expect[w][~np.isnan(expect[w])])


def test_live_variants_step_bitwise_like_a_built_simulator():
    """set_variants on a simulator whose graphs are captured == a simulator built with the variants:
    model arrays, the solver's spatial inertias, forward and differentiable rollouts, bitwise."""
    from warp_critic.core import runtime
    from warp_critic.physics.simulator import Simulator

    runtime.init()
    scene = load_scene(REACHER)
    variants = [
        Variant(changes="arm1.mass=3"),
        Variant(),
        Variant(changes="arm1.stretch=1.5; arm2.mass*=0.5:scale"),  # moves arm2's joint
        Variant(changes="ee.point-mass+=2; arm1.offset+=0.3"),
    ]
    W = len(variants)
    kw = dict(dt=0.01, substeps=2, differentiable=True)
    built = Simulator(scene, variants, **kw)
    live = Simulator(scene, [Variant()] * W, **kw)
    q, qd, tau = torch.full((W, 2), 0.3), torch.zeros(W, 2), torch.ones(W, 2)
    live.step(q, qd, tau)
    live.step(q, qd, tau)  # captured and replayed before the change
    set_variants(live, variants)
    assert live.variants == variants
    for f in BODY_FIELDS + JOINT_FIELDS + DERIVED_FIELDS:
        assert np.array_equal(getattr(built.model, f).numpy(), getattr(live.model, f).numpy()), f
    for f in ("body_I_m", "body_X_com"):  # re-derived by Featherstone (a Newton internal)
        assert np.array_equal(
            getattr(built.bridge.solver, f).numpy(), getattr(live.bridge.solver, f).numpy()
        ), f
    a = b = (q, qd)
    for _ in range(15):
        a, b = built.step(*a, tau), live.step(*b, tau)
    assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])
    assert not torch.equal(a[0][0], a[0][1])  # the variants do change the dynamics

    def grads(sim):
        q0 = torch.zeros(W, 2, requires_grad=True)
        u = torch.ones(W, 2, requires_grad=True)
        roll, x, xd = sim.begin_rollout(), q0, torch.zeros(W, 2)
        for k in range(8):
            x, xd = roll.step(x, xd, u * (1 + 0.1 * k))
        (x**2).sum().backward()
        return x.detach(), q0.grad, u.grad

    assert all(torch.equal(x, y) for x, y in zip(grads(built), grads(live)))
    with pytest.raises(ValueError):
        set_variants(live, variants[:2])


def _rows(run: Path) -> list[dict]:
    return [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines() if line]


@pytest.mark.slow
def test_draws_in_the_metrics_batched_seeds_and_resume(tmp_path):
    """Each row holds its worlds' draws; batched seeds draw what single-seed runs draw; a run
    stopped at iteration 2 and resumed to 4 draws and trains exactly as the uninterrupted one."""
    from warp_critic.cli.main import main

    ranges = parse_ranges("arm1.mass=0.25..6; arm2.stretch=0.7..2")
    assert main(variants_train_argv(tmp_path / "batched", "--seeds", "3,4")) == 0
    assert main(variants_train_argv(tmp_path / "single", "--seed", "4")) == 0
    assert main(variants_train_argv(tmp_path / "half", "--seed", "4", iterations=2)) == 0
    assert main(variants_train_argv(tmp_path / "half", "--seed", "4", "--resume")) == 0
    single = _rows(tmp_path / "single")
    assert len(single) == 4
    for it, row in enumerate(single):
        values = np.array(row["train_variant_values"])
        assert values.shape == (4 * 2, 2)  # 4 goals x 2 worlds, 2 ranges
        assert np.array_equal(values, draw(ranges, 8, seed=4, iteration=it))
    for other in (_rows(tmp_path / "batched" / "seed4"), _rows(tmp_path / "half")):
        assert [r["train_variant_values"] for r in other] == [
            r["train_variant_values"] for r in single
        ]
        assert [r["task_loss"] for r in other] == [r["task_loss"] for r in single]
    seed3 = _rows(tmp_path / "batched" / "seed3")
    assert seed3[0]["train_variant_values"] != single[0]["train_variant_values"]
    config = json.loads((tmp_path / "single" / "config.json").read_text())
    assert config["train_variants"] == "arm1.mass=0.25..6; arm2.stretch=0.7..2"


@pytest.mark.slow
@pytest.mark.subprocess
@pytest.mark.parametrize(
    "value, words",
    [
        ("arm1.mass=4..1", "the range 4..1 is empty"),
        ("arm9.mass=1..2", "unknown link 'arm9'"),
        ("arm1.offset+=-3..1", "must be > 0"),
        ("arm1.mass=x", "'x' is not a number"),
    ],
)
def test_bad_train_variants_flag_is_one_line_exit_2(tmp_path, value, words):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "warp_critic.cli.main", "meta-train", REACHER]
    cmd += ["--iterations", "1", "--train-variants", value, "--out", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("warp-critic: error: --train-variants:"), lines
    assert words in lines[0]
    assert not out.exists()


def test_history_features_and_the_history_critic():
    """history = [qd_t - qd_{t-1}, tau_{t-1}] (zeros at t = 0); the history critic reads it (its
    output changes with it), batched seeds evaluate as single critics, and critic_loss passes it."""
    from warp_critic.learning.critic import Critic
    from warp_critic.learning.critic_inputs import HISTORY, history_features
    from warp_critic.learning.losses import critic_loss
    from warp_critic.learning.networks import MLPPolicy, Normalizer
    from warp_critic.learning.rollout import Trajectory
    from warp_critic.learning.stacked import StackedCritic

    T, W, dof = 5, 3, 2
    gen = torch.Generator().manual_seed(0)
    qd = torch.randn(T + 1, W, dof, generator=gen)
    tau = torch.randn(T, W, dof, generator=gen)
    h = history_features(qd, tau)
    assert h.shape == (T, W, 2 * dof)
    assert torch.equal(h[0], torch.zeros(W, 2 * dof))
    assert torch.equal(h[3, :, :dof], qd[3] - qd[2]) and torch.equal(h[3, :, dof:], tau[2])
    norm = Normalizer(torch.zeros(dof), torch.full((dof,), 2.0), 5.0, torch.full((dof,), 3.0))
    torch.manual_seed(1)
    critics = [Critic(dof, norm, hidden=16, inputs="history") for _ in range(2)]
    assert critics[0].rollout_data == (HISTORY,) and critics[0].net[0].in_features == 5 * dof
    q = torch.randn(T, W, dof, generator=gen)
    g = torch.zeros(T, W, dof)
    a = critics[0](q, qd[:T], tau, g, history=h)
    assert not torch.allclose(a, critics[0](q, qd[:T], tau, g, history=torch.zeros_like(h)))
    with pytest.raises(ValueError, match="needs history"):
        critics[0](q, qd[:T], tau, g)
    stacked = StackedCritic(critics)
    both = torch.cat([q, q], dim=1), torch.cat([qd[:T]] * 2, 1), torch.cat([tau] * 2, 1)
    out = stacked(*both, torch.cat([g, g], 1), history=torch.cat([h, h], 1))
    assert torch.allclose(out[:, :W], a, atol=1e-6)
    assert torch.allclose(out[:, W:], critics[1](q, qd[:T], tau, g, history=h), atol=1e-6)
    policy = MLPPolicy(norm)
    params = policy.init(W, generator=gen)
    traj = Trajectory(torch.randn(T + 1, W, dof, generator=gen), qd, tau)
    policy_tau = policy(params, traj.q[:-1], traj.qd[:-1])
    expect = critics[0](traj.q[:-1], traj.qd[:-1], policy_tau, g, history=h).sum(0)
    assert torch.allclose(critic_loss(critics[0], policy, params, traj, g[0]), expect)


@pytest.mark.slow
@pytest.mark.parametrize("inputs, width", [("history", 5 * 2), ("pose-dynamics", 4 * 2 + 20)])
def test_history_and_told_critics_train_resume_and_meta_test(tmp_path, inputs, width):
    """The critics that read more than the states (the last step's response; the world's model,
    tests/test_dynamics_input.py) train, resume and meta-test on a new model from the command line."""
    import math

    from warp_critic.cli.main import main

    run = tmp_path / "run"
    argv = variants_train_argv(run, "--critic-input", inputs, iterations=2)
    assert main(argv) == 0
    ckpt = torch.load(run / "checkpoint.pt", weights_only=True)
    assert ckpt["critic_input"] == inputs
    assert ckpt["critic_state"]["net.0.weight"].shape[1] == width
    at = argv.index("--iterations") + 1
    assert main([*argv[:at], "3", *argv[at + 1 :], "--resume"]) == 0
    rows = [json.loads(x) for x in (run / "metrics.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [0, 1, 2]
    out = tmp_path / "test.json"
    test = ["meta-test", str(run), "--num-goals", "2", "--inits", "1", "--device", "cpu"]
    assert main([*test, "--variant", "arm2.mass=4", "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert "arm2.mass=4" in json.dumps(result["variant"]) and math.isfinite(result["mse_mean"])
