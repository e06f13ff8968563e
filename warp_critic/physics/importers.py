"""Newton's importers, one call per robot-file format, and the builder surgery a robot file needs.

* :func:`import_builder`: ``add_urdf`` (the URDF without its meshes: they are not needed for
  dynamics; one warning names the first missing mesh file), ``add_mjcf`` or ``add_usd``;
* :func:`check_topology`: refuse floating bases and closed loops;
* :func:`lock`: weld joints at a position; :func:`collapse`: merge fixed joints, keeping every
  per-DoF list aligned; :func:`depths`: each body's depth in the kinematic tree.
"""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from warp_critic.core.errors import SceneError
from warp_critic.physics.actuation import Actuation, mjcf_resolver, read_mjcf, read_urdf
from warp_critic.physics.mjcf_file import (
    check_one_joint_per_body,
    expand,
    flatten_names,
    keyframe_home,
    loops,
    one_articulation,
    strip_meshes,
)
from warp_critic.physics.robot_meshes import mesh_path


def fail(path: Path, problem: str) -> SceneError:
    return SceneError(f"{path}: {' '.join(str(problem).split())}")


def short(label: str) -> str:
    return label.rsplit("/", 1)[-1]


# ------------------------------------------------------------------------------------------------


def _urdf_without_meshes(path: Path) -> tuple[str, str | None, ET.Element]:
    """The URDF text with mesh visuals/colliders removed, the first mesh file that is missing, and
    the parsed root element."""
    try:
        tree = ET.parse(path)
    except (ET.ParseError, OSError) as exc:
        raise fail(path, f"not a readable URDF ({exc})") from None
    robot = tree.getroot()
    if robot.tag != "robot":
        raise fail(path, f"not a URDF (root element <{robot.tag}>, expected <robot>)")
    if robot.find("link") is None:
        raise fail(path, "no <link> in the URDF: not a robot")
    missing = None
    for link in robot.iter("link"):
        for kind in ("visual", "collision"):
            for element in list(link.findall(kind)):
                mesh = element.find("geometry/mesh")
                if mesh is None:
                    continue
                if missing is None and not _mesh_exists(path, mesh.get("filename", "")):
                    missing = mesh.get("filename", "")
                link.remove(element)
    return ET.tostring(robot, encoding="unicode"), missing, robot


def _mesh_exists(urdf: Path, filename: str) -> bool:
    """Whether a URDF mesh reference resolves to a file (package:// searched up from the URDF)."""

    return mesh_path(urdf, filename) is not None


# the armature and damping newton gives a joint whose file authors none: derived later
# (derive.model_defaults), the file's own values kept
UNSET = -1.0


def import_builder(path: Path, fmt: str) -> tuple[Any, Actuation, list[str]]:
    """Newton's importer for the file's format (``urdf``, ``mjcf`` or ``usd``: read from its
    content, :mod:`warp_critic.physics.file_format`) -> a ModelBuilder with fixed joints still in
    (an MJCF's props left out), what the file actuates, and the notes for the user (a missing mesh,
    the props dropped), to be said once the file has passed its checks. Joints whose file gives no
    armature or damping carry :data:`UNSET` there."""
    import newton

    builder = newton.ModelBuilder()
    builder.default_joint_cfg.armature = UNSET
    builder.default_joint_cfg.damping = UNSET
    missing = None
    actuation = Actuation()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if fmt == "urdf":
                text, missing, root = _urdf_without_meshes(path)
                actuation = read_urdf(root)
                builder.add_urdf(text, joint_ordering="dfs")
            elif fmt == "mjcf":
                actuation, mesh_notes = _read_mjcf(path)
                # equalities are checked against the trained joints (joint_choice.check_loops, the
                # couplings of robot_checks): one inside a locked gripper is no concern
                assert actuation.root is not None  # read_mjcf keeps the tree newton is to read
                builder.add_mjcf(
                    ET.tostring(actuation.root, encoding="unicode"),
                    path_resolver=mjcf_resolver(path),
                    skip_equality_constraints=True,
                )
                # a <position>/<velocity> actuator's kp/kv become newton's joint drive gains, which
                # the Featherstone step applies as a spring-damper to a zero target on top of the
                # policy's torques (explicitly: the FR3's kv 200 on a 0.08 kg m^2 wrist diverges
                # at any dt >= 1 ms). warp-critic drives the joints with torques only (its bound is
                # the actuator's force range): the servo's gains are the controller's, not the robot's
                builder.joint_target_ke = [0.0] * len(builder.joint_target_ke)
                builder.joint_target_kd = [0.0] * len(builder.joint_target_kd)
            else:
                builder.add_usd(str(path), load_sites=False)
        except SceneError:
            raise
        except Exception as exc:  # newton/pxr/xml errors: one line, never a traceback
            text = " ".join(str(exc).split())[:300] or type(exc).__name__
            raise fail(path, f"newton's importer failed: {text}") from None
    for w in caught:
        text = str(w.message)
        if missing is None and "does not exist" in text and "Asset file" in text:
            missing = text.split("Asset file", 1)[1].split("does not exist")[0].strip()
    notes = list(mesh_notes) if fmt == "mjcf" else []
    if missing:
        notes.append(f"{path}: mesh file {missing} is missing (meshes are not needed for dynamics)")
    if actuation.props:
        notes.append(
            f"{path}: dropped {len(actuation.props)} bodies outside the actuated robot "
            f"(no actuated joint): {', '.join(actuation.props)}"
        )
    return builder, actuation, notes


