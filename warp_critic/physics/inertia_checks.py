"""Masses and inertia tensors of a robot file, checked as newton's finalize would correct them.

Newton's ``ModelBuilder.finalize`` "corrects" a body's mass and inertia (``verify_and_correct_inertia``:
a non-finite value zeroed, a negative mass set to 0, the smallest principal moment raised to 1e-6 of
the largest, principal moments shifted until they satisfy the triangle inequality) with one warning
that names no body. :func:`check_inertias` refuses such a body in one line naming it and the value,
or (``repair``) replaces its tensor by :func:`nearest_valid`. Two rounding-size errors are repaired
without being asked, each with a one-line note naming the body and the size of the change: a
triangle-inequality miss of at most :data:`TRIANGLE_TOLERANCE` of the largest principal moment
(moved to the nearest valid inertia), and an inertia on a massless frame welded to its parent
(dropped: the frame is merged into its parent). Rules: :mod:`warp_critic.physics.robot_checks`.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np

from warp_critic.core.errors import SceneError

__all__ = ["MASS_RANGE", "TOLERATED", "check_inertias", "inertia_problem", "nearest_valid"]

MASS_RANGE = (1e-6, 1e6)  # kg: a robot link's mass outside it is a unit or typing mistake
# newton's inertia check (newton/_src/geometry/inertia.py): the floor below which it inflates the
# smallest principal moment, and the triangle inequality's tolerance
REL_FLOOR, ABS_FLOOR, F32_EPS = 1e-6, 1e-10, float(np.finfo(np.float32).eps)
REPAIR_INERTIA = "import with --repair-inertia to project it to the nearest valid inertia"
# a triangle-inequality miss up to this fraction of the largest principal moment is rounding in
# the file (a well-known URDF: 0.00306 + 0.02364 < 0.02690, 0.7%): repaired with a note, not refused
TRIANGLE_TOLERANCE = 0.05
TOLERATED = "repaired without --repair-inertia"


def _fail(path: Path, problem: str) -> SceneError:
    return SceneError(f"{path}: {' '.join(str(problem).split())}")


def _short(label: str) -> str:
    return label.rsplit("/", 1)[-1]


def _g(x: float) -> str:
    return f"{x:.6g}"


def _moved_bodies(builder) -> set[int]:
    """Bodies that a movable joint moves (the others are merged into their parent or the world)."""
    import newton

    movable = {int(newton.JointType.REVOLUTE), int(newton.JointType.PRISMATIC)}
    return {c for c, t in zip(builder.joint_child, builder.joint_type) if int(t) in movable}


def _inertia_text(T: np.ndarray) -> str:
    names = ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")
    values = (T[0, 0], T[1, 1], T[2, 2], T[0, 1], T[0, 2], T[1, 2])
    return " ".join(f"{n}={_g(float(v))}" for n, v in zip(names, values) if n[1] == n[2] or v)


def inertia_problem(T: np.ndarray, moved: bool) -> str | None:
    """What is wrong with the inertia ``T (3, 3)`` [kg m^2] of a body with mass, or None."""
    if not np.all(np.isfinite(T)):
        bad = np.isinf(T) if np.any(np.isinf(T)) else np.isnan(T)
        names = ("ixx", "ixy", "ixz", "iyx", "iyy", "iyz", "izx", "izy", "izz")
        first = int(np.flatnonzero(bad.reshape(-1))[0])
        return f"inertia {names[first]}={_g(float(T.reshape(-1)[first]))} is not a finite number"
    diag = np.diag(T)
    if np.any(diag < 0):
        axis = "xyz"[int(np.argmin(diag))]
        return f"inertia i{axis}{axis}={_g(float(diag.min()))} is negative"
    sym = 0.5 * (T + T.T)
    if not np.allclose(T, sym, rtol=1e-5, atol=1e-8):
        return f"inertia {_inertia_text(T)} is not symmetric"
    w = np.linalg.eigvalsh(sym)
    top = max(float(w[2]), 0.0)
    moments = ", ".join(_g(float(x)) for x in w)
    if w[0] < -max(REL_FLOOR * top, ABS_FLOOR):
        return (
            f"inertia {_inertia_text(T)} is not positive definite (principal moments {moments}: "
            "an off-diagonal term too large)"
        )
    if w[0] + w[1] < w[2] - max(F32_EPS * top, ABS_FLOOR):
        return (
            f"inertia {_inertia_text(T)} violates the triangle inequality (principal moments "
            f"{moments}: {_g(float(w[0]))} + {_g(float(w[1]))} < {_g(float(w[2]))})"
        )
    if moved and w[0] < max(REL_FLOOR * top, ABS_FLOOR):
        return (
            f"inertia {_inertia_text(T)} is degenerate (principal moments {moments}: the smallest "
            "is below 1e-6 of the largest, newton would inflate it)"
        )
    return None


def _triangle_miss(T: np.ndarray) -> float | None:
    """How far the principal moments miss the triangle inequality, as a fraction of the largest
    (<= 0: they satisfy it); None for a tensor that is not finite and positive."""
    if not np.all(np.isfinite(T)):
        return None
    w = np.linalg.eigvalsh(0.5 * (T + T.T))
    if not w[0] > 0:
        return None
    return float((w[2] - w[0] - w[1]) / w[2])


def nearest_valid(T: np.ndarray) -> np.ndarray:
    """The valid inertia nearest to ``T`` (Frobenius norm): same principal axes, principal moments
    projected onto {each >= a floor, each pair's sum >= the third}."""
    sym = 0.5 * (T + T.T)
    w, V = np.linalg.eigh(sym)
    scale = max(float(np.abs(w).max()), 1e-9)
    floor, margin = 2 * max(REL_FLOOR * scale, ABS_FLOOR), 4 * F32_EPS * scale
    # constraints a.x >= b: x_i >= floor and x_i + x_j - x_k >= margin
    rows = [(np.eye(3)[i], floor) for i in range(3)]
    rows += [(np.ones(3) - 2 * np.eye(3)[k], margin) for k in range(3)]
    best, best_d = None, math.inf
    for size in range(4):
        for active in itertools.combinations(rows, size):
            x = w.copy()
            if active:
                A = np.array([a for a, _ in active])
                b = np.array([b for _, b in active])
                gram = A @ A.T
                if abs(np.linalg.det(gram)) < 1e-12:
                    continue
                x = w - A.T @ np.linalg.solve(gram, A @ w - b)
            if all(a @ x >= b - 1e-12 * scale for a, b in rows):
                d = float(np.sum((x - w) ** 2))
                if d < best_d:
                    best, best_d = x, d
    assert best is not None  # the set is non-empty and closed: some active set is optimal
    return (V * best) @ V.T


def _welded_to_world(builder) -> set[int]:
    """Bodies joined to the world by fixed joints only (merged into it)."""
    import newton

    fixed = int(newton.JointType.FIXED)
    joint_of = {c: j for j, c in enumerate(builder.joint_child)}
    welded: set[int] = set()
    for b in range(builder.body_count):
        chain, x = [], b
        while x >= 0 and x in joint_of and int(builder.joint_type[joint_of[x]]) == fixed:
            chain.append(x)
            x = builder.joint_parent[joint_of[x]]
            if len(chain) > builder.body_count:
                break
        if x < 0:
            welded.update(chain)
    return welded


def check_inertias(path: Path, builder, repair: bool) -> list[str]:
    """Refuse or (``repair``) replace each invalid mass/inertia of ``builder`` (module docstring);
    the repairs made, one line each."""
    import warp as wp

    repairs = []
    moved, welded = _moved_bodies(builder), _welded_to_world(builder)
    lo, hi = MASS_RANGE
    for b, label in enumerate(builder.body_label):
        if b in welded:  # merged into the world: its mass never moves
            continue
        m = float(builder.body_mass[b])
        T = np.array(builder.body_inertia[b], dtype=np.float64).reshape(3, 3)
        name = _short(label)
        if not math.isfinite(m) or m < 0:
            raise _fail(path, f"body {name!r} has mass {_g(m)} kg: a mass is a finite number > 0")
        if m == 0.0:
            if np.any(T != 0) and b not in moved:  # a frame welded to its parent: merged into it
                builder.body_inertia[b] = wp.mat33(*([0.0] * 9))
                repairs.append(
                    f"body {name}: inertia {_inertia_text(T)} dropped: the frame has no mass and "
                    f"is welded to its parent ({TOLERATED})"
                )
                continue
            if np.any(T != 0) and not repair:
                raise _fail(
                    path,
                    f"body {name!r} has mass 0 kg but inertia {_inertia_text(T)}: give its mass "
                    f"({REPAIR_INERTIA}: none without mass)",
                )
            if np.any(T != 0):
                builder.body_inertia[b] = wp.mat33(*([0.0] * 9))
                repairs.append(f"body {name} inertia {_inertia_text(T)} -> 0 (it has no mass)")
            continue  # a massless link: merged into its parent, or refused later as having no mass
        if m > hi or (m < lo and b in moved):  # a tiny mass on a welded frame link is merged
            raise _fail(
                path,
                f"body {name!r} has mass {_g(m)} kg, outside {lo:g}..{hi:g} kg (a unit or typing mistake?)",
            )
        problem = inertia_problem(T, b in moved)
        if problem is None:
            continue
        miss = _triangle_miss(T)
        if miss is not None and 0.0 < miss <= TRIANGLE_TOLERANCE and "triangle" in problem:
            J = nearest_valid(T)
            builder.body_inertia[b] = wp.mat33(*(float(v) for v in J.reshape(-1)))
            change = float(np.abs(np.linalg.eigvalsh(J) - np.linalg.eigvalsh(T)).max())
            repairs.append(
                f"body {name}: its principal moments miss the triangle inequality by "
                f"{100 * miss:.2g}% of the largest (rounding): moved to the nearest valid inertia, "
                f"no moment changed by more than {_g(change)} kg m^2 ({TOLERATED})"
            )
            continue
        if not repair or not np.all(np.isfinite(T)):
            fix = f" ({REPAIR_INERTIA})" if np.all(np.isfinite(T)) else ""
            raise _fail(path, f"body {name!r}: {problem}{fix}")
        J = nearest_valid(T)
        builder.body_inertia[b] = wp.mat33(*(float(v) for v in J.reshape(-1)))
        repairs.append(
            f"body {name} inertia {_inertia_text(T)} -> {_inertia_text(J)} (nearest valid)"
        )
    return repairs
