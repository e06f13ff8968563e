"""Write a robot imported from a URDF/MJCF/plain USD as a warp-critic scene file (``.usda``).

The written file is an ordinary scene (:mod:`warp_critic.physics.scene`): one articulation root
with ``warp_critic:endEffectorBody``/``tipOffset`` and every training default the robot file did not
say (:mod:`warp_critic.physics.derive`) as ``warp_critic:*`` attributes, so that a user can read and
edit them; from then on the scene is the truth. It holds the dynamics newton imported -- fixed
joints merged, locked joints welded at the home pose -- and no meshes:

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


def write_scene(scene, out: str | Path) -> Path:
    """Write ``scene`` (a robot loaded by :func:`warp_critic.physics.robot.load_robot`) to ``out``.

    Refuses (:class:`UserError`) an existing ``out`` or a suffix that is not ``.usda``/``.usd``.
    """
    import newton
    import torch
    from pxr import Sdf, Usd, UsdGeom, UsdPhysics

    out = Path(out).expanduser()
    if out.suffix not in (".usda", ".usd"):
        raise UserError(f"--out {out}: a scene file ends in .usda or .usd")
    if out.exists() or out.is_symlink():
        raise UserError(f"--out {out}: exists; the import never overwrites a file")
    if not out.parent.is_dir():
        raise UserError(f"--out {out}: no such directory {out.parent}")

    from warp_critic.physics.derive import _simulator

    sim = _simulator(scene, 1, 1e-3, 1, 0.0)
    model = sim.model
    poses = sim.body_poses(torch.zeros(1, scene.dof))[0].astype(np.float64)
    mass = model.body_mass.numpy()
    com = model.body_com.numpy()
    inertia = model.body_inertia.numpy().astype(np.float64)
    X_p = model.joint_X_p.numpy().astype(np.float64)
    X_c = model.joint_X_c.numpy().astype(np.float64)
    axes = model.joint_axis.numpy().astype(np.float64)
    jtype = model.joint_type.numpy()
    parent, child = model.joint_parent.numpy(), model.joint_child.numpy()
    armature = model.joint_armature.numpy()
    limit_ke, limit_kd = scene.limit_ke, scene.limit_kd

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
    rp = root.GetPrim()
    body_names = [f"{b}" for b in scene.body_names]
    rp.CreateAttribute("warp_critic:endEffectorBody", Sdf.ValueTypeNames.String, custom=True).Set(
        body_names[scene.ee_body]
    )
    rp.CreateAttribute("warp_critic:tipOffset", Sdf.ValueTypeNames.Float3, custom=True).Set(
        _vec3(scene.tip_offset)
    )
    repairs = list(getattr(scene, "import_repairs", ()))
    if repairs:  # what the import changed in the robot file on request (robot_checks)
        rp.CreateAttribute(
            "warp_critic:importRepairs", Sdf.ValueTypeNames.StringArray, custom=True
        ).Set(repairs)
    T = Sdf.ValueTypeNames
    from warp_critic.physics import schema

    values = {**scene.defaults, "home": [float(x) for x in scene.home]}
    for (
        attr
    ) in schema.ATTRIBUTES:  # the scene schema's attributes, authored as the loader reads them
        if attr.key in values:
            rp.CreateAttribute(attr.usd, T.Find(attr.type), custom=True).Set(
                schema.to_usd(attr, values[attr.key])
            )

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

    UsdGeom.Scope.Define(stage, f"/{name}/joints")
    for j, jname in enumerate(scene.joint_names):
        revolute = int(jtype[j]) == int(newton.JointType.REVOLUTE)
        path = f"/{name}/joints/{jname}"
        uj = (UsdPhysics.RevoluteJoint if revolute else UsdPhysics.PrismaticJoint).Define(
            stage, path
        )
        turn = _quat_x_to(axes[j])
        uj.CreateAxisAttr("X")
        lo, hi = scene.q_lower[j], scene.q_upper[j]
        if not (lo <= -1e9 and hi >= 1e9):
            scale = 1.0 / DEG if revolute else 1.0
            uj.CreateLowerLimitAttr(float(lo * scale))
            uj.CreateUpperLimitAttr(float(hi * scale))
        if parent[j] >= 0:
            uj.CreateBody0Rel().SetTargets([Sdf.Path(paths[parent[j]])])
        uj.CreateBody1Rel().SetTargets([Sdf.Path(paths[child[j]])])
        uj.CreateLocalPos0Attr(_vec3(X_p[j, :3]))
        uj.CreateLocalRot0Attr(_gf_quat(_quat_mul(X_p[j, 3:], turn)))
        uj.CreateLocalPos1Attr(_vec3(X_c[j, :3]))
        uj.CreateLocalRot1Attr(_gf_quat(_quat_mul(X_c[j, 3:], turn)))
        prim = uj.GetPrim()
        per = DEG if revolute else 1.0  # newton reads revolute gains per degree
        for gain, value in (
            ("newton:damping", scene.damping[j] * per),
            ("newton:limitStiffness", limit_ke[j] * per),
            ("newton:limitDamping", limit_kd[j] * per),
            ("newton:armature", float(armature[j])),
        ):
            prim.CreateAttribute(gain, T.Float).Set(float(value))
        prim.CreateAttribute("warp_critic:effortLimit", T.Float, custom=True).Set(
            float(scene.effort_limit[j])
        )
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
