"""The recordings open readable in the real rerun viewer.

A tiny meta-training run's recording, a DDPG run's and the landscape analysis' are rendered by the
rerun viewer itself under Xvfb (Mesa's software Vulkan driver: ``.ci/run`` installs ``xvfb`` and
``mesa-vulkan-drivers``) with ``rerun FILE --screenshot-to``, and the pixels are checked: every plot
panel of the layout the recording opens with has drawn data, and the 3-D view shows the robot. A
layout that opens on a timeline the plots are not logged on (``step``) leaves them empty and fails.
Skipped, with the reason, only where the viewer cannot start (no ``xvfb-run`` or no ``rerun``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import REACHER

from warp_critic.cli.main import main

RERUN = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")
pytestmark = pytest.mark.skipif(
    shutil.which("xvfb-run") is None or RERUN is None,
    reason="the rerun viewer cannot start here: no xvfb-run (apt-get install xvfb "
    "mesa-vulkan-drivers) or no rerun binary",
)
WINDOW = "1600x1000"

# panels as fractions (left, top, right, bottom) of the screenshot, inside their title bars and axes
TOP, BOTTOM = 0.035, 0.965  # below the viewer's top bar, above the collapsed time panel


def rows(n: int, left: float, right: float) -> list[tuple[float, float, float, float]]:
    h = (BOTTOM - TOP) / n
    return [(left, TOP + i * h + 0.035, right, TOP + (i + 1) * h - 0.012) for i in range(n)]


def screenshot(rrd: Path) -> np.ndarray:
    """The viewer's window, rendered with ``rrd`` open: ``(H, W, 3)`` uint8."""
    from PIL import Image

    png = rrd.with_suffix(".png")
    env = {**os.environ, "WGPU_BACKEND": "vulkan"}
    cmd = ["xvfb-run", "-a", RERUN, str(rrd), "--screenshot-to", str(png)]
    p = subprocess.run(
        [*cmd, "--window-size", WINDOW], env=env, capture_output=True, text=True, timeout=300
    )
    assert p.returncode == 0 and png.is_file(), p.stderr[-2000:]
    return np.asarray(Image.open(png).convert("RGB"))


def coloured(img: np.ndarray, box: tuple[float, float, float, float]) -> float:
    """Share of the pixels in ``box`` that are saturated colour: drawn series, images, the robot.
    The viewer's own furniture (background, grid, axes, tick labels, title text) is grey."""
    H, W, _ = img.shape
    x0, t, x1, b = box
    part = img[int(t * H) : int(b * H), int(x0 * W) : int(x1 * W)].astype(int)
    spread = part.max(-1) - part.min(-1)
    return float(((spread > 60) & (part.max(-1) > 90)).mean())


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    from warp_critic.analysis.landscape.run import LandscapeConfig, run_landscape
    from warp_critic.core import runtime

    runtime.init()
    out = tmp_path_factory.mktemp("viewer")
    common = ["--horizon", "8", "--worlds-per-goal", "2", "--device", "cpu", "--record-every", "2"]
    assert main(["meta-train", REACHER, "--iterations", "4", *common, "--out", str(out / "m")]) == 0
    ddpg = ["--batch-size", "8", "--warmup-iterations", "1", "--critic-hidden", "32"]
    argv = ["baseline", "ddpg", REACHER, "--iterations", "4", *common, *ddpg]
    assert main([*argv, "--out", str(out / "d")]) == 0
    cfg = LandscapeConfig(
        out=out / "l", iterations=4, grid=9, inits_per_state=2, sup_fit_steps=2, quiet=True
    )
    run_landscape(cfg)
    return {
        "meta-train": out / "m" / "recording.rrd",
        "ddpg": out / "d" / "recording.rrd",
        "landscape": out / "l" / "landscape.rrd",
    }


@pytest.mark.parametrize("kind", ["meta-train", "ddpg"])
def test_run_recording_opens_with_data_in_every_panel(recordings, kind):
    img = screenshot(recordings[kind])
    plots = rows(4, 0.015, 0.485)  # the left half: task loss, per goal, critic, policy or actor
    for i, box in enumerate(plots):
        assert coloured(img, box) > 0.002, (kind, "plot panel", i, "is empty")
    robot = (0.51, TOP + 0.035, 0.99, BOTTOM - 0.01)  # the right half: the 3-D view
    assert coloured(img, robot) > 0.004, (kind, "the 3-D view shows no robot")


def test_landscape_recording_opens_with_data_in_every_panel(recordings):
    img = screenshot(recordings["landscape"])
    # left three quarters: 3 goals x 3 value maps; right quarter: the trace above the training losses
    for i, box in enumerate(rows(3, 0.01, 0.74)):
        x0, t, x1, b = box
        for j in range(3):
            w = (x1 - x0) / 3
            cell = (x0 + j * w + 0.01, t, x0 + (j + 1) * w - 0.01, b)
            assert coloured(img, cell) > 0.05, ("value map", i, j, "is empty")
    losses = rows(2, 0.76, 0.99)[1]
    assert coloured(img, losses) > 0.002, "the training-loss plot is empty"
