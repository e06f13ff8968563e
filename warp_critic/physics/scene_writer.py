"""Writing a robot as a warp-critic USD scene (the inverse of :mod:`.usd_scene`).

:func:`write_robot` authors a :class:`Robot` (links, joints, end-effector, training defaults keyed
as :data:`~warp_critic.physics.schema.ATTRIBUTES`) as one ``.usda`` file; ``tools/make_scenes.py``
holds the robots and writes ``scenes/*.usda`` with it.

Conventions of the written USD (all SI: metres, kilograms, seconds; ``upAxis = Z``):

* ``/<robot>`` is an Xform with ``UsdPhysics.ArticulationRootAPI``. Its children are one Xform per
  moving link (``RigidBodyAPI`` + ``MassAPI``) placed at its pose for q = 0, and ``/<robot>/joints``.
* The base is welded to the world by giving the first joint no ``body0``: the world-side frame
  (``localPos0``/``localRot0``) is then the joint frame in world coordinates. Links that are
  welded to the world (the iiwa's ``iiwa_link_0``) or massless (the URDFs' ``endEffector`` /
  ``iiwa_link_ee``) are not bodies, so newton builds exactly the actuated DoFs.
* Joints follow URDF: ``localPos0``/``localRot0`` = the URDF ``<origin>`` in the parent link frame,
  ``localPos1``/``localRot1`` = identity (the child link frame *is* the joint frame), axis = the
  URDF axis (X, Y or Z). No drives.
* USD revolute limits are in DEGREES. Newton's importer also reads the per-joint gains
  ``newton:damping``, ``newton:limitStiffness`` and ``newton:limitDamping`` of revolute joints
  per DEGREE (it multiplies them by 180/pi), so we author ``value_per_rad * pi/180`` for revolute
  joints and the plain value (per metre) for prismatic ones.
* Mass properties: ``physics:mass``, ``physics:centerOfMass`` (link frame) and the full inertia
  tensor about the centre of mass, diagonalised with numpy and stored as ``physics:diagonalInertia``
  plus ``physics:principalAxes`` (quaternion q with I = R(q) diag(d) R(q)^T).
* Custom data (the format: ``warp_critic/physics/schema.py``): ``warp_critic:effortLimit``
  (float, N*m or N) on every joint; ``warp_critic:endEffectorBody`` (string, the end-effector
  link's prim name) and ``warp_critic:tipOffset`` (float3, m, in that link's frame) on the
  articulation root.
* Training defaults of the scene (``Robot.defaults``, keyed as the schema's ``ATTRIBUTES``): custom
  attributes of the articulation root, so that they travel with the file's content, not its name.
  Each is written with the schema's USD type and checked with the schema's rule, the rule the
  loader applies. Real numbers are DOUBLES so that they read back as the exact Python floats of the
  table (a float32 would turn 0.0025 into 0.0024999999441206455). The optional schedule
  (``iterations``, ``inner_steps``, ``critic_input``, ``start_std``, ``home_starts``) holds the
  settings of the runs this project reports for the robot, so that ``warp-critic meta-train
  scenes/kuka.usda`` on its defaults is the reported configuration.
* Visual geometry (capsules/spheres/cylinders) has NO ``CollisionAPI``: newton loads it as
  zero-density visual shapes, so it never changes the authored mass properties.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics

from warp_critic.physics import schema

__all__ = ["Joint", "Link", "Robot", "write_robot"]

DEG = math.pi / 180.0  # rad per degree: USD authors revolute limits (and newton's gains) per degree


@dataclass(frozen=True)
class Link:
    """A moving link: its mass properties about its own frame, and how thick it is drawn."""

    name: str
    mass: float  # kg
    com: tuple[float, float, float]  # m, link frame
    inertia: tuple[float, float, float, float, float, float]  # ixx iyy izz ixy ixz iyz about com
    visual_radius: float = 0.03  # m, capsule radius of the drawn link


@dataclass(frozen=True)
class Joint:
    """A 1-DoF joint as URDF writes it (origin in the parent frame, axis in the joint frame)."""

    name: str
    kind: str  # "revolute" | "prismatic"
    parent: str | None  # None = world
    child: str
    xyz: tuple[float, float, float]  # m, origin in the parent frame (world if None)
    rpy: tuple[float, float, float]  # rad, URDF fixed-axis roll-pitch-yaw
    axis: str  # "X" | "Y" | "Z" in the joint frame
    lower: float  # rad or m
    upper: float
    effort: float  # N*m or N
    damping: float  # N*m*s/rad or N*s/m


@dataclass(frozen=True)
class Robot:
    """Links and joints (parents before children), end-effector, limit gains, defaults, visuals."""

    links: tuple[Link, ...]
    joints: tuple[Joint, ...]
    ee: str  # end-effector link name
    tip: tuple[float, float, float]  # m, tip in the ee link frame
    limit_ke: float
    limit_kd: float
    base_visual: tuple[float, float] | None = None  # (radius, height) of a static base cylinder
    point_visual: dict[str, float] = field(default_factory=dict)  # link -> sphere radius
    # training defaults, keyed as warp_critic.physics.schema.ATTRIBUTES ({}: none authored)
    defaults: dict[str, Any] = field(default_factory=dict)


# ================================================================================================
# Geometry helpers (numpy, float64)
# ================================================================================================


def rpy_to_matrix(rpy) -> np.ndarray:
    """URDF roll-pitch-yaw (fixed X, then Y, then Z axes): R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Rotation matrix -> unit quaternion (w, x, y, z) with w >= 0."""
    w = math.sqrt(max(0.0, 1.0 + m[0, 0] + m[1, 1] + m[2, 2])) / 2.0
    x = math.sqrt(max(0.0, 1.0 + m[0, 0] - m[1, 1] - m[2, 2])) / 2.0
    y = math.sqrt(max(0.0, 1.0 - m[0, 0] + m[1, 1] - m[2, 2])) / 2.0
    z = math.sqrt(max(0.0, 1.0 - m[0, 0] - m[1, 1] + m[2, 2])) / 2.0
    x = math.copysign(x, m[2, 1] - m[1, 2])
    y = math.copysign(y, m[0, 2] - m[2, 0])
    z = math.copysign(z, m[1, 0] - m[0, 1])
    q = np.array([w, x, y, z])
    return q / np.linalg.norm(q)


def quat_to_matrix(q) -> np.ndarray:
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def inertia_matrix(i6) -> np.ndarray:
    ixx, iyy, izz, ixy, ixz, iyz = i6
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], dtype=float)


def principal_inertia(i6) -> tuple[np.ndarray, np.ndarray]:
    """Diagonalise a symmetric inertia tensor: returns (diag, quat wxyz) with I = R diag R^T."""
    inertia = inertia_matrix(i6)
    if not np.any(inertia - np.diag(np.diag(inertia))):
        return np.diag(inertia).copy(), np.array([1.0, 0.0, 0.0, 0.0])
    diag, vecs = np.linalg.eigh(inertia)
    if np.linalg.det(vecs) < 0.0:  # make the eigenvector basis a proper rotation
        vecs[:, 0] = -vecs[:, 0]
    quat = matrix_to_quat(vecs)
    rot = quat_to_matrix(quat)
    err = np.abs(rot @ np.diag(diag) @ rot.T - inertia).max()
    assert err < 1e-12 * max(1.0, np.abs(inertia).max()), f"inertia diagonalisation error {err}"
    return diag, quat


def gf_quat(q) -> Gf.Quatf:
    return Gf.Quatf(float(q[0]), Gf.Vec3f(float(q[1]), float(q[2]), float(q[3])))


def set_pose(xformable: UsdGeom.Xformable, pos, quat) -> None:
    xformable.AddTranslateOp().Set(Gf.Vec3d(*map(float, pos)))
    xformable.AddOrientOp().Set(gf_quat(quat))


def add_capsule(stage: Usd.Stage, path: str, a, b, radius: float, color) -> None:
    """A visual capsule (no CollisionAPI) from point ``a`` to point ``b`` in its parent's frame."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = b - a
    length = float(np.linalg.norm(d))
    if length < 1e-9:
        geom = UsdGeom.Sphere.Define(stage, path)
        geom.CreateRadiusAttr(radius)
        set_pose(geom, a, (1, 0, 0, 0))
    else:
        geom = UsdGeom.Capsule.Define(stage, path)
        geom.CreateAxisAttr("Z")
        geom.CreateRadiusAttr(radius)
        geom.CreateHeightAttr(length)
        z = np.array([0.0, 0.0, 1.0])
        u = d / length
        axis = np.cross(z, u)
        s, c = np.linalg.norm(axis), float(z @ u)
        if s < 1e-12:
            quat = (1, 0, 0, 0) if c > 0 else (0, 1, 0, 0)
        else:
            half = math.atan2(s, c) / 2.0
            quat = (math.cos(half), *(math.sin(half) * axis / s))
        set_pose(geom, (a + b) / 2.0, quat)
    geom.CreateDisplayColorAttr([Gf.Vec3f(*color)])


