"""Finding the scene a saved run was trained on, by its content.

A run records its scene's absolute path (``scene_file``) and content hash (``scene_hash``); runs made
before that record the path as it was given (relative to where training ran). The scene is looked
for, in order, at the recorded absolute path, at the path as given, next to the shipped scenes (same
file name), and among all shipped scenes; the first file whose content hash is the run's is used.
A file found elsewhere than recorded is named in a one-line warning.
"""

from __future__ import annotations

from pathlib import Path

from warp_critic.core.errors import SceneError, UserError, warn
from warp_critic.physics.load import load_scene
from warp_critic.physics.scene import Scene, scenes_dir


def _candidates(recorded: list[str]) -> list[Path]:
    out: list[Path] = []
    for r in recorded:
        out.append(Path(r))
    shipped = scenes_dir()
    for r in recorded:
        out.append(shipped / Path(r).name)
    out += sorted(shipped.glob("*.usda"))
    seen, unique = set(), []
    for p in out:
        key = str(p.absolute())
        if key not in seen:
            seen.add(key)
            unique.append(p)
    return unique


def _loader(config: dict):
    """``path -> Scene`` with the run's robot options (a robot file's end effector, joints)."""
    from warp_critic.physics.load import load_any

    joints = config.get("joints")
    if joints is not None:
        joints = [n.strip() for n in str(joints).split(",") if n.strip()]
    ee_body, tip_offset = config.get("ee_body"), config.get("tip_offset")
    if ee_body is None and tip_offset is None and joints is None:
        return load_scene
    return lambda path: load_any(path, ee_body=ee_body, tip_offset=tip_offset, joints=joints)


def find_run_scene(ckpt: dict, run_dir) -> Scene:
    """The scene of the run whose checkpoint is ``ckpt`` (see the module docstring)."""
    given = str(ckpt["config"]["scene"])
    load_scene = _loader(ckpt["config"])
    recorded = [r for r in (ckpt.get("scene_file"), given) if r]
    want = ckpt.get("scene_hash")
    if not want:  # a run that recorded no content hash: the path as recorded
        return load_scene(recorded[0])
    first = Path(recorded[0])
    for p in _candidates(recorded):
        if not p.is_file():
            continue
        try:
            scene = load_scene(str(p))
        except SceneError:
            continue
        if scene.content_hash == want:
            if p.absolute() != first.absolute():
                why = "has other content" if first.is_file() else "is not found"
                warn(
                    f"{run_dir}: its scene {given} {why} here; using {p}: it has the same content "
                    "as the scene the run was trained on"
                )
            return scene
    if first.is_file():
        raise UserError(
            f"{run_dir}: the scene file {given} has changed since the run was trained "
            f"(and no scene in {scenes_dir()} has its content)"
        )
    raise UserError(
        f"{run_dir}: the scene file {given} is not found "
        f"(nor a scene with its content in {scenes_dir()})"
    )


__all__ = ["find_run_scene"]
