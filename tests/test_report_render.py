"""The report is rendered from ``results.json`` alone: the committed ``docs/paper/results.json``
renders the committed ``docs/paper/REPORT.md``, header included, byte for byte, and every section's
render is pure (the same text twice from one dict, its input untouched, no file opened, a changed
number shows).

No stage runs: these tests read the two committed files only.
"""

from __future__ import annotations

import builtins
import copy
import io
import json
import pathlib

import pytest
from conftest import ROOT

from warp_critic.reproduce.report.write import SECTIONS, render_report

PAPER = ROOT / "docs" / "paper"


@pytest.fixture(scope="module")
def results() -> dict:
    return json.loads((PAPER / "results.json").read_text(encoding="utf-8"))


def _no_files(monkeypatch) -> None:
    """Any file opened from here on fails the test."""

    def refuse(*args, **kwargs):
        raise AssertionError(f"render opened a file: {args[:1]}")

    for owner, name in (
        (builtins, "open"),
        (io, "open"),
        (pathlib.Path, "open"),
        (pathlib.Path, "read_text"),
        (pathlib.Path, "read_bytes"),
        (pathlib.Path, "exists"),
        (pathlib.Path, "is_file"),
    ):
        monkeypatch.setattr(owner, name, refuse)


def test_the_committed_results_render_the_committed_report(results):
    report = (PAPER / "REPORT.md").read_text(encoding="utf-8")
    assert report.startswith("# Reproduction: Model Based Meta Learning of Critics")
    rendered = render_report(results)
    if rendered != report:  # name the first line that differs, not a 500-line diff
        got, want = rendered.splitlines(), report.splitlines()
        i = next((i for i, (a, b) in enumerate(zip(got, want)) if a != b), min(len(got), len(want)))
        raise AssertionError(
            f"REPORT.md line {i + 1}: rendered {got[i : i + 1]!r}, committed "
            f"{want[i : i + 1]!r} (regenerate docs/paper: reproduce, then copy results.json)"
        )


def test_the_header_is_rendered_from_results_too(results):
    changed = copy.deepcopy(results)
    changed["call"]["seconds"] = 12345.6
    changed["ledger"]["calls"] = 99
    head = render_report(changed).split("\n", 8)[:8]
    assert "- written " + results["call"]["written"] + "; this call took 12345.6 s" in head
    assert any(line.startswith("- ledger (`ledger.jsonl`): 99 call(s)") for line in head)


def test_every_section_has_its_view_in_results(results):
    assert set(results["sections"]) == {"stages", *(s.name for s in SECTIONS)}


def test_render_is_pure(results, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no stage folder, no figure in reach
    before = copy.deepcopy(results)
    _no_files(monkeypatch)
    first = render_report(results)
    assert render_report(results) == first
    assert results == before  # rendering changed nothing in its input
    for section in SECTIONS:
        view = results["sections"][section.name]
        assert section.render(view) == section.render(copy.deepcopy(view))


def test_a_changed_number_in_results_changes_the_report(results):
    changed = copy.deepcopy(results)
    changed["sections"]["toy"]["numerical"]["ours"] = 2.5
    changed["claims"][0]["verdict"] = "not comparable"
    text = render_report(changed)
    assert "ours 2.5, supervised" in text and "ours 2.5, supervised" not in render_report(results)
    assert f"| **not comparable** | {changed['claims'][0]['reason']} |" in text
    # a section that did not run renders as not run, from its view alone
    changed["sections"]["maps"] = None
    assert "Not run (stage `maps`)." in render_report(changed)
