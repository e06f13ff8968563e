"""The meta-test budget sweep (warp_critic/reproduce/budget.py): the choice is the argmin on the
training goals, the reporting goals come from seeds that chose nothing, and the command's bad
input is one line."""

from __future__ import annotations

import math

import pytest

from warp_critic.cli.main import main
from warp_critic.core.errors import FieldError, UserError
from warp_critic.evaluation import seed_uses
from warp_critic.reproduce import budget


def test_the_choice_is_the_lowest_finite_error_ties_to_fewer_steps():
    curve = {
        0.1: {1: 0.9, 10: 0.5, 100: 0.2},
        1.0: {1: 0.6, 10: 0.2, 100: math.inf},  # diverged at 100: never chosen
        10.0: {1: math.inf, 10: math.inf, 100: math.inf},
    }
    assert budget.choose(curve) == (1.0, 10, 0.2)  # ties 0.2: fewer steps
    curve[0.1][100] = 0.19
    assert budget.choose(curve) == (0.1, 100, 0.19)
    assert budget.best_scale_at(curve, 1) == (1.0, 0.6)
    assert budget.envelope(curve) == {1: 0.6, 10: 0.2, 100: 0.19}
    with pytest.raises(UserError, match="every step size and budget diverged"):
        budget.choose({1.0: {1: math.inf}})


def test_ours_is_also_reported_at_each_baselines_chosen_budget():
    curves = {
        "ours": {0.1: {3: 0.05, 300: 0.01}, 1.0: {3: 0.02, 300: 0.03}},
        "ddpg": {0.1: {3: 0.5, 300: 0.1}, 1.0: {3: 0.4, 300: 0.3}},
    }
    chosen = {
        m: dict(zip(("scale", "steps", "mse_train"), budget.choose(c))) for m, c in curves.items()
    }
    assert chosen["ours"]["steps"] == 300 and chosen["ddpg"]["steps"] == 300
    curves["ddpg"][1.0][3] = 0.05
    chosen["ddpg"] = dict(zip(("scale", "steps", "mse_train"), budget.choose(curves["ddpg"])))
    assert (chosen["ddpg"]["scale"], chosen["ddpg"]["steps"]) == (1.0, 3)
    want = budget.wanted(chosen, curves)
    assert want["ddpg"] == [(1.0, 3)]
    assert want["ours"] == [(0.1, 300), (1.0, 3)]  # ours' best scale at DDPG's 3 steps


def test_the_reporting_goals_never_come_from_a_seed_that_chose():
    assert seed_uses.chose(seed_uses.CHOOSE_BUDGET_SEED)  # the ledger names what it chose
    assert budget.BudgetConfig().choose_seed == seed_uses.CHOOSE_BUDGET_SEED
    cfg = budget.BudgetConfig(runs={"ours": ["run"]})
    cfg.validate()
    assert all(not seed_uses.chose(cfg.report_seed + c) for c in range(len(cfg.report_stds)))
    with pytest.raises(FieldError, match="goal seed 1 chose") as e:
        budget.BudgetConfig(runs={"ours": ["run"]}, report_seed=1).validate()
    assert e.value.field == "report_seed"
    with pytest.raises(FieldError, match="include the choosing seed"):
        budget.BudgetConfig(runs={"ours": ["run"]}, report_seed=1999, choose_seed=2000).validate()
    with pytest.raises(FieldError, match="ours' runs are needed"):
        budget.BudgetConfig(runs={"ddpg": ["run"]}).validate()
    with pytest.raises(FieldError) as e:
        budget.BudgetConfig(runs={"ours": ["run"]}, budgets=[3, 3]).validate()
    assert e.value.field == "budgets"


@pytest.mark.parametrize(
    "argv,message",
    [
        (["--from", "{tmp}/nowhere"], "--from: {tmp}/nowhere: not a folder"),
        (["--from", "{tmp}"], "no complete stage metatrain-reacher-ours-*"),
        (["--from", "{tmp}/paper", "--budgets", "0,3"], "--budgets: [0, 3]: positive whole step"),
        (["--from", "{tmp}/paper", "--report-seed", "1"], "--report-seed: goal seed 1 chose"),
    ],
)
def test_bad_input_is_one_line(tmp_path, capsys, argv, message):
    stage = tmp_path / "paper" / "metatrain-reacher-ours-0123456789"
    (stage / "run" / "seed0").mkdir(parents=True)
    (stage / "stage.json").write_text("{}")
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code = main(
        [
            "budget",
            *argv,
            "--scene",
            "reacher",
            "--methods",
            "ours",
            "--out",
            str(tmp_path / "b.json"),
        ]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert message.replace("{tmp}", str(tmp_path)) in err and "Traceback" not in err


@pytest.mark.parametrize(
    "flags,message",
    [
        ({"--scene": "pendulum"}, "--scene: 'pendulum': unknown; one of reacher, kuka"),
        ({"--methods": "ours,ppo"}, "--methods: unknown method(s) ppo"),
        ({"--methods": None, "--from": "{tmp}"}, "no complete stage metatrain-reacher-<method>-*"),
        ({"--choose-seed": "-1"}, "--choose-seed must be an integer in 0.."),
        ({"--device": "tpu"}, "--device must be auto, cpu, cuda or cuda:N (got 'tpu')"),
        ({"--out": "{tmp}/b.txt"}, "--out {tmp}/b.txt: must be a .json file"),
        ({"--figure": "{tmp}/notes.txt"}, "--figure {tmp}/notes.txt: must be a .png file"),
        ({"--figure": "{tmp}/mine.png"}, "exists and is not a PNG image; not overwriting it"),
        ({"--figure": "{tmp}/nowhere/f.png"}, "{tmp}/nowhere is not a folder"),
    ],
)
def test_every_flag_is_checked_before_any_work(tmp_path, capsys, flags, message):
    """A bad flag is one line and exit 2 before the sweep starts (which can take hours), and a user's
    file named by ``--figure`` or ``--out`` is left byte for byte."""
    stage = tmp_path / "paper" / "metatrain-reacher-ours-0123456789"
    (stage / "run" / "seed0").mkdir(parents=True)
    (stage / "stage.json").write_text("{}")
    (tmp_path / "notes.txt").write_text("my notes")
    (tmp_path / "mine.png").write_text("not a picture")
    argv = {"--from": f"{tmp_path}/paper", "--scene": "reacher", "--methods": "ours"}
    argv.update({"--out": f"{tmp_path}/b.json", **flags})
    words = [
        w for k, v in argv.items() if v is not None for w in (k, v.replace("{tmp}", str(tmp_path)))
    ]
    code = main(["budget", *words])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert message.replace("{tmp}", str(tmp_path)) in err
    assert (tmp_path / "notes.txt").read_text() == "my notes"
    assert (tmp_path / "mine.png").read_text() == "not a picture"
    assert not (tmp_path / "b.json").exists() and not list(tmp_path.glob("b.json.progress*"))
