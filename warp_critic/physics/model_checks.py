"""The checks of a built model that every robot gets, from a robot file (:mod:`.robot_checks`, which
adds the file's own) or from a scene file (:mod:`.usd_scene`: a copy of a scene edited by hand is
checked as an import is): masses and inertias in range, joint limits that are numbers with lower <=
upper, joint axes that move something, and the tip's offset from its body. Each failure is one
:class:`~warp_critic.core.errors.SceneError` line naming the body or joint and the value."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from warp_critic.core.errors import FieldError
from warp_critic.physics.inertia_checks import _fail, _g, _short, check_inertias

TIP_OFFSET_MAX = 10.0  # m


def check_tip_offset(tip: Sequence[float]) -> None:
    """A tip farther than :data:`TIP_OFFSET_MAX` from its body is a mistake (a FieldError)."""
    norm = math.sqrt(sum(float(v) ** 2 for v in tip))
    if not norm <= TIP_OFFSET_MAX:
        raise FieldError(
            "tip_offset",
            f"{','.join(_g(float(v)) for v in tip)} is {_g(norm)} m from the end-effector body; "
            f"a tip is at most {TIP_OFFSET_MAX:g} m from it",
        )


def check_model(path: Path, builder) -> None:
    """The checks of :func:`check_robot` that a scene file gets too (no repairs: a scene is loaded
    as it is): masses and inertias, joint limits and axes of every joint (a scene trains each)."""
    check_inertias(path, builder, repair=False)
    movable = _movable(builder)
    _limits(path, builder, movable, {_short(builder.joint_label[j]) for j in movable})
    _axes(path, builder, movable)


def _movable(builder) -> list[int]:
    import newton

    kinds = {int(newton.JointType.REVOLUTE), int(newton.JointType.PRISMATIC)}
    return [j for j, t in enumerate(builder.joint_type) if int(t) in kinds]


def _limits(path: Path, builder, movable: list[int], trained: set[str]) -> None:
    for j in movable:
        dof = builder.joint_qd_start[j]
        lo, hi = float(builder.joint_limit_lower[dof]), float(builder.joint_limit_upper[dof])
        name = _short(builder.joint_label[j])
        if not (math.isfinite(lo) or lo == -math.inf) or not (math.isfinite(hi) or hi == math.inf):
            raise _fail(path, f"joint {name!r} has limits {_g(lo)}..{_g(hi)}: not numbers")
        if lo > hi:
            raise _fail(path, f"joint {name!r} has lower limit {_g(lo)} > upper limit {_g(hi)}")
        if lo == hi and name in trained:
            raise _fail(
                path,
                f"joint {name!r} cannot move: lower limit = upper limit = {_g(lo)} (make it a fixed "
                "joint, or leave it out of the trained joints, --joints, to lock it)",
            )


def _axes(path: Path, builder, movable: list[int]) -> None:
    """A revolute or prismatic joint needs an axis: a zero one moves nothing (its mass matrix row
    is zero, so the model cannot be stepped)."""
    for j in movable:
        axis = [float(x) for x in builder.joint_axis[builder.joint_qd_start[j]]]
        if not math.fsum(x * x for x in axis) > 1e-18:
            raise _fail(
                path,
                f"joint {_short(builder.joint_label[j])} has a zero joint axis "
                f"({', '.join(_g(x) for x in axis)}): it moves nothing",
            )
