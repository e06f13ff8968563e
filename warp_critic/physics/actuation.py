"""What a robot file actuates: the joints it drives, their torque bounds, and the props beside it.

* MJCF: the joints named by ``<actuator>`` elements (``motor``, ``general``, ``position``, ...;
  default classes included). A motor's bound is ``gear x max |ctrlrange|`` (when the control is
  limited), capped by ``forcerange``; other actuator types give ``forcerange`` only. Bodies at the
  top of ``<worldbody>`` whose subtree holds joints, none of them driven by an actuator (directly
  or through a tendon: targets, objects, slide- or free-jointed props) are dropped before newton
  reads the file; a body without joints is welded to the world and kept. A file with no
  ``<actuator>`` drives every movable joint.
* URDF: the joints of ``<transmission>`` elements, and the revolute, continuous and prismatic
  joints whose ``<limit effort>`` is not zero.
* :func:`arm_chains`: an arm with a hand (the driven joints branch below a driven joint) trains the
  chain up to the branching body; a hand (chains that branch on a body no driven joint moves)
  trains every chain.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

# MJCF actuator elements that drive one joint through ``joint=``
_ACTUATORS = (
    "motor",
    "general",
    "position",
    "velocity",
    "intvelocity",
    "damper",
    "cylinder",
    "muscle",
    "plugin",  # an engine plugin's actuator (mujoco.pid, ...): its forcerange bounds the joint
)


@dataclass
class Actuation:
    """What the file actuates.

    Attributes:
        actuated: joint name -> the file's torque bound [N m or N] (None: the file gives none), or
            None when the file names no actuators at all (every movable joint is driven).
        props: names of the top-level MJCF bodies dropped (no actuated joint in their subtree).
        source: what decided ``actuated`` (``"actuators"``, ``"transmissions"``, ``"effort"``).
        tendons: joint name -> the MJCF tendon through which an actuator drives it (not modelled:
            the joint counts as unactuated, and its refusal names the tendon).
        home: MJCF joint name -> its position in the file's ``home`` keyframe [rad or m].
        drawn: the MJCF mesh geoms removed before import, for drawing
            (:class:`warp_critic.physics.mjcf_file.DrawnMesh`).
        loops: the MJCF ``connect``/``weld`` equalities ``(kind, body1, body2)``.
        root: the MJCF file's expanded tree, as newton read it (None: a URDF).
        spatial: the MJCF spatial tendons an actuator pulls (routed through sites: the joints
            they move are not named; not modelled).
    """

    actuated: dict[str, float | None] | None = None
    props: list[str] = field(default_factory=list)
    source: str = ""
    tendons: dict[str, str] = field(default_factory=dict)
    home: dict[str, float] = field(default_factory=dict)
    drawn: list = field(default_factory=list)
    loops: list[tuple[str, str, str]] = field(default_factory=list)
    root: ET.Element | None = None
    spatial: list[str] = field(default_factory=list)


def _number(text: str | None, default: float = math.nan) -> float:
    try:
        return float(text) if text is not None else default
    except ValueError:
        return default


def _pair(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    parts = text.split()
    if len(parts) != 2:
        return None
    lo, hi = _number(parts[0]), _number(parts[1])
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo >= hi:
        return None
    return lo, hi


def _default_classes(root: ET.Element) -> dict[str, dict[str, dict[str, str]]]:
    """MJCF ``<default>`` classes: class -> element tag -> attributes (nested classes inherit)."""
    classes: dict[str, dict[str, dict[str, str]]] = {}

    def walk(element: ET.Element, inherited: dict[str, dict[str, str]], name: str) -> None:
        mine = {tag: dict(attrs) for tag, attrs in inherited.items()}
        for child in element:
            if child.tag != "default":
                mine.setdefault(child.tag, {}).update(child.attrib)
        classes[name] = mine
        for child in element:
            if child.tag == "default":
                walk(child, mine, child.get("class", "main"))

    for top in root.findall("default"):
        walk(top, {}, top.get("class", "main"))
    return classes


def _limited(flag: str | None, given: bool) -> bool:
    """MJCF ``*limited``: ``true``, ``false`` or ``auto`` (limited when a range is given)."""
    if flag is None or flag == "auto":
        return given
    return flag == "true"


def _actuator_bound(tag: str, attrs: dict[str, str]) -> float | None:
    """The torque bound [N m or N] one MJCF actuator gives its joint (None: none)."""
    bounds = []
    force = _pair(attrs.get("forcerange"))
    if force is not None and _limited(attrs.get("forcelimited"), True):
        bounds.append(max(abs(force[0]), abs(force[1])))
    ctrl = _pair(attrs.get("ctrlrange"))
    if tag == "motor" and ctrl is not None and _limited(attrs.get("ctrllimited"), True):
        gear = _number((attrs.get("gear") or "1").split()[0], 1.0)
        bounds.append(abs(gear) * max(abs(ctrl[0]), abs(ctrl[1])))
    return min(bounds) if bounds else None


def read_mjcf(root: ET.Element) -> Actuation:
    """The actuation of an MJCF file (its root element, includes expanded); its props are removed
    from ``root``: top-level bodies whose subtree holds no joint an actuator drives, directly or
    through a tendon."""
    classes = _default_classes(root)
    actuated: dict[str, float | None] = {}
    driven_tendons: set[str] = set()
    for section in root.findall("actuator"):
        for element in section:
            if element.tag not in _ACTUATORS:
                continue
            cls = classes.get(element.get("class", "main"), {})
            attrs = {**cls.get("general", {}), **cls.get(element.tag, {}), **element.attrib}
            joint = attrs.get("joint")
            if joint is None:  # a tendon, site or body transmission drives no one joint
                driven_tendons |= {attrs["tendon"]} if "tendon" in attrs else set()
                continue
            bound = _actuator_bound(element.tag, attrs)
            old = actuated.get(joint)
            actuated[joint] = bound if old is None else (old if bound is None else old + bound)
    tendons = {
        j.get("joint", ""): tendon.get("name", "")
        for tendon in root.iter("fixed")
        if tendon.get("name") in driven_tendons
        for j in tendon.findall("joint")
    }
    spatial = [str(t.get("name")) for t in root.iter("spatial") if t.get("name") in driven_tendons]
    if not actuated and not tendons and not spatial:
        return Actuation(root=root)
    props: list[str] = []
    for worldbody in root.findall("worldbody"):
        for body in list(worldbody.findall("body")):
            joints = {j.get("name") for j in body.iter() if j.tag in ("joint", "freejoint")}
            if joints and not joints & (set(actuated) | set(tendons)):  # unjointed: welded
                worldbody.remove(body)
                props.append(body.get("name") or "(unnamed body)")
    found = Actuation(actuated=actuated, props=props, source="actuators", tendons=tendons)
    found.root, found.spatial = root, spatial
    return found


def mjcf_resolver(path: Path):
    """newton's ``path_resolver`` for MJCF text read from ``path``: assets beside the file."""

    def resolve(base: str | None, file_path: str) -> str:
        if os.path.isabs(file_path):
            return os.path.normpath(file_path)
        return os.path.normpath(os.path.join(base or str(path.parent), file_path))

    return resolve


