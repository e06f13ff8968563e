"""``reproduce --baselines``: a baseline beyond the paper's two (TD3) gets its own stages, changes
no stage of the paper, and its rows join the report's curves, maps and tables only when its
stages exist."""

from __future__ import annotations

import json

import pytest

from warp_critic.cli.main import main as cli_main
from warp_critic.reproduce.engine.stage import Stage
from warp_critic.reproduce.engine.stages import StageRecord
from warp_critic.reproduce.experiments.extra_baselines import merge_rows
from warp_critic.reproduce.experiments.naming import BEYOND, Outputs, stage_name
from warp_critic.reproduce.experiments.plan import ReproduceConfig, plan
from warp_critic.reproduce.experiments.settings import default_settings

TD3_STAGES = sorted(
    ["metatrain-kuka-td3", "metatrain-reacher-td3", "td3-maps", "td3-tables"]
    # its rows on every held-out goal seed
    + [f"td3-{g}-heldout{s}" for g in ("maps", "tables") for s in ("", "-1010", "-1020")]
)


def test_td3_adds_its_stages_and_changes_none_of_the_paper():
    paper = plan(default_settings(False, 5))
    extra = ("td3",)
    both = plan(default_settings(False, 5, extra), extra=extra)
    assert {k: v.hash for k, v in paper.items()} == {k: both[k].hash for k in paper}
    assert sorted(set(both) - set(paper)) == TD3_STAGES
    # TD3's published settings at the baselines' budget, on the paper's task
    td3 = both["metatrain-reacher-td3"].settings["values"]
    ddpg = both["metatrain-reacher-ddpg"].settings["values"]
    assert td3["iterations"] == ddpg["iterations"] and td3["inner_steps"] == ddpg["inner_steps"]
    assert "actor_lr" not in td3  # the tuned DDPG lr is DDPG's; TD3 keeps its own default
    # its evaluations read ours' nominal runs (the reference) and its own, and evaluate its rows
    maps = both["td3-maps"]
    assert sorted(maps.depends) == ["metatrain-reacher-ours", "metatrain-reacher-td3"]
    assert maps.outputs.rows == ("td3",) and maps.settings == both["maps"].settings
    assert maps.outputs.adds_to == "maps" and maps.kind == "maps"
    rc = ReproduceConfig(out="unused", only=["tables"], baselines=["ddpg", "meta-critic", "td3"])
    assert rc.selected() == ["tables", "td3-tables"]
    assert ReproduceConfig(out="unused", only=["tables"]).selected() == ["tables"]


@pytest.mark.parametrize(
    "baselines, words",
    [
        ("td3", "the paper's baselines are always reproduced: add ddpg, meta-critic"),
        ("ddpg,meta-critic,ppo", "unknown baseline 'ppo'"),
    ],
)
def test_bad_baselines_are_one_line(tmp_path, capsys, baselines, words):
    out = tmp_path / "paper"
    assert cli_main(["reproduce", "--quick", "--out", str(out), "--baselines", baselines]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1 and err[0].startswith("warp-critic: error: --baselines: ") and words in err[0]
    )
    assert not out.exists()


@pytest.mark.slow
def test_a_td3_stage_runs_and_the_report_shows_its_rows_only_when_selected(tmp_path, capsys):
    out = tmp_path / "paper"
    common = ["reproduce", "--quick", "--seeds", "1", "--only", "maps,tables", "--device", "cpu"]
    argv = [*common, "--out", str(out), "--baselines", "ddpg,meta-critic,td3"]
    assert cli_main(argv) == 0
    # 2 robots x 4 methods' meta-trainings, maps, tables, td3-maps, td3-tables
    assert "12 stage(s) to run" in capsys.readouterr().err
    (td3,) = [json.loads(p.read_text()) for p in out.glob("td3-maps-*/stage.json")]
    assert sorted(td3["result"]["goals"]) == ["td3"]  # ours' runs are not evaluated again
    report = (out / "REPORT.md").read_text()
    assert report.count("| this run: TD3, all seeds |") == 2 + 5  # 2 maps' grids, 5 tables
    assert report.count("| TD3 | 6 |") == 2  # Figure 3's training tables
    assert "Meta-Critic 4." in report and ", TD3 " in report  # the goal grid's sentence
    claims = report[report.index("## The paper's claims") : report.index("## Stages")]
    assert "DDPG" in claims and "TD3" not in claims  # the paper's claims: the paper's baselines
    results = json.loads((out / "results.json").read_text())
    assert "reacher/td3" in results["metatrain"] and "td3" in results["maps"]["goals_mse_mean"]
    assert {c["method"] for c in results["tables"]} == {"ours", "ddpg", "meta-critic", "td3"}
    # without the selection, the same folder's report has no TD3 row and nothing runs
    assert cli_main([*common, "--out", str(out)]) == 0
    assert "0 stage(s) to run" in capsys.readouterr().err
    assert "TD3" not in (out / "REPORT.md").read_text()


def test_merge_rows_adds_an_extra_evaluation_to_the_paper_stage_it_joins(tmp_path):
    def rec(name: str, result: dict) -> StageRecord:
        return StageRecord("tables", name, tmp_path / name, {"result": result})

    cell = {"table": "table1", "column": 0}
    paper = rec("tables", {"cells": [{**cell, "method": "ours"}]})
    extra = rec("td3-tables", {"cells": [{**cell, "method": "td3"}]})
    planned = {
        "tables": Stage("tables", "tables", {}, {}, "0", Outputs(scene="kuka")),
        "td3-tables": Stage(
            "td3-tables",
            "tables",
            {},
            {},
            "1",
            Outputs(scene="kuka", rows=("td3",), adds_to="tables"),
        ),
    }
    merged = merge_rows({"tables": paper, "td3-tables": extra}, planned)
    merged_tables = merged["tables"]
    assert merged_tables is not None
    assert [c["method"] for c in merged_tables.data["result"]["cells"]] == ["ours", "td3"]
    assert [c["method"] for c in paper.data["result"]["cells"]] == ["ours"]  # a copy
    # the extra stage not complete (or not planned): the paper's record as it is
    assert merge_rows({"tables": paper, "td3-tables": None}, planned)["tables"] is paper


def test_stage_name_is_the_one_spelling_of_every_stage():
    """The names the plan, ``--only``, the report and the stage directories share."""
    assert stage_name("metatrain", "kuka", "td3") == "metatrain-kuka-td3"
    assert stage_name("metatrain", "reacher", recipe="wide-long") == (
        "beyond-metatrain-reacher-wide-long"
    )
    assert stage_name("maps") == "maps" and stage_name("maps", by="td3") == "td3-maps"
    assert stage_name("tables", by=BEYOND) == "beyond-tables"
    assert stage_name("tables", heldout=True) == "tables-heldout"
    for bad in ({}, {"method": "ours", "recipe": "wide-long"}):  # neither, or both
        with pytest.raises(ValueError, match="a method or a recipe"):
            stage_name("metatrain", "kuka", **bad)
