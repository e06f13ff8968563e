"""Dynamics variants: per-world changes of the robot applied to a newton builder.

Variants change one link, the end-effector link ``e`` (tip ``p`` in its frame), consistently:

1. Link length: with old length ``L = |p|``, new length ``L' = (link_length or L) * link_scale``,
   ``s = L'/L`` and unit direction ``u = p/L``, the link's mass distribution is stretched by
   ``S = I + (s-1) u u^T`` at constant mass: tip ``p -> S p = s p``; centre of mass ``c -> S c``
   (its component along ``u`` scales by ``s``); the second moment about the COM,
   ``Sigma = tr(I_c)/2 * 1 - I_c``, becomes ``S Sigma S^T`` and ``I_c' = tr(Sigma') * 1 - Sigma'``
   (a thin rod along ``u`` thus gets ``s^2`` times its transverse inertia, as a rod of the same
   mass and length ``s L`` has). Positions on the link (child-joint origins, visual shapes) map by
   ``S`` too; capsules/cylinders/boxes aligned with ``u`` are lengthened by ``s``.
2. Tip mass: a point mass ``m_a`` at the (new) tip ``p``: ``M' = M + m_a``,
   ``c' = (M c + m_a p)/M'`` and, by the parallel-axis theorem,
   ``I' = I_c + M (|d|^2 1 - d d^T) + m_a (|r|^2 1 - r r^T)`` with ``d = c - c'``, ``r = p - c'``.
3. Then ``changes``: :class:`~warp_critic.physics.link_changes.LinkChange`\\ s of ANY link, in order
   (mass set/add/scale at the COM, point masses, kinematic offsets and stretches of a link's length;
   see :mod:`warp_critic.physics.link_changes` for the text form and the exact rules).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from warp_critic.core.errors import FieldError
from warp_critic.physics.link_changes import LinkChange, format_changes, parse_changes

#: [kg] the mass a link SET to 0 kg gets (newton zeroes the inertia of a massless body); its weight
#: at 1 m is 1e-5 N*m, far below anything measured
MIN_MASS = 1e-6

__all__ = [
    "Variant",
    "apply_changes",
    "apply_variant",
    "is_finite",
    "length_map",
    "changed_tip",
    "link_value",
]


@dataclass(frozen=True)
class Variant:
    """A change of the robot's end-effector link (see the module docstring for the exact rules).

    Attributes:
        ee_mass: point mass [kg] ADDED at the end-effector tip (>= 0).
        link_length: if not None, SET the end-effector link length ``|tip offset|`` [m] (> 0).
        link_scale: multiply the end-effector link length (> 0); applied after ``link_length``.
        changes: :class:`LinkChange`\\ s of any link applied after the three above, in order; the
            text form ``'iiwa_link_7.mass=5; ee.offset+=0.4'`` is accepted and parsed.
    """

    ee_mass: float = 0.0
    link_length: float | None = None
    link_scale: float = 1.0
    changes: tuple[LinkChange, ...] = ()

    def __post_init__(self):
        if isinstance(self.changes, str) or self.changes is None:
            object.__setattr__(self, "changes", parse_changes(self.changes))
        elif not isinstance(self.changes, tuple):
            object.__setattr__(self, "changes", tuple(self.changes))

    @property
    def text(self) -> str:
        """The link changes in their text form (``''`` for none)."""
        return format_changes(self.changes)

    def validate(self) -> None:
        """Raise :class:`FieldError` naming the offending field."""
        if not is_finite(self.ee_mass) or self.ee_mass < 0.0:
            raise FieldError("ee_mass", f"must be >= 0 (got {self.ee_mass})")
        if self.link_length is not None and (
            not is_finite(self.link_length) or self.link_length <= 0.0
        ):
            raise FieldError("link_length", f"must be > 0 (got {self.link_length})")
        if not is_finite(self.link_scale) or self.link_scale <= 0.0:
            raise FieldError("link_scale", f"must be > 0 (got {self.link_scale})")
        for change in self.changes:
            if not isinstance(change, LinkChange):
                raise FieldError("variant", f"expected link changes (got {change!r})")
            change.validate()

    @property
    def changes_length(self) -> bool:
        return self.link_length is not None or self.link_scale != 1.0


def is_finite(x) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def length_map(
    variant: Variant, tip_offset: np.ndarray, scene_name: str, ee_name: str
) -> tuple[float, np.ndarray]:
    """(s, S): the length ratio and the stretch matrix ``I + (s-1) u u^T`` of ``variant`` for an
    end-effector link whose tip is ``tip_offset`` ``(3,)`` [m] in its frame.

    Raises:
        FieldError: for an invalid variant, or a length change of a link without length.
    """
    variant.validate()
    if not variant.changes_length:
        return 1.0, np.eye(3)
    old = float(np.linalg.norm(tip_offset))
    if old == 0.0:
        name = "link_length" if variant.link_length is not None else "link_scale"
        raise FieldError(
            name,
            f"does not apply to scene '{scene_name}': its end-effector "
            f"'{ee_name}' has a zero tip offset (no link length)",
        )
    new = (variant.link_length if variant.link_length is not None else old) * variant.link_scale
    s = new / old
    u = tip_offset / old
    return s, np.eye(3) + (s - 1.0) * np.outer(u, u)


def apply_variant(
    builder, ee_body: int, tip_offset: np.ndarray, variant: Variant, s: float, stretch: np.ndarray
) -> None:
    """Apply ``variant`` to one robot copy in ``builder`` (python lists, before finalize), given
    ``(s, stretch)`` from :func:`length_map`."""
    if s != 1.0:
        _stretch_link(builder, ee_body, stretch, tip_offset / np.linalg.norm(tip_offset), s)
    if variant.ee_mass > 0.0:
        _add_point_mass(builder, ee_body, float(variant.ee_mass), stretch @ tip_offset)


def _set_body_mass(builder, body: int, mass: float, com: np.ndarray, inertia: np.ndarray) -> None:
    """Replace one body's mass properties (entries are reassigned: they may be shared)."""
    import warp as wp

    builder.body_mass[body] = float(mass)
    builder.body_inv_mass[body] = 1.0 / float(mass)
    builder.body_com[body] = wp.vec3(*map(float, com))
    builder.body_inertia[body] = wp.mat33(*map(float, inertia.reshape(-1)))
    builder.body_inv_inertia[body] = wp.mat33(*map(float, np.linalg.inv(inertia).reshape(-1)))


