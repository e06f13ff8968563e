"""The paper's analyses: the 1-D toy of section 4.1 (``toy*.py``, ``docs/toy.md``) and the 2-D
point-mass landscapes of section 4.2 (``landscape*.py``, ``docs/landscape.md``)."""

from __future__ import annotations

from pathlib import Path

import warp_critic


def scenes_dir() -> Path:
    """The repository's ``scenes/`` folder, found from the installed package (works from any cwd)."""
    return Path(warp_critic.__file__).resolve().parents[1] / "scenes"


def scene_path(name: str) -> Path:
    """``scenes/<name>`` of the repository, e.g. ``scene_path("point_mass.usda")``."""
    return scenes_dir() / name
