"""tools/robot_zoo.py --floor: the open-loop floor on a run's own meta-test goals, read back from
the runs a ``--train`` pass left (here copies of the tiny reacher run)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch
from helpers import load_tool


@pytest.mark.slow
def test_floor_reads_the_newest_runs_and_optimises_on_their_meta_test_goals(
    finished_run, tmp_path, capsys
):
    from warp_critic.evaluation.metatest import MetaTestConfig, meta_test
    from warp_critic.physics.scene import Variant
    from warp_critic.reproduce.experiments.reach import best_open_loop_floor

    zoo = load_tool("robot_zoo")
    runs = tmp_path / "runs"
    for name in ("kuka-20261206-000000", "reacher-20261206-000000", "reacher-20261206-000001"):
        shutil.copytree(finished_run, runs / name)
    newest = runs / "reacher-20261206-000001"
    for run in (runs / "kuka-20261206-000000", newest):  # the older reacher run: never meta-tested
        cfg = MetaTestConfig(run_dir=str(run), num_goals=2, inits=1, goal_std=0.1, device="cpu",
                             out=str(run / "metatest-zoo.json"))  # fmt: skip
        meta_test(cfg)
    assert zoo.main(["--floor", "--floor-iterations", "3", "--runs-dir", str(runs)]) == 0
    rows = capsys.readouterr().out.splitlines()
    assert rows[1].split()[-1] == "floor" and rows[3].split()[0] == "reacher", rows
    result = json.loads((newest / "metatest-zoo.json").read_text())
    cells = rows[3].split()
    assert float(cells[4]) == float(f"{result['mse_mean_before']:.4g}")
    assert float(cells[5]) == float(f"{result['mse_mean']:.4g}")
    goals = torch.as_tensor(result["goals"], dtype=torch.float32)
    best = best_open_loop_floor(str(newest), [Variant()], goals, iterations=3, lrs=[0.1, 0.03])
    assert np.isfinite(best).all()
    assert float(cells[6]) == float(f"{best.mean() / goals.shape[1]:.4g}")


def test_floor_without_a_meta_tested_run_is_one_line(tmp_path, capsys):
    assert load_tool("robot_zoo").main(["--floor", "--runs-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("robot_zoo: error: --runs-dir: ") and "\n" not in err
    assert "no meta-tested run of kuka" in err
