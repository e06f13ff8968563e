"""``tools/gpu_check.py``: the one-call GPU check runs (here on the CPU, in its tiny mode) and writes
the JSON and table it promises, so it cannot rot before a GPU is lent; ``auto`` stays on the CPU."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from warp_critic.physics.simulator import AUTO_PICKS_CUDA, resolve_device

ROOT = Path(__file__).resolve().parents[1]


def test_auto_device_is_the_cpu_until_cuda_is_measured_faster():
    assert AUTO_PICKS_CUDA is False
    assert resolve_device("auto") == "cpu"


@pytest.mark.slow
@pytest.mark.subprocess
def test_gpu_check_tiny_on_cpu(tmp_path):
    out = tmp_path / "check.json"
    proc = subprocess.run(
        [
            sys.executable,
            str(ROOT / "tools" / "gpu_check.py"),
            "--device",
            "cpu",
            "--tiny",
            "--budget",
            "300",
            "--out",
            str(out),
        ],  # fmt: skip
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = json.loads(out.read_text())
    assert got["device"] == "cpu" and got["devices"] == ["cpu"] and got["tiny"] is True
    assert got["cuda_tests"]["exit"] in (0, 5) and "skipped" in got["cuda_tests"]["summary"]
    rows = got["rollouts"]
    assert [r["worlds"] for r in rows] == [1, 4]
    assert rows[0]["cpu"]["fwd_bwd"] > 0  # the first size always runs
    (it,) = got["iterations"]
    assert it["device"] == "cpu" and it["mode"] == "graphs" and it["per_it"] > 0
    assert "| worlds | cpu |" in proc.stdout and "s/iteration" in proc.stdout


@pytest.mark.slow
@pytest.mark.subprocess
def test_gpu_check_refuses_cuda_without_a_gpu_and_bad_flags(tmp_path):
    def run(*args):
        return subprocess.run(
            [sys.executable, str(ROOT / "tools" / "gpu_check.py"), *args],
            capture_output=True, text=True, cwd=tmp_path,
        )  # fmt: skip

    bad = run("--budget", "0")
    assert bad.returncode == 2 and "--budget" in bad.stderr and "Traceback" not in bad.stderr
    bad = run("--out", str(tmp_path / "no" / "such" / "f.json"))
    assert bad.returncode == 2 and "--out" in bad.stderr
    cuda = run("--device", "cuda", "--tiny")
    if cuda.returncode == 2:  # no GPU here (CI): one line, nothing written
        assert "no CUDA device" in cuda.stderr and not (tmp_path / "gpu_check.json").exists()
