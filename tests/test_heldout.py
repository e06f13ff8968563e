"""The held-out stages and verdicts (issue 54 items 3 and 5): three goal seeds that chose nothing,
Tables 1-3 and the maps pooled over them with crossed-bootstrap intervals, and ours meta-trained at
the baselines' environment steps."""

import json
import lzma
from pathlib import Path

import numpy as np
import pytest

from warp_critic.evaluation import seed_uses
from warp_critic.reproduce.experiments.heldout import EQUAL_STEPS_ROW
from warp_critic.reproduce.experiments.plan import ReproduceConfig, needed, plan
from warp_critic.reproduce.experiments.settings import (
    BASELINE_ITERATIONS,
    EQUAL_STEP_ITERATIONS,
)
from warp_critic.reproduce.report import heldout as H
from warp_critic.reproduce.report.rules import COMPARE_SHARE

ROOT = Path(__file__).resolve().parents[1]


def _plan(**kw):
    rc = ReproduceConfig(**kw)
    s = rc.validate()
    return rc, plan(s, rc.beyond, rc.extra)


def test_every_held_out_seed_chose_nothing_and_draws_no_goal_twice():
    seeds = seed_uses.HELD_OUT_SEEDS
    assert len(seeds) >= 3
    assert all(seed_uses.chose(s) == [] for s in seeds)
    # Table 1 draws column c from seed + c (10 columns): the ranges of the seeds may not overlap,
    # nor reach the seed that scored seed 1's tables or the one that chose the budgets
    ranges = [set(range(s, s + 10)) for s in (*seeds, 1, seed_uses.CHOOSE_BUDGET_SEED)]
    assert sum(len(r) for r in ranges) == len(set().union(*ranges))


@pytest.mark.slow  # builds the full plan (loads every scene): seconds
def test_plan_scores_tables_and_maps_on_every_held_out_seed_with_the_extra_rows():
    _, p = _plan(baselines=["ddpg", "meta-critic", "td3"])
    for group in ("tables", "maps"):
        seeds = sorted(
            st.settings["seed"]
            for st in p.values()
            if st.kind == group and "heldout" in st.name and st.outputs.adds_to is None
        )
        assert seeds == list(seed_uses.HELD_OUT_SEEDS), group
    assert p["tables-heldout-1010"].settings["seed"] == 1010
    assert p["td3-tables-heldout-1020"].outputs.adds_to == "tables-heldout-1020"
    assert p["maps-heldout-1010"].settings["reach_iterations"] == 0  # the maps stage's floors
    # the first seed's tables stage is the one that existed: the published stage's settings and
    # inputs (its hash also covers its inputs' hashes, which a change of ``TUNED`` renews)
    (d,) = (ROOT / "docs/paper/stages").glob("tables-heldout-??????????")
    published = json.loads(lzma.open(d / "stage.json.xz").read())
    assert p["tables-heldout"].settings == published["settings"]
    assert sorted(p["tables-heldout"].depends) == sorted(published["depends"])


@pytest.mark.slow  # builds the full plan (loads every scene): seconds
def test_the_held_out_group_runs_every_seed_and_the_equal_step_rows():
    rc, p = _plan(only=["tables-heldout"], baselines=["ddpg", "meta-critic", "td3"])
    first, second = needed(rc, p)
    assert set(second) == {
        "tables-heldout",
        "tables-heldout-1010",
        "tables-heldout-1020",
        *(
            f"{by}-tables-heldout{s}"
            for by in ("td3", "equal-steps")
            for s in ("", "-1010", "-1020")
        ),
    }
    assert "metatrain-kuka-ours-equal-steps" in first


@pytest.mark.slow  # builds the full plan (loads every scene): seconds
def test_equal_step_iterations_match_the_baselines_environment_steps():
    """375 of ours' iterations are the baselines' 1500: read from the published stage records."""

    def result(prefix):
        d = next((ROOT / "docs/paper/stages").glob(prefix + "-*"))
        return json.loads(lzma.open(d / "stage.json.xz").read())["result"]

    ours, ddpg = result("metatrain-kuka-ours"), result("metatrain-kuka-ddpg")
    baseline_steps = ddpg["env_steps_per_iteration"] * BASELINE_ITERATIONS["kuka"]
    assert ddpg["iterations"] == BASELINE_ITERATIONS["kuka"]
    assert ours["env_steps_per_iteration"] * EQUAL_STEP_ITERATIONS["kuka"] == baseline_steps
    _, p = _plan()
    st = p["metatrain-kuka-ours-equal-steps"]
    assert st.settings["values"] == {
        **p["metatrain-kuka-ours"].settings["values"],
        "iterations": 375,
    }
    assert p["equal-steps-tables-heldout"].outputs.labels == {st.name: EQUAL_STEPS_ROW}


def test_crossed_interval_brackets_the_mean_and_grows_with_the_spread():
    rng = np.random.default_rng(3)
    narrow = 0.1 + 0.001 * rng.standard_normal((5, 3))
    wide = 0.1 + 0.05 * rng.standard_normal((5, 3))
    m, lo, hi = H.crossed_interval(narrow)
    assert lo <= m <= hi
    _, lo2, hi2 = H.crossed_interval(wide)
    assert hi2 - lo2 > 10 * (hi - lo)
    assert H.crossed_interval(np.full((5, 3), 0.2)) == pytest.approx((0.2, 0.2, 0.2))
    assert H.crossed_interval(np.array([[0.1, np.inf]]))[2] == np.inf
    assert H.crossed_interval(wide) == H.crossed_interval(wide)  # a fixed generator


