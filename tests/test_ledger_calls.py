"""The ledger's calls, one row each (``engine.ledger.calls``), and ``tools/ledger_calls.py``, which
writes them into a page's block."""

from __future__ import annotations

import json

from helpers import load_tool

from warp_critic.reproduce.engine.ledger import calls
from warp_critic.reproduce.engine.stage import dir_name, stage_of_dir

tool = load_tool("ledger_calls")


def _rows() -> list[dict]:
    start = {"event": "start", "machine": {"cpu": "AMD EPYC"}, "command": "warp-critic reproduce"}
    return [
        {**start, "call": "a", "time": "2026-12-07T03:00:00Z"},
        {"call": "a", "event": "stage", "dir": "toy-e95b4993a1", "time": "2026-12-07T03:01:00Z"},
        {"call": "a", "event": "end", "status": "done", "wall_s": 95.5, "time": "2026-12-07T03:01:36Z"},
        {**start, "call": "b", "time": "2026-12-07T04:00:00Z"},
        {"call": "b", "event": "stage", "dir": "maps-heldout-1010-a0bbedb7fc", "time": "2026-12-07T04:10:00Z"},
        {"call": "b", "event": "alive", "time": "2026-12-07T04:15:00Z"},  # then killed: no end
        {"call": "z", "event": "end", "status": "done", "time": "2026-12-07T05:00:00Z"},  # no start
    ]  # fmt: skip


def test_each_call_has_its_times_status_and_stages_and_a_killed_one_ends_at_its_last_beat():
    a, b = calls(_rows())
    assert (a["status"], a["wall_s"], a["stages"]) == ("done", 95.5, ["toy-e95b4993a1"])
    assert (b["status"], b["end"], b["wall_s"]) == ("killed", "2026-12-07T04:15:00Z", 900.0)
    assert b["stages"] == ["maps-heldout-1010-a0bbedb7fc"] and b["cpu"] == "AMD EPYC"


def test_a_stage_directory_names_its_stage():
    assert stage_of_dir(dir_name("maps-heldout-1010", "a0bbedb7fc")) == "maps-heldout-1010"
    assert stage_of_dir("maps-heldout") == "maps-heldout"  # no hash: as it is


def test_the_tool_writes_the_calls_block_and_checks_it(tmp_path, capsys):
    folder = tmp_path / "paper"
    folder.mkdir()
    (folder / "ledger.jsonl").write_text("".join(json.dumps(r) + "\n" for r in _rows()))
    text = tool.block(_rows())
    assert "| 1 | 2026-12-07 03:00 | 03:01 | 96 | done | toy |" in text
    assert "| 2 | 2026-12-07 04:00 | 04:15 | 900 | killed | maps-heldout-1010 |" in text
    assert "2 calls, 996 s (0.3 h) of wall time, 2 stages completed; CPU: AMD EPYC" in text
    page = tmp_path / "README.md"
    page.write_text(f"a\n{tool.BEGIN}\n{tool.END}\nb\n")
    assert tool.main([str(folder), "--check", str(page)]) == 1
    assert tool.main([str(folder), "--write", str(page)]) == 0
    assert tool.main([str(folder), "--check", str(page)]) == 0
    assert tool.main([str(tmp_path / "none")]) == 2
    assert "no ledger.jsonl" in capsys.readouterr().err
