"""Shared test set-up.

* The test process starts the way the CLI starts a command (:func:`warp_critic.core.runtime.init`: Warp
  started quietly, one torch thread), so library-level tests see what users see.
* The scenes' paths, for every test module (``from conftest import REACHER``).
* ``finished_run``: one tiny finished meta-train run directory, made once per session; tests that
  change it work on a copy (``copy_of``).
* ``mesh_arm``: a planar two-link MJCF arm whose links are triangle meshes (no collision, explicit
  inertials), for the recordings' mesh drawing.
* A test that starts a child process (a program through :mod:`subprocess`, or a fresh interpreter
  through :mod:`multiprocessing`; from its own code, a fixture it sets up first, or a ``tools/`` or
  ``bench/`` script it runs) fails unless it is marked ``subprocess``: the marker is kept true by
  running, not by reading the code. The package's own children (a recording's ``rerun rrd
  optimize``, ``--jobs`` workers, Ray) are what a command does, as its file writes are: not counted.
"""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"
REACHER = str(SCENES / "reacher.usda")
KUKA = str(SCENES / "kuka.usda")
POINT_MASS = str(SCENES / "point_mass.usda")


def pytest_configure(config):
    from warp_critic.core import runtime

    runtime.init()


# ------------------------------------------------------------------------------------------------
# a test that starts a child process is marked ``subprocess``
# ------------------------------------------------------------------------------------------------

# the child processes a test started since the last test report, as short command lines
STARTED: list[str] = []


def _started_by_the_tests() -> bool:
    """Whether the child being started was asked for by the repository's code outside the package:
    the innermost frame of ``warp_critic`` itself (a package child, by module name, so an installed
    package counts too) or of a file of this repository (tests, tools, bench) decides; frames of the
    standard library and installed packages in between do not. No such frame: a library's own
    thread started it, which no test asked for."""
    frame = sys._getframe(2)
    while frame is not None:
        module = frame.f_globals.get("__name__", "")
        if module == "warp_critic" or module.startswith("warp_critic."):
            return False
        path = frame.f_code.co_filename
        if path.startswith(f"{ROOT}{os.sep}") and f"{os.sep}site-packages{os.sep}" not in path:
            return True
        frame = frame.f_back
    return False


def _command(args) -> str:
    text = args if isinstance(args, str | bytes) else shlex.join(map(str, args))
    text = text.decode(errors="replace") if isinstance(text, bytes) else text
    return text if len(text) <= 120 else text[:117] + "..."


def watch_children() -> None:
    """Record in :data:`STARTED` every child process the tests start from now on (see
    :func:`_started_by_the_tests`): programs (every :class:`subprocess.Popen`, which
    ``subprocess.run`` goes through) and :mod:`multiprocessing`'s fresh interpreters (spawn and
    forkserver). Called once per test process, on its first test (an xdist controller runs none and
    is left alone); the children themselves are fresh interpreters and unpatched."""
    import multiprocessing.util

    execute_child = subprocess.Popen._execute_child
    spawnv_passfds = multiprocessing.util.spawnv_passfds

    def watched_execute_child(self, args, *rest, **kw):
        if _started_by_the_tests():
            STARTED.append(_command(args))
        return execute_child(self, args, *rest, **kw)

    def watched_spawnv_passfds(path, args, passfds):
        if _started_by_the_tests():
            STARTED.append(_command(args))
        return spawnv_passfds(path, args, passfds)

    subprocess.Popen._execute_child = watched_execute_child
    multiprocessing.util.spawnv_passfds = watched_spawnv_passfds


