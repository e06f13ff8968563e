"""The recordings open readable in the real rerun viewer.

A tiny meta-training run's recording, a DDPG run's, the landscape analysis' and a meta-test's (of an
arm drawn from triangle meshes) are rendered by the rerun viewer itself under Xvfb (Mesa's software Vulkan driver: ``.ci/run`` installs ``xvfb`` and
``mesa-vulkan-drivers``) with ``rerun FILE --screenshot-to``, and the pixels are checked: every plot
panel of the layout the recording opens with has drawn data, and the 3-D view shows the robot. A
layout that opens on a timeline the plots are not logged on (``step``) leaves them empty and fails.
The mesh arm's meshes are checked against the same recording drawn without them (line strips).
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
pytestmark = [
    pytest.mark.slow,  # the recordings train and the viewer starts: minutes in all
    pytest.mark.viewer,
    pytest.mark.subprocess,
    pytest.mark.skipif(
        shutil.which("xvfb-run") is None or RERUN is None,
        reason="the rerun viewer cannot start here: no xvfb-run (apt-get install xvfb "
        "mesa-vulkan-drivers) or no rerun binary",
    ),
]
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
    # --new: its own viewer on a free port, never streaming into one already listening on 9876
    # (another screenshot still closing, or a viewer the user has open)
    cmd = ["xvfb-run", "-a", RERUN, str(rrd), "--new", "--screenshot-to", str(png)]
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


@pytest.fixture(scope="module")
def metatest_shots(tmp_path_factory, mesh_arm):
    """Screenshots of a meta-test's recording of the mesh arm, drawn from its meshes and, for
    comparison, with the meshes taken out of the drawing (the line-strip fallback)."""
    import dataclasses

    from warp_critic.running.robot_drawing import RobotDrawing

    out = tmp_path_factory.mktemp("viewer-metatest")
    tiny = ["--horizon", "8", "--worlds-per-goal", "2", "--device", "cpu", "--iterations", "2"]
    assert main(["meta-train", str(mesh_arm), *tiny, "--out", str(out / "run")]) == 0
    test = ["meta-test", str(out / "run"), "--num-goals", "4", "--inits", "2"]
    test += ["--policy-steps", "2", "--device", "cpu"]
    assert main([*test, "--out", str(out / "meshes.json")]) == 0
    real = RobotDrawing.from_model.__func__  # type: ignore[attr-defined]

    def without_meshes(cls, *args):
        d = real(cls, *args)
        return dataclasses.replace(
            d,
            mesh_body=d.mesh_body[:0],
            mesh_local=d.mesh_local[:0],
            mesh_vertices=[],
            mesh_indices=[],
        )

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(RobotDrawing, "from_model", classmethod(without_meshes))
        assert main([*test, "--out", str(out / "lines.json")]) == 0
    return {k: screenshot(out / f"{k}.rrd") for k in ("meshes", "lines")}


ROBOT_VIEW = (0.51, TOP + 0.035, 0.99, BOTTOM - 0.01)  # the right half: the 3-D view


def test_metatest_recording_opens_with_data_in_every_panel(metatest_shots):
    img = metatest_shots["meshes"]
    for i, box in enumerate(rows(2, 0.015, 0.485)):  # final error per goal, error over the steps
        assert coloured(img, box) > 0.002, ("plot panel", i, "is empty")
    assert coloured(img, ROBOT_VIEW) > 0.004, "the 3-D view shows no robot"


def test_a_mesh_robot_is_drawn_from_its_meshes(metatest_shots):
    """The arm's links are 10 cm thick meshes: far more coloured pixels than its line strips."""
    meshes = coloured(metatest_shots["meshes"], ROBOT_VIEW)
    lines = coloured(metatest_shots["lines"], ROBOT_VIEW)
    print(f"coloured share of the 3-D view: meshes {meshes:.4f}, line strips {lines:.4f}")
    assert meshes > 2 * lines > 0, (meshes, lines)
