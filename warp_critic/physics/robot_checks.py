"""A robot file's physical validity, checked before newton's importer result is used.

Newton's importers take what a file says and, where it is physically impossible, either drop it
(a URDF ``<mimic>`` joint, an MJCF ``<equality><joint>`` coupling: the generic solvers ignore them)
or "correct" it when the model is finalised, with a warning that names no body (a negative or
non-finite inertia, one that violates the triangle inequality, a degenerate one). A file like that
is refused here, in one :class:`SceneError` line naming the body or joint and the value:

* a joint coupled to another (URDF ``<mimic>``, MJCF ``<equality><joint>``) where either joint is
  trained; repair on request: ``lock_mimic`` welds the coupled joint at the position the coupling
  gives at the home pose;
* a body's mass that is not a finite number in 1e-6..1e6 kg (a frame link welded to its parent may
  be lighter: it is merged); a mass of 0 with an inertia on a moving body (a welded frame's is
  dropped with a note); an inertia entry that is not a finite number (named as the file writes
  it; never repaired: no nearest valid tensor exists); a negative diagonal entry, a negative
  principal moment (a large off-diagonal entry), principal moments that violate the triangle
  inequality by more than 5% of the largest (a smaller miss is repaired with a note), or (on a
  body its own joint moves) a smallest
  principal moment below newton's floor (1e-6 of the largest); repair on request:
  ``repair_inertia`` projects the tensor to the nearest valid one (Frobenius norm, the same
  principal axes; a massless body's inertia is dropped). Links welded to the world are not
  checked: they are merged into it and never move (:mod:`~warp_critic.physics.inertia_checks`);
* joint limits with lower > upper; lower == upper on a joint that is trained (a joint that cannot
  move: leave it out of the trained joints to lock it);
* a URDF ``effort`` that is negative or not a number; ``effort="0"`` means no actuator, refused on a
  trained joint (warp-critic drives every joint it trains); a missing effort is unlimited;
* a link (URDF) or body (MJCF) defined twice, a joint defined twice.

An MJCF motor's ``ctrlrange`` (times its gear) bounds the joint's effort where no ``forcerange``
does, as in MuJoCo; the smaller bound wins. The repairs made are returned as one line each: the
scene records them (``warp_critic:importRepairs``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

from warp_critic.core.errors import FieldError
from warp_critic.physics import derive
from warp_critic.physics.importers import lock
from warp_critic.physics.inertia_checks import _fail, _g, _short, check_inertias
from warp_critic.physics.model_checks import (
    _axes,
    _limits,
    _movable,
)

__all__ = [
    "IMPORT_RULES",
    "check_robot",
    "given_home",
]

LOCK_MIMIC = "import with --lock-mimic to lock it where the coupling puts it at the home pose"


IMPORT_RULES = """\
refused, in one line naming the body or joint and the value (nothing is written):
  a joint coupled to another (URDF <mimic>, MJCF <equality><joint>): --lock-mimic welds it where
    the coupling puts it at the home pose;
  a mass that is not a finite number in 1e-6..1e6 kg; mass 0 with an inertia on a moving link;
    an inertia entry that is not a finite number (no repair: give the number); an inertia with a
    negative diagonal entry, not positive definite, violating the triangle inequality by more
    than 5% of its largest principal moment or (on a moving link) degenerate: --repair-inertia
    projects it to the nearest valid inertia (a smaller triangle miss is repaired, and a massless
    welded frame's inertia dropped, each with a one-line note);
  a joint axis that is zero or not finite;
  joint limits lower > upper, or lower = upper on a trained joint; a URDF effort < 0 or not a
    number; effort="0" (no actuator) on a trained joint (leave it out of --joints to lock it);
  a link, body or joint defined twice; a --tip-offset over 10 m.
  A missing effort is unlimited; an MJCF motor's ctrlrange x gear bounds its joint's effort where
  no forcerange does. The format is read from the content (a URDF saved as .xml is a URDF); a
  .xacro file is to be expanded first. A repair is printed and recorded in the scene's
  warp_critic:importRepairs.
"""


def check_robot(
    path: Path,
    builder,
    fmt: str,
    trained: Sequence[str] | None = None,
    lock_mimic: bool = False,
    repair_inertia: bool = False,
    home: dict[str, float] | None = None,
    root=None,
) -> tuple[str, ...]:
    """Refuse what the module docstring lists (a :class:`SceneError`), or repair it on request.

    ``builder``: newton's ``ModelBuilder`` straight from the importer (fixed joints not merged);
    ``fmt``: ``urdf``/``mjcf``/``usd``; ``trained``: the joints to train (None: every movable one);
    ``home``: joint name -> the home the user gave (``--home``; a locked follower follows it).
    ``fmt``: ``urdf``/``mjcf``/``usd``; ``trained``: the joints to train (None: every movable one).
    ``root``: the file's parsed tree where the caller has it (an MJCF's, includes expanded).
    Returns the repairs made, one line each (changed in ``builder``)."""
    if root is None:
        root = _xml_root(path) if fmt in ("urdf", "mjcf") else None
    if root is not None:
        _check_names(path, root, fmt)
        _finite_in_file(path, root, fmt)
    repairs: list[str] = []
    repairs += _couplings(path, builder, root, fmt, lock_mimic, trained, home or {})
    repairs += check_inertias(path, builder, repair_inertia)
    movable = _movable(builder)
    trained_set = (
        set(trained) if trained is not None else {_short(builder.joint_label[j]) for j in movable}
    )
    _limits(path, builder, movable, trained_set)
    _axes(path, builder, movable)
    if fmt == "mjcf":
        _mjcf_efforts(builder)
    if fmt in ("urdf", "mjcf"):
        _efforts(path, builder, movable, trained_set)
    return tuple(repairs)


# ------------------------------------------------------------------------------------------------
# the file's names and couplings
# ------------------------------------------------------------------------------------------------


def _xml_root(path: Path):
    try:
        return ET.parse(path).getroot()
    except (ET.ParseError, OSError):
        return None  # the importer has said or will say why


def _check_names(path: Path, root, fmt: str) -> None:
    kinds = (
        (("link", "link"), ("joint", "joint"))
        if fmt == "urdf"
        else (("body", "body"), ("joint", "joint"))
    )
    for tag, word in kinds:
        elements = root.findall(tag) if fmt == "urdf" else list(root.iter(tag))
        if fmt == "mjcf" and tag == "joint":  # <equality>/<tendon> also hold <joint> elements
            world = root.find("worldbody")
            elements = list((root if world is None else world).iter("joint"))
        seen: set[str] = set()
        for e in elements:
            name = e.get("name")
            if name is None:
                continue
            if name in seen:
                raise _fail(
                    path,
                    f"{word} {name!r} is defined twice; the importer would keep the first "
                    "silently (rename or remove the other)",
                )
            seen.add(name)


#: The inertia entries as a URDF ``<inertia>`` and an MJCF ``fullinertia`` / ``diaginertia`` list them.
_INERTIA = ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")


def _attr(element, name: str) -> str | None:
    return None if element is None else element.get(name)


def _finite_in_file(path: Path, root, fmt: str) -> None:
    """A non-finite inertia entry or joint axis, named as the file writes it: the importer spreads
    a NaN over the whole tensor (every entry then reads ``nan``) and normalises a NaN axis to zero."""

    def numbers(text: str | None) -> list[float]:
        try:
            return [float(x) for x in (text or "").split()]
        except ValueError:
            return []

    def bad(values) -> bool:
        return any(not math.isfinite(v) for v in values)

    if fmt == "urdf":
        inertias = [(e.get("name", "?"), e.find("inertial/inertia")) for e in root.findall("link")]
        for name, el in inertias:
            if el is None:
                continue
            for key in _INERTIA:
                v = numbers(el.get(key))
                if bad(v):
                    raise _fail(path, f"body {name!r}: inertia {key}={v[0]:g} is not a finite "
                                "number (give its value; --repair-inertia cannot project it)")  # fmt: skip
        axes = [(j.get("name", "?"), numbers(_attr(j.find("axis"), "xyz"))) for j in root.findall("joint")]  # fmt: skip
    else:
        for body in root.iter("body"):
            el = body.find("inertial")
            if el is None:
                continue
            for attr in ("fullinertia", "diaginertia"):
                v = numbers(el.get(attr))
                i = next((k for k, x in enumerate(v) if not math.isfinite(x)), None)
                if i is not None and i < len(_INERTIA):
                    raise _fail(path, f"body {body.get('name', '?')!r}: inertia {_INERTIA[i]}={v[i]:g} "
                                "is not a finite number (give its value; --repair-inertia cannot project it)")  # fmt: skip
        axes = [(j.get("name", "?"), numbers(j.get("axis"))) for j in root.iter("joint")]
    for name, axis in axes:
        if bad(axis):
            raise _fail(path, f"joint {name!r} has a joint axis ({', '.join(f'{x:g}' for x in axis)}) "
                        "that is not finite: it moves nothing")  # fmt: skip


def _couplings(
    path: Path,
    builder,
    root,
    fmt: str,
    lock_mimic: bool,
    trained: Sequence[str] | None,
    home: dict[str, float],
) -> list[str]:
    """``(follower, leader or None, polynomial coefficients)`` per coupling: locked or refused."""
    found: list[tuple[str, str | None, list[float]]] = []
    if fmt == "urdf" and root is not None:
        for joint in root.findall("joint"):
            mimic = joint.find("mimic")
            if mimic is not None:
                c = [float(mimic.get("offset", 0)), float(mimic.get("multiplier", 1))]
                found.append((joint.get("name", "?"), mimic.get("joint"), c))
    elif fmt == "mjcf" and root is not None:
        for eq in root.iter("equality"):
            for joint in eq.findall("joint"):
                if joint.get("active", "true").lower() == "false":
                    continue
                poly = [float(x) for x in joint.get("polycoef", "0 1 0 0 0").split()]
                if joint.get("joint2") is None:
                    poly = poly[:1]
                found.append((joint.get("joint1", "?"), joint.get("joint2"), poly))
    else:
        labels = [_short(lb) for lb in builder.joint_label]
        for f, lead, c0, c1 in zip(
            builder.constraint_mimic_joint0,
            builder.constraint_mimic_joint1,
            builder.constraint_mimic_coef0,
            builder.constraint_mimic_coef1,
        ):
            found.append((labels[f], labels[lead], [float(c0), float(c1)]))
    if trained is not None:  # both joints locked (not trained): nothing couples them any more
        found = [c for c in found if c[0] in trained or (c[1] is not None and c[1] in trained)]
    if not found:
        return []
    if not lock_mimic:
        follower, leader, poly = found[0]
        rule = _poly_text(poly, leader)
        raise _fail(
            path,
            f"joint {follower!r} is coupled to another ({follower} = {rule}); the coupling "
            f"would vanish from the scene and the goals would ask for poses it forbids "
            f"({LOCK_MIMIC})",
        )
    return [_lock_follower(path, builder, *c, home) for c in found]


def _poly_text(poly: list[float], leader: str | None) -> str:
    terms = [_g(poly[0])] + [
        f"{_g(c)} x {leader}" + (f"^{i}" if i > 1 else "") for i, c in enumerate(poly[1:], 1) if c
    ]
    return " + ".join(terms)


def _lock_follower(
    path: Path, builder, follower: str, leader: str | None, poly, given: dict[str, float]
) -> str:

    labels = [_short(lb) for lb in builder.joint_label]
    if follower not in labels or (leader is not None and leader not in labels):
        raise _fail(path, f"joint {follower!r} is coupled to a joint not in the file ({leader!r})")
    jf = labels.index(follower)

    def home(j: int) -> float:
        dof = builder.joint_qd_start[j]
        lo, hi = float(builder.joint_limit_lower[dof]), float(builder.joint_limit_upper[dof])
        q = float(builder.joint_q[builder.joint_q_start[j]])
        return derive.home_value(lo, hi, q, 1e9)

    if leader is None:
        x = 0.0
    else:  # the leader's home: the one given (--home), else the one derived from the file
        x = given[leader] if leader in given else home(labels.index(leader))
    value = float(sum(c * x**i for i, c in enumerate(poly)))
    dof = builder.joint_qd_start[jf]
    lo, hi = float(builder.joint_limit_lower[dof]), float(builder.joint_limit_upper[dof])
    at = min(max(value, lo), hi)
    lock(builder, [jf], {jf: at})
    _drop_mimic(builder, jf)
    where = f" at {leader}'s home {_g(x)}" if leader is not None else ""
    clamp = f" (the coupling's {_g(value)}, clamped to its limits)" if at != value else ""
    return f"joint {follower} locked at {_g(at)}{clamp}: coupled as {follower} = {_poly_text(poly, leader)}{where}"


def _drop_mimic(builder, joint: int) -> None:
    if joint < len(builder.joint_mimic_joint):
        builder.joint_mimic_joint[joint] = -1
    keep = [i for i, f in enumerate(builder.constraint_mimic_joint0) if f != joint]
    for name in ("joint0", "joint1", "coef0", "coef1", "enabled", "label", "world"):
        values = getattr(builder, f"constraint_mimic_{name}", None)
        if values is not None and len(values) >= len(keep):
            setattr(builder, f"constraint_mimic_{name}", [values[i] for i in keep])


# ------------------------------------------------------------------------------------------------
# limits and efforts
# ------------------------------------------------------------------------------------------------


def _efforts(path: Path, builder, movable: list[int], trained: set[str]) -> None:
    for j in movable:
        dof = builder.joint_qd_start[j]
        effort = float(builder.joint_effort_limit[dof])
        name = _short(builder.joint_label[j])
        if math.isnan(effort) or effort < 0:
            raise _fail(
                path, f"joint {name!r} has effort limit {_g(effort)}: an effort is a number >= 0"
            )
        if effort == 0.0 and name in trained:
            raise _fail(
                path,
                f"joint {name!r} has effort limit 0: no actuator, and warp-critic drives every "
                "joint it trains (leave it out of the trained joints, --joints, to lock it)",
            )


def _mjcf_efforts(builder) -> None:
    """A motor's ``ctrlrange`` x gear bounds its joint's effort where no ``forcerange`` does."""
    attrs = getattr(builder, "custom_attributes", {}) or {}

    def values(key: str) -> list:
        a = attrs.get(f"mujoco:actuator_{key}")
        return list(getattr(a, "values", None) or []) if a is not None else []

    trntype, trnid = values("trntype"), values("trnid")
    gaintype, biastype, gainprm, gear = (
        values("gaintype"),
        values("biastype"),
        values("gainprm"),
        values("gear"),
    )
    ctrl, has_ctrl, ctrl_on = values("ctrlrange"), values("has_ctrlrange"), values("ctrllimited")
    force, has_force, force_on = (
        values("forcerange"),
        values("has_forcerange"),
        values("forcelimited"),
    )
    for a in range(len(trntype)):
        if int(trntype[a]) != 0:  # a joint transmission only
            continue
        dof = int(trnid[a][0])
        if not 0 <= dof < len(builder.joint_effort_limit):
            continue
        bounds = []
        limited = int(ctrl_on[a]) == 1 or (int(ctrl_on[a]) == 2 and int(has_ctrl[a]))
        if limited and int(gaintype[a]) == 0 and int(biastype[a]) == 0:  # a motor: force = g u
            g = abs(float(gear[a][0]) * float(gainprm[a][0]))
            bounds.append(g * max(abs(float(ctrl[a][0])), abs(float(ctrl[a][1]))))
        if int(force_on[a]) == 1 or (int(force_on[a]) == 2 and int(has_force[a])):
            bounds.append(max(abs(float(force[a][0])), abs(float(force[a][1]))))
        if bounds:
            builder.joint_effort_limit[dof] = min(float(builder.joint_effort_limit[dof]), *bounds)


def given_home(
    path: Path,
    given: Sequence[tuple[str, float]],
    names: list[str],
    jointed: list[int],
    lower: dict[int, float],
    upper: dict[int, float],
    unlimited: float,
) -> dict[int, float]:
    """Joint index -> the home value the user gave (``--home``), each checked against the file: a
    movable joint of it, inside its limits (a joint whose limits are at ``unlimited`` has none)."""
    index = {names[j]: j for j in jointed}
    out = {}
    for name, value in given:
        j = index.get(name)
        if j is None:
            raise FieldError(
                "home", f"{path}: no movable joint {name!r} (its joints: {', '.join(index)})"
            )
        limited = max(abs(lower[j]), abs(upper[j])) < unlimited  # newton writes 1e10 for none
        if not math.isfinite(value) or (limited and not lower[j] <= value <= upper[j]):
            raise FieldError(
                "home",
                f"{path}: joint {name!r} at {value:g} is outside its limits "
                f"[{lower[j]:g}, {upper[j]:g}]",
            )
        out[j] = value
    return out