def unmarked_children(item: pytest.Item, report: pytest.TestReport) -> None:
    """Turn ``report`` (one phase of ``item``: setup, call or teardown) into a failure naming the
    first child process of :data:`STARTED` when ``item`` is not marked ``subprocess``; clear
    :data:`STARTED` either way. A phase that already failed or was skipped keeps its own report."""
    started = list(STARTED)
    STARTED.clear()
    if started and report.passed and item.get_closest_marker("subprocess") is None:
        report.outcome = "failed"
        report.longrepr = (
            f"{item.nodeid} started {len(started)} child process(es) ({started[0]}) in its "
            f"{report.when} but is not marked @pytest.mark.subprocess (mark it, and slow if it "
            "takes seconds)"
        )


_watching = False


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_protocol(item, nextitem):
    global _watching
    if not _watching:
        watch_children()
        _watching = True


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item, call):
    report = yield
    unmarked_children(item, report)
    return report


@pytest.fixture(scope="session")
def finished_run(tmp_path_factory) -> Path:
    """A finished 2-iteration reacher meta-train run (2 goals x 2 worlds, horizon 5). Do not modify."""
    from warp_critic.methods.ours import TrainConfig, meta_train

    out = tmp_path_factory.mktemp("finished") / "run"
    meta_train(
        TrainConfig(
            scene=REACHER,
            goals=[[0.5, 0.3], [-0.4, 0.2]],
            worlds_per_goal=2,
            horizon=5,
            iterations=2,
            device="cpu",
            out=str(out),
            checkpoint_every=1,
        ),
        progress=False,
    )
    return out


@pytest.fixture
def copy_of(tmp_path):
    """``copy_of(run_dir) -> Path``: a private copy of a run directory to modify."""

    def make(run: Path) -> Path:
        dest = tmp_path / f"copy-{run.name}"
        shutil.copytree(run, dest)
        return dest

    return make


def link_mesh(length: float = 0.5, radius: float = 0.05, sides: int = 12) -> tuple[str, str]:
    """A closed ``sides``-gon prism along x (0 to ``length``): MJCF ``vertex`` and ``face`` text."""
    import math

    ring = [
        (radius * math.cos(2 * math.pi * i / sides), radius * math.sin(2 * math.pi * i / sides))
        for i in range(sides)
    ]
    verts = [(x, y, z) for x in (0.0, length) for y, z in ring] + [(0.0, 0, 0), (length, 0, 0)]
    a, b = 2 * sides, 2 * sides + 1  # the two end-cap centres
    faces = []
    for i in range(sides):
        j = (i + 1) % sides
        faces += [
            (i, j, sides + j),
            (i, sides + j, sides + i),
            (a, j, i),
            (b, sides + i, sides + j),
        ]
    vertex = " ".join(f"{c:.5f}" for v in verts for c in v)
    return vertex, " ".join(str(k) for f in faces for k in f)


MESH_ARM = """<mujoco model="mesh_arm">
  <compiler angle="radian"/>
  <asset><mesh name="link" vertex="{vertex}" face="{face}"/></asset>
  <worldbody>
    <geom type="cylinder" size="0.08 0.05" pos="0 0 0.05" contype="0" conaffinity="0"/>
    <body name="l1" pos="0 0 0.1">
      <joint name="j1" type="hinge" axis="0 0 1" range="-2 2"/>
      <inertial pos="0.25 0 0" mass="1" diaginertia="0.001 0.02 0.02"/>
      <geom type="mesh" mesh="link" contype="0" conaffinity="0"/>
      <body name="l2" pos="0.5 0 0">
        <joint name="j2" type="hinge" axis="0 0 1" range="-2 2"/>
        <inertial pos="0.25 0 0" mass="1" diaginertia="0.001 0.02 0.02"/>
        <geom type="mesh" mesh="link" contype="0" conaffinity="0"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.fixture(scope="session")
def mesh_arm(tmp_path_factory) -> Path:
    """The path of an MJCF two-link arm drawn from triangle meshes (see :func:`link_mesh`)."""
    vertex, face = link_mesh()
    path = tmp_path_factory.mktemp("mesh_arm") / "mesh_arm.xml"
    path.write_text(MESH_ARM.format(vertex=vertex, face=face))
    return path
