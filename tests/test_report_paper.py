"""The report's computed readings: steps to error levels, solved seeds, verdicts (synthetic curves)."""

from __future__ import annotations

import json
import math

import pytest

from warp_critic.reproduce.experiments.settings import METHOD_LABELS
from warp_critic.reproduce.report import paper as rp


def _result(curves: dict[str, list[float]], per: int = 100, seconds: float = 2.0) -> dict:
    return {
        "env_steps_per_iteration": per,
        "seeds": {
            s: {"task_loss": c, "seconds_each": [seconds] * len(c)} for s, c in curves.items()
        },
    }


class _Rec:
    def __init__(self, result):
        self.data = {"result": result}


def test_steps_to_levels_stays_below_and_never():
    res = _result({"0": [1.0, 0.2, 0.05, 0.02], "1": [1.0, 0.5, 0.4, 0.35]})
    t = rp.steps_to_levels(res, window=1)
    assert t[0.3]["steps"] == [200] and t[0.3]["never"] == 1
    assert t[0.03]["steps"] == [400] and t[0.03]["seconds"] == [8.0]
    assert t[0.1]["never"] == 1 and t[0.1]["seeds"] == 2
    # the running mean over 2 iterations: 1, 0.6, 0.125, 0.035
    t2 = rp.steps_to_levels(res, window=2)
    assert t2[0.3]["steps"] == [300] and t2[0.03]["never"] == 2
    # a curve cut at a budget of 300 steps: seed 0 has not settled below 0.03 by then
    assert rp.steps_to_levels(res, budget=300, window=1)[0.03]["never"] == 2


def test_solved_seeds_use_the_tail_of_the_curve():
    res = _result({"0": [1.0] * 18 + [0.05, 0.05], "1": [0.05] * 18 + [1.0, 1.0]})
    assert rp.solved_seeds(res, "reacher") == [True, False]


def test_solved_cell_pools_only_solved_seeds():
    cell = {"mse_per_seed": [0.1, 0.5, 0.3], "mse_std_per_seed": [0.0, 0.0, 0.0]}
    mean, std = rp.solved_cell(cell, [True, False, True])
    assert mean == pytest.approx(0.2) and std == pytest.approx(0.1)
    assert rp.solved_cell(cell, [False, False, False]) is None
    assert math.isnan(rp.solved_cell({"mse_per_seed": [0.1]}, [True])[1])


def test_sample_efficiency_verdict_is_computed():
    fast = _Rec(_result({"0": [1.0] + [0.02] * 40, "1": [1.0] + [0.02] * 40}))
    slow = _Rec(_result({"0": [1.0, 0.5, 0.2] + [0.02] * 40, "1": [1.0, 0.5, 0.2] + [0.02] * 40}))

    def levels(got: dict) -> dict:
        return {m: rp.steps_to_levels(r.data["result"]) for m, r in got.items()}

    assert rp.sample_efficiency_verdict(levels({"ours": fast, "ddpg": slow}))[0] == "met"
    assert rp.sample_efficiency_verdict(levels({"ours": slow, "ddpg": fast}))[0] == "not met"
    flat = _Rec(_result({"0": [1.0, 1.0]}))
    assert rp.sample_efficiency_verdict(levels({"ours": flat, "ddpg": flat}))[0] == "not comparable"


def test_steps_lines_render_the_levels_as_results_json_keys_them():
    fast = _Rec(_result({"0": [1.0] + [0.02] * 40, "1": [1.0] + [0.02] * 40}))
    flat = _Rec(_result({"0": [1.0, 1.0], "1": [1.0, 1.0]}))
    levels = {
        m: {str(k): v for k, v in rp.steps_to_levels(r.data["result"]).items()}
        for m, r in (("ours", fast), ("ddpg", flat))
    }
    lines = rp.steps_lines(json.loads(json.dumps(levels)))
    assert len(lines) == 2 + 2 * len(rp.LEVELS)
    ours, ddpg = METHOD_LABELS["ours"], METHOD_LABELS["ddpg"]
    assert lines[2].startswith(f"| {ours} | 0.3 | 400 [400, 400] | 0 of 2 |")
    assert lines[-1] == f"| {ddpg} | 0.03 | — | 2 of 2 | — |"


def test_error_at_budget_reads_the_curve_at_equal_steps():
    res = _result({"0": [1.0, 0.5, 0.2, 0.1]}, per=100)
    assert rp.error_at_budget(res, 250, window=1) == [0.5]
    assert rp.error_at_budget(res, 50, window=1) == [1.0]
    # the steps rule's window: the running mean over the iterations up to the budget
    assert rp.error_at_budget(res, 350, window=2) == [pytest.approx(0.35)]
    assert rp.error_at_budget(res, 250) == [0.75]  # fewer iterations than WINDOW: all of them


def test_meta_critic_aux_alive_from_the_record_else_the_run_directory(tmp_path):
    import json
    from types import SimpleNamespace

    from warp_critic.reproduce.report.training import (
        aux_alive_bases_of,
        aux_alive_of,
        aux_alive_sentence,
    )

    (tmp_path / "run" / "seed1").mkdir(parents=True)
    rows = [{"aux_loss": 0.69, "meta_improvement": m} for m in [1e-3, 1e-4, 0.0, 0.0]]
    (tmp_path / "run" / "seed1" / "metrics.jsonl").write_text(
        "".join(json.dumps(r) + "\n" for r in rows)
    )
    seeds = {
        "0": {"run_dir": "run/seed0", "aux_alive": 1.0},  # recorded by the stage
        "1": {"run_dir": "run/seed1"},  # read from its metrics
        "2": {"run_dir": "run/seed2"},  # neither: not recorded
    }
    rec = SimpleNamespace(dir=tmp_path, data={"result": {"seeds": seeds}})
    alive = aux_alive_of(rec)
    assert alive == [1.0, 0.0, None]
    line = aux_alive_sentence(alive)
    assert "100%, 0%, not recorded" in line and "In 1 of 2 recorded seeds" in line
    # the sentence names what the share was judged by: these metrics have no aux_grad_ratio
    bases = aux_alive_bases_of(rec)
    assert bases == [None, "meta_improvement != 0", None]
    assert "judged by meta_improvement != 0" in aux_alive_sentence(alive, bases)
    assert "aux_grad_ratio >= 1e-06" not in aux_alive_sentence(alive, bases)
    (tmp_path / "run" / "seed2").mkdir()
    ratio = [{"aux_loss": 0.69, "meta_improvement": 0.0, "aux_grad_ratio": 0.1}] * 4
    (tmp_path / "run" / "seed2" / "metrics.jsonl").write_text(
        "".join(json.dumps(r) + "\n" for r in ratio)
    )
    assert aux_alive_bases_of(rec)[2] == "aux_grad_ratio >= 1e-06"
    assert aux_alive_of(rec)[2] == 1.0
    assert "stayed alive in every recorded seed" in aux_alive_sentence([0.9, 1.0])
    assert "not recorded for these seeds" in aux_alive_sentence([None, None])