# ================================================================================================
# Writer
# ================================================================================================

COLORS = [(0.9, 0.45, 0.1), (0.7, 0.7, 0.7)]


def write_defaults(name: str, robot: Robot, prim: Usd.Prim) -> None:
    """Author ``robot.defaults`` as the schema's training-default attributes of ``prim``, each
    checked first with the rule the loader applies."""
    unknown = set(robot.defaults) - {a.key for a in schema.ATTRIBUTES}
    assert not unknown, f"{name}: defaults {sorted(unknown)} are not in the scene schema"
    lower = [j.lower for j in robot.joints]
    upper = [j.upper for j in robot.joints]
    joint_names = [j.name for j in robot.joints]
    for attr in schema.ATTRIBUTES:
        if attr.key not in robot.defaults:
            continue
        value = schema.to_usd(attr, robot.defaults[attr.key])
        try:
            schema.parse(attr, value, lower, upper, joint_names)
        except schema.RuleError as exc:
            raise ValueError(f"{name}: {attr.usd} {exc}") from None
        type_name = Sdf.ValueTypeNames.Find(attr.type)
        prim.CreateAttribute(attr.usd, type_name, custom=True).Set(value)


def write_robot(name: str, robot: Robot, path: Path) -> None:
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)
    stage.SetMetadata(
        "comment", "Generated by tools/make_scenes.py -- edit the table there, not this file."
    )

    root = UsdGeom.Xform.Define(stage, f"/{name}")
    stage.SetDefaultPrim(root.GetPrim())
    UsdPhysics.ArticulationRootAPI.Apply(root.GetPrim())
    root.GetPrim().CreateAttribute(schema.EE_ATTR, Sdf.ValueTypeNames.String, custom=True).Set(
        robot.ee
    )
    root.GetPrim().CreateAttribute(schema.TIP_ATTR, Sdf.ValueTypeNames.Float3, custom=True).Set(
        Gf.Vec3f(*map(float, robot.tip))
    )
    write_defaults(name, robot, root.GetPrim())

    if robot.base_visual is not None:  # static (not a rigid body): drawn only
        radius, height = robot.base_visual
        UsdGeom.Xform.Define(stage, f"/{name}/base")
        cyl = UsdGeom.Cylinder.Define(stage, f"/{name}/base/geom")
        cyl.CreateAxisAttr("Z")
        cyl.CreateRadiusAttr(radius)
        cyl.CreateHeightAttr(height)
        set_pose(cyl, (0, 0, height / 2.0), (1, 0, 0, 0))
        cyl.CreateDisplayColorAttr([Gf.Vec3f(0.3, 0.3, 0.3)])

    assert robot.ee in {link.name for link in robot.links}, (
        f"{name}: end-effector {robot.ee!r} is not a link"
    )
    _write_links(stage, name, robot)
    UsdGeom.Scope.Define(stage, f"/{name}/joints")
    for joint in robot.joints:
        _write_joint(stage, name, robot, joint)
    stage.GetRootLayer().Save()


