"""Write a robot imported from a URDF/MJCF/plain USD as a warp-critic scene file (``.usda``).

The written file is an ordinary scene (:mod:`warp_critic.physics.scene`): one articulation root
with ``warp_critic:endEffectorBody``/``tipOffset`` and every training default the robot file did not
say (:mod:`warp_critic.physics.derive`) as ``warp_critic:*`` attributes, so that a user can read and
edit them; from then on the scene is the truth. It holds the dynamics newton imported -- fixed
joints merged, locked joints welded at the home pose -- and the robot file's link meshes, for
drawing only (``UsdGeom.Mesh`` children of the bodies: no collision, no mass):

* one Xform per body with ``RigidBodyAPI`` + ``MassAPI`` (mass, centre of mass, the inertia tensor
  diagonalised as ``diagonalInertia`` + ``principalAxes``), posed at q = 0;
* one ``PhysicsRevoluteJoint``/``PhysicsPrismaticJoint`` per DoF with the newton joint frames
  (``localPos0/Rot0`` = parent frame, ``localPos1/Rot1`` = child frame, both turned so that the
  joint axis is their X axis), limits (revolute in degrees; none for a continuous joint),
  ``newton:damping``/``limitStiffness``/``limitDamping``/``armature`` (newton reads the revolute
  ones per degree) and ``warp_critic:effortLimit``. The first joint has no ``body0``: it is welded
  to the world.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from warp_critic.core.errors import UserError

DEG = math.pi / 180.0


def _quat_x_to(axis: np.ndarray) -> np.ndarray:
    """Quaternion ``(x, y, z, w)`` rotating the X axis onto the unit vector ``axis``."""
    x = np.array([1.0, 0.0, 0.0])
    a = axis / np.linalg.norm(axis)
    c = float(np.dot(x, a))
    if c < -1.0 + 1e-12:
        return np.array([0.0, 0.0, 1.0, 0.0])  # 180 degrees about Z
    v = np.cross(x, a)
    q = np.array([v[0], v[1], v[2], 1.0 + c])
    return q / np.linalg.norm(q)


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of ``(x, y, z, w)`` quaternions."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def _matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Rotation matrix -> ``(x, y, z, w)``."""
    w = math.sqrt(max(0.0, 1.0 + m[0, 0] + m[1, 1] + m[2, 2])) / 2.0
    x = math.copysign(
        math.sqrt(max(0.0, 1.0 + m[0, 0] - m[1, 1] - m[2, 2])) / 2.0, m[2, 1] - m[1, 2]
    )
    y = math.copysign(
        math.sqrt(max(0.0, 1.0 - m[0, 0] + m[1, 1] - m[2, 2])) / 2.0, m[0, 2] - m[2, 0]
    )
    z = math.copysign(
        math.sqrt(max(0.0, 1.0 - m[0, 0] - m[1, 1] + m[2, 2])) / 2.0, m[1, 0] - m[0, 1]
    )
    q = np.array([x, y, z, w])
    return q / np.linalg.norm(q)


def _gf_quat(q):
    from pxr import Gf

    return Gf.Quatf(float(q[3]), Gf.Vec3f(float(q[0]), float(q[1]), float(q[2])))


def _vec3(v):
    from pxr import Gf

    return Gf.Vec3f(*(float(x) for x in v))


def prim_names(names: list[str]) -> list[str]:
    """Valid, distinct USD prim names for ``names`` (a URDF link ``link_9.0`` -> ``link_9_0``;
    a clash gets ``_2``, ``_3``, ..)."""
    from pxr import Tf

    out: list[str] = []
    for n in names:
        base = Tf.MakeValidIdentifier(str(n)) or "prim"
        name, k = base, 2
        while name in out:
            name, k = f"{base}_{k}", k + 1
        out.append(name)
    return out


def _check_out(out: Path) -> None:
    if out.suffix not in (".usda", ".usd"):
        raise UserError(f"--out {out}: a scene file ends in .usda or .usd")
    if out.exists() or out.is_symlink():
        raise UserError(f"--out {out}: exists; the import never overwrites a file")
    if not out.parent.is_dir():
        raise UserError(f"--out {out}: no such directory {out.parent}")


