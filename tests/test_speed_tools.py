"""The speed benchmarks' command lines: bad input is one line and exit code 2, before any run;
``--against`` checks out another commit temporarily and removes it again."""

from __future__ import annotations

import subprocess

import pytest
from conftest import ROOT
from helpers import load_tool


@pytest.mark.parametrize(
    "argv",
    [
        ["--iterations", "2"],
        ["--seeds", "a,b"],
        ["--repeats", "0"],
        # git is asked for the commit, and refuses it
        pytest.param(
            ["--against", "no-such-commit-0123", "--seeds", "0"], marks=pytest.mark.subprocess
        ),
        ["--worlds-per-goal", "0"],
        ["--worlds-per-goal", "8", "--method", "ddpg"],
    ],
)
def test_bench_speed_refuses_bad_arguments_in_one_line(argv, capsys):
    assert load_tool("bench_speed", "bench").main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("bench_speed: error: "), err


@pytest.mark.slow
@pytest.mark.subprocess
def test_bench_speed_against_leaves_no_worktree_behind():
    tool = load_tool("bench_speed", "bench")
    head = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    with tool.other_checkout(head) as (python, root):
        assert (root / "warp_critic" / "kernels").is_dir()  # mapped as the editable install maps it
        out = subprocess.run(
            [python, "-c", "import warp_critic.kernels as k; print(k.__file__)"],
            capture_output=True,
            text=True,
            cwd=root.parent,
        )
        assert out.returncode == 0 and out.stdout.startswith(str(root)), out.stderr
    after = subprocess.run(
        ["git", "-C", str(ROOT), "worktree", "list"], capture_output=True, text=True
    ).stdout
    assert str(root) not in after and not root.exists()
