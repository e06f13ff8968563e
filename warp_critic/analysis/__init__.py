"""The paper's analyses: the 1-D toy of section 4.1 (:mod:`.toy`, ``docs/toy.md``) and the 2-D
point-mass landscapes of section 4.2 (:mod:`.landscape`, ``docs/landscape.md``); :mod:`.checks`
holds their settings' range checks."""

from __future__ import annotations

from pathlib import Path

from warp_critic.physics.scene import scenes_dir

__all__ = ["scene_path"]


def scene_path(name: str) -> Path:
    """A scene shipped with warp-critic, e.g. ``scene_path("point_mass.usda")`` (works from any cwd)."""
    return scenes_dir() / name
