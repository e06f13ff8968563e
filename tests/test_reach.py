"""The open-loop reachability floor (:mod:`warp_critic.reproduce.experiments.reach`): a world whose rollout goes
non-finite backtracks without touching the others, and the best over learning rates is the
per-world minimum."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from warp_critic.learning import rollout as rollout_module
from warp_critic.physics.scene import Variant
from warp_critic.reproduce.experiments import reach

# both tests run the open-loop floor over a finished run (about a second each): not in the fast loop
pytestmark = pytest.mark.slow

GOALS = torch.tensor([[0.5, -1.0], [-0.5, 1.0], [0.3, 0.2]])


def test_a_diverging_world_backtracks_and_leaves_the_others_bitwise(finished_run, monkeypatch):
    run = str(finished_run)
    ref = reach.open_loop_floor(run, [Variant()], GOALS, iterations=5, lr=0.1)
    real = rollout_module.rollout
    calls, backtracked = [], []

    def poisoned(*args, **kwargs):  # world 0's final state non-finite at the third iteration
        traj = real(*args, **kwargs)
        calls.append(1)
        if len(calls) == 3:
            q = traj.q.clone()
            q[-1, 0] = float("nan")
            traj = rollout_module.Trajectory(q, traj.qd, traj.tau)
        return traj

    real_backtrack = reach._backtrack

    def spy(opt, u, best_u, bad):
        backtracked.append(bad.nonzero().flatten().tolist())
        real_backtrack(opt, u, best_u, bad)
        assert torch.equal(u.detach()[:, bad], 0.5 * best_u[:, bad])

    monkeypatch.setattr(rollout_module, "rollout", poisoned)
    monkeypatch.setattr(reach, "_backtrack", spy)
    out = reach.open_loop_floor(run, [Variant()], GOALS, iterations=5, lr=0.1)
    assert backtracked == [[0]]
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(out[0, 1:], ref[0, 1:])  # the worlds are independent
    assert out[0, 0] <= float((GOALS[0] ** 2).sum()) + 1e-6  # at most the start's error


def test_the_best_floor_is_the_per_world_minimum_over_learning_rates(finished_run):
    run = str(finished_run)
    lrs = [0.1, 0.01]
    each = [reach.open_loop_floor(run, [Variant()], GOALS, iterations=3, lr=lr) for lr in lrs]
    best = reach.best_open_loop_floor(run, [Variant()], GOALS, iterations=3, lrs=lrs)
    np.testing.assert_array_equal(best, np.minimum(*each))
    assert not np.array_equal(each[0], each[1])  # the rates do differ
