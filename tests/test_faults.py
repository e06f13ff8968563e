"""Faults: a run killed at any point resumes to the same numbers; two runs never share a directory;
a crafted checkpoint never runs its code.

The runs here are real ``warp-critic`` processes (``python -m warp_critic.cli.main``), killed with SIGKILL
(what a crash, an OOM kill or a lost node does) at exact points
(``fault_injection.py`` here), or stopped with SIGTERM.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from conftest import REACHER
from helpers import TINY_TRAIN, run_cli, start_cli

from warp_critic.running.recording import read_times

TINY = [*TINY_TRAIN, "--checkpoint-every", "1", "--record-every", "1"]
ITERATIONS = 6


def killed_at(point: str) -> list[str]:
    """The command that runs ``warp-critic`` and kills it at ``point`` (``POINT:N``,
    ``fault_injection.py``): for ``run_cli(..., command=...)``."""
    return [sys.executable, str(Path(__file__).with_name("fault_injection.py")), point]


def rows(run: Path) -> list[dict]:
    return [json.loads(x) for x in (run / "metrics.jsonl").read_text().splitlines()]


def rerun_verify(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "rerun_cli", "rrd", "verify", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.fixture(scope="module")
def straight(tmp_path_factory) -> Path:
    run = tmp_path_factory.mktemp("straight") / "run"
    p = run_cli("meta-train", REACHER, *TINY, "--iterations", str(ITERATIONS), "--out", str(run))
    assert p.returncode == 0, p.stderr
    return run


@pytest.mark.slow
@pytest.mark.subprocess
def test_sigkill_at_several_points_resumes_to_the_same_metrics_and_a_complete_recording(
    tmp_path, straight
):
    run = tmp_path / "run"
    # 1. killed while writing its 3rd checkpoint (written to a temporary file, not yet in place)
    p = run_cli(
        "meta-train",
        REACHER,
        *TINY,
        "--iterations",
        str(ITERATIONS),
        "--out",
        str(run),
        command=killed_at("checkpoint.pt:3"),
    )
    assert p.returncode == -signal.SIGKILL
    assert (
        torch.load(run / "checkpoint.pt", weights_only=True)["iteration"] == 1
    )  # the last one in place
    assert (run / ".lock").exists() and list(
        run.glob(".checkpoint.pt.*.tmp")
    )  # what a crash leaves
    # 2. resumed, killed right after the metrics row of its 2nd iteration (before that checkpoint)
    p = run_cli(
        "meta-train",
        REACHER,
        "--iterations",
        str(ITERATIONS),
        "--out",
        str(run),
        "--resume",
        command=killed_at("metrics-row:2"),
    )
    assert p.returncode == -signal.SIGKILL
    assert "taking over the lock" in p.stderr
    # 3. resumed, killed while writing the recording merge of... no: while writing config.json at start
    p = run_cli(
        "meta-train",
        REACHER,
        "--iterations",
        str(ITERATIONS),
        "--out",
        str(run),
        "--resume",
        command=killed_at("config.json:1"),
    )
    assert p.returncode == -signal.SIGKILL
    # 4. resumed to the end
    p = run_cli(
        "meta-train", REACHER, "--iterations", str(ITERATIONS), "--out", str(run), "--resume"
    )
    assert p.returncode == 0, p.stderr
    assert not list(run.glob(".*.tmp")) and not (run / ".lock").exists()

    a, b = rows(straight), rows(run)
    assert [r["iteration"] for r in b] == list(range(ITERATIONS))
    for x, y in zip(a, b):
        assert y["task_loss"] == pytest.approx(x["task_loss"], rel=1e-5)
        assert y["task_loss_per_goal"] == pytest.approx(x["task_loss_per_goal"], rel=1e-5)
    # the recording verifies and holds every rollout of the run
    assert not (run / "recording.segment.rrd").exists()
    v = rerun_verify(run / "recording.rrd")
    assert v.returncode == 0, v.stderr
    for label in ("before", "after"):
        times = read_times(run / "recording.rrd", f"/robot/goal1/{label}/")
        assert times == set(range(ITERATIONS)), (label, sorted(times))


def start_long_run(run: Path, until: str) -> subprocess.Popen:
    """A meta-train that runs (almost) forever, once ``run/until`` exists."""
    p = start_cli("meta-train", REACHER, *TINY, "--iterations", "100000", "--out", str(run))
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not (run / until).exists():
        time.sleep(0.1)
    return p


@pytest.mark.slow
@pytest.mark.subprocess
def test_sigterm_stops_like_ctrl_c_and_closes_the_recording(tmp_path):
    run = tmp_path / "run"
    p = start_long_run(run, "checkpoint.pt")
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=120)
    lines = [x for x in err.splitlines() if not x.startswith("[")]
    assert p.returncode == 130, err
    assert (
        len(lines) == 1
        and "interrupted" in lines[0]
        and "is kept" in lines[0]
        and "--resume" in lines[0]
    ), lines
    assert rerun_verify(run / "recording.rrd").returncode == 0
    assert not (run / ".lock").exists()


@pytest.mark.slow
@pytest.mark.subprocess
def test_a_second_run_into_a_locked_directory_is_refused_at_once(tmp_path):
    run = tmp_path / "run"
    first = start_long_run(run, "metrics.jsonl")
    assert (run / ".lock").exists()
    for argv in (
        ["meta-train", REACHER, "--iterations", "8", "--out", str(run), "--resume"],
        ["meta-train", REACHER, *TINY, "--iterations", "8", "--out", str(run)],
    ):
        t0 = time.monotonic()
        second = run_cli(*argv)
        assert second.returncode == 2, second.stderr
        # refused before any simulation; the interpreter and torch import take most of this
        assert time.monotonic() - t0 < 30
        err = second.stderr.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("warp-critic: error:"), err
    assert first.poll() is None  # still running, undisturbed
    first.send_signal(signal.SIGTERM)
    out, err = first.communicate(timeout=300)
    assert first.returncode == 130, err
    done = rows(run)
    assert len(done) > 1 and [r["iteration"] for r in done] == list(range(len(done)))
    assert json.loads((run / "config.json").read_text())["iterations"] == 100000


@pytest.mark.slow
def test_a_signal_whose_interrupt_a_callback_swallows_still_stops_the_run(tmp_path):
    """SIGTERM raises KeyboardInterrupt wherever the main thread is; a callback that swallows it (a
    finaliser, a C extension's callback) must not leave the run going with the handler already in its
    "stopping" phase (seen in CI: a SIGTERM'd run never exited)."""
    from helpers import tiny_cfg

    from warp_critic.cli import signals
    from warp_critic.methods.ours import meta_train

    swallowed = []

    def swallow(info):
        if info.iteration == 1:
            try:
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(5)  # the handler runs here and raises
            except KeyboardInterrupt:
                swallowed.append(info.iteration)

    previous = signals.install()
    signals.running()
    try:
        with pytest.raises(KeyboardInterrupt):
            meta_train(
                tiny_cfg(tmp_path / "run", iterations=40), callbacks=[swallow], progress=False
            )
    finally:
        signals.restore(previous)
    assert swallowed == [1]
    # it stopped at the end of the iteration that took the signal, and released its lock
    assert [r["iteration"] for r in rows(tmp_path / "run")] == [0, 1]
    assert not (tmp_path / "run" / ".lock").exists()


def test_lock_is_refused_within_a_second_in_process(tmp_path):
    from warp_critic.core.errors import UserError
    from warp_critic.running.rundir import RunDir

    rd = RunDir.create(tmp_path / "run", "ours")
    t0 = time.monotonic()
    with pytest.raises(UserError, match=f"in use by process {os.getpid()}"):
        RunDir.open(tmp_path / "run").lock()
    assert time.monotonic() - t0 < 1.0
    rd.unlock()
    RunDir.open(tmp_path / "run").lock()  # free again


class _Payload:
    def __init__(self, marker: str):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


@pytest.mark.slow
@pytest.mark.subprocess
@pytest.mark.parametrize("command", ["meta-test", "resume"])
def test_a_crafted_checkpoint_does_not_run_its_payload(tmp_path, straight, command):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(straight, run)
    marker = tmp_path / "pwned"
    torch.save(
        {"kind": "warp-critic/checkpoint-v1", "config": {}, "x": _Payload(str(marker))},
        run / "checkpoint.pt",
    )
    before = (run / "checkpoint.pt").read_bytes()
    if command == "meta-test":
        p = run_cli("meta-test", str(run), "--device", "cpu")
    else:
        p = run_cli("meta-train", REACHER, "--iterations", "9", "--out", str(run), "--resume")
    assert p.returncode == 2, p.stderr
    err = p.stderr.strip().splitlines()
    assert len(err) == 1 and "refused" in err[0], err
    assert not marker.exists()
    assert (run / "checkpoint.pt").read_bytes() == before
