"""The committed paper-setting run stays within its size budget, and holds what the report reads.

``docs/paper`` is part of every clone for ever (git keeps what is deleted), so it holds only what the
report needs to be regenerated and checked (``docs/paper/README.md``, "What this folder keeps").
"""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import load_tool

from warp_critic.reproduce.engine.carry import complete_stages
from warp_critic.reproduce.experiments.records import stage_problem
from warp_critic.running.rundir import OMITTED

PAPER = Path(__file__).resolve().parents[1] / "docs" / "paper"
# at most 45 MB in the tree (1 MB = 10**6 bytes): issue 44's 40 MB, plus the held-out seeds'
# stages and the critics of ours at the baselines' environment steps (3.6 MB), which a reader must
# be able to meta-test again (docs/paper/README.md, "What this folder keeps")
BUDGET_MB = 45


def _size(folder: Path) -> int:
    return sum(f.stat().st_size for f in folder.rglob("*") if f.is_file())


def test_docs_paper_within_budget():
    mb = _size(PAPER) / 1e6
    assert mb <= BUDGET_MB, f"docs/paper is {mb:.1f} MB, over its {BUDGET_MB} MB budget"


@pytest.mark.slow
def test_every_stage_the_report_read_is_carried_complete():
    """Each stage named in ``results.json`` is complete in the archive ``stages/`` (its record
    compressed, ``stage.json.xz``), nothing else of a stage lies beside the report, and a
    meta-training stage of the paper's methods keeps its checkpoints (the critics anyone can
    meta-test), a recipe's only its record (its critics' scores are in the beyond stages)."""
    import json

    results = json.loads((PAPER / "results.json").read_text())
    read = {v["dir"] for v in results["stages"].values()}
    archived = complete_stages(
        PAPER / "stages", stage_problem
    )  # an edited or damaged record fails here
    assert len(read) >= 10 and read <= set(archived), sorted(read - set(archived))
    assert not [d.name for d in PAPER.iterdir() if d.is_dir() and d.name in read]
    stages = sorted(d for d in (PAPER / "stages").iterdir() if d.is_dir())
    assert not list((PAPER / "stages").rglob("stage.json")), "an uncompressed stage record"
    text = json.dumps(results)
    for d in stages:
        if d.name.startswith("metatrain-kuka-") or (
            d.name.startswith("metatrain-reacher-") and d.name in text
        ):
            seeds = sorted((d / "run").glob("seed*/checkpoint.pt"))
            assert seeds, f"{d.name}: its critics are gone (the tables/maps stages read them)"
            for run in sorted((d / "run").glob("seed*")):  # each: its critic, or why not
                assert (run / "checkpoint.pt").is_file() or (run / OMITTED).is_file(), run
        if d.name.startswith("beyond-metatrain-"):
            kept = sorted(p.name for p in d.iterdir())
            assert kept == ["stage.json.xz"], f"{d.name}: a recipe keeps its record alone: {kept}"


@pytest.mark.parametrize("name", ["REPORT.md", "results.json", "README.md"])
def test_report_files_present(name):
    assert (PAPER / name).is_file()


def test_the_readme_says_what_the_folder_holds_measured():
    """docs/paper/README.md's contents table is the one ``tools/paper_contents.py`` measures."""
    tool = load_tool("paper_contents")
    assert tool.main(["--check", str(PAPER / "README.md")]) == 0


def test_every_published_file_is_in_one_category_with_its_size(tmp_path, capsys):
    """Critics, notes, records, the report and an unknown file each land in their row; the counts
    and sizes are the files'; the kept seeds are named."""
    tool = load_tool("paper_contents")
    files = {
        "stages/metatrain-a-0/run/seed0/checkpoint.pt": 2_000_000,
        f"stages/metatrain-a-0/run/seed1/{OMITTED}": 10,
        "stages/metatrain-a-0/stage.json.xz": 300_000,
        "stages/maps-0/errors.json.xz": 200_000,
        "REPORT.md": 50_000,
        "README.md": 123,  # the page itself: not measured
        "stray.bin": 7,
    }
    for name, size in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(b"x" * size)
    rows = {(k.what if k else "other"): (n, b) for k, n, b in tool.measure(tmp_path)}
    assert rows[tool.KINDS[0].what] == (1, 2_000_000)
    assert rows[tool.KINDS[1].what] == (1, 10)
    assert rows[tool.KINDS[2].what] == (2, 500_000)
    assert rows["other"] == (1, 7) and sum(n for n, _ in rows.values()) == 6
    text = tool.block(tmp_path)
    assert text.startswith("2.6 MB in 6 files besides this page")
    assert "1 of the 2 seeds' critics of 1 meta-trainings are kept (seed0)" in text
    assert tool.main(["--folder", str(tmp_path / "none")]) == 2
    assert "no such folder" in capsys.readouterr().err


def test_the_readme_lists_the_ledgers_calls_as_the_ledger_holds_them():
    """docs/paper/README.md's calls table is the one ``tools/ledger_calls.py`` writes."""
    tool = load_tool("ledger_calls")
    assert tool.main([str(PAPER), "--check", str(PAPER / "README.md")]) == 0
