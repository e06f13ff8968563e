"""Each method's own meta-test budget as reproduce stages (warp_critic/reproduce/experiments/budget.py,
warp_critic/reproduce/report/budget.py): their names and plan, the existing stages' hashes
unchanged, the budget a reporting stage reads, the report's numbers and verdicts, bad ``--set``
values, and one real ``--quick`` run of just these stages through the CLI."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from warp_critic.cli.main import main as cli_main
from warp_critic.core.errors import FieldError, UserError
from warp_critic.reproduce.engine.stage import Stage
from warp_critic.reproduce.engine.stages import STAGE_KIND, StageRecord
from warp_critic.reproduce.experiments import budget as eb
from warp_critic.reproduce.experiments.naming import BUDGET, Outputs, stage_name
from warp_critic.reproduce.experiments.plan import ReproduceConfig, needed, plan
from warp_critic.reproduce.report import budget as rb

EXTRA = ["ddpg", "meta-critic", "td3"]


def test_the_budget_stages_are_named_by_stage_name():
    assert stage_name(BUDGET, "kuka", "td3") == "budget-kuka-td3"
    assert stage_name("tables", by="td3", heldout=True, budget=True) == "budget-td3-tables-heldout"
    assert (
        stage_name("maps", by="ours", heldout=1010, budget=True) == "budget-ours-maps-heldout-1010"
    )
    assert eb.BUDGET_GROUPS == ("budget", "budget-tables-heldout", "budget-maps-heldout")
    with pytest.raises(ValueError, match="names a robot and a method"):
        stage_name(BUDGET, "kuka")


@pytest.fixture(scope="module")
def plans():
    rc = ReproduceConfig(quick=True, beyond=True, baselines=EXTRA)
    settings = rc.validate()
    return settings, plan(settings, True, rc.extra), plan(settings, True, rc.extra, budget=True)


def test_the_budget_stages_are_added_and_no_other_stage_changes(plans):
    settings, without, with_budget = plans
    assert {n: st.dir_name for n, st in without.items()} == {
        n: with_budget[n].dir_name for n in without
    }
    added = set(with_budget) - set(without)
    methods = ("ours", *EXTRA)
    seeds = settings["heldout"]["seeds"]
    want = {stage_name(BUDGET, scene, m) for scene in ("reacher", "kuka") for m in methods}
    want |= {
        stage_name(g, by=m, heldout=s, budget=True)
        for g in ("tables", "maps")
        for m in methods
        for s in seeds
    }
    assert added == want
    td3 = with_budget[stage_name("tables", by="td3", heldout=seeds[0], budget=True)]
    # TD3's rows read ours' and TD3's meta-training and choice, and the earlier baselines' choices
    # (where one chose TD3's number of steps, ours' row at it is that stage's), no other stage
    assert set(td3.depends) == {
        "metatrain-kuka-ours",
        "metatrain-kuka-td3",
        "budget-kuka-ours",
        "budget-kuka-td3",
        "budget-kuka-ddpg",
        "budget-kuka-meta-critic",
    }
    # the first baseline's reads no other baseline's: its hash is the one before rows were shared
    ddpg = with_budget[stage_name("maps", by="ddpg", heldout=seeds[0], budget=True)]
    assert list(ddpg.depends) == [
        "metatrain-reacher-ours",
        "metatrain-reacher-ddpg",
        "budget-reacher-ours",
        "budget-reacher-ddpg",
    ]
    assert td3.settings == with_budget[stage_name("tables", heldout=seeds[0])].settings
    assert td3.outputs.rows == ("td3", "ours-at-td3") and td3.outputs.budget_of == "td3"
    choice = with_budget["budget-kuka-td3"]
    assert choice.kind == BUDGET and set(choice.depends) == {"metatrain-kuka-td3"}


def test_adding_td3_reruns_no_other_methods_budget_stage(plans):
    _, _, with_td3 = plans
    rc = ReproduceConfig(quick=True, beyond=True)
    paper = plan(rc.validate(), True, rc.extra, budget=True)
    ours = [n for n in paper if n.startswith("budget-") and "td3" not in n]
    assert ours and all(paper[n].dir_name == with_td3[n].dir_name for n in ours)


def test_the_budget_groups_run_with_beyond_or_when_named():
    assert not ReproduceConfig(quick=True).plans_budget
    assert ReproduceConfig(quick=True, beyond=True).plans_budget
    rc = ReproduceConfig(quick=True, only=["budget-tables-heldout"])
    assert rc.plans_budget and not rc.plans_beyond
    first, second = needed(rc, plan(rc.validate(), budget=True))
    assert second == ["budget-ours-tables-heldout", "budget-ddpg-tables-heldout",
                      "budget-meta-critic-tables-heldout"]  # fmt: skip
    assert "budget-kuka-ddpg" in first and "metatrain-kuka-ddpg" in first
    assert not any("reacher" in n for n in first)
    rc = ReproduceConfig(quick=True, only=["budget"])
    first, second = needed(rc, plan(rc.validate(), budget=True))
    assert sorted(second) == sorted(f"budget-{s}-{m}" for s in ("reacher", "kuka")
                                    for m in ("ours", "ddpg", "meta-critic"))  # fmt: skip


def _write(out: Path, dir_name: str, result: dict) -> None:
    (out / dir_name).mkdir(parents=True)
    record = {"kind": STAGE_KIND, "seconds": 1.0, "result": result}
    (out / dir_name / "stage.json").write_text(json.dumps(record))


def test_a_reporting_stage_reads_the_chosen_budgets(tmp_path):
    runs = {"seeds": {"1": {"run_dir": "run/seed1"}, "0": {"run_dir": "run/seed0"}}}
    _write(tmp_path, "metatrain-kuka-ours-a", runs)
    _write(tmp_path, "metatrain-kuka-td3-b", runs)
    # ours is best at 3 steps x1; at TD3's 30 steps its best step size is x0.1
    curve = {"0.1": {"3": 0.5, "30": 0.02}, "1.0": {"3": 0.01, "30": 0.4}}
    _write(tmp_path, "budget-kuka-ours-c", {"curve": curve, "chosen": {"scale": 1.0, "steps": 3}})
    _write(tmp_path, "budget-kuka-td3-d", {"chosen": {"scale": 3.16, "steps": 30}})
    dep = {
        "metatrain-kuka-ours": "metatrain-kuka-ours-a",
        "metatrain-kuka-td3": "metatrain-kuka-td3-b",
        "budget-kuka-ours": "budget-kuka-ours-c",
        "budget-kuka-td3": "budget-kuka-td3-d",
    }
    o = Outputs(scene="kuka", rows=("td3", "ours-at-td3"), budget_of="td3")
    st = Stage("budget-td3-tables-heldout", "tables", {}, dep, "h", o)
    kw = eb.reporting_kwargs(st, tmp_path)
    assert kw["steps"] == 30 and kw["only"] == ["td3", "ours-at-td3"]
    assert kw["scales"] == {"td3": 3.16, "ours-at-td3": 0.1}
    seeds = ["metatrain-kuka-ours-a/run/seed0", "metatrain-kuka-ours-a/run/seed1"]
    assert kw["runs"]["ours"] == kw["runs"]["ours-at-td3"] == seeds
    assert kw["runs"]["td3"][0] == "metatrain-kuka-td3-b/run/seed0"
    ours = Stage("budget-ours-tables-heldout", "tables", {}, dep, "h", Outputs(scene="kuka",
                 rows=("ours",), budget_of="ours"))  # fmt: skip
    assert eb.reporting_kwargs(ours, tmp_path)["scales"] == {"ours": 1.0}
    (tmp_path / "budget-kuka-td3-d" / "stage.json").unlink()
    with pytest.raises(UserError, match="the stage budget-kuka-td3 this one needs is not complete"):
        eb.reporting_kwargs(st, tmp_path)


def _choices(tmp_path: Path, steps: dict[str, int]) -> dict[str, str]:
    """Complete meta-trainings and choices on the KUKA for each method of ``steps`` (method -> its
    chosen number of steps, at x1; ours' curve best at x0.1 from 30 steps on); their dependencies."""
    runs = {"seeds": {"0": {"run_dir": "run/seed0"}}}
    curve = {"0.1": {"3": 0.5, "30": 0.02, "300": 0.01}, "1.0": {"3": 0.01, "30": 0.4, "300": 1.0}}
    dep = {}
    for m, n in steps.items():
        _write(tmp_path, f"metatrain-kuka-{m}-a", runs)
        result = {"chosen": {"scale": 1.0, "steps": n}, **({"curve": curve} if m == "ours" else {})}
        _write(tmp_path, f"budget-kuka-{m}-b", result)
        dep |= {
            f"metatrain-kuka-{m}": f"metatrain-kuka-{m}-a",
            f"budget-kuka-{m}": f"budget-kuka-{m}-b",
        }
    return dep


@pytest.mark.parametrize(
    "steps,only,shared",
    [
        # DDPG chose Meta-Critic's 300 steps: ours at 300 steps is DDPG's stage's row
        ({"ours": 3, "ddpg": 300, "meta-critic": 300}, ["meta-critic"],
         {"ours-at-meta-critic": ["ddpg", "ours-at-ddpg"]}),
        # ours' own 3 steps: ours' own stage's row (ours' best step size at 3 is its chosen x1)
        ({"ours": 3, "ddpg": 300, "meta-critic": 3}, ["meta-critic"],
         {"ours-at-meta-critic": ["ours", "ours"]}),
        # a number of steps no earlier stage runs ours at: this stage's own row
        ({"ours": 3, "ddpg": 300, "meta-critic": 30}, ["meta-critic", "ours-at-meta-critic"], {}),
    ],
)  # fmt: skip
def test_ours_at_a_number_of_steps_is_meta_tested_once(tmp_path, steps, only, shared):
    dep = _choices(tmp_path, steps)
    o = Outputs(scene="kuka", rows=("meta-critic", "ours-at-meta-critic"), budget_of="meta-critic")
    st = Stage("budget-meta-critic-maps-heldout", "maps", {}, dep, "h", o)
    kw = eb.reporting_kwargs(st, tmp_path)
    assert kw["only"] == only and kw["shared"] == shared and kw["steps"] == steps["meta-critic"]
    # the first baseline's stage reads no other baseline's choice: it runs both its rows
    first = {k: v for k, v in dep.items() if "meta-critic" not in k}
    o = Outputs(scene="kuka", rows=("ddpg", "ours-at-ddpg"), budget_of="ddpg")
    kw = eb.reporting_kwargs(Stage("budget-ddpg-maps-heldout", "maps", {}, first, "h", o), tmp_path)
    assert kw["only"] == ["ddpg", "ours-at-ddpg"] and kw["shared"] == {}


def test_shared_rows_are_filled_in_from_the_stage_that_ran_them():
    def table(rows):
        return [{"table": "table1", "column": 0, "method": r, "v": v} for r, v in rows.items()]

    per = {  # TD3's row is Meta-Critic's, which is DDPG's: filled in whatever the order
        "td3": {"cells": table({"td3": 3.0}), "alpha_scales": {"td3": 1.0},
                "shared_rows": {"ours-at-td3": ["meta-critic", "ours-at-meta-critic"]}},
        "meta-critic": {"cells": table({"meta-critic": 2.0}), "alpha_scales": {"meta-critic": 1.0},
                        "shared_rows": {"ours-at-meta-critic": ["ddpg", "ours-at-ddpg"]}},
        "ddpg": {"cells": table({"ddpg": 1.0, "ours-at-ddpg": 0.5}),
                 "alpha_scales": {"ddpg": 1.0, "ours-at-ddpg": 0.1}},
    }  # fmt: skip
    got = eb.with_shared_rows(per)
    assert list(got) == ["td3", "meta-critic", "ddpg"] and got["ddpg"] == per["ddpg"]
    assert [(c["method"], c["v"]) for c in got["td3"]["cells"]] == [
        ("td3", 3.0),
        ("ours-at-td3", 0.5),
    ]
    assert got["td3"]["alpha_scales"] == {"td3": 1.0, "ours-at-td3": 0.1}
    assert per["td3"]["alpha_scales"] == {"td3": 1.0}  # the stage results themselves unchanged
    assert list(eb.with_shared_rows({m: per[m] for m in ("td3", "meta-critic")})) == []
    maps = {
        "ours": {"goals": {"ours": "G"}, "mass": {"ours": "M"}, "length": {"ours": "L"},
                 "alpha_scales": {"ours": 1.0}},
        "ddpg": {"goals": {"ddpg": "g"}, "mass": {"ddpg": "m"}, "length": {"ddpg": "l"},
                 "alpha_scales": {"ddpg": 3.16}, "shared_rows": {"ours-at-ddpg": ["ours", "ours"]}},
    }  # fmt: skip
    d = eb.with_shared_rows(maps)["ddpg"]
    assert d["goals"] == {"ddpg": "g", "ours-at-ddpg": "G"} and d["length"]["ours-at-ddpg"] == "L"
    assert d["alpha_scales"]["ours-at-ddpg"] == 1.0


# ------------------------------------------------------------------------------------------------
# the report on synthetic records
# ------------------------------------------------------------------------------------------------


def _rec(name: str, result: dict) -> StageRecord:
    return StageRecord("x", name, Path(f"/r/{name}-0"), {"result": result, "seconds": 1.0})


def _choice(m: str, scale: float, steps: int) -> dict:
    curve = {str(s): {"3": 0.2 / s, "30": 0.1 if s == scale else 0.3} for s in (0.1, 1.0)}
    curve[str(scale)][str(steps)] = 0.05
    return {"curve": curve, "chosen": {"scale": scale, "steps": steps, "mse_train": 0.05},
            "untrained": 0.3, "method": m}  # fmt: skip


def _tables(rows: dict[str, float], steps: int, scales: dict) -> dict:
    """One seed's held-out tables result: every row's per-seed MSE ``v`` in every column."""
    columns = {"table1": [0.1, 0.5], "table2": [3.0], "table3": [0.0]}
    cells = [
        {"table": t, "column": ci, "method": row, "mse_per_seed": [v, v * 1.1],
         "untrained_mse_mean": 0.3}
        for t, vs in columns.items() for ci in range(len(vs)) for row, v in rows.items()
    ]  # fmt: skip
    return {"columns": columns, "cells": cells, "policy_updates": steps, "alpha_scales": scales}


def _maps(rows: dict[str, float], steps: int, scales: dict) -> dict:
    cell = lambda v: {"mse_per_seed": [v, v], "mse_mean": v}  # noqa: E731
    return {
        "goals": {r: {"mse": [[v, v], [v, v]], "mse_per_seed": [v, v]} for r, v in rows.items()},
        "mass": {r: [cell(v)] for r, v in rows.items()},
        "length": {r: [cell(v), cell(v)] for r, v in rows.items()},
        "policy_updates": steps,
        "alpha_scales": scales,
    }


def _records(at_ddpg: float) -> dict:
    """Ours (0.01 at 3 steps), DDPG (0.1 at 30 steps) and ours at DDPG's 30 steps (``at_ddpg``),
    on two held-out seeds; TD3's choice only (no reporting stage: it joins no comparison)."""
    recs = {
        stage_name(BUDGET, "kuka", "ours"): _rec("budget-kuka-ours", _choice("ours", 1.0, 3)),
        stage_name(BUDGET, "kuka", "ddpg"): _rec("budget-kuka-ddpg", _choice("ddpg", 0.1, 30)),
        stage_name(BUDGET, "kuka", "td3"): _rec("budget-kuka-td3", _choice("td3", 1.0, 30)),
    }
    for seed in (1000, 1010):
        for group, make in (("tables", _tables), ("maps", _maps)):
            ours = stage_name(group, by="ours", heldout=seed, budget=True)
            ddpg = stage_name(group, by="ddpg", heldout=seed, budget=True)
            recs[ours] = _rec(ours, make({"ours": 0.01}, 3, {"ours": 1.0}))
            rows = {"ddpg": 0.1, "ours-at-ddpg": at_ddpg}
            recs[ddpg] = _rec(ddpg, make(rows, 30, {"ddpg": 0.1, "ours-at-ddpg": 0.1}))
    return recs


def test_the_report_pools_the_held_out_seeds_and_judges_both_comparisons(tmp_path):
    c = rb.compute(_records(at_ddpg=0.5))
    assert json.loads(json.dumps(c)) == c  # JSON-able and unchanged by results.json's round trip
    assert list(c["choice"]) == ["kuka"] and list(c["choice"]["kuka"]) == ["ours", "ddpg", "td3"]
    assert c["choice"]["kuka"]["ddpg"]["steps"] == 30
    assert c["choice"]["kuka"]["ddpg"]["at_scale"] == {"3": 2.0, "30": 0.05}
    t = c["tables"]
    assert t["seeds"] == [1000, 1010] and t["baselines"] == ["ddpg"]  # TD3 reported nowhere
    cell = t["table1"]["rows"]["ours"][0]
    assert math.isclose(cell["mean"], 0.0105) and cell["lo"] <= 0.0105 <= cell["hi"]
    assert t["budgets"]["ours-at-ddpg"] == {"steps": 30, "scale": 0.1}
    verdicts = {x["claim"]: x["verdict"] for x in c["claims"]}
    assert len(verdicts) == 2 * 3 + 2 * 3  # two comparisons per table and per map
    own = [v for k, v in verdicts.items() if "own meta-test budget: ours below every" in k]
    at = [v for k, v in verdicts.items() if "own number of meta-test steps: ours below" in k]
    assert set(own) == {"met"} and set(at) == {"not met"}  # ours' 0.5 at 30 steps > DDPG's 0.1
    flipped = {x["claim"]: x["verdict"] for x in rb.compute(_records(at_ddpg=0.05))["claims"]}
    assert set(flipped.values()) == {"met"}
    md = "\n".join(rb.render(json.loads(json.dumps(c))))  # as results.json gives it back
    assert md == "\n".join(rb.render(c))
    assert "| DDPG | 30 | 0.1 | 0.05 | 0.3 | 2 | 0.05 |" in md
    assert "| ours at DDPG's steps (30 steps, x0.1) | 0.525 [" in md
    assert "### Figures 4-6 at the chosen budgets, held-out goal seeds 1000, 1010" in md
    figs = rb.plot(c, tmp_path)
    assert [p.name for _, p, _ in figs] == ["budget_kuka.png"] and figs[0][1].is_file()


def test_the_report_reads_a_shared_row_where_it_was_run():
    """Meta-Critic chose DDPG's 30 steps: its stages hold its own row and name DDPG's for ours'; the
    report shows ours at Meta-Critic's steps with DDPG's numbers, judges both pairs, says so, and
    leaves Meta-Critic out where DDPG's stage is missing."""
    recs = _records(at_ddpg=0.05)
    recs[stage_name(BUDGET, "kuka", "meta-critic")] = _rec(
        "budget-kuka-meta-critic", _choice("meta-critic", 0.1, 30)
    )
    for seed in (1000, 1010):
        for group, make in (("tables", _tables), ("maps", _maps)):
            name = stage_name(group, by="meta-critic", heldout=seed, budget=True)
            r = make({"meta-critic": 0.2}, 30, {"meta-critic": 0.1})
            recs[name] = _rec(
                name, {**r, "shared_rows": {"ours-at-meta-critic": ["ddpg", "ours-at-ddpg"]}}
            )
    c = rb.compute(recs)
    t = c["tables"]
    assert t["baselines"] == ["ddpg", "meta-critic"]
    assert t["table1"]["rows"]["ours-at-meta-critic"] == t["table1"]["rows"]["ours-at-ddpg"]
    assert t["budgets"]["ours-at-meta-critic"] == {
        "steps": 30,
        "scale": 0.1,
        "same_as": "ours-at-ddpg",
    }
    assert (
        c["maps"]["grid_mean"]["mass"]["ours-at-meta-critic"]
        == c["maps"]["grid_mean"]["mass"]["ours-at-ddpg"]
    )
    pairs = [x for x in c["claims"] if "own number of meta-test steps" in x["claim"]]
    assert len(pairs) == 6  # 3 tables and 3 maps, each with both baselines' pairs
    assert "ours below in 4 of 4 (column, baseline) pairs" in [x["ours"] for x in pairs][0]
    md = "\n".join(rb.render(json.loads(json.dumps(c))))
    assert (
        "ours at Meta-Critic's steps (30 steps, x0.1) is ours at DDPG's steps (30 steps, x0.1)"
        in md
    )
    missing = {n: r for n, r in recs.items() if not n.startswith("budget-ddpg-")}
    assert rb.compute(missing)["tables"]["baselines"] == []  # Meta-Critic's ours row is nowhere


def test_only_the_sections_of_complete_stages_appear():
    recs = _records(at_ddpg=0.5)
    only_choice = {n: r for n, r in recs.items() if n.startswith("budget-kuka")}
    c = rb.compute(only_choice)
    assert c["tables"] is None and c["maps"] is None and c["claims"] == []
    assert "Tables 1-3 at the chosen budgets: not run" in "\n".join(rb.render(c))
    assert rb.compute({})["choice"] == {}
    assert rb.budget_render(None) == []  # no budget stage: no section (the report unchanged)


# ------------------------------------------------------------------------------------------------
# bad --set values, and the real run
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "override,words",
    [
        ("budget.steps=[0,3]", "budget.steps=0: must be >= 1"),
        ("budget.steps=[3,3]", "budget.steps=[3, 3]: a step count is given twice"),
        ("budget.alpha_scales=[-1]", "budget.alpha_scales=-1: must be > 0"),
        ("budget.inits=0", "budget.inits=0: must be >= 1"),
        ("budget.seed=1", "budget.seed=1: goal seed 1 chose another setting"),
        ("budget.seed=1001", "budget.seed=1001: draws the goals a table or map reports on"),
        ("budget.steps=3", "budget.steps=3: must be a list"),
    ],
)
def test_bad_budget_settings_are_refused_in_one_line(override, words, tmp_path, capsys):
    with pytest.raises(FieldError) as e:
        ReproduceConfig(quick=True, overrides=[override]).validate()
    assert words in str(e.value)
    out = tmp_path / "paper"
    assert cli_main(["reproduce", "--quick", "--out", str(out), "--set", override]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()


@pytest.mark.slow
def test_the_budget_stages_run_through_the_cli_and_reach_the_report(tmp_path, capsys):
    out = tmp_path / "paper"
    only = "budget,budget-tables-heldout,budget-maps-heldout"
    argv = ["reproduce", "--quick", "--seeds", "1", "--only", only, "--device", "cpu"]
    assert cli_main([*argv, "--out", str(out)]) == 0
    # 2 robots x 3 methods' meta-trainings and choices, 3 methods x (tables, maps) on seed 1000
    assert "18 stage(s) to run" in capsys.readouterr().err
    (ddpg,) = [
        json.loads(p.read_text()) for p in out.glob("budget-ddpg-tables-heldout-*/stage.json")
    ]
    (choice,) = [json.loads(p.read_text()) for p in out.glob("budget-kuka-ddpg-*/stage.json")]
    res, chosen = ddpg["result"], choice["result"]["chosen"]
    assert res["policy_updates"] == chosen["steps"] in (1, 3)
    assert res["alpha_scales"]["ddpg"] == chosen["scale"]
    (ours,) = [json.loads(p.read_text()) for p in out.glob("budget-kuka-ours-*/stage.json")]
    if ours["result"]["chosen"]["steps"] == chosen["steps"]:  # ours' own stage's row
        assert res["shared_rows"] == {"ours-at-ddpg": ["ours", "ours"]}
        assert {c["method"] for c in res["cells"]} == {"ddpg"}
    else:
        assert "shared_rows" not in res
        assert {c["method"] for c in res["cells"]} == {"ddpg", "ours-at-ddpg"}
    assert "| ours at DDPG's steps (" in (out / "REPORT.md").read_text()
    report = (out / "REPORT.md").read_text()
    assert "## Each method at its own meta-test budget" in report
    assert "### Table 3 at the chosen budgets, held-out goal seeds 1000" in report
    results = json.loads((out / "results.json").read_text())
    assert set(results["budget"]["choice"]) == {"reacher", "kuka"}
    assert (out / "figures" / "budget_kuka.png").is_file()
    assert cli_main([*argv, "--out", str(out)]) == 0
    assert "0 stage(s) to run" in capsys.readouterr().err


def test_the_held_out_section_points_at_the_budget_section_only_when_it_is_there():
    """The held-out claims give every method seed 1's steps; where they are, the report's own-budget
    section gives each its own, else the section names how to get them (never a folder that a
    republished report no longer holds)."""
    from warp_critic.reproduce.report.heldout_section import heldout_render

    view = {"equal_steps": [], "tables": None, "maps": None}
    there = " ".join(heldout_render({**view, "own_budgets": True}))
    absent = " ".join(heldout_render({**view, "own_budgets": False}))
    assert "the section 'Each method at its own meta-test budget' gives each method" in there
    assert "`warp-critic budget`, or `reproduce --beyond`" in absent
    assert "docs/paper/budget" not in there + absent
