"""The committed paper-setting run stays within its size budget, and holds what the report reads.

``docs/paper`` is part of every clone for ever (git keeps what is deleted), so it holds only what the
report needs to be regenerated and checked (``docs/paper/README.md``, "What this folder keeps").
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

PAPER = Path(__file__).resolve().parents[1] / "docs" / "paper"
BUDGET_MIB = 125


def _size(folder: Path) -> int:
    return sum(f.stat().st_size for f in folder.rglob("*") if f.is_file())


def test_docs_paper_within_budget():
    mib = _size(PAPER) / 2**20
    assert mib <= BUDGET_MIB, f"docs/paper is {mib:.1f} MiB, over its {BUDGET_MIB} MiB budget"


def test_every_stage_the_report_read_is_carried_complete():
    """Each stage named in ``results.json`` has a complete ``stage.json`` under ``stages/``, and a
    meta-training stage that an evaluation stage still reads keeps its checkpoints."""
    results = json.loads((PAPER / "results.json").read_text())
    text = json.dumps(results)
    stages = sorted(d for d in (PAPER / "stages").iterdir() if d.is_dir())
    named = [d for d in stages if d.name in text]
    assert len(named) >= 10, "results.json names fewer stages than the report reads"
    for d in named:
        rec = json.loads((d / "stage.json").read_text())
        assert rec["stage"] and isinstance(rec["seconds"], (int, float)), d.name
    for d in stages:
        if d.name.startswith(("metatrain-kuka-", "beyond-metatrain-kuka-")) or (
            d.name.startswith("metatrain-reacher-") and d.name in text
        ):
            seeds = sorted((d / "run").glob("seed*/checkpoint.pt"))
            assert seeds, f"{d.name}: its critics are gone (the tables/maps stages read them)"


@pytest.mark.parametrize("name", ["REPORT.md", "results.json", "README.md"])
def test_report_files_present(name):
    assert (PAPER / name).is_file()
