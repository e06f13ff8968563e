"""The scene format: what a warp-critic USD scene holds, and the one table of its attributes.

A scene file (``tools/make_scenes.py`` writes ``scenes/*.usda`` from this table) holds ONE
fixed-base articulation:

* a prim with ``UsdPhysics.ArticulationRootAPI`` carrying :data:`EE_ATTR` (string, the
  end-effector link's prim name or path) and :data:`TIP_ATTR` (float3, metres, in that link's frame);
* rigid bodies (``RigidBodyAPI`` + ``MassAPI`` with ``physics:mass`` > 0 and
  ``physics:diagonalInertia`` >= 0, plus ``centerOfMass``/``principalAxes``), one per moving link;
* only ``UsdPhysics.RevoluteJoint``/``PrismaticJoint`` joints (the first one with no ``body0``:
  welded to the world), each with :data:`EFFORT_ATTR` (float, N*m or N).

Training defaults travel with the scene's CONTENT (not its file name): the optional attributes of
the articulation root in :data:`ATTRIBUTES`, one row each (USD name, ``Scene.defaults`` key = config
field, USD type, rule, the default when the scene authors none, meaning). The loader
(:mod:`warp_critic.physics.usd_scene`) validates them with :func:`parse`, the writer
(:mod:`warp_critic.physics.scene_writer`) authors them with :func:`to_usd`, the task config falls back to :func:`fallbacks`, and the README's table is
:func:`markdown_table`. Real numbers may be ``double`` or ``float`` (the generated scenes use double
so that 0.0025 reads back as exactly 0.0025).

Units are SI throughout: metres, kilograms, seconds, radians (USD authors revolute limits in
degrees; newton converts them). Passive damping and limit gains come from ``newton:damping``,
``newton:limitStiffness``, ``newton:limitDamping``, which newton reads per DEGREE for revolute
joints; the model values are per radian.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from warp_critic.core.critic_input_names import CRITIC_INPUT_NAMES

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "ATTRIBUTES",
    "EE_ATTR",
    "EFFORT_ATTR",
    "STANDARD_GRAVITY",
    "TIP_ATTR",
    "Attribute",
    "RuleError",
    "attribute",
    "fallback_text",
    "fallbacks",
    "keys",
    "markdown_table",
    "parse",
    "to_usd",
]

EFFORT_ATTR = "warp_critic:effortLimit"
EE_ATTR = "warp_critic:endEffectorBody"
TIP_ATTR = "warp_critic:tipOffset"
STANDARD_GRAVITY = 9.81  # m/s^2, along -z

# Sentinels for defaults that are not one value.
REQUIRED = "required"  # the scene or the user must give it
EFFORT_LIMITS = "the joints' effort limits"
ZEROS = "zeros"


@dataclass(frozen=True)
class Attribute:
    """One training-default attribute of the articulation root.

    Attributes:
        usd: the attribute name in the file, e.g. ``warp_critic:maxTorque``.
        key: its ``Scene.defaults`` key and config field (``home``: :attr:`Scene.home`).
        type: the USD type the writer authors (``double``, ``int``, ``string``, ``double[]``).
        rule: what a value must satisfy, one of :data:`RULES`.
        default: the value when neither the scene nor the user sets it, or :data:`REQUIRED`,
            :data:`EFFORT_LIMITS`, :data:`ZEROS`.
        doc: meaning and unit.
        scope: who reads it: ``task`` (every method's task config), ``meta-train`` (ours only),
            ``scene`` (the simulation itself: part of the content hash).
    """

    usd: str
    key: str
    type: str
    rule: str
    default: Any
    doc: str
    scope: str = "task"


# rule -> how the README states it ("dof" = the scene's joint count)
RULES: dict[str, str] = {
    "goals": "G x dof values (G >= 1 goals, flattened row-major), each inside the joint limits",
    "pose": "dof values inside the joint limits",
    "torques": "1 or dof values, each > 0",
    "count": "integer > 0",
    "natural": "integer >= 0",
    "positive": "> 0",
    "nonnegative": ">= 0",
    "finite": "finite",
    "critic_input": ", ".join(CRITIC_INPUT_NAMES[:-1]) + " or " + CRITIC_INPUT_NAMES[-1],
}

ATTRIBUTES: tuple[Attribute, ...] = (
    Attribute("warp_critic:goals", "goals", "double[]", "goals", REQUIRED,
              "training goals in joint space (rad or m)"),
    Attribute("warp_critic:horizon", "horizon", "int", "count", 50, "control steps per rollout"),
    Attribute("warp_critic:dt", "dt", "double", "positive", 0.01, "physics time step (s)"),
    Attribute("warp_critic:substeps", "substeps", "int", "count", 1,
              "physics steps per control step"),
    Attribute("warp_critic:maxTorque", "max_torque", "double[]", "torques", EFFORT_LIMITS,
              "policy torque bound per joint (N*m or N), or one for all joints"),
    Attribute("warp_critic:qdScale", "qd_scale", "double", "positive", 5.0,
              "velocity normalisation (rad/s or m/s)"),
    Attribute("warp_critic:gravity", "gravity", "double", "finite", STANDARD_GRAVITY,
              "gravity along -z (m/s^2)"),
    Attribute("warp_critic:startStd", "start_std", "double", "nonnegative", 0.0,
              "std of random training start states around home (rad or m)"),
    Attribute("warp_critic:homeStarts", "home_starts", "int", "natural", 0,
              "worlds per goal kept at home when startStd > 0"),
    Attribute("warp_critic:alpha", "alpha", "double", "positive", 1e-3,
              "inner learning rate (policy update with the critic)", "meta-train"),
    Attribute("warp_critic:lr", "lr", "double", "positive", 3e-3,
              "outer learning rate (Adam on the critic)", "meta-train"),
    Attribute("warp_critic:iterations", "iterations", "int", "count", 300,
              "outer iterations of meta-training", "meta-train"),
    Attribute("warp_critic:innerSteps", "inner_steps", "int", "count", 1,
              "inner critic-gradient steps per outer iteration", "meta-train"),
    Attribute("warp_critic:criticInput", "critic_input", "string", "critic_input", "full",
              "critic input layout", "meta-train"),
    Attribute("warp_critic:homePose", "home", "double[]", "pose", ZEROS,
              "home (start) joint positions (rad or m)", "scene"),
)  # fmt: skip

_BY_KEY = {a.key: a for a in ATTRIBUTES}


def attribute(key: str) -> Attribute:
    """The row of ``key`` (a ``Scene.defaults`` key or ``home``); ``KeyError`` if there is none."""
    return _BY_KEY[key]


def keys(scope: str) -> tuple[str, ...]:
    """The keys of the attributes of ``scope`` (``task``, ``meta-train`` or ``scene``), in table order."""
    return tuple(a.key for a in ATTRIBUTES if a.scope == scope)


def fallbacks() -> dict[str, Any]:
    """Key -> the value used when neither the scene nor the user sets it (plain values only)."""
    return {
        a.key: a.default
        for a in ATTRIBUTES
        if a.default not in (REQUIRED, EFFORT_LIMITS, ZEROS) and a.scope != "scene"
    }


def fallback_text(key: str) -> str:
    """``key``'s default as help texts write it (``0``, ``300``, ``full``)."""
    value = attribute(key).default
    return f"{value:g}" if isinstance(value, float) else str(value)


# ------------------------------------------------------------------------------------------------
# Rules: a raw value read from a file -> the Python value, or RuleError naming the problem
# ------------------------------------------------------------------------------------------------


class RuleError(ValueError):
    """A value breaks its attribute's rule; the message is the problem (the caller names file/attr)."""


def _number(value) -> float | None:
    """A real number (not bool/str/vector) as float, else None."""
    if isinstance(value, (bool, str, bytes)) or value is None:
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def _numbers(value) -> list[float] | None:
    """A 1-D array of real numbers as a list of floats, else None."""
    if isinstance(value, (str, bytes)) or value is None:
        return None
    try:
        items = list(value)
    except TypeError:
        return None
    out = [_number(v) for v in items]
    return [v for v in out if v is not None] if all(v is not None for v in out) else None


def parse(
    attr: Attribute,
    raw: Any,
    lower: Sequence[float] | np.ndarray,
    upper: Sequence[float] | np.ndarray,
    joint_names: Sequence[str],
) -> Any:
    """Check ``raw`` (as read from the file) against ``attr.rule``; return the ``Scene.defaults`` value.

    ``lower``/``upper``: ``(dof,)`` joint limits [rad or m] for goals and poses (a relative
    tolerance of 1e-6 absorbs the degree round trip). Goals come back as G lists of dof floats,
    torque bounds and poses as lists, counts as int, the rest as float or str.

    Raises:
        RuleError: the problem, e.g. ``must be > 0 (got -1.0)``.
    """
    rule, dof = attr.rule, len(joint_names)
    if rule in ("goals", "torques", "pose"):
        values = _numbers(raw)
        if values is None:
            raise RuleError(f"must be an array of numbers (got {raw!r})")
        if not all(math.isfinite(v) for v in values):
            raise RuleError(f"must be finite (got {values})")
        if rule == "goals":
            if not values or len(values) % dof:
                raise RuleError(
                    f"needs G x {dof} values (G >= 1 goals of {dof} joint positions, "
                    f"flattened), got {len(values)}"
                )
            goals = [values[i : i + dof] for i in range(0, len(values), dof)]
            for g, goal in enumerate(goals):
                _inside(goal, lower, upper, joint_names, f"goal {g}")
            return goals
        if rule == "pose":
            if len(values) != dof:
                raise RuleError(f"needs {dof} values (got {len(values)})")
            _inside(values, lower, upper, joint_names, "the home pose")
            return values
        if len(values) not in (1, dof):
            raise RuleError(f"needs 1 or {dof} values (got {len(values)})")
        if any(v <= 0.0 for v in values):
            raise RuleError(f"must be > 0 (got {values})")
        return values
    if rule == "critic_input":
        if raw not in CRITIC_INPUT_NAMES:
            raise RuleError(f"must be one of {', '.join(CRITIC_INPUT_NAMES)} (got {raw!r})")
        return str(raw)
    value = _number(raw)
    if value is None:
        raise RuleError(f"must be a number (got {raw!r})")
    if not math.isfinite(value):
        raise RuleError(f"must be finite (got {value})")
    if rule in ("count", "natural"):
        if value < (1 if rule == "count" else 0) or not value.is_integer():
            kind = "positive" if rule == "count" else "non-negative"
            raise RuleError(f"must be a {kind} integer (got {raw!r})")
        return int(value)
    if rule == "positive" and value <= 0.0:
        raise RuleError(f"must be > 0 (got {value})")
    if rule == "nonnegative" and value < 0.0:
        raise RuleError(f"must be >= 0 (got {value})")
    return value


def _inside(q, lower, upper, joint_names, what: str) -> None:
    for j, v in enumerate(q):
        tol = 1e-6 * max(1.0, abs(lower[j]), abs(upper[j]))
        if not lower[j] - tol <= v <= upper[j] + tol:
            raise RuleError(
                f"{what} has {joint_names[j]} = {v}, outside the joint limits "
                f"[{lower[j]:.6g}, {upper[j]:.6g}]"
            )


def to_usd(attr: Attribute, value: Any) -> Any:
    """The Python value the writer sets for ``attr`` (goals flattened row-major, numbers exact)."""
    if attr.type == "double[]":
        rows = value if attr.rule == "goals" else [value]
        return [float(v) for row in rows for v in row]
    if attr.type == "double":
        return float(value)
    if attr.type == "int":
        return int(value)
    return str(value)


# ------------------------------------------------------------------------------------------------
# The README's table
# ------------------------------------------------------------------------------------------------


def markdown_table() -> str:
    """The attribute table as the README shows it (a test keeps the README equal to this)."""
    lines = [
        "| attribute | type | key / flag | rule | default | meaning |",
        "|---|---|---|---|---|---|",
    ]
    for a in ATTRIBUTES:
        default = a.default if isinstance(a.default, str) else repr(a.default)
        flag = "`Scene.home`" if a.scope == "scene" else f"`--{a.key.replace('_', '-')}`"
        key = f"`{a.key}` / {flag}"
        lines.append(f"| `{a.usd}` | {a.type} | {key} | {RULES[a.rule]} | {default} | {a.doc} |")
    return "\n".join(lines)
