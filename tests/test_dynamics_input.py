"""The ``pose-dynamics`` critic: each world's model told to the critic (privileged data).

The descriptor is zero at the nominal model and moves exactly the numbers of what a variant changes;
a live simulator whose variants were redrawn describes its worlds as one built with those variants;
the critic reads the descriptor (its output changes with it), batched seeds evaluate as single
critics, and the critic loss passes the trajectory's descriptor (a run trains, resumes and meta-tests
on a new model through the command line: tests/test_train_variants.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from conftest import REACHER
from helpers import load_tool, variants_train_argv

from warp_critic.physics.descriptor import PER_BODY, PER_JOINT, DynamicsDescriptor
from warp_critic.physics.load import load_scene
from warp_critic.physics.redraw import set_variants
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
    assert describe.size == PER_BODY * B + PER_JOINT * J == 20 == len(describe.names)
    assert describe.names[0] == "arm1.mass" and describe.names[PER_BODY] == "arm2.mass"
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
    from warp_critic.learning.critic import Critic
    from warp_critic.learning.critic_inputs import DYNAMICS
    from warp_critic.learning.losses import critic_loss
    from warp_critic.learning.networks import MLPPolicy, Normalizer
    from warp_critic.learning.rollout import Trajectory
    from warp_critic.learning.stacked import StackedCritic

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
    assert critics[0].rollout_data == (DYNAMICS,) and critics[0].net[0].in_features == 4 * dof + K
    assert Critic(dof, norm, hidden=16, inputs="pose").rollout_data == ()
    relative = Critic(dof, norm, hidden=16, inputs="relative-dynamics")
    assert relative.rollout_data == (DYNAMICS,) and relative.net[0].in_features == 3 * dof + K
    q, qd, tau = (torch.randn(T, W, dof, generator=gen) for _ in range(3))
    g = torch.zeros(T, W, dof)
    d = torch.randn(W, K, generator=gen)
    a = critics[0](q, qd, tau, g, dynamics=d)
    assert a.shape == (T, W)
    assert not torch.allclose(a, critics[0](q, qd, tau, g, dynamics=torch.zeros_like(d)))
    with pytest.raises(ValueError, match="dynamics"):
        critics[0](q, qd, tau, g)
    stacked = StackedCritic(critics)
    assert stacked.rollout_data == (DYNAMICS,)
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


def test_identified_critic_feeds_the_told_critic_its_estimate():
    """The identifier maps a trajectory's observed steps to ``(W, K)`` with fixed input scales; the
    identified critic is the told critic at that estimate, never at the trajectory's true model."""
    from warp_critic.learning.critic import Critic
    from warp_critic.learning.critic_inputs import HISTORY, history_features
    from warp_critic.learning.identify import (
        IdentifiedCritic,
        Identifier,
        identifier_inputs,
        trajectory_inputs,
    )
    from warp_critic.learning.losses import critic_loss_at
    from warp_critic.learning.networks import Normalizer
    from warp_critic.learning.rollout import Trajectory

    T, W, dof, K = 5, 3, 2, 4
    gen = torch.Generator().manual_seed(0)
    norm = Normalizer(
        torch.zeros(dof), torch.full((dof,), 2.0), 5.0, torch.full((dof,), 3.0), dynamics_size=K
    )
    torch.manual_seed(0)
    told = Critic(dof, norm, hidden=16, inputs="pose-dynamics")
    ident = Identifier(dof, K, hidden=8)
    with pytest.raises(ValueError, match="reads the dynamics"):
        IdentifiedCritic(Critic(dof, norm, hidden=16, inputs="pose"), ident)
    traj = Trajectory(
        torch.randn(T + 1, W, dof, generator=gen),
        torch.randn(T + 1, W, dof, generator=gen),
        torch.randn(T, W, dof, generator=gen),
        torch.randn(W, K, generator=gen),  # the truth, which the identified critic must not read
    )
    x = trajectory_inputs(traj)
    assert x.shape == (T, W, 4 * dof)
    assert torch.equal(
        x, identifier_inputs(traj.q[:T], traj.qd[:T], history_features(traj.qd, traj.tau))
    )
    ident.standardise_from(x)
    assert torch.allclose(ident.x_mean, x.reshape(-1, 4 * dof).mean(0))
    d_hat = ident.of_trajectory(traj)
    assert d_hat.shape == (W, K)
    critic = IdentifiedCritic(told, ident)
    assert critic.rollout_data == (HISTORY,)  # never the true model
    g = torch.zeros(W, dof)
    tau = torch.randn(T, W, dof, generator=gen)
    got = critic_loss_at(critic, traj, tau, g)
    want = told(traj.q[:T], traj.qd[:T], tau, g.expand(T, W, dof), dynamics=d_hat).sum(0)
    assert torch.allclose(got, want, atol=1e-6)
    truth = told(traj.q[:T], traj.qd[:T], tau, g.expand(T, W, dof), dynamics=traj.dynamics).sum(0)
    assert not torch.allclose(got, truth)


