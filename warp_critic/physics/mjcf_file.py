"""An MJCF file made ready for newton's importer: what it includes, which meshes it needs, its home.

* :func:`expand`: the file with every ``<include>`` pasted in (newton's own expansion, the one
  ``add_mjcf`` does; asset paths made absolute), one tree that the actuation reader, the checks
  and the importer all read;
* :func:`strip_meshes`: mesh geoms are needed for dynamics only where a body's mass and inertia
  come from its geoms (no ``<inertial>`` under ``inertiafromgeom="auto"``, every body under
  ``"true"``); the others are removed before newton reads the file (it would load each mesh file
  to build colliders warp-critic never uses). A missing or unreadable mesh file a body's inertia
  needs is refused in one line; any other is one note. The removed geoms are kept for drawing
  (:class:`DrawnMesh`);
* :func:`keyframe_home`: the ``<keyframe><key name="home">`` joint positions;
* :func:`loops`: the ``<equality>`` ``connect``/``weld`` pairs (closed kinematic loops), checked
  against the trained joints (a loop inside a locked gripper is rigid, so no concern).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from warp_critic.core.errors import SceneError

__all__ = [
    "DrawnMesh",
    "expand",
    "flatten_names",
    "keyframe_home",
    "one_articulation",
    "loops",
    "strip_meshes",
]

# qpos entries per MJCF joint type (hinge and slide: 1)
_QPOS = {"free": 7, "ball": 4}
# mesh file formats the drawing reads: STL without any package, OBJ with trimesh
_DRAWN_SUFFIXES = (".stl", ".obj")


@dataclass(frozen=True)
class DrawnMesh:
    """One mesh geom of a body, for drawing.

    Attributes:
        body: the MJCF body name.
        pose: ``(7,)`` the geom's frame in the body: position [m], quaternion ``(x, y, z, w)``.
        file: the mesh file (absolute).
        scale: ``(3,)`` the mesh asset's scale.
        visual: whether the geom is a visual one (no contacts), drawn in preference to colliders.
    """

    body: str
    pose: tuple[float, ...]
    file: str
    scale: tuple[float, float, float]
    visual: bool


def _fail(path: Path, problem: str) -> SceneError:
    return SceneError(f"{path}: {' '.join(str(problem).split())}")


def expand(path: Path) -> ET.Element:
    """The MJCF file's root element with its ``<include>`` elements expanded (newton's expansion,
    the one its importer does: a file's assets resolved to absolute paths). Raises SceneError."""
    from newton._src.utils.import_mjcf import _load_and_expand_mjcf

    try:
        root, _ = _load_and_expand_mjcf(str(path))
    except ET.ParseError as exc:
        raise _fail(path, f"not a readable MJCF file ({exc})") from None
    except (OSError, ValueError) as exc:
        raise _fail(path, f"an <include> cannot be read ({exc})") from None
    return root


def _classes(root: ET.Element) -> dict[str, dict[str, dict[str, str]]]:
    from warp_critic.physics.actuation import _default_classes

    return _default_classes(root)


def _compiler(root: ET.Element, key: str, default: str) -> str:
    values = [c.get(key) for c in root.iter("compiler") if c.get(key) is not None]
    return str(values[-1]).lower() if values else default


def _bodies(root: ET.Element):
    """``(body element, its childclass in effect)`` for every body under ``<worldbody>``."""
    out: list[tuple[ET.Element, str]] = []

    def walk(element: ET.Element, cls: str) -> None:
        for child in element:
            if child.tag in ("body", "frame"):
                inner = child.get("childclass", cls)
                if child.tag == "body":
                    out.append((child, inner))
                walk(child, inner)

    for world in root.findall("worldbody"):
        walk(world, "main")
    return out


def _attrs(element: ET.Element, tag: str, cls: str, classes) -> dict[str, str]:
    """An element's attributes over its default class's (``class``, else the childclass)."""
    defaults = classes.get(element.get("class", cls), classes.get("main", {}))
    return {**defaults.get(tag, {}), **element.attrib}