def _write_links(stage, name: str, robot: Robot) -> None:
    """One rigid body per link, posed at q = 0, with its mass properties and drawn capsules."""
    # World pose of every link at q = 0 (URDF: the child link frame is the joint frame).
    world_rot: dict[str | None, np.ndarray] = {None: np.eye(3)}
    world_pos: dict[str | None, np.ndarray] = {None: np.zeros(3)}
    for joint in robot.joints:
        rot = rpy_to_matrix(joint.rpy)
        world_pos[joint.child] = world_pos[joint.parent] + world_rot[joint.parent] @ np.asarray(
            joint.xyz, float
        )
        world_rot[joint.child] = world_rot[joint.parent] @ rot

    children: dict[str | None, list[Joint]] = {j.parent: [] for j in robot.joints}
    for j in robot.joints:
        children[j.parent].append(j)

    for k, link in enumerate(robot.links):
        xform = UsdGeom.Xform.Define(stage, f"/{name}/{link.name}")
        set_pose(xform, world_pos[link.name], matrix_to_quat(world_rot[link.name]))
        prim = xform.GetPrim()
        UsdPhysics.RigidBodyAPI.Apply(prim)
        mass_api = UsdPhysics.MassAPI.Apply(prim)
        diag, quat = principal_inertia(link.inertia)
        mass_api.CreateMassAttr(float(link.mass))
        mass_api.CreateCenterOfMassAttr(Gf.Vec3f(*map(float, link.com)))
        mass_api.CreateDiagonalInertiaAttr(Gf.Vec3f(*map(float, diag)))
        mass_api.CreatePrincipalAxesAttr(gf_quat(quat))
        # drawn geometry: a capsule from the link origin to each child joint (or to the tip)
        ends = [np.asarray(j.xyz, float) for j in children.get(link.name, [])]
        if link.name == robot.ee:
            ends.append(np.asarray(robot.tip, float))
        color = COLORS[k % len(COLORS)]
        if link.visual_radius > 0.0:
            for e, end in enumerate(ends):
                add_capsule(
                    stage,
                    f"/{name}/{link.name}/visual_{e}",
                    np.zeros(3),
                    end,
                    link.visual_radius,
                    color,
                )
        if link.name in robot.point_visual:
            add_capsule(
                stage,
                f"/{name}/{link.name}/visual_point",
                np.zeros(3),
                np.zeros(3),
                robot.point_visual[link.name],
                color,
            )