def test_identifier_version_2_reads_the_response_size_free():
    """Version 2's moments: scaling a trajectory's velocity changes and torques by ``c`` shifts each
    log root mean square by ``log c`` and leaves the correlations; for one joint driven by
    ``tau = I qdd`` the difference of the two logs is ``log I`` whatever the torques' size. Version
    1 has a linear head over the mean features; other versions are refused."""
    from warp_critic.learning.identify import Identifier

    gen = torch.Generator().manual_seed(1)
    T, W, dof, K = 7, 3, 2, 5
    x = torch.randn(T, W, 4 * dof, generator=gen)
    ident = Identifier(dof, K, hidden=8)
    ident.standardise_from(x)
    n = 2 * dof
    assert ident.moments == n + n * (n - 1) // 2
    m = ident.response_moments(x)
    scaled = x.clone()
    scaled[..., 2 * dof :] *= 10.0
    m10 = ident.response_moments(scaled)
    assert torch.allclose(m10[:, :n] - m[:, :n], torch.full((W, n), math.log(10.0)), atol=1e-4)
    assert torch.allclose(m10[:, n:], m[:, n:], atol=1e-5)
    assert ident(x).shape == (W, K)

    one = Identifier(1, 1, hidden=4)  # x: [q, qd, dqd, tau]; unit scales
    inertia = torch.tensor([0.5, 2.0, 8.0])
    for size in (0.01, 1.0):
        tau = size * torch.randn(20, 3, 1, generator=gen)
        xs = torch.cat([torch.zeros(20, 3, 2), tau / inertia[:, None], tau], dim=-1)
        logs = one.response_moments(xs)[:, :2]
        assert torch.allclose(logs[:, 1] - logs[:, 0], inertia.log(), atol=1e-4)

    assert isinstance(Identifier(dof, K, hidden=8, version=1).head, torch.nn.Linear)
    with pytest.raises(ValueError, match="1 or 2"):
        Identifier(dof, K, version=3)


def exit_code(argv: list[str]) -> int:
    """``warp-critic ARGV`` in process: its exit code, whether returned or raised (argparse)."""
    from warp_critic.cli.main import main

    try:
        return main(argv)
    except SystemExit as e:
        return int(e.code or 0)


