"""Reading a USD scene file: open it, check what newton's importer would silently repair, import it.

:func:`read_usd_scene` is what :func:`warp_critic.physics.load.load_scene` calls for a USD file
(the format: :mod:`warp_critic.physics.schema`). Every problem is a one-line
:class:`~warp_critic.core.errors.SceneError` naming the file; pxr and newton errors on odd files
never escape as tracebacks.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path
from typing import Any

import numpy as np

from warp_critic.core.errors import FieldError, SceneError
from warp_critic.physics import schema
from warp_critic.physics.model_checks import check_model, check_tip_offset
from warp_critic.physics.scene import Scene
from warp_critic.physics.scene_hash import content_hash
from warp_critic.physics.schema import EE_ATTR, EFFORT_ATTR, TIP_ATTR
from warp_critic.physics.variants import is_finite

__all__ = ["read_usd_scene"]


def _fail(path: Path, problem: str) -> SceneError:
    return SceneError(f"{path}: {' '.join(str(problem).split())}")


def _open_stage(path: Path):
    from pxr import Sdf, Usd

    if Sdf.FileFormat.FindByExtension(path.suffix.lstrip(".")) is None:
        raise _fail(
            path,
            f"not a USD file (unknown extension {path.suffix or '(none)'!r}; "
            "expected .usd, .usda, .usdc or .usdz)",
        )
    try:
        stage = Usd.Stage.Open(str(path))
        if stage is not None:
            # USD keeps layers that are still referenced in memory and Open reuses them: read
            # again what changed on disk since (a file edited while this process runs)
            stage.Reload()
    except Exception as exc:  # pxr.Tf.ErrorException and friends
        raise _fail(path, f"not a readable USD file ({_first_line(exc)})") from None
    if stage is None:
        raise _fail(path, "not a readable USD file")
    return stage


def _first_line(exc: BaseException) -> str:
    """A short one-line reason; pxr errors read "Error in '<function>' at line N in file F : '<reason>'"."""
    text = " ".join(str(exc).split())
    reason = re.search(r" : '([^']+)'", text)
    if reason:
        text = reason.group(1)
    return text[:300] if text else type(exc).__name__


def _check_stage(path: Path, stage) -> tuple[object, dict[str, float]]:
    """Validate what newton's importer would silently repair; return (root prim, effort by joint)."""
    from pxr import UsdPhysics

    roots, joints, bodies = [], [], []
    for prim in stage.Traverse():
        if prim.HasAPI(UsdPhysics.ArticulationRootAPI):
            roots.append(prim)
        if prim.IsA(UsdPhysics.Joint):
            joints.append(prim)
        if prim.HasAPI(UsdPhysics.RigidBodyAPI):
            bodies.append(prim)
    if not roots:
        raise _fail(path, "no prim with UsdPhysics.ArticulationRootAPI (not a robot scene)")
    if len(roots) > 1:
        raise _fail(path, f"{len(roots)} articulation roots; a scene holds exactly one robot")
    if not joints:
        raise _fail(path, "the articulation has no joints")
    if not bodies:
        raise _fail(path, "no rigid bodies (UsdPhysics.RigidBodyAPI)")
    _known_attributes(path, stage)

    effort: dict[str, float] = {}
    for prim in joints:
        if not (prim.IsA(UsdPhysics.RevoluteJoint) or prim.IsA(UsdPhysics.PrismaticJoint)):
            raise _fail(
                path,
                f"joint {prim.GetPath()} is a {prim.GetTypeName()}; only "
                "PhysicsRevoluteJoint and PhysicsPrismaticJoint are supported",
            )
        value = prim.GetAttribute(EFFORT_ATTR).Get() if prim.HasAttribute(EFFORT_ATTR) else None
        if value is None or not is_finite(value) or value <= 0.0:
            raise _fail(
                path, f"joint {prim.GetPath()} needs a positive {EFFORT_ATTR} (got {value})"
            )
        effort[str(prim.GetPath())] = float(value)

    for prim in bodies:
        mass_api = UsdPhysics.MassAPI(prim)
        mass = mass_api.GetMassAttr().Get() if prim.HasAPI(UsdPhysics.MassAPI) else None
        if mass is None or not prim.GetAttribute("physics:mass").HasAuthoredValue():
            raise _fail(path, f"link {prim.GetPath()} has no physics:mass (MassAPI)")
        if not is_finite(mass) or mass <= 0.0:
            raise _fail(path, f"link {prim.GetPath()} has non-positive mass {mass} kg")
        inertia = mass_api.GetDiagonalInertiaAttr().Get()
        if inertia is None or not mass_api.GetDiagonalInertiaAttr().HasAuthoredValue():
            raise _fail(path, f"link {prim.GetPath()} has no physics:diagonalInertia")
        if not all(is_finite(v) for v in inertia) or any(v < 0.0 for v in inertia):
            raise _fail(
                path, f"link {prim.GetPath()} has negative or non-finite inertia {tuple(inertia)}"
            )
        if sum(inertia) <= 0.0:
            raise _fail(path, f"link {prim.GetPath()} has zero inertia")
    return roots[0], effort


