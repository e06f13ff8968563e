"""``warp-critic reproduce --status``: each stage of the command's plan complete, part way (a
meta-training's iteration and time left, a meta-test's kept batches) or not started, read without
running, locking or writing anything."""

from __future__ import annotations

import json

import pytest

from warp_critic.cli.main import main

QUICK = ["reproduce", "--quick", "--device", "cpu"]


def _lines(capsys) -> list[str]:
    return capsys.readouterr().out.strip().splitlines()


@pytest.fixture(scope="module")
def toy_done(tmp_path_factory):
    """An output folder where only the toy ran."""
    out = tmp_path_factory.mktemp("status") / "out"
    assert main([*QUICK, "--only", "toy", "--out", str(out)]) == 0
    return out


def test_a_new_folder_is_all_not_started_and_is_not_created(tmp_path, capsys):
    out = tmp_path / "new"
    assert main([*QUICK, "--out", str(out), "--status"]) == 0
    lines = _lines(capsys)
    assert lines[0].startswith(f"reproduce: {out}: 0 of ") and "0 part way" in lines[0]
    assert lines[1] == "no reproduce call is running on this folder now"
    assert all(line.split()[0:2] == ["not", "started"] for line in lines[2:]) and len(lines) > 10
    assert not out.exists()


@pytest.mark.slow
def test_complete_part_way_and_not_started_stages_are_told_apart(toy_done, capsys):
    out = toy_done
    assert main([*QUICK, "--out", str(out), "--status"]) == 0
    by_dir = {line.split()[-1] if "(" not in line else line.split(" (")[0].split()[-1]: line
              for line in _lines(capsys)[2:]}  # fmt: skip
    toy = next(d for d in by_dir if d.startswith("toy-"))
    assert by_dir[toy].split()[0] == "complete" and " min)" in by_dir[toy]
    # a meta-training stopped at iteration 30 of 200, 2 s per iteration: 170 x 2 s left
    ours = next(d for d in by_dir if d.startswith("metatrain-reacher-ours-"))
    run = out / ours / "run" / "seed0"
    run.mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({"iterations": 200}))
    rows = [{"iteration": i, "seconds": 2.0} for i in range(30)]
    (run / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows) + '{"torn')
    # a maps stage with two meta-test batches kept and one part way
    maps = next(d for d in by_dir if d.startswith("maps-") and "heldout" not in d)
    for name in ("batch-0.pt", "batch-1.pt", "batch-2-partial.pt"):
        (out / maps / "progress").mkdir(parents=True, exist_ok=True)
        (out / maps / "progress" / name).write_bytes(b"")
    before = sorted(p.name for p in out.iterdir())
    assert main([*QUICK, "--out", str(out), "--status"]) == 0
    lines = _lines(capsys)
    assert "1 of " in lines[0] and "2 part way" in lines[0]
    assert "need about 0.1 h more" in lines[0]  # 340 s
    (mt,) = [line for line in lines if ours in line]
    assert mt.split()[:2] == ["part", "way"]
    assert "(iteration 30 of 200, 2.00 s per iteration; about 0.1 h left)" in mt
    (mp,) = [line for line in lines if maps in line]
    assert "(2 meta-test batch(es) done, 1 part way)" in mp
    assert sorted(p.name for p in out.iterdir()) == before  # nothing written


@pytest.mark.slow
def test_a_not_started_stage_names_its_time_in_the_reference_run(toy_done, tmp_path):
    """A reference archive holding the same stage directory (the same settings) gives its time and
    the sum over the not-started stages; a stage it lacks gets none."""
    import shutil

    from warp_critic.reproduce.experiments.plan import ReproduceConfig
    from warp_critic.reproduce.status import published_archive, status

    (toy,) = [p for p in toy_done.iterdir() if p.name.startswith("toy-")]
    took = json.loads((toy / "stage.json").read_text())["seconds"]
    reference = tmp_path / "archive"
    shutil.copytree(toy, reference / toy.name)
    rc = ReproduceConfig(quick=True, device="cpu", out=str(tmp_path / "new"))
    lines = status(rc, reference).splitlines()
    assert lines[0].endswith(
        f"; 1 of the not-started stages took {took / 3600:.1f} h of stage time in the reference run"
    )
    (line,) = [x for x in lines if toy.name in x]
    assert line.split()[:2] == ["not", "started"]
    assert line.endswith(f"(the reference run: {took / 60:.1f} min)")
    assert all("reference run" not in x for x in lines[2:] if toy.name not in x)
    # the published run's settings are not --quick's: nothing of it matches here
    assert "reference run" not in status(rc, published_archive())


