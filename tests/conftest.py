"""Shared test set-up.

* The test process starts the way the CLI starts a command (:func:`warp_critic.core.runtime.init`: Warp
  started quietly, one torch thread), so library-level tests see what users see.
* The scenes' paths, for every test module (``from conftest import REACHER``).
* ``finished_run``: one tiny finished meta-train run directory, made once per session; tests that
  change it work on a copy (``copy_of``).
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