#: Every ``warp_critic:*`` attribute a scene may author (the loader reads each of them).
KNOWN_ATTRIBUTES = (
    EE_ATTR,
    TIP_ATTR,
    EFFORT_ATTR,
    "warp_critic:importRepairs",  # the repairs an import made (physics/export.py)
    *(a.usd for a in schema.ATTRIBUTES),
)


def _known_attributes(path: Path, stage) -> None:
    """A ``warp_critic:*`` attribute the loader does not read is a typing mistake that would
    otherwise change nothing: named, with the nearest real one."""
    import difflib

    for prim in stage.Traverse():
        for prop in prim.GetProperties():
            name = prop.GetName()
            if name.startswith("warp_critic:") and name not in KNOWN_ATTRIBUTES:
                near = difflib.get_close_matches(name, KNOWN_ATTRIBUTES, n=1)
                hint = (
                    f"did you mean {near[0]}?"
                    if near
                    else "warp-critic reads "
                    + ", ".join(a.split(":", 1)[1] for a in KNOWN_ATTRIBUTES)
                )
                raise _fail(path, f"{prim.GetPath()}: unknown attribute {name} ({hint})")


def _read_root(path: Path, root) -> tuple[str, np.ndarray]:
    """The end-effector name and tip offset authored on the articulation root."""
    ee_name = root.GetAttribute(EE_ATTR).Get() if root.HasAttribute(EE_ATTR) else None
    if not ee_name or not isinstance(ee_name, str):
        raise _fail(
            path, f"articulation root {root.GetPath()} lacks the string attribute {EE_ATTR}"
        )
    raw = root.GetAttribute(TIP_ATTR).Get() if root.HasAttribute(TIP_ATTR) else None
    try:
        tip = np.array([float(v) for v in (() if raw is None else raw)], dtype=np.float64)
    except (TypeError, ValueError):
        tip = None
    if tip is None or tip.shape != (3,) or not np.isfinite(tip).all():
        raise _fail(path, f"articulation root {root.GetPath()} lacks a finite float3 {TIP_ATTR}")
    return ee_name, tip


def _read_defaults(
    path: Path, root, q_lower: np.ndarray, q_upper: np.ndarray, joint_names: list[str]
) -> tuple[dict[str, Any], np.ndarray]:
    """The training defaults the articulation root authors (``Scene.defaults``) and the home pose,
    each checked against its rule in :data:`~warp_critic.physics.schema.ATTRIBUTES`."""
    defaults: dict[str, Any] = {}
    home = np.zeros(len(joint_names))
    for attr in schema.ATTRIBUTES:
        prop = root.GetAttribute(attr.usd) if root.HasAttribute(attr.usd) else None
        raw = prop.Get() if prop is not None and prop.HasAuthoredValue() else None
        if raw is None:
            continue
        try:
            value = schema.parse(attr, raw, q_lower, q_upper, joint_names)
        except schema.RuleError as exc:
            raise _fail(path, f"articulation root {root.GetPath()}: {attr.usd} {exc}") from None
        if attr.key == "home":
            home = np.array(value, dtype=np.float64)
        else:
            defaults[attr.key] = value
    return defaults, home