@pytest.mark.slow
def test_a_call_holding_the_folder_is_named(toy_done, capsys):
    from warp_critic.running.locks import FolderLock

    lock = FolderLock(toy_done, "reproduce output")
    lock.acquire()
    try:
        assert main([*QUICK, "--out", str(toy_done), "--status"]) == 0
    finally:
        lock.release()
    assert _lines(capsys)[1].startswith("a reproduce call is running on this folder now (process")


def test_a_folder_that_is_no_reproduce_output_is_one_line_exit_2(tmp_path, capsys):
    (tmp_path / "mine.txt").write_text("x")
    assert main([*QUICK, "--out", str(tmp_path), "--status"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a reproduce output" in err[0] and str(tmp_path) in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.txt"]


@pytest.mark.parametrize(
    "flags, words",
    [
        (["--jobs", "0"], "--jobs must be an integer in 1..1024"),
        (["--jobs", "2", "--ray", "local"], "exclude each other"),
    ],
)
def test_status_refuses_the_executor_flags_its_call_would_refuse(tmp_path, capsys, flags, words):
    """``--status`` answers for the same command without it: flags that call refuses are refused
    here too, in one line, and nothing is created (Ray is not started)."""
    out = tmp_path / "new"
    assert main([*QUICK, "--out", str(out), *flags, "--status"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0]
    assert not out.exists()


def test_a_stage_at_a_chosen_budget_is_estimated_from_this_folders_default_budget_stage(tmp_path):
    """No earlier run holds the held-out stages at the chosen budgets (their hours are most of a
    plan with --beyond): their time is the same evaluation's at the default budget, per row, times
    their rows and rollouts; no estimate while a choice or that stage is not complete."""
    from warp_critic.reproduce.engine.stage import Stage
    from warp_critic.reproduce.engine.stages import STAGE_KIND
    from warp_critic.reproduce.experiments.naming import Outputs
    from warp_critic.reproduce.status import StageState, budget_estimate, render

    def write(name: str, result: dict, seconds: float = 1.0) -> None:
        (tmp_path / name).mkdir()
        record = {"kind": STAGE_KIND, "seconds": seconds, "result": result}
        (tmp_path / name / "stage.json").write_text(json.dumps(record))

    runs = {"seeds": {"0": {"run_dir": "run/seed0"}}}
    curve = {"1.0": {"3": 0.01, "30": 0.4}, "0.1": {"3": 0.5, "30": 0.02}}
    dep = {}
    for m, n in (("ours", 3), ("ddpg", 30)):
        write(f"metatrain-kuka-{m}-h", runs)
        write(f"budget-kuka-{m}-h", {"chosen": {"scale": 1.0, "steps": n}, "curve": curve})
        dep |= {
            f"metatrain-kuka-{m}": f"metatrain-kuka-{m}-h",
            f"budget-kuka-{m}": f"budget-kuka-{m}-h",
        }
    s = {"seed": 1000}
    base = Stage("tables-heldout", "tables", s, {}, "h", None)
    o = Outputs(scene="kuka", rows=("ddpg", "ours-at-ddpg"), budget_of="ddpg")
    st = Stage("budget-ddpg-tables-heldout", "tables", s, dep, "h", o)
    other = Stage("tables-heldout-1010", "tables", {"seed": 1010}, {}, "h", None)
    stages = {x.name: x for x in (base, st, other)}
    assert budget_estimate(tmp_path, st, stages) is None  # no default-budget stage of seed 1000
    write(other.dir_name, {"cells": [{"method": "ours"}], "policy_updates": 3}, 5.0)
    assert budget_estimate(tmp_path, st, stages) is None  # another seed's is not this one's
    cells = [{"method": m} for m in ("ours", "ddpg", "meta-critic", "ours")]
    write(base.dir_name, {"cells": cells, "policy_updates": 3}, 300.0)
    seconds, how = budget_estimate(tmp_path, st, stages)
    assert seconds == pytest.approx(300.0 / 3 * 2 * (30 + 2) / (3 + 2))
    assert how == (
        "estimated from tables-heldout: 1.7 min per row x 2 row(s) x (30 + 2) / (3 + 2) rollouts"
    )
    assert budget_estimate(tmp_path, base, stages) is None  # not a stage at a chosen budget
    line = render(
        [StageState("x", "x-h", "not started", how, estimate_seconds=seconds)], tmp_path, None
    )
    assert "1 at a chosen meta-test budget need about 0.4 h, estimated from this folder" in line
    (tmp_path / "budget-kuka-ddpg-h" / "stage.json").unlink()
    assert budget_estimate(tmp_path, st, stages) is None  # DDPG's choice is not made yet