def _body_mass(builder, body: int) -> tuple[float, np.ndarray, np.ndarray]:
    return (
        float(builder.body_mass[body]),
        np.array(builder.body_com[body], dtype=np.float64),
        np.array(builder.body_inertia[body], dtype=np.float64).reshape(3, 3),
    )


def _stretch_link(builder, body: int, stretch: np.ndarray, u: np.ndarray, s: float) -> None:
    """Stretch ``body``'s mass distribution and attachments by ``stretch`` (module docstring, 1.)."""
    import newton
    import warp as wp

    mass, com, inertia = _body_mass(builder, body)
    second_moment = np.trace(inertia) / 2.0 * np.eye(3) - inertia
    second_moment = stretch @ second_moment @ stretch.T
    inertia = np.trace(second_moment) * np.eye(3) - second_moment
    _set_body_mass(builder, body, mass, stretch @ com, inertia)

    for j, parent in enumerate(builder.joint_parent):
        if parent == body:
            x = builder.joint_X_p[j]
            builder.joint_X_p[j] = wp.transform(wp.vec3(*map(float, stretch @ np.array(x.p))), x.q)

    # Visual shapes (zero density, so no effect on the dynamics): move them with the link, and
    # lengthen boxes (half extents) and capsules/cylinders (half height, along their z axis)
    # whose axis is the link direction.
    axial = (int(newton.GeoType.CAPSULE), int(newton.GeoType.CYLINDER))
    for k, shape_body in enumerate(builder.shape_body):
        if shape_body != body:
            continue
        x = builder.shape_transform[k]
        builder.shape_transform[k] = wp.transform(
            wp.vec3(*map(float, stretch @ np.array(x.p))), x.q
        )
        u_local = np.array(wp.quat_rotate_inv(x.q, wp.vec3(*map(float, u))))
        axis = int(np.argmax(np.abs(u_local)))
        kind = int(builder.shape_type[k])
        if abs(u_local[axis]) < 1.0 - 1e-6:
            continue  # not aligned with the link: keep its size
        if kind == int(newton.GeoType.BOX):
            index = axis
        elif kind in axial and axis == 2:
            index = 1
        else:
            continue
        scale = list(builder.shape_scale[k])
        scale[index] *= s
        builder.shape_scale[k] = tuple(scale)


def _add_point_mass(builder, body: int, added: float, point: np.ndarray) -> None:
    """Add a point mass ``added`` [kg] at ``point`` (body frame) to ``body`` (module docstring, 2.)."""
    mass, com, inertia = _body_mass(builder, body)
    new_mass = mass + added
    new_com = (mass * com + added * point) / new_mass

    def shift(m: float, r: np.ndarray) -> np.ndarray:
        return m * (float(r @ r) * np.eye(3) - np.outer(r, r))

    inertia = inertia + shift(mass, com - new_com) + shift(added, point - new_com)
    _set_body_mass(builder, body, new_mass, new_com, inertia)


# -- link changes (any link; module docstring, 3.) ---------------------------------------------------


def _link_index(change: LinkChange, body_names: list[str], ee_body: int) -> int:
    if change.link == "ee":
        return ee_body
    if change.link in body_names:
        return body_names.index(change.link)
    raise FieldError(
        "variant",
        f"{change.text()!r}: unknown link {change.link!r} (links: ee, {', '.join(body_names)})",
    )


