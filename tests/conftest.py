"""Shared test set-up.

* The test process starts the way the CLI starts a command (:func:`warp_critic.core.runtime.init`: Warp
  started quietly, one torch thread), so library-level tests see what users see.
* The scenes' paths, for every test module (``from conftest import REACHER``).
* ``finished_run``: one tiny finished meta-train run directory, made once per session; tests that
  change it work on a copy (``copy_of``).
* ``mesh_arm``: a planar two-link MJCF arm whose links are triangle meshes (no collision, explicit
  inertials), for the recordings' mesh drawing.
"""

from __future__ import annotations

import shutil
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