@pytest.mark.slow
def test_identify_command_writes_a_run_that_meta_tests_without_the_model(tmp_path, capsys):
    """warp-critic identify on a told run: a new run whose critic is the identified one (meta-test
    loads it and tests a new model), the regression's losses written; misuse is one line, exit 2."""
    from warp_critic.cli.main import main
    from warp_critic.evaluation.metatest import build_test_critic
    from warp_critic.learning.identify import IdentifiedCritic, Identifier

    told, plain = tmp_path / "told", tmp_path / "plain"
    assert main(variants_train_argv(told, "--critic-input", "pose-dynamics", iterations=1)) == 0
    assert main(variants_train_argv(plain, "--critic-input", "pose", iterations=1)) == 0
    out = tmp_path / "identified"
    argv = [str(told), "--out", str(out), "--iterations", "3", "--goals", "2", "--inits", "2"]
    assert main(["identify", *argv]) == 0
    text = capsys.readouterr().out
    assert "varied entries" in text and f"run: {out}" in text
    rows = [json.loads(x) for x in (out / "identify.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [0, 1, 2] and all(
        math.isfinite(r["loss"]) for r in rows
    )
    ckpt = torch.load(out / "checkpoint.pt", weights_only=True)
    from warp_critic.learning.networks import Normalizer

    norm = Normalizer(
        torch.zeros(2), torch.ones(2), 5.0, torch.ones(2), dynamics_size=ckpt["identifier"]["size"]
    )
    critic, _ = build_test_critic(ckpt, norm)
    assert isinstance(critic, IdentifiedCritic)
    assert ckpt["identifier"]["version"] == 2 and critic.identifier.version == 2
    # an identifier written before versions existed (no "version") loads as version 1
    old = Identifier(2, ckpt["identifier"]["size"], hidden=ckpt["identifier"]["hidden"], version=1)
    legacy = {**ckpt, "identifier_state": old.state_dict()}
    legacy["identifier"] = {k: v for k, v in ckpt["identifier"].items() if k != "version"}
    loaded, _ = build_test_critic(legacy, norm)
    assert loaded.identifier.version == 1 and isinstance(loaded.identifier.head, torch.nn.Linear)
    result = tmp_path / "test.json"
    test = ["meta-test", str(out), "--num-goals", "2", "--inits", "1", "--device", "cpu"]
    assert main([*test, "--variant", "arm2.mass=4", "--out", str(result)]) == 0
    assert math.isfinite(json.loads(result.read_text())["mse_mean"])
    for bad, words in (
        ([str(plain), "--out", str(tmp_path / "x")], "not told the model"),
        ([str(told), "--out", str(out)], "not an empty folder"),
        ([str(told), "--out", str(tmp_path / "y"), "--iterations", "0"], "--iterations"),
        ([str(told), "--out", str(tmp_path / "y"), "--version", "3"], "--version"),
        ([str(told), "--out", str(tmp_path / "y"), "--variants", "arm9.mass=1..2"], "arm9"),
        ([str(told), "--out", str(tmp_path / "y"), "--variants", "arm2.mass=2..1"], "LO > HI"),
    ):
        assert exit_code(["identify", *bad]) == 2
        err = capsys.readouterr().err
        assert err.startswith("warp-critic: error: ") and err.count("\n") == 1 and words in err, err
        assert "--variants" in err or "arm" not in words
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
    # a drawn model that diverges (a massless arm1): the run stops on divergence (on_divergence
    # stop, the default), so identify refuses it up front as its meta-train does (the run's step
    # cannot hold the model: physics/stability): one line naming --variants, exit 2, no run
    few = ["--iterations", "2", "--goals", "2", "--inits", "2"]
    code = exit_code(
        ["identify", str(told), "--out", str(tmp_path / "z"), *few, "--variants", "arm1.mass=0..0"]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("warp-critic: error: --variants"), err
    assert err.count("\n") == 1 and "holds from about arm1.mass=" in err, err
    assert not (tmp_path / "z").exists()
    # other draws than training's: recorded in the summary
    light = tmp_path / "light"
    argv = [str(told), "--out", str(light), "--iterations", "2", "--goals", "2", "--inits", "2"]
    assert main(["identify", *argv, "--variants", "arm2.mass=0.25..1:keep"]) == 0
    capsys.readouterr()
    assert json.loads((light / "identify.json").read_text())["variants"] == "arm2.mass=0.25..1:keep"
    assert "variants" not in json.loads((out / "identify.json").read_text())

    # what the identifier reads, update by update, for two models that differ in the second mass
    probe = load_tool("probe_identifier")
    two = ["--variant", "arm2.mass=0.5:keep", "--variant", "arm2.mass=4:keep"]
    assert probe.main([str(out), *two, "--goals", "2", "--inits", "2"]) == 0
    text = capsys.readouterr().out
    lines = [x.split() for x in text.splitlines() if x.strip().startswith("arm2.mass ")]
    e_m = 0.01  # the descriptor's mass epsilon: 1% of the nominal links' mean mass (1 kg)
    want = [f"{math.log((m + e_m) / (1 + e_m)):.3f}" for m in (0.5, 4.0)]
    assert [x[1] for x in lines] == want, text
    assert all(len(x) == 2 + 2 * 3 for x in lines)  # truth, then mean and ±std for 3 updates
    for bad, words in (
        ([str(told), *two], "no model identifier"),
        ([str(out), "--variant", "arm9.mass=1"], "arm9"),
        ([str(out), *two, "--inits", "0"], "--inits"),
    ):
        with pytest.raises(SystemExit) as e:
            probe.main(bad)
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert err.startswith("probe_identifier: error: ") and err.count("\n") == 1, err
        assert words in err, err


@pytest.mark.slow
def test_identify_with_one_seed_gives_one_result(tmp_path):
    """Two identifications of one run with one --seed agree loss for loss, whatever torch's global
    RNG holds (the identifier's initial weights come from the seed)."""
    from warp_critic.cli.main import main

    told = tmp_path / "told"
    assert main(variants_train_argv(told, "--critic-input", "pose-dynamics", iterations=1)) == 0
    losses = []
    for k in range(2):
        torch.manual_seed(100 + k)  # a different global RNG state before each call
        out = tmp_path / f"identified{k}"
        argv = [str(told), "--out", str(out), "--iterations", "2", "--goals", "2", "--inits", "1"]
        assert main(["identify", *argv, "--seed", "3"]) == 0
        rows = (out / "identify.jsonl").read_text().splitlines()
        losses.append([json.loads(x)["loss"] for x in rows])
    assert len(losses[0]) == 2 and losses[0] == losses[1]


def test_identified_critic_feeds_each_seed_its_own_identifier():
    """Batched seeds (worlds seed-major): each block of worlds is estimated by its own identifier,
    exactly as that identifier alone on those worlds."""
    from warp_critic.learning.critic import Critic
    from warp_critic.learning.critic_inputs import history_features
    from warp_critic.learning.identify import IdentifiedCritic, Identifier, identifier_inputs
    from warp_critic.learning.networks import Normalizer

    T, S, Wc, dof, K = 4, 2, 3, 2, 4
    gen = torch.Generator().manual_seed(2)
    norm = Normalizer(torch.zeros(dof), torch.ones(dof), 5.0, torch.ones(dof), dynamics_size=K)
    torch.manual_seed(1)
    idents = [Identifier(dof, K, hidden=8) for _ in range(S)]
    critic = IdentifiedCritic(Critic(dof, norm, hidden=16, inputs="pose-dynamics"), idents)
    q, qd = (
        torch.randn(T, S * Wc, dof, generator=gen),
        torch.randn(T + 1, S * Wc, dof, generator=gen),
    )
    tau = torch.randn(T, S * Wc, dof, generator=gen)
    history = history_features(qd, tau)
    d_hat = critic.estimate(q, qd[:T], history)
    for s, ident in enumerate(idents):
        sl = slice(s * Wc, (s + 1) * Wc)
        own = ident(identifier_inputs(q[:, sl], qd[:T, sl], history[:, sl]))
        assert torch.allclose(d_hat[sl], own)
    assert not torch.allclose(d_hat[:Wc], idents[1](identifier_inputs(q, qd[:T], history))[:Wc])
    with pytest.raises(ValueError, match="do not split"):
        critic.estimate(q[:, :5], qd[:T, :5], history[:, :5])


@pytest.mark.slow
def test_resuming_an_identified_run_trains_its_critic_on_the_estimates(tmp_path):
    """``meta-train --resume`` on ``warp-critic identify``'s output: the critic keeps training, fed its
    identifier's estimates as at meta-test (the iterations say so, and they differ from resuming
    the told run from the same state), and the identifier stays in the checkpoint, unchanged."""
    import shutil

    from warp_critic.cli.main import main

    told = tmp_path / "told"
    assert main(variants_train_argv(told, "--critic-input", "pose-dynamics", iterations=2)) == 0
    out = tmp_path / "identified"
    argv = [str(told), "--out", str(out), "--iterations", "2", "--goals", "2", "--inits", "2"]
    assert main(["identify", *argv]) == 0
    before = torch.load(out / "checkpoint.pt", weights_only=False)
    again = tmp_path / "told-again"
    shutil.copytree(told, again)
    for run in (out, again):
        (run / ".lock").unlink(missing_ok=True)
        resume = ["meta-train", REACHER, "--resume", "--out", str(run), "--iterations", "4"]
        assert main([*resume, "--device", "cpu"]) == 0
    after = torch.load(out / "checkpoint.pt", weights_only=False)
    assert after["iteration"] == 3
    assert after["identifier"] == before["identifier"]
    for k, v in before["identifier_state"].items():
        assert torch.equal(after["identifier_state"][k], v)
    assert any(
        not torch.equal(after["critic_state"][k], v) for k, v in before["critic_state"].items()
    )
    rows = [json.loads(x) for x in (out / "metrics.jsonl").read_text().splitlines()]
    assert [r.get("critic_fed") for r in rows] == [None, None, "identified", "identified"]
    told_rows = [json.loads(x) for x in (again / "metrics.jsonl").read_text().splitlines()]
    assert rows[:2] == told_rows[:2] and "critic_fed" not in told_rows[-1]
    assert rows[2]["task_loss"] != told_rows[2]["task_loss"]