def _new_value(change: LinkChange, old: float) -> float:
    v = float(change.value)
    return {"=": v, "+=": old + v, "*=": old * v}[change.op]


def _new_length(change: LinkChange, end: np.ndarray) -> tuple[float, float, np.ndarray]:
    """(old length, new length, unit direction) of a length change of a link whose end is ``end``."""
    old = float(np.linalg.norm(end))
    if old == 0.0:
        raise FieldError("variant", f"{change.text()!r}: the link has no length (its end is at 0)")
    new = _new_value(change, old)
    if not new > 0.0:
        raise FieldError("variant", f"{change.text()!r}: the new length {new:g} m must be > 0")
    return old, new, end / old


def changed_tip(
    changes: tuple[LinkChange, ...], tip: np.ndarray, body_names: list[str], ee_body: int
) -> np.ndarray:
    """``(3,)`` the end-effector tip [m] in its link frame after ``changes`` (only length changes of
    the end-effector link move it: by the same ratio for an offset and a stretch)."""
    tip = np.asarray(tip, dtype=np.float64)
    for change in changes:
        if (
            change.what in ("offset", "stretch")
            and _link_index(change, body_names, ee_body) == ee_body
        ):
            old, new, _ = _new_length(change, tip)
            tip = tip * (new / old)
    return tip


def _children(builder, body: int) -> list[int]:
    return [j for j, parent in enumerate(builder.joint_parent) if parent == body]


def _end(builder, body: int, ee_body: int, tip: np.ndarray, change: LinkChange) -> np.ndarray:
    """The link's end in its frame: the tip for the end-effector link, else its one child joint."""
    if body == ee_body:
        return tip
    children = _children(builder, body)
    if len(children) != 1:
        raise FieldError(
            "variant",
            f"{change.text()!r}: link {change.link!r} has {len(children)} child joints "
            "(a length or end needs exactly one, or the end-effector tip)",
        )
    return np.array(builder.joint_X_p[children[0]].p, dtype=np.float64)


def apply_changes(
    builder, changes: tuple[LinkChange, ...], body_names: list[str], ee_body: int, tip: np.ndarray
) -> np.ndarray:
    """Apply ``changes`` in order to one robot copy in ``builder`` (python lists, before finalize)
    whose end-effector tip is ``tip`` ``(3,)`` m; returns the tip after them."""
    import warp as wp

    tip = np.asarray(tip, dtype=np.float64)
    for change in changes:
        body = _link_index(change, body_names, ee_body)
        if change.what == "mass":
            mass, com, inertia = _body_mass(builder, body)
            new = _new_value(change, mass)
            if new < 0.0:
                raise FieldError("variant", f"{change.text()!r}: the new mass {new:g} kg is < 0")
            if change.mode == "scale":
                if mass == 0.0 or new == 0.0:
                    raise FieldError(
                        "variant",
                        f"{change.text()!r}: scaling the inertia needs old and new mass > 0 "
                        "(use :keep)",
                    )
                inertia = inertia * (new / mass)
            # newton treats a body of mass 0 as static and zeroes its inertia at finalize: a link
            # set to 0 kg keeps its rotational inertia (as the paper's model does) with MIN_MASS
            _set_body_mass(builder, body, max(new, MIN_MASS), com, inertia)
        elif change.what == "point-mass":
            point = (
                np.array(change.point, dtype=np.float64)
                if change.point is not None
                else _end(builder, body, ee_body, tip, change)
            )
            if change.value > 0.0:
                _add_point_mass(builder, body, float(change.value), point)
        else:
            end = _end(builder, body, ee_body, tip, change)
            old, new, u = _new_length(change, end)
            s = new / old
            if change.what == "stretch":
                _stretch_link(builder, body, np.eye(3) + (s - 1.0) * np.outer(u, u), u, s)
            else:  # a kinematic offset: the child frames move along the link, no mass change
                for j in _children(builder, body):
                    x = builder.joint_X_p[j]
                    p = np.array(x.p, dtype=np.float64) + (new - old) * u
                    builder.joint_X_p[j] = wp.transform(wp.vec3(*map(float, p)), x.q)
            if body == ee_body:
                tip = tip * s
    return tip


def link_value(
    builder, change: LinkChange, body_names: list[str], ee_body: int, tip: np.ndarray
) -> float:
    """What ``change`` sets on its link, as the link is in ``builder`` now: its mass [kg] for a
    mass change, its length [m] for an offset or a stretch, 0 for a point mass."""
    body = _link_index(change, body_names, ee_body)
    if change.what == "mass":
        return float(builder.body_mass[body])
    if change.what == "point-mass":
        return 0.0
    end = _end(builder, body, ee_body, np.asarray(tip, dtype=np.float64), change)
    return float(np.linalg.norm(end))
