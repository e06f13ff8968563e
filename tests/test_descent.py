"""A long batched meta-test goes on where a killed call left it, to the same numbers
(``warp_critic/reproduce/experiments/descent.py``); a complete stage drops its progress and
a carried stage never holds it."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from warp_critic.physics.scene import Variant
from warp_critic.reproduce.experiments import descent
from warp_critic.reproduce.experiments.evaluate import Job, evaluate

GOALS = torch.tensor([[0.3, -0.2], [-1.0, 0.8], [0.6, 0.4]])


def _jobs(run) -> list[Job]:
    return [
        Job("a", str(run), GOALS, Variant()),
        Job("b", str(run), GOALS[:2], Variant(ee_mass=0.5), alpha_scale=3.0),
        Job("c", str(run), GOALS, Variant(link_length=0.8)),
    ]


def _call(run, **kw):
    args = dict(inits=2, steps=23, seed=4, device="cpu", progress=False, max_worlds=10)
    return evaluate(_jobs(run), **{**args, **kw})


def _same(r, ref) -> None:
    for k in ("errors", "before"):
        for a, b in zip(r[k], ref[k]):
            np.testing.assert_array_equal(a, b)
    for n in ref.get("errors_at", {}):
        for a, b in zip(r["errors_at"][n], ref["errors_at"][n]):
            np.testing.assert_array_equal(a, b)
    assert r["alphas"] == ref["alphas"] and r["diverged"] == ref["diverged"]


class Killed(Exception):
    """Raised by the patched step function: a call killed part way."""


def _count_steps(monkeypatch, kill_after: int | None = None) -> list[int]:
    """Patch the descent's step function to count the steps it takes (and raise after
    ``kill_after`` chunks: a call killed part way)."""
    from warp_critic.learning import inner

    real, taken, chunks = inner.inner_update, [], [0]

    def counted(*a, **kw):
        if kill_after is not None and chunks[0] >= kill_after:
            raise Killed
        chunks[0] += 1
        params, trajs = real(*a, **kw)
        taken.append(len(trajs))
        return params, trajs

    monkeypatch.setattr(inner, "inner_update", counted)
    return taken


def test_a_killed_evaluation_resumes_to_the_same_numbers(finished_run, tmp_path, monkeypatch):
    ref = _call(finished_run, at=(5, 12))
    assert ref["batches"] == 2  # 12 worlds, 4 and 6, then 6: two batches of whole jobs
    progress = tmp_path / "progress"
    _count_steps(monkeypatch, kill_after=3)  # chunks of 5, 7 and 10 steps (stops at 5, 12, 23)
    with pytest.raises(Killed):
        _call(finished_run, at=(5, 12), resume=progress, save_every=0.0)
    files = sorted(p.name for p in progress.iterdir())
    assert files == ["batch-0-partial.pt"]  # batch 0 was part way: 22 of its 23 steps
    monkeypatch.undo()
    taken = _count_steps(monkeypatch)
    r = _call(finished_run, at=(5, 12), resume=progress, save_every=0.0)
    _same(r, ref)
    assert sum(taken) == 2 * 23 - 22  # the 22 steps of batch 0 before the kill: not again
    assert sorted(p.name for p in progress.iterdir()) == ["batch-0.pt", "batch-1.pt"]

    taken.clear()
    again = _call(finished_run, at=(5, 12), resume=progress)
    _same(again, ref)
    assert taken == []  # both batches done: read back, nothing descends


def test_progress_of_other_inputs_is_not_used(finished_run, tmp_path, monkeypatch):
    progress = tmp_path / "progress"
    _call(finished_run, steps=4, resume=progress)
    taken = _count_steps(monkeypatch)
    other = _call(finished_run, steps=4, seed=5, resume=progress)  # other initial policies
    assert sum(taken) == 2 * 4
    monkeypatch.undo()
    _same(other, _call(finished_run, steps=4, seed=5))
    (progress / "batch-1.pt").write_bytes(b"torn")  # a file cut short: warned of, redone
    taken = _count_steps(monkeypatch)
    _same(_call(finished_run, steps=4, seed=5, resume=progress), other)
    assert sum(taken) == 4


def test_the_descent_holds_at_most_a_chunk_of_rollouts(finished_run, monkeypatch):
    """Chunked descent: no call takes more than ``STEPS_PER_CHUNK`` steps, and the budgets read on
    the way are exact (the steps are a function of the policies alone)."""
    taken = _count_steps(monkeypatch)
    r = _call(finished_run, at=(5, 12))
    assert max(taken) <= descent.STEPS_PER_CHUNK and sum(taken) == 2 * 23
    monkeypatch.undo()
    for n in (5, 12):
        alone = _call(finished_run, steps=n)
        for a, b in zip(r["errors_at"][n], alone["errors"]):
            np.testing.assert_array_equal(a, b)


def test_a_complete_stage_drops_its_progress_and_carry_skips_it(tmp_path):
    from warp_critic.reproduce.engine import carry
    from warp_critic.reproduce.engine.stage import PROGRESS
    from warp_critic.reproduce.engine.stages import MARKER, Runner
    from warp_critic.reproduce.experiments.records import CARRY

    out = tmp_path / "out"
    d = out / "toy-abc"
    (d / PROGRESS).mkdir(parents=True)
    (d / PROGRESS / "batch-0.pt").write_bytes(b"x")
    (out / MARKER).write_text(json.dumps({"kind": "warp-critic/reproduce-output-v1"}) + "\n")
    runner = Runner(out, CARRY.check, log=lambda line: None)
    runner.finish("toy", "toy", "abc", {}, {"x": 1}, 1.0)
    assert (d / "stage.json").is_file() and not (d / PROGRESS).exists()

    (d / PROGRESS).mkdir()  # left by hand: still never carried
    (d / PROGRESS / "batch-0.pt").write_bytes(b"x")
    carry._copy_stage(d, tmp_path, slim=None, pack=True)
    assert sorted(p.name for p in (tmp_path / d.name).iterdir()) == ["stage.json.xz"]


def test_a_stage_part_way_goes_on_from_an_archive_in_another_folder(
    finished_run, tmp_path, monkeypatch
):
    """A sitting ends inside a long meta-test: ``carry save`` keeps the stage's finished batches
    (never a running one's policies), ``restore`` puts them in another machine's output folder,
    and the meta-test there takes only the steps of the batches not finished, to the same
    numbers. Once the stage is complete, the next save replaces the batches by its record."""
    import shutil

    from warp_critic.reproduce.engine import carry
    from warp_critic.reproduce.engine.stage import PROGRESS
    from warp_critic.reproduce.engine.stages import MARKER, Runner
    from warp_critic.reproduce.experiments.records import CARRY

    one, two, archive = tmp_path / "one" / "paper", tmp_path / "two" / "paper", tmp_path / "arch"
    seed0 = "metatrain-reacher-ours-0123456789/run/seed0"
    shutil.copytree(finished_run, one / seed0)
    (one / MARKER).write_text(json.dumps({"kind": "warp-critic/reproduce-output-v1"}) + "\n")
    progress = one / "toy-abc" / PROGRESS
    ref = _call(one / seed0, resume=progress)
    (progress / "batch-1.pt").unlink()  # the sitting ended in batch 1
    (progress / "batch-1-partial.pt").write_bytes(b"policies")
    saved = carry.save(one, archive, CARRY)
    assert saved.partway == ["toy-abc"]
    assert [p.name for p in (archive / "toy-abc" / PROGRESS).iterdir()] == ["batch-0.pt"]
    assert carry.restore(archive, two, CARRY).partway == ["toy-abc"]
    shutil.copytree(finished_run, two / seed0)
    taken = _count_steps(monkeypatch)
    ref["alphas"] = {str(two / seed0): ref["alphas"][str(one / seed0)]}  # the same run, moved
    _same(_call(two / seed0, resume=two / "toy-abc" / PROGRESS), ref)
    assert sum(taken) == 23  # batch 1 alone: batch 0 was read back
    assert carry.save(one, archive, CARRY).partway == []  # nothing new
    runner = Runner(one, CARRY.check, log=lambda line: None)
    toy = {"closed_form": {}, "numerical": {}, "table_markdown": "", "files": {}}
    runner.finish("toy", "toy", "abc", {}, toy, 1.0)
    assert carry.save(one, archive, CARRY).stages == ["toy-abc"]
    assert sorted(p.name for p in (archive / "toy-abc").iterdir()) == ["stage.json.xz"]


def test_the_budget_command_resumes_a_killed_sweep_from_its_batches(
    finished_run, tmp_path, monkeypatch
):
    """``warp-critic budget``'s driver keeps each batch in ``OUT.progress/`` while it works: a call
    killed in the sweep goes on without those batches' steps, to the same file, and the folder is
    gone at the end."""
    from warp_critic.reproduce.budget import BudgetConfig, run_budget

    run = str(finished_run)
    cfg = BudgetConfig(
        runs={"ours": [run, run]},
        budgets=[1, 3],
        alpha_scales=[0.5, 2.0],
        inits=2,
        report_stds=[0.2],
        num_goals=2,
        device="cpu",
        max_worlds=4,  # one job (2 training goals x 2 inits) a batch: 4 batches
    )
    ref = run_budget(cfg, tmp_path / "ref.json")
    out = tmp_path / "b.json"
    # two batches of the sweep (each two chunks: steps 0-1, 1-3), then killed
    _count_steps(monkeypatch, kill_after=4)
    with pytest.raises(Killed):
        run_budget(cfg, out)
    assert not out.exists()
    assert sorted(p.name for p in (tmp_path / "b.json.progress" / "ours-sweep").iterdir()) == [
        "batch-0.pt",
        "batch-1.pt",
    ]
    monkeypatch.undo()
    taken = _count_steps(monkeypatch)
    r = run_budget(cfg, out)
    n = r["chosen"]["ours"]["steps"]  # the report: the chosen scale x 2 runs, 2 batches this far
    assert sum(taken) == (4 - 2) * 3 + 2 * n  # the sweep's other 2 batches, then the report
    assert not (tmp_path / "b.json.progress").exists()
    assert r["chosen"] == ref["chosen"]
    assert r["sweep"]["ours"]["curve"] == ref["sweep"]["ours"]["curve"]
    assert [c["mse_mean"] for c in r["report"]["ours"]["cells"]] == [
        c["mse_mean"] for c in ref["report"]["ours"]["cells"]
    ]
