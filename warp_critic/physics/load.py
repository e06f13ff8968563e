"""The one way in: a scene file or a robot file, read by what the file is.

:func:`load_scene` reads our scene files (USD with ``warp_critic:*`` attributes, :mod:`.usd_scene`;
each file version once, :mod:`.scene_cache`) and imports robot files (URDF, MJCF, a USD robot
without our attributes: :mod:`.robot`, with the training defaults derived from the robot).
:func:`load_any` does the same with an import's options, which only robot files take. Both return
a :class:`~warp_critic.physics.scene.Scene` or raise one line naming the file (``SceneError``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from warp_critic.core.errors import SceneError
from warp_critic.physics.model_checks import check_tip_offset
from warp_critic.physics.robot import RobotOptions, is_robot_file, load_robot
from warp_critic.physics.scene import Scene
from warp_critic.physics.scene_cache import FileCache
from warp_critic.physics.usd_scene import read_usd_scene

__all__ = ["load_any", "load_scene"]

_CACHE: FileCache[Scene] = FileCache()


def load_scene(path: str | Path) -> Scene:
    """Parse and validate a scene file (once per file version; later calls hit a cache).

    Raises:
        SceneError: one line naming the file and the problem (missing file, not USD, no
            articulation root, unsupported joint, bad mass properties, ...).
    """
    path = Path(path).expanduser()
    if not path.exists():
        raise SceneError(f"{path}: no such scene file")
    if path.is_dir():
        raise SceneError(f"{path}: is a directory, not a USD scene file")
    if is_robot_file(path):  # a URDF/MJCF/plain USD robot: imported with derived defaults
        return load_robot(path)
    return _CACHE.get(path.resolve(), read_usd_scene)  # the one place a format is chosen


def load_any(
    path: str | Path,
    *,
    ee_body: str | None = None,
    tip_offset: Sequence[float] | None = None,
    joints: Sequence[str] | None = None,
    lock_mimic: bool = False,
    repair_inertia: bool = False,
    home: Mapping[str, float] | None = None,
) -> Scene:
    """A scene file (our ``warp_critic:*`` USD) or a robot file, by what the file is.

    ``tip_offset``: ``(3,)`` [m], or None; ``joints``: joint names, or None; ``home``: joint name ->
    home value [rad or m], or None (see :class:`RobotOptions`).
    """
    tip: tuple[float, float, float] | None = None
    if tip_offset is not None:
        if len(tip_offset) != 3:
            raise SceneError(f"{path}: tip_offset needs 3 values x,y,z (got {len(tip_offset)})")
        tip = (float(tip_offset[0]), float(tip_offset[1]), float(tip_offset[2]))
        check_tip_offset(tip)
    options = RobotOptions(
        ee_body=ee_body,
        tip_offset=tip,
        joints=None if joints is None else tuple(joints),
        lock_mimic=lock_mimic,
        repair_inertia=repair_inertia,
        home=None if home is None else tuple((str(k), float(v)) for k, v in home.items()),
    )
    path = Path(path).expanduser()
    if path.exists() and not path.is_dir() and is_robot_file(path):
        return load_robot(path, options)
    if options.any():
        asked = {"ee_body": ee_body, "tip_offset": tip_offset, "joints": joints, "home": home}
        given = [flag for flag, v in asked.items() if v is not None]
        raise SceneError(
            f"{path}: {', '.join(given)} apply to robot files (URDF, MJCF, USD without "
            "warp_critic attributes); this scene names its own end effector and joints"
        )
    return load_scene(path)