def read_usd_scene(path: Path) -> Scene:
    """Parse and validate the USD scene file at ``path`` (resolved, existing)."""
    import newton

    stage = _open_stage(path)
    try:
        root, effort = _check_stage(path, stage)
        ee_name, tip = _read_root(path, root)
        digest = content_hash(path, stage)
    except SceneError:
        raise
    except Exception as exc:  # unexpected pxr errors on odd files must not escape either
        raise _fail(path, f"invalid scene ({_first_line(exc)})") from None

    if importlib.util.find_spec("newton_usd_schemas") is None:
        # an installation problem, not a scene problem: let it surface as such
        raise ImportError(
            "newton's USD importer needs the 'newton-usd-schemas' package "
            "(pip install 'newton-usd-schemas>=0.6')"
        )

    builder = newton.ModelBuilder()
    try:
        builder.add_usd(stage, load_sites=False)
    except Exception as exc:  # newton/pxr errors must not escape
        raise _fail(path, f"newton's USD importer failed: {_first_line(exc)}") from None

    # The importer must have produced exactly one chain of 1-DoF joints.
    allowed = {int(newton.JointType.REVOLUTE), int(newton.JointType.PRISMATIC)}
    if any(int(t) not in allowed for t in builder.joint_type):
        raise _fail(
            path,
            "the imported articulation has joints other than revolute/prismatic "
            "(is a body missing a joint to the world or to its parent?)",
        )
    if not (
        builder.joint_coord_count == builder.joint_dof_count == builder.joint_count == len(effort)
    ):
        raise _fail(
            path,
            f"imported {builder.joint_count} joints / {builder.joint_dof_count} DoFs "
            f"but the file has {len(effort)} revolute/prismatic joints",
        )

    labels = list(builder.body_label)
    matches = [
        i
        for i, label in enumerate(labels)
        if label == ee_name or label.rsplit("/", 1)[-1] == ee_name
    ]
    if len(matches) != 1:
        raise _fail(
            path,
            f"{EE_ATTR} = {ee_name!r} names {len(matches)} of the bodies "
            f"{[label.rsplit('/', 1)[-1] for label in labels]}",
        )

    try:
        effort_limit = np.array([effort[label] for label in builder.joint_label])
    except KeyError as exc:
        raise _fail(path, f"imported joint {exc} not found in the file") from None
    builder.joint_effort_limit = [float(v) for v in effort_limit]

    # what an imported robot file must satisfy (masses in range, valid inertias, limits, axes,
    # the tip), checked the same way on a scene file (a copy of a scene edited by hand)
    check_model(path, builder)
    try:
        check_tip_offset(tip.tolist())
    except FieldError as e:
        raise _fail(path, f"{TIP_ATTR} {e.problem}") from None

    joint_names = [label.rsplit("/", 1)[-1] for label in builder.joint_label]
    try:
        defaults, home = _read_defaults(
            path,
            root,
            np.array(builder.joint_limit_lower, dtype=np.float64),
            np.array(builder.joint_limit_upper, dtype=np.float64),
            joint_names,
        )
    except SceneError:
        raise
    except Exception as exc:  # unexpected pxr errors on odd attributes must not escape either
        raise _fail(path, f"invalid training defaults ({_first_line(exc)})") from None
    return Scene(
        path,
        builder,
        matches[0],
        tip,
        effort_limit,
        defaults=defaults,
        home=home,
        content_hash=digest,
    )