def _pooled(ours_wins: int, cols: int = 10) -> dict:
    def cells(values):
        return [{"mean": v, "lo": v - 0.01, "hi": v + 0.01} for v in values]

    ours = [0.1 if ci < ours_wins else 0.5 for ci in range(cols)]
    t = {
        "values": [0.1 * (i + 1) for i in range(cols)],
        "untrained": [0.3] * cols,
        "rows": {
            "ours": cells(ours),
            "ddpg": cells([0.3] * cols),
            "meta-critic": cells([0.4] * cols),
            EQUAL_STEPS_ROW: cells([0.35] * cols),
        },
    }
    return {"table1": t}


def test_table_claims_are_comparative_at_the_stated_share():
    need = int(np.ceil(COMPARE_SHARE * 10))
    met = H.judge_tables(_pooled(need), [1000, 1010, 1020])
    not_met = H.judge_tables(_pooled(need - 1), [1000, 1010, 1020])
    assert met[0]["verdict"] == "met" and not_met[0]["verdict"] == "not met"
    assert "1000, 1010, 1020" in met[0]["claim"]
    # ours at the baselines' environment steps is judged as its own row: 0.35 is between them
    equal = next(c for c in met if "equal environment steps" in c["claim"])
    assert equal["verdict"] == "not met" and "0 of 10" in equal["ours"]


def test_pool_tables_means_over_training_and_goal_seeds():
    def result(offset):
        cells = []
        for table in ("table1", "table2", "table3"):
            for m, base in (("ours", 0.1), ("ddpg", 0.3)):
                cells.append(
                    {
                        "table": table,
                        "column": 0,
                        "method": m,
                        "mse_per_seed": [base + offset, base + offset + 0.02],
                        "untrained_mse_mean": 0.5,
                    }
                )
        return {"columns": {t: [1.0] for t in ("table1", "table2", "table3")}, "cells": cells}

    pooled = H.pool_tables([result(0.0), result(0.04)], {"ddpg": [True, False]})
    ours = pooled["table1"]["rows"]["ours"][0]
    assert ours["mean"] == pytest.approx(0.13)
    assert ours["lo"] >= 0.1 - 1e-12 and ours["hi"] <= 0.16 + 1e-12
    solved = pooled["table1"]["rows"]["ddpg:solved"][0]
    assert solved["mean"] == pytest.approx(0.32)  # training seed 0 only, over both goal seeds


def test_pool_maps_averages_cells_over_goal_seeds_with_solved_rows():
    def result(offset):
        def cells(base):
            return [
                {
                    "mse_mean": base + offset + 0.01,
                    "mse_per_seed": [base + offset, base + offset + 0.02],
                }
            ] * 4

        return {
            "goals": {
                m: {"mse": [base + offset] * 9, "mse_per_seed": [base + offset, base + offset]}
                for m, base in (("ours", 0.01), ("ddpg", 0.3))
            },
            "mass": {"ours": cells(0.01), "ddpg": cells(0.3)},
            "length": {"ours": cells(0.01), "ddpg": cells(0.3)},
        }

    pooled = H.pool_maps([result(0.0), result(0.02)], {"ddpg": [False, True]})
    assert pooled["goals"]["ours"] == pytest.approx([0.02] * 9)
    assert pooled["goals_fraction_below_0.05"] == {"ours": 1.0, "ddpg": 0.0}
    assert pooled["mass"]["ddpg"] == pytest.approx([0.32] * 4)
    assert pooled["mass"]["ddpg:solved"] == pytest.approx([0.33] * 4)  # training seed 1 only
    grid = pooled["grid_mean"]["mass"]["ours"]
    assert grid["mean"] == pytest.approx(0.03) and grid["lo"] <= grid["mean"] <= grid["hi"]
    claims, verdicts = H.judge_maps(pooled, [1000, 1010])
    assert [c["verdict"] for c in claims] == ["met", "met", "met"]  # ours 0.02 on every goal
    assert verdicts["mass"]["below_all"] == 4 and "seeds that solved" in claims[1]["reason"]


@pytest.mark.parametrize(
    "value, words",
    [
        ("[1000,1001]", "draw the same Table 1 goals"),
        ("[2000]", "chose a setting: it cannot be held out"),
        ("[1]", "chose a setting"),
        ("[]", "one or more goal seeds"),
        ("[1000.5]", "heldout.seeds"),
    ],
)
def test_a_held_out_seed_that_chose_or_overlaps_is_refused(value, words):
    from warp_critic.core.errors import FieldError

    with pytest.raises(FieldError, match="set") as e:
        ReproduceConfig(quick=True, overrides=[f"heldout.seeds={value}"]).validate()
    assert words in str(e.value) and "\n" not in str(e.value)
    bad_iters = ["heldout.equal_step_iterations.kuka=0"]
    with pytest.raises(FieldError, match="equal_step_iterations"):
        ReproduceConfig(quick=True, overrides=bad_iters).validate()