def _quat(attrs: dict[str, str], degrees: bool, seq: str) -> tuple[float, ...] | None:
    """An MJCF orientation as ``(x, y, z, w)`` (identity where none is given; None for the forms
    the drawing does not place: ``xyaxes``, ``zaxis``)."""
    if "quat" in attrs:
        w, x, y, z = (float(v) for v in attrs["quat"].split())
        n = math.sqrt(w * w + x * x + y * y + z * z) or 1.0
        return (x / n, y / n, z / n, w / n)
    unit = math.pi / 180.0 if degrees else 1.0
    if "axisangle" in attrs:
        x, y, z, a = (float(v) for v in attrs["axisangle"].split())
        n = math.sqrt(x * x + y * y + z * z) or 1.0
        s = math.sin(0.5 * a * unit) / n
        return (x * s, y * s, z * s, math.cos(0.5 * a * unit))
    if "euler" in attrs:
        q = np.array([0.0, 0.0, 0.0, 1.0])
        for axis, angle in zip(seq, (float(v) for v in attrs["euler"].split())):
            e = np.zeros(3)
            e["xyz".index(axis.lower())] = math.sin(0.5 * angle * unit)
            r = np.array([*e, math.cos(0.5 * angle * unit)])
            # lower case: axes that move with the frame (q r); upper case: fixed axes (r q)
            q = _qmul(q, r) if axis.islower() else _qmul(r, q)
        return tuple(float(v) for v in q)
    if "xyaxes" in attrs or "zaxis" in attrs:
        return None
    return (0.0, 0.0, 0.0, 1.0)


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    (ax, ay, az, aw), (bx, by, bz, bw) = a, b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def _mesh_assets(root: ET.Element, classes) -> dict[str, tuple[str, tuple[float, float, float]]]:
    """Mesh asset name -> (file, scale)."""
    out = {}
    for asset in root.iter("asset"):
        for mesh in asset.findall("mesh"):
            attrs = _attrs(mesh, "mesh", "main", classes)
            file = attrs.get("file")
            if not file:
                continue
            name = attrs.get("name") or Path(file).name.rsplit(".", 1)[0]
            scale = tuple(float(v) for v in attrs.get("scale", "1 1 1").split())
            out[name] = (file, (scale[0], scale[1], scale[2]) if len(scale) == 3 else (1.0,) * 3)
    return out


def _readable(file: str) -> bool:
    p = Path(file)
    return p.is_file() and p.stat().st_size > 0


def strip_meshes(path: Path, root: ET.Element) -> tuple[list[str], list[DrawnMesh]]:
    """Remove (in ``root``) the mesh geoms no body's inertia needs (module docstring). Returns the
    notes for the user (the first missing mesh file a drawing would have used) and the removed
    geoms, for drawing. Raises SceneError where a mesh the dynamics need is missing."""
    classes = _classes(root)
    assets = _mesh_assets(root, classes)
    from_geoms = _compiler(root, "inertiafromgeom", "auto")
    degrees = _compiler(root, "angle", "degree") != "radian"
    seq = str(next((c.get("eulerseq") for c in root.iter("compiler") if c.get("eulerseq")), "xyz"))
    drawn: list[DrawnMesh] = []
    missing: str | None = None
    for body, cls in _bodies(root):
        needs = from_geoms == "true" or (from_geoms == "auto" and body.find("inertial") is None)
        for geom in list(body.findall("geom")):
            attrs = _attrs(geom, "geom", cls, classes)
            mesh = attrs.get("mesh")
            if mesh is None or attrs.get("type", "mesh") != "mesh" or mesh not in assets:
                continue
            file, scale = assets[mesh]
            if needs:
                if not _readable(file):
                    raise _fail(
                        path,
                        f"body {body.get('name', '(unnamed)')!r} takes its mass and inertia from "
                        f"its geoms (no <inertial>), and its mesh file {file} is missing or empty",
                    )
                continue
            body.remove(geom)
            quat = _quat(attrs, degrees, seq)
            if not _readable(file):
                missing = missing or file
            elif quat is not None and Path(file).suffix.lower() in _DRAWN_SUFFIXES:
                pos = [float(v) for v in attrs.get("pos", "0 0 0").split()]
                visual = attrs.get("contype") == "0" and attrs.get("conaffinity") == "0"
                drawn.append(
                    DrawnMesh(body.get("name", ""), (*pos[:3], *quat), file, scale, visual)
                )
    used = {e.get("mesh") for e in root.iter() if e.get("mesh")}
    for asset in root.iter("asset"):  # meshes no geom uses: newton would load them all the same
        for element in list(asset.findall("mesh")):
            name = element.get("name") or Path(element.get("file", "")).name.rsplit(".", 1)[0]
            if name not in used:
                asset.remove(element)
    notes = []
    if missing:
        notes.append(
            f"{path}: mesh file {missing} is missing (meshes are not needed for dynamics: the "
            "bodies' <inertial> gives them; the robot is drawn without it)"
        )
    return notes, drawn


def _joint_type(joint: ET.Element, cls: str, classes) -> str:
    if joint.tag == "freejoint":
        return "free"
    return _attrs(joint, "joint", cls, classes).get("type", "hinge")