def read_urdf(robot: ET.Element) -> Actuation:
    """The actuation of a URDF (its root element)."""
    names = {
        str(j.get("name"))
        for t in robot.iter("transmission")
        for j in t.findall("joint")
        if j.get("name")
    }
    actuated: dict[str, float | None] = {}
    for joint in robot.findall("joint"):
        if joint.get("type") not in ("revolute", "continuous", "prismatic"):
            continue
        limit = joint.find("limit")
        if joint.get("name") not in names and (
            limit is not None and _number(limit.get("effort"), 1.0) == 0.0
        ):
            continue  # no transmission and no effort: the file says nothing drives it
        actuated[str(joint.get("name"))] = None
    return Actuation(actuated=actuated, source="effort")


def arm_chains(builder, trained: set[int]) -> list[tuple[list[int], int]]:
    """Arms with a hand: the trained joints branch below a trained joint. Returns, per arm, the
    trained joints on the path from the world to its first such branching body, and that body;
    none for a single chain or a hand (its chains branch on a body that no trained joint moves);
    two for a bimanual robot (two arms whose hands branch apart)."""
    joint_of = {c: j for j, c in enumerate(builder.joint_child)}

    def path(body: int) -> list[int]:  # joints from the world down to ``body``
        out: list[int] = []
        while body >= 0 and body in joint_of and len(out) <= len(joint_of):
            j = joint_of[body]
            out.append(j)
            body = builder.joint_parent[j]
        return out[::-1]

    below: dict[int, set[int]] = {}  # body -> its child joints whose subtree has a trained joint
    for j in trained:
        chain = path(builder.joint_child[j])
        for k in chain:
            below.setdefault(builder.joint_parent[k], set()).add(k)
    branching = [
        b
        for b, kids in below.items()
        if b >= 0 and len(kids) >= 2 and any(k in trained for k in path(b))
    ]
    # the first branching body of each arm: no other branching body above it
    firsts = [
        b for b in branching if not any(o != b and joint_of.get(o) in path(b) for o in branching)
    ]
    return [([k for k in path(b) if k in trained], b) for b in sorted(firsts)]