def write_scene(scene, out: str | Path, gravity: float | None = None) -> Path:
    """Write ``scene`` (a robot loaded by :func:`warp_critic.physics.robot.load_robot`) to ``out``,
    its defaults derived under ``gravity`` [m/s^2] (None: the rules' 9.81).

    Refuses (:class:`UserError`) an existing ``out`` or a suffix that is not ``.usda``/``.usd``.
    """
    from pxr import Usd, UsdGeom, UsdPhysics

    out = Path(out).expanduser()
    _check_out(out)
    name = "".join(c if c.isalnum() or c == "_" else "_" for c in scene.name) or "robot"
    if name[0].isdigit():
        name = f"r_{name}"
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)
    stage.SetMetadata(
        "comment",
        f"Imported from {scene.path.name} by warp-critic import; the warp_critic:* attributes "
        "hold the derived training defaults -- edit them here.",
    )
    root = UsdGeom.Xform.Define(stage, f"/{name}")
    stage.SetDefaultPrim(root.GetPrim())
    UsdPhysics.ArticulationRootAPI.Apply(root.GetPrim())
    body_names = prim_names(scene.body_names)
    defaults = scene.defaults if gravity is None else scene.defaults_at(gravity)
    _write_root_attributes(root.GetPrim(), scene, body_names[scene.ee_body], defaults)
    _write_model(stage, scene, name, body_names)
    tmp = out.with_name(f".{out.name}.tmp")
    stage.GetRootLayer().Export(str(tmp))
    try:
        import os

        os.link(tmp, out)  # fails if ``out`` appeared meanwhile: never overwrite
    except FileExistsError:
        raise UserError(f"--out {out}: exists; the import never overwrites a file") from None
    finally:
        tmp.unlink(missing_ok=True)
    return out


def _write_root_attributes(rp, scene, ee_name: str, defaults: dict) -> None:
    """The articulation root's ``warp_critic:*`` attributes: end effector, tip, repairs and the
    training defaults (the scene schema's attributes, authored as the loader reads them)."""
    from pxr import Sdf

    from warp_critic.physics import schema

    T = Sdf.ValueTypeNames
    rp.CreateAttribute("warp_critic:endEffectorBody", T.String, custom=True).Set(ee_name)
    rp.CreateAttribute("warp_critic:tipOffset", T.Float3, custom=True).Set(_vec3(scene.tip_offset))
    repairs = list(getattr(scene, "import_repairs", ()))
    if repairs:  # what the import changed in the robot file on request (robot_checks)
        rp.CreateAttribute("warp_critic:importRepairs", T.StringArray, custom=True).Set(repairs)
    values = {**defaults, "home": [float(x) for x in scene.home]}
    for attr in schema.ATTRIBUTES:
        if attr.key in values:
            rp.CreateAttribute(attr.usd, T.Find(attr.type), custom=True).Set(
                schema.to_usd(attr, values[attr.key])
            )


def _write_model(stage, scene, name: str, body_names: list[str]) -> None:
    """One rigid body Xform per body (mass, centre of mass, principal inertia) posed at q = 0,
    and one revolute/prismatic joint per DoF (module docstring)."""
    import torch
    from pxr import UsdGeom, UsdPhysics

    from warp_critic.physics.derive import _simulator

    sim = _simulator(scene, 1, 1e-3, 1, 0.0)
    model = sim.model
    poses = sim.body_poses(torch.zeros(1, scene.dof))[0].astype(np.float64)
    mass = model.body_mass.numpy()
    com = model.body_com.numpy()
    inertia = model.body_inertia.numpy().astype(np.float64)
    paths = []
    for b, bname in enumerate(body_names):
        path = f"/{name}/{bname}"
        paths.append(path)
        xf = UsdGeom.Xform.Define(stage, path)
        xf.AddTranslateOp().Set(_vec3(poses[b, :3]))
        xf.AddOrientOp().Set(_gf_quat(poses[b, 3:]))
        prim = xf.GetPrim()
        UsdPhysics.RigidBodyAPI.Apply(prim)
        api = UsdPhysics.MassAPI.Apply(prim)
        diag, vecs = np.linalg.eigh(inertia[b])
        if np.linalg.det(vecs) < 0:
            vecs[:, 0] = -vecs[:, 0]
        api.CreateMassAttr(float(mass[b]))
        api.CreateCenterOfMassAttr(_vec3(com[b]))
        api.CreateDiagonalInertiaAttr(_vec3(np.maximum(diag, 0.0)))
        api.CreatePrincipalAxesAttr(_gf_quat(_matrix_to_quat(vecs)))
    _write_meshes(stage, scene, paths)
    UsdGeom.Scope.Define(stage, f"/{name}/joints")
    for j, jname in enumerate(prim_names(scene.joint_names)):
        _write_joint(stage, scene, model, j, f"/{name}/joints/{jname}", paths)