def _read_mjcf(path: Path) -> tuple[Actuation, list[str]]:
    """An MJCF file's tree as newton is to read it (:mod:`warp_critic.physics.mjcf_file`: includes
    expanded, props dropped, the meshes no inertia needs removed) in its :class:`Actuation`, with
    its ``home`` keyframe, its drawn meshes and its loops; and the notes of its meshes."""
    root = expand(path)
    flatten_names(root)
    home = keyframe_home(root)  # before the props go: the key's qpos counts their joints
    actuation = read_mjcf(root)
    check_one_joint_per_body(path, root)  # the robot's bodies: the props are gone
    notes, drawn = strip_meshes(path, root)
    one_articulation(root)
    actuation.home, actuation.drawn, actuation.loops = home, drawn, loops(root)
    return actuation, notes


def check_topology(path: Path, builder) -> None:
    """Refuse floating bases, closed loops and bodies that two joints move."""
    import newton

    free = {int(newton.JointType.FREE), int(newton.JointType.DISTANCE)}
    for j, t in enumerate(builder.joint_type):
        if int(t) in free:
            raise fail(
                path,
                f"floating base: joint {short(builder.joint_label[j])!r} lets "
                f"{short(builder.body_label[builder.joint_child[j]])!r} move freely in the world; "
                "warp-critic trains fixed-base robots",
            )
    children = list(builder.joint_child)
    loops = len(children) != len(set(children)) or any(a < 0 for a in builder.joint_articulation)
    eq = getattr(builder, "equality_constraint_type", None) or []
    if loops or len(eq):
        raise fail(path, "closed kinematic loop: warp-critic trains open-chain (tree) robots")
    jointed = set(children)
    for b, label in enumerate(builder.body_label):
        if b not in jointed:
            raise fail(path, f"floating base: body {short(label)!r} has no joint to the world")


def lock(builder, locked: list[int], home: dict[int, float]) -> None:
    """Turn the joints ``locked`` into fixed joints at their home position (baked into X_p)."""
    import newton
    import warp as wp

    for j in locked:
        q = home.get(j, 0.0)
        dof = builder.joint_qd_start[j]
        axis = wp.vec3(*builder.joint_axis[dof])
        if int(builder.joint_type[j]) == int(newton.JointType.REVOLUTE):
            motion = wp.transform(wp.vec3(0.0, 0.0, 0.0), wp.quat_from_axis_angle(axis, q))
        else:
            motion = wp.transform(axis * q, wp.quat_identity())
        builder.joint_X_p[j] = wp.transform_expand(builder.joint_X_p[j]) * motion
        builder.joint_type[j] = newton.JointType.FIXED


# per-DoF lists that collapse_fixed_joints() does not rebuild (it truncates or leaves them)
_PER_DOF_KEPT = ("joint_f", "joint_act", "joint_velocity_limit", "joint_friction")


def collapse(builder) -> dict:
    """``builder.collapse_fixed_joints()``, with every per-DoF list realigned to the kept joints."""
    saved = {}
    for j, label in enumerate(builder.joint_label):
        start = builder.joint_qd_start[j]
        end = (
            builder.joint_qd_start[j + 1] if j + 1 < builder.joint_count else len(builder.joint_qd)
        )
        saved[label] = {a: list(getattr(builder, a)[start:end]) for a in _PER_DOF_KEPT}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        info = builder.collapse_fixed_joints()
    for a in _PER_DOF_KEPT:
        setattr(builder, a, [v for label in builder.joint_label for v in saved[label][a]])
    return info


def depths(builder) -> tuple[list[int], list[int]]:
    """Per body: depth in joints from the world, and the body's joint (original order)."""
    parent_of = {c: p for p, c in zip(builder.joint_parent, builder.joint_child)}
    depth = []
    for b in range(builder.body_count):
        d, x = 0, b
        while x >= 0 and d <= builder.body_count:
            x, d = parent_of.get(x, -1), d + 1
        depth.append(d)
    return depth, list(parent_of)


def moved_bodies(builder, joints: set[int]) -> list[int]:
    """The bodies that one of ``joints`` moves (their subtrees), in body order."""
    parent_joint = {c: j for j, c in enumerate(builder.joint_child)}
    out = []
    for b in range(builder.body_count):
        x, steps = b, 0
        while x >= 0 and x in parent_joint and steps <= builder.body_count:
            if parent_joint[x] in joints:
                out.append(b)
                break
            x, steps = builder.joint_parent[parent_joint[x]], steps + 1
    return out