def keyframe_home(root: ET.Element) -> dict[str, float]:
    """Joint name -> its position [rad or m] in the ``home`` keyframe (hinge and slide joints;
    empty without such a key or where its ``qpos`` does not match the joints)."""
    key = next((k for kf in root.iter("keyframe") for k in kf.iter("key")
                if k.get("name") == "home" and k.get("qpos")), None)  # fmt: skip
    if key is None:
        return {}
    try:
        qpos = [float(v) for v in str(key.get("qpos")).split()]
    except ValueError:
        return {}
    classes = _classes(root)
    out: dict[str, float] = {}
    i = 0
    for body, cls in _bodies(root):
        for joint in body:
            if joint.tag not in ("joint", "freejoint"):
                continue
            kind = _joint_type(joint, cls, classes)
            n = _QPOS.get(kind, 1)
            if kind in ("hinge", "slide") and i < len(qpos) and joint.get("name"):
                out[str(joint.get("name"))] = qpos[i]
            i += n
    return out if i == len(qpos) else {}


def loops(root: ET.Element) -> list[tuple[str, str, str]]:
    """``(kind, body1, body2)`` for each active ``connect``/``weld`` equality between two bodies
    (a ``site``-form one: the sites' bodies); ``body2`` ``""`` for the world."""
    site_body = {
        str(s.get("name")): str(b.get("name", ""))
        for b, _ in _bodies(root)
        for s in b.findall("site")
        if s.get("name")
    }
    out = []
    for eq in root.iter("equality"):
        for e in eq:
            if e.tag not in ("connect", "weld") or e.get("active", "true") == "false":
                continue
            if e.get("site1"):
                b1, b2 = (
                    site_body.get(str(e.get("site1")), ""),
                    site_body.get(e.get("site2", ""), ""),
                )
            else:
                b1, b2 = e.get("body1", ""), e.get("body2", "")
            out.append((e.tag, b1, b2))
    return out


# attributes that name a body, joint, site, tendon or actuator
_REFERENCES = ("name", "joint", "joint1", "joint2", "body", "body1", "body2", "site", "site1",
               "site2", "tendon", "tendon1", "tendon2", "objname", "target", "jointinparent")  # fmt: skip


def flatten_names(root: ET.Element) -> None:
    """Replace ``/`` by ``_`` in the names of bodies, joints, sites and tendons and everywhere they
    are named (in ``root``): newton joins names into ``/``-separated labels, so ``F0/J0`` and
    ``F1/J0`` would both read back as ``J0``."""
    kinds = ("body", "joint", "freejoint", "site", "fixed", "spatial")
    slashed = {
        str(e.get("name")) for e in root.iter() if e.tag in kinds and "/" in e.get("name", "")
    }
    if not slashed:
        return
    for element in root.iter():
        for key in _REFERENCES:
            value = element.get(key)
            if value in slashed:
                element.set(key, value.replace("/", "_"))


def check_one_joint_per_body(path: Path, root: ET.Element) -> None:
    """Refuse a body that several hinge/slide joints move (newton merges them into one D6 joint,
    named after all of them, which warp-critic cannot train or lock)."""
    for body, _ in _bodies(root):
        joints = [j.get("name", "(unnamed)") for j in body.findall("joint")]
        if len(joints) > 1:
            shown = ", ".join(joints[:3]) + (f", .., {joints[-1]}" if len(joints) > 3 else "")
            who = f"body {body.get('name')!r}" if body.get("name") else "an unnamed body"
            raise _fail(
                path,
                f"{who} moves on {len(joints)} joints ({shown}), "
                "which newton merges into one D6 joint: warp-critic trains revolute and prismatic "
                "joints, one per body",
            )


def one_articulation(root: ET.Element) -> None:
    """Put the top-level bodies of ``<worldbody>`` (in ``root``) under one jointless, massless
    body: newton makes one articulation of each top-level body, and warp-critic steps one
    articulation per world (a hand whose fingers hang from the world, Shadow's DEX-EE, would
    become one per finger)."""
    worlds = root.findall("worldbody")
    tops = [(w, e) for w in worlds for e in w if e.tag in ("body", "frame")]
    if len(tops) < 2:
        return
    robot = ET.Element("body", {"name": "warp_critic_world"})
    worlds[0].insert(list(worlds[0]).index(tops[0][1]), robot)
    for world, element in tops:
        world.remove(element)
        robot.append(element)


GRIPPER_NAME = re.compile(r"grip|jaw|finger|claw", re.IGNORECASE)