def _write_meshes(stage, scene, paths: list[str]) -> None:
    """The robot file's link meshes (:func:`warp_critic.physics.robot_meshes.link_meshes`) as
    ``UsdGeom.Mesh`` children of their bodies: visual only (newton loads them without density or
    collision), so that recordings of the imported scene draw the robot as it looks. A link
    welded to the world hangs its meshes on a static ``world_meshes`` Xform (no rigid body)."""
    from pxr import UsdGeom, Vt

    from warp_critic.physics.robot_meshes import link_meshes

    world = paths[0].rsplit("/", 1)[0] + "/world_meshes"
    for k, (body, local, vertices, triangles) in enumerate(link_meshes(scene)):
        if body < 0 and not stage.GetPrimAtPath(world):
            UsdGeom.Xform.Define(stage, world)
        mesh = UsdGeom.Mesh.Define(stage, f"{paths[body] if body >= 0 else world}/mesh_{k}")
        mesh.AddTranslateOp().Set(_vec3(local[:3]))
        mesh.AddOrientOp().Set(_gf_quat(local[3:]))
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(vertices, np.float32)))
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(triangles)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([int(i) for i in triangles.reshape(-1)]))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)


def _write_joint(stage, scene, model, j: int, path: str, paths: list[str]) -> None:
    """Joint ``j`` at ``path``: its frames turned so that its axis is their X axis, limits
    (revolute in degrees), newton's gains (per degree for a revolute joint) and the effort limit."""
    import newton
    from pxr import Sdf, UsdPhysics

    T = Sdf.ValueTypeNames
    X_p = model.joint_X_p.numpy().astype(np.float64)[j]
    X_c = model.joint_X_c.numpy().astype(np.float64)[j]
    parent, child = int(model.joint_parent.numpy()[j]), int(model.joint_child.numpy()[j])
    revolute = int(model.joint_type.numpy()[j]) == int(newton.JointType.REVOLUTE)
    uj = (UsdPhysics.RevoluteJoint if revolute else UsdPhysics.PrismaticJoint).Define(stage, path)
    turn = _quat_x_to(model.joint_axis.numpy().astype(np.float64)[j])
    uj.CreateAxisAttr("X")
    lo, hi = scene.q_lower[j], scene.q_upper[j]
    if not (lo <= -1e9 and hi >= 1e9):
        scale = 1.0 / DEG if revolute else 1.0
        uj.CreateLowerLimitAttr(float(lo * scale))
        uj.CreateUpperLimitAttr(float(hi * scale))
    if parent >= 0:
        uj.CreateBody0Rel().SetTargets([Sdf.Path(paths[parent])])
    uj.CreateBody1Rel().SetTargets([Sdf.Path(paths[child])])
    uj.CreateLocalPos0Attr(_vec3(X_p[:3]))
    uj.CreateLocalRot0Attr(_gf_quat(_quat_mul(X_p[3:], turn)))
    uj.CreateLocalPos1Attr(_vec3(X_c[:3]))
    uj.CreateLocalRot1Attr(_gf_quat(_quat_mul(X_c[3:], turn)))
    prim = uj.GetPrim()
    per = DEG if revolute else 1.0  # newton reads revolute gains per degree
    for gain, value in (
        ("newton:damping", scene.damping[j] * per),
        ("newton:limitStiffness", scene.limit_ke[j] * per),
        ("newton:limitDamping", scene.limit_kd[j] * per),
        ("newton:armature", float(model.joint_armature.numpy()[j])),
    ):
        prim.CreateAttribute(gain, T.Float).Set(float(value))
    prim.CreateAttribute("warp_critic:effortLimit", T.Float, custom=True).Set(
        float(scene.effort_limit[j])
    )
