"""``docs/rerun``: the archive of the reproduction with nothing carried, resumed over sittings
(``docs/rerun/README.md``). What a sitting commits there must be restorable and still be a stage
of the run it belongs to: a change of settings that orphans an archived stage fails here, not in a
sitting hours later."""

from __future__ import annotations

import json
import lzma
from pathlib import Path

import pytest

from warp_critic.reproduce.engine.carry import ARCHIVED_LEDGER, complete_stages
from warp_critic.reproduce.engine.partway import progress_only
from warp_critic.reproduce.experiments.records import stage_problem

RERUN = Path(__file__).resolve().parents[1] / "docs" / "rerun"
#: the command the archive's run is (``docs/rerun/README.md``)
COMMAND = ["--out", "runs/paper", "--beyond", "--baselines", "ddpg,meta-critic,td3"]

pytestmark = pytest.mark.skipif(not RERUN.is_dir(), reason="no reproduction in progress")


def _ledger() -> list[dict]:
    text = lzma.decompress((RERUN / ARCHIVED_LEDGER).read_bytes()).decode()
    return [json.loads(line) for line in text.splitlines()]


def test_every_entry_is_a_complete_stage_or_a_stage_part_way():
    complete = complete_stages(RERUN, stage_problem)  # an edited or damaged record fails here
    others = [d.name for d in RERUN.iterdir() if d.is_dir() and d.name not in complete]
    assert all(progress_only(RERUN / n) for n in others), others
    files = {p.name for p in RERUN.iterdir() if p.is_file()}
    assert files == {"README.md", ARCHIVED_LEDGER}
    assert not list(RERUN.rglob("*-partial.pt")) and not list(RERUN.rglob("*.rrd"))


def test_every_archived_stage_is_one_the_run_still_plans():
    """The archived stage directories are ``NAME-HASH`` of the run's present plan: a change of a
    stage's settings (a new ``TUNED``, a preset) makes its archived copy a stage no sitting would
    read, and the archive must drop it (and what was computed from it) in the same commit."""
    import argparse

    from warp_critic.cli.reproduce import add_arguments, config_from_args
    from warp_critic.reproduce.experiments.plan import plan

    p = argparse.ArgumentParser()
    add_arguments(p)
    rc = config_from_args(p.parse_args(COMMAND))
    stages = plan(rc.validate(), rc.plans_beyond, rc.extra, rc.plans_budget)
    planned = {f"{s.name}-{s.hash}" for s in stages.values()}
    archived = {d.name for d in RERUN.iterdir() if d.is_dir()}
    assert archived <= planned, sorted(archived - planned)


def test_every_complete_stage_was_run_by_a_call_of_the_archived_ledger():
    """Nothing carried in: each complete stage has its ``stage`` record in the ledger, every call
    names its commit, and no command names a machine's folder."""
    rows = _ledger()
    ran = {r.get("dir") for r in rows if r.get("event") == "stage"}
    complete = set(complete_stages(RERUN, stage_problem))
    assert complete <= ran, sorted(complete - ran)
    starts = [r for r in rows if r.get("event") == "start"]
    assert starts and all(r.get("code", {}).get("commit") for r in starts)
    for r in starts:
        out = r["command"].split("--out", 1)[1].split()[0]
        assert not Path(out).is_absolute(), r["command"]
