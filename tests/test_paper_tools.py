"""tools/tune_baselines.py and tools/diagnose_reacher_map.py: their draws and their bad input."""

from __future__ import annotations

import pytest
from test_tools import load_tool


def test_tune_draws_the_published_setting_first_without_repetition():
    tool = load_tool("tune_baselines")
    drawn = tool.settings(6, seed=0)
    assert drawn[0] == tool.PUBLISHED and len(drawn) == 6
    assert len({tuple(sorted(s.items())) for s in drawn}) == 6
    for s in drawn:
        assert all(s[k] in tool.GRID[k] for k in tool.GRID)
    assert tool.settings(6, seed=0) == drawn and tool.settings(6, seed=1) != drawn


@pytest.mark.parametrize(
    "name, argv, words",
    [
        ("tune_baselines", ["--scenes", "pendulum"], "unknown scene"),
        ("tune_baselines", ["--seeds", "0,100"], "other than the reported"),
        ("tune_baselines", ["--methods", "ppo"], "unknown method"),
        ("diagnose_reacher_map", ["/nonexistent/run"], "not a run directory"),
        ("diagnose_reacher_map", ["x", "--grid", "1"], "--grid >= 2"),
    ],
)
def test_tools_bad_input_is_one_line_exit_2(name, argv, words, capsys):
    with pytest.raises(SystemExit) as e:
        load_tool(name).main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ": error: " in err and words in err, err
