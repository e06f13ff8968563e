"""Library calls show their effects in their signature: configs come back as new objects, random
state is passed in, and nothing is printed."""

from __future__ import annotations

import copy
import random

import numpy as np
import pytest
import torch
from conftest import REACHER

from warp_critic.core.errors import FieldError
from warp_critic.evaluation.metatest import MetaTestConfig, meta_test, setup_meta_test
from warp_critic.methods.ours import TrainConfig, meta_train
from warp_critic.running.task import load_task_scene


def test_load_task_scene_returns_a_filled_copy_and_leaves_the_config_alone():
    cfg = TrainConfig(scene=REACHER, device="cpu")
    before = copy.deepcopy(cfg)
    filled, scene = load_task_scene(cfg)
    assert cfg == before
    assert filled is not cfg and filled.horizon == scene.defaults["horizon"]
    assert filled.goals == scene.defaults["goals"] and filled.out == "runs/reacher-meta"


def test_resume_leaves_the_callers_config_alone(finished_run, copy_of):
    run = copy_of(finished_run)
    cfg = TrainConfig(scene=REACHER, iterations=3, device="cpu", out=str(run), resume=True)
    before = copy.deepcopy(cfg)
    result = meta_train(cfg, progress=False, record=False, given={"iterations"})
    assert (
        cfg == before and cfg.horizon is None
    )  # the run's saved horizon (5) was used, not put here
    assert [r["iteration"] for r in result.metrics] == [0, 1, 2]


def test_meta_test_draws_from_its_own_generator_and_prints_nothing(finished_run, tmp_path, capsys):
    tc = MetaTestConfig(
        run_dir=str(finished_run), num_goals=2, inits=1, device="cpu", out=str(tmp_path / "m.json")
    )
    torch.manual_seed(123), np.random.seed(123), random.seed(123)
    states = np.random.get_state()[1].copy(), random.getstate()
    result = meta_test(tc)
    # numpy's and Python's global state untouched (not reseeded), the results independent of torch's
    assert np.array_equal(np.random.get_state()[1], states[0]) and random.getstate() == states[1]
    torch.manual_seed(999)
    assert meta_test(tc)["final_error_all"] == result["final_error_all"]
    assert capsys.readouterr().out == ""
    # the generator is an argument: the default is one seeded with tc.seed
    mine = setup_meta_test(tc, torch.Generator().manual_seed(tc.seed))
    assert mine.goals.tolist() == result["goals"]
    other = setup_meta_test(tc, torch.Generator().manual_seed(tc.seed + 1))
    assert other.goals.tolist() != result["goals"]
    lines: list[str] = []
    meta_test(tc, progress=lines.append)
    assert lines and lines[0].startswith("meta-test ours on reacher")


def test_available_memory_is_psutils_capped_by_the_cgroup(tmp_path, monkeypatch):
    from warp_critic.core import memory

    free = memory.psutil.virtual_memory().available
    limit, usage = tmp_path / "memory.max", tmp_path / "memory.current"
    monkeypatch.setattr(memory, "_CGROUP_FILES", ((str(limit), str(usage)),))
    limit.write_text("max\n")  # cgroup v2 without a limit
    assert abs(memory.available_memory() - free) < 2**30
    limit.write_text(f"{3 * 2**30}\n")
    usage.write_text(f"{2**30}\n")
    assert memory.available_memory() == min(2 * 2**30, memory.psutil.virtual_memory().available)
    # the one check: 80% of what is available, naming the field
    with pytest.raises(
        FieldError, match="inits: 4 worlds need about 1.8 GiB, more than 80% of the 2.0 GiB"
    ):
        memory.check_fits("inits", "4 worlds", 2**30 + 2**29 + 2**28)
    memory.check_fits("inits", "4 worlds", 2**30)