def _write_joint(stage, name: str, robot: Robot, joint: Joint) -> None:
    """One revolute or prismatic joint with its limits, newton's gains and the effort limit."""
    jpath = f"/{name}/joints/{joint.name}"
    revolute = joint.kind == "revolute"
    if revolute:
        uj = UsdPhysics.RevoluteJoint.Define(stage, jpath)
        lower, upper, gain_scale = joint.lower / DEG, joint.upper / DEG, DEG
    elif joint.kind == "prismatic":
        uj = UsdPhysics.PrismaticJoint.Define(stage, jpath)
        lower, upper, gain_scale = joint.lower, joint.upper, 1.0
    else:
        raise ValueError(f"{name}/{joint.name}: unsupported joint kind {joint.kind!r}")
    uj.CreateAxisAttr(joint.axis)
    uj.CreateLowerLimitAttr(float(lower))
    uj.CreateUpperLimitAttr(float(upper))
    if joint.parent is not None:
        uj.CreateBody0Rel().SetTargets([Sdf.Path(f"/{name}/{joint.parent}")])
    uj.CreateBody1Rel().SetTargets([Sdf.Path(f"/{name}/{joint.child}")])
    uj.CreateLocalPos0Attr(Gf.Vec3f(*map(float, joint.xyz)))
    uj.CreateLocalRot0Attr(gf_quat(matrix_to_quat(rpy_to_matrix(joint.rpy))))
    uj.CreateLocalPos1Attr(Gf.Vec3f(0.0, 0.0, 0.0))
    uj.CreateLocalRot1Attr(Gf.Quatf(1.0))
    prim = uj.GetPrim()
    # newton reads these per degree for revolute joints (value * 180/pi), per metre otherwise
    prim.CreateAttribute("newton:damping", Sdf.ValueTypeNames.Float).Set(joint.damping * gain_scale)
    prim.CreateAttribute("newton:limitStiffness", Sdf.ValueTypeNames.Float).Set(
        robot.limit_ke * gain_scale
    )
    prim.CreateAttribute("newton:limitDamping", Sdf.ValueTypeNames.Float).Set(
        robot.limit_kd * gain_scale
    )
    prim.CreateAttribute(schema.EFFORT_ATTR, Sdf.ValueTypeNames.Float, custom=True).Set(
        joint.effort
    )
