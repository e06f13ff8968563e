"""Scenes: USD robots vs the paper's own dynamics (differentiable-robot-model) and newton's URDF import.

Forward dynamics are read off ONE Featherstone step: newton integrates semi-implicitly,
``qd1 = qd0 + dt * qdd(q0, qd0, tau)``, so ``qdd = (qd1 - qd0) / dt`` exactly for any ``dt`` (the
acceleration is evaluated at the start state); a largish ``dt`` keeps float32 cancellation small.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import newton
import numpy as np
import pytest
import torch
import warp as wp
from conftest import ROOT, SCENES
from helpers import load_tool

from warp_critic.core.errors import SceneError, UserError
from warp_critic.physics import schema
from warp_critic.physics.load import load_scene
from warp_critic.physics.scene import Variant

DT = 1e-2  # s; any dt gives the same qdd (see the module docstring)


def _drm_data() -> Path:
    import diff_robot_data

    return Path(diff_robot_data.__file__).parent


URDF = {
    "reacher": lambda: _drm_data() / "2link_robot.urdf",
    "kuka": lambda: _drm_data() / "kuka_iiwa" / "urdf" / "iiwa7.urdf",
}


def newton_qdd(model, q, qd, tau) -> np.ndarray:
    """(worlds, dof) accelerations from one Featherstone step at (q, qd) with torques tau."""
    worlds = model.world_count
    q, qd, tau = (
        np.broadcast_to(np.asarray(a, np.float32), (worlds, model.joint_dof_count // worlds))
        for a in (q, qd, tau)
    )
    s0, s1, control = model.state(), model.state(), model.control()
    s0.joint_q.assign(q.reshape(-1))
    s0.joint_qd.assign(qd.reshape(-1))
    control.joint_f.assign(tau.reshape(-1))
    newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
    newton.solvers.SolverFeatherstone(model).step(s0, s1, control, None, DT)
    qd1 = s1.joint_qd.numpy().reshape(worlds, -1).astype(np.float64)
    return (qd1 - qd.astype(np.float64)) / DT


def drm_qdd(urdf: Path, q, qd, tau) -> np.ndarray:
    from differentiable_robot_model import DifferentiableRobotModel

    robot = DifferentiableRobotModel(str(urdf), device="cpu")
    t = lambda a: torch.tensor(np.asarray(a, np.float32))  # noqa: E731  (same float32 inputs as newton)
    qdd = robot.compute_forward_dynamics(
        t(q), t(qd), t(tau) * 1.0, include_gravity=True, use_damping=True
    )
    return qdd.detach().numpy().astype(np.float64)


def random_states(scene, n: int, seed: int = 0, torque_fraction: float = 0.05):
    rng = np.random.default_rng(seed)
    q = rng.uniform(0.95 * scene.q_lower, 0.95 * scene.q_upper, size=(n, scene.dof))
    qd = rng.normal(0.0, 1.0, size=(n, scene.dof))
    tau = rng.uniform(-1.0, 1.0, size=(n, scene.dof)) * torque_fraction * scene.effort_limit
    return [a.astype(np.float32) for a in (q, qd, tau)]


def assert_qdd_close(ours: np.ndarray, ref: np.ndarray, rtol: float = 1e-3) -> tuple[float, float]:
    """Per-state relative error of the acceleration vector (norm), with a small absolute floor."""
    err = np.linalg.norm(ours - ref, axis=1)
    scale = np.linalg.norm(ref, axis=1)
    rel = err / np.maximum(scale, 1e-3)
    assert rel.max() < rtol, f"max relative qdd error {rel.max():.2e}\nours={ours}\nref={ref}"
    return float(np.abs(ours - ref).max()), float(rel.max())


# ------------------------------------------------------------------------------------------------
# 1. Forward dynamics vs differentiable-robot-model
# ------------------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("name", ["reacher", "kuka"])
def test_forward_dynamics_match_drm(name):
    scene = load_scene(SCENES / f"{name}.usda")
    q, qd, tau = random_states(scene, 10)
    model = scene.build_model([Variant()] * len(q))
    abs_err, rel_err = assert_qdd_close(
        newton_qdd(model, q, qd, tau), drm_qdd(URDF[name](), q, qd, tau)
    )
    print(
        f"{name}: max |qdd - qdd_drm| = {abs_err:.3g} rad/s^2, max relative (norm) = {rel_err:.3g}"
    )


# ------------------------------------------------------------------------------------------------
# 2. The USD scene equals newton's own URDF import
# ------------------------------------------------------------------------------------------------


def _rot(q) -> np.ndarray:
    return np.array(wp.quat_to_matrix(wp.quat(*map(float, q)))).reshape(3, 3)


@pytest.mark.filterwarnings("ignore:Asset file")  # the iiwa URDF's meshes are not shipped
@pytest.mark.parametrize("name", ["reacher", "kuka"])
def test_usd_equals_newton_urdf_import(name):
    scene = load_scene(SCENES / f"{name}.usda")
    usd = scene.build_model([Variant()])
    assert usd.joint_coord_count == usd.joint_dof_count == usd.joint_count == scene.dof
    builder = newton.ModelBuilder()
    builder.add_urdf(str(URDF[name]()), floating=False)
    urdf = builder.finalize("cpu")

    # URDF bodies that are welded on (fixed joints: the base and the massless end-effector frames)
    # are not bodies in the scene; everything else must match one to one, in order.
    jtype, jchild = urdf.joint_type.numpy(), urdf.joint_child.numpy()
    moving = [
        int(jchild[j]) for j in range(urdf.joint_count) if jtype[j] != int(newton.JointType.FIXED)
    ]
    names = [urdf.body_label[b].rsplit("/", 1)[-1] for b in moving]
    assert names == scene.body_names
    for attr in ("body_mass", "body_com", "body_inertia"):
        np.testing.assert_allclose(
            getattr(usd, attr).numpy(),
            getattr(urdf, attr).numpy()[moving],
            rtol=1e-6,
            atol=1e-8,
            err_msg=attr,
        )

    revolute = [j for j in range(urdf.joint_count) if jtype[j] != int(newton.JointType.FIXED)]
    assert [urdf.joint_label[j].rsplit("/", 1)[-1] for j in revolute] == scene.joint_names
    for attr in ("joint_X_p", "joint_X_c"):
        ours, theirs = getattr(usd, attr).numpy(), getattr(urdf, attr).numpy()[revolute]
        np.testing.assert_allclose(ours[:, :3], theirs[:, :3], atol=1e-7, err_msg=attr)
        for a, b in zip(ours, theirs):  # q and -q are the same rotation
            np.testing.assert_allclose(_rot(a[3:]), _rot(b[3:]), atol=1e-6, err_msg=attr)
    np.testing.assert_allclose(usd.joint_axis.numpy(), urdf.joint_axis.numpy(), atol=1e-7)
    for attr in ("joint_limit_lower", "joint_limit_upper", "joint_damping", "joint_effort_limit"):
        np.testing.assert_allclose(
            getattr(usd, attr).numpy(), getattr(urdf, attr).numpy(), rtol=1e-6, err_msg=attr
        )
    # the scene's own gains, independent of newton's URDF defaults
    np.testing.assert_allclose(usd.joint_damping.numpy(), 0.5, rtol=1e-6)
    np.testing.assert_allclose(usd.joint_limit_ke.numpy(), 1000.0, rtol=1e-6)
    np.testing.assert_allclose(scene.damping, 0.5, rtol=1e-6)

    if name == "kuka":  # the tip offset is the URDF's fixed iiwa_link_ee frame
        q = random_states(scene, 1, seed=2)[0][0]
        poses = []
        for model, body in (
            (usd, scene.ee_body),
            (urdf, urdf.body_label.index("iiwa7/iiwa_link_ee")),
        ):
            state = model.state()
            state.joint_q.assign(q)
            newton.eval_fk(model, state.joint_q, state.joint_qd, state)
            poses.append(state.body_q.numpy()[body])
        tip = wp.transform_point(wp.transform(*map(float, poses[0])), wp.vec3(*scene.tip_offset))
        np.testing.assert_allclose(np.array(tip), poses[1][:3], atol=1e-6)


def test_scene_metadata():
    reacher = load_scene(SCENES / "reacher.usda")
    assert (reacher.name, reacher.dof, reacher.joint_names) == (
        "reacher",
        2,
        ["baseHinge", "interArm"],
    )
    assert reacher.body_names[reacher.ee_body] == "arm2"
    np.testing.assert_allclose(reacher.tip_offset, [1.0, 0.0, 0.0])
    np.testing.assert_allclose(reacher.effort_limit, [20.0, 20.0])
    np.testing.assert_allclose(reacher.q_upper, 2.9670597283903604, rtol=1e-6)
    assert load_scene(str(SCENES / "reacher.usda")) is reacher  # parsed once

    kuka = load_scene(SCENES / "kuka.usda")
    assert kuka.dof == 7 and kuka.body_names[kuka.ee_body] == "iiwa_link_7"
    np.testing.assert_allclose(kuka.tip_offset, [0.0, 0.0, 0.045])
    np.testing.assert_allclose(kuka.effort_limit, 300.0)
    np.testing.assert_allclose(kuka.limit_kd, 0.5, rtol=1e-6)

    point = load_scene(SCENES / "point_mass.usda")
    model = point.build_model([Variant()])
    assert point.dof == model.joint_coord_count == model.joint_dof_count == 2
    assert list(model.joint_type.numpy()) == [int(newton.JointType.PRISMATIC)] * 2
    np.testing.assert_allclose(model.joint_axis.numpy(), [[1, 0, 0], [0, 1, 0]])
    np.testing.assert_allclose(point.q_lower, -5.0)
    np.testing.assert_allclose(point.damping, 0.0)
    assert point.body_names[point.ee_body] == "mass"
    assert model.body_mass.numpy()[point.ee_body] == pytest.approx(1.0)
    # a push along x and along y: a = F/m (the 1 g carriage adds to x only), gravity does no work
    qdd = newton_qdd(model, [0.0, 0.0], [0.0, 0.0], [2.0, 3.0])[0]
    np.testing.assert_allclose(qdd, [2.0 / 1.001, 3.0], rtol=1e-5)
    with pytest.raises(UserError, match="link_scale"):
        point.build_model([Variant(link_scale=2.0)])


@pytest.mark.slow
@pytest.mark.subprocess
def test_generator_reproduces_committed_scenes(tmp_path):
    subprocess.run(
        [sys.executable, str(ROOT / "tools" / "make_scenes.py"), str(tmp_path)],
        check=True,
        capture_output=True,
    )
    for name in ("point_mass", "reacher", "kuka"):
        assert (tmp_path / f"{name}.usda").read_bytes() == (SCENES / f"{name}.usda").read_bytes(), (
            f"scenes/{name}.usda is stale: run python tools/make_scenes.py"
        )


# ------------------------------------------------------------------------------------------------
# 3. Variants
# ------------------------------------------------------------------------------------------------

# reacher at q = 0 (both links along +x), zero velocity: M qdd = tau (gravity is along the axes,
# damping acts on velocity only). Planar 2-link mass matrix with link 1 length l1, com lc1, lc2,
# inertias about the com (z) I1, I2, plus a point mass ma at distance L2 along link 2.
L1, LC, I_ZZ, M_LINK = 1.0, 0.5, 0.001, 1.0


def reacher_mass_matrix(lc2: float, i2: float, ma: float, tip: float) -> np.ndarray:
    i1 = I_ZZ + M_LINK * LC**2
    m11 = i1 + i2 + M_LINK * (L1**2 + lc2**2 + 2 * L1 * lc2)
    m12 = i2 + M_LINK * (lc2**2 + L1 * lc2)
    m22 = i2 + M_LINK * lc2**2
    jac = np.array([L1 + tip, tip])  # d(tip y)/dq at q = 0
    return np.array([[m11, m12], [m12, m22]]) + ma * np.outer(jac, jac)


@pytest.mark.parametrize(
    "variant, lc2, i2, ma, tip",
    [
        (Variant(), 0.5, 0.001, 0.0, 1.0),
        (Variant(ee_mass=0.7), 0.5, 0.001, 0.7, 1.0),
        # stretch rule: Sigma = tr(I)/2 - I = 0.0005 * 1; Sigma_xx *= s^2; I_zz = Sigma_xx + Sigma_yy
        (Variant(link_scale=2.0), 1.0, 0.0005 * (4 + 1), 0.0, 2.0),
        (Variant(link_length=0.5), 0.25, 0.0005 * (0.25 + 1), 0.0, 0.5),
        (
            Variant(ee_mass=0.3, link_length=0.5, link_scale=3.0),
            0.75,
            0.0005 * (2.25 + 1),
            0.3,
            1.5,
        ),
    ],
)
def test_reacher_variant_matches_analytic_mass_matrix(variant, lc2, i2, ma, tip):
    scene = load_scene(SCENES / "reacher.usda")
    tau = np.array([1.0, 0.0])
    qdd = newton_qdd(scene.build_model([variant]), [0.0, 0.0], [0.0, 0.0], tau)[0]
    expected = np.linalg.solve(reacher_mass_matrix(lc2, i2, ma, tip), tau)
    np.testing.assert_allclose(qdd, expected, rtol=2e-4)


def _scaled_reacher_urdf(tmp_path: Path, ma: float, s: float) -> Path:
    """The 2-link URDF with arm2 stretched by s and a point mass ma at its tip (x = s)."""
    m2, c2, tip = 1.0, 0.5 * s, 1.0 * s
    mass = m2 + ma
    com = (m2 * c2 + ma * tip) / mass
    ixx = 0.001  # along the link: unchanged by the stretch, zero for the point mass
    iyy = 0.0005 * (s * s + 1) + m2 * (c2 - com) ** 2 + ma * (tip - com) ** 2
    text = URDF["reacher"]().read_text()
    arm2 = re.search(r'<link name="arm2">.*?</link>', text, re.S).group(0)
    new = re.sub(
        r"<inertial>.*?</inertial>",
        f'<inertial><origin rpy="0 0 0" xyz="{com!r} 0 0"/><mass value="{mass!r}"/>'
        f'<inertia ixx="{ixx!r}" ixy="0" ixz="0" iyy="{iyy!r}" iyz="0" izz="{iyy!r}"/></inertial>',
        arm2,
        flags=re.S,
    )
    path = tmp_path / "reacher_variant.urdf"
    path.write_text(text.replace(arm2, new))
    return path


def test_reacher_variant_matches_drm_on_modified_urdf(tmp_path):
    scene = load_scene(SCENES / "reacher.usda")
    variant = Variant(ee_mass=0.5, link_scale=1.5)
    q, qd, tau = random_states(scene, 8, seed=1)
    ours = newton_qdd(scene.build_model([variant] * len(q)), q, qd, tau)
    ref = drm_qdd(_scaled_reacher_urdf(tmp_path, 0.5, 1.5), q, qd, tau)
    assert_qdd_close(ours, ref)
    assert not np.allclose(
        ours, newton_qdd(scene.build_model([Variant()] * len(q)), q, qd, tau), rtol=1e-2
    )


def test_link_scale_moves_the_tip():
    scene = load_scene(SCENES / "reacher.usda")
    variants = [Variant(), Variant(link_scale=2.0)]
    model = scene.build_model(variants)
    state = model.state()
    q = np.array([0.3, -0.7, 0.3, -0.7], np.float32)
    state.joint_q.assign(q)
    newton.eval_fk(model, state.joint_q, state.joint_qd, state)
    body_q = state.body_q.numpy().reshape(2, len(scene.body_names), 7)
    assert scene.body_names[scene.ee_body] == "arm2"
    dists = []
    for w, variant in enumerate(variants):
        pose = body_q[w, scene.ee_body]
        tip = np.array(
            wp.transform_point(
                wp.transform(*map(float, pose)), wp.vec3(*scene.tip_offset_of(variant))
            )
        )
        dists.append(np.linalg.norm(tip - pose[:3]))  # arm2's origin is the elbow joint
        expected = np.array([math.cos(0.3), math.sin(0.3), 0]) + (w + 1) * np.array(
            [math.cos(-0.4), math.sin(-0.4), 0]
        )
        np.testing.assert_allclose(tip, expected + [0, 0, 0.15], atol=1e-5)
    assert dists[1] == pytest.approx(2 * dists[0], rel=1e-6)
    np.testing.assert_allclose(
        scene.tip_offset_of(Variant(link_length=0.25, link_scale=2.0)), [0.5, 0, 0]
    )
    # the drawn capsule of arm2 (visual only) follows: centre and half height double
    shapes = np.flatnonzero(model.shape_body.numpy() == len(scene.body_names) + scene.ee_body)
    assert len(shapes) == 1
    np.testing.assert_allclose(
        model.shape_transform.numpy()[shapes[0], :3], [1.0, 0.0, 0.0], atol=1e-6
    )
    np.testing.assert_allclose(model.shape_scale.numpy()[shapes[0], :2], [0.025, 1.0], atol=1e-6)


def _arrays(model) -> dict[str, np.ndarray]:
    names = (
        "body_mass",
        "body_com",
        "body_inertia",
        "body_inv_mass",
        "body_inv_inertia",
        "joint_X_p",
        "joint_X_c",
        "joint_axis",
        "joint_limit_lower",
        "joint_limit_upper",
        "joint_damping",
        "joint_effort_limit",
        "shape_transform",
        "shape_scale",
    )
    return {n: getattr(model, n).numpy() for n in names}


@pytest.mark.parametrize("name", ["reacher", "kuka", "point_mass"])
def test_neutral_variants_reproduce_the_base_model(name):
    scene = load_scene(SCENES / f"{name}.usda")
    builder = newton.ModelBuilder()
    builder.add_usd(str(scene.path))  # newton's plain import (it does not read our effort limits)
    base = _arrays(builder.finalize("cpu"))
    base["joint_effort_limit"] = scene.effort_limit.astype(np.float32)
    neutral = [Variant(), Variant(ee_mass=0.0, link_scale=1.0)]
    if np.linalg.norm(scene.tip_offset) > 0:
        neutral.append(Variant(link_length=float(np.linalg.norm(scene.tip_offset))))
    for variant in neutral:
        ours = _arrays(scene.build_model([variant]))
        for key, value in base.items():
            np.testing.assert_array_equal(ours[key], value, err_msg=f"{variant}: {key}")


def test_worlds_carry_their_own_variants():
    scene = load_scene(SCENES / "kuka.usda")
    q, qd, tau = (a[:1] for a in random_states(scene, 1, seed=3))
    model = scene.build_model([Variant(), Variant(ee_mass=2.0)])
    assert model.world_count == 2 and model.joint_dof_count == 2 * scene.dof
    nb = len(scene.body_names)
    mass = model.body_mass.numpy().reshape(2, nb)
    np.testing.assert_allclose(mass[1] - mass[0], np.eye(nb)[scene.ee_body] * 2.0, atol=1e-6)
    np.testing.assert_array_equal(model.body_world.numpy(), np.repeat([0, 1], nb))
    qdd = newton_qdd(model, q, qd, tau)
    single = newton_qdd(scene.build_model([Variant()]), q, qd, tau)[0]
    heavy = newton_qdd(scene.build_model([Variant(ee_mass=2.0)]), q, qd, tau)[0]
    np.testing.assert_allclose(qdd[0], single, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(qdd[1], heavy, rtol=1e-5, atol=1e-5)
    assert np.abs(qdd[1] - qdd[0]).max() > 1e-2
    # the tip mass about link 7's com: parallel-axis by hand (tip on the z axis, com at z = 0.02)
    inertia = model.body_inertia.numpy().reshape(2, nb, 3, 3)[:, scene.ee_body]
    m, c, p, ma = 3.129, 0.02, 0.045, 2.0
    c_new = (m * c + ma * p) / (m + ma)
    added = m * (c - c_new) ** 2 + ma * (p - c_new) ** 2
    np.testing.assert_allclose(inertia[1] - inertia[0], np.diag([added, added, 0.0]), atol=1e-7)
    np.testing.assert_allclose(
        model.body_com.numpy().reshape(2, nb, 3)[1, scene.ee_body], [0, 0, c_new], atol=1e-7
    )


def test_kuka_wrist_limit_is_stable_at_control_rate():
    """Full effort pushing the lightest joint (the wrist) into its limit: bounded, no blow-up."""
    scene = load_scene(SCENES / "kuka.usda")
    model = scene.build_model([Variant()])
    solver = newton.solvers.SolverFeatherstone(model)
    s0, s1, control = model.state(), model.state(), model.control()
    f = np.zeros(scene.dof, np.float32)
    f[-1] = scene.effort_limit[-1]
    control.joint_f.assign(f)
    for _ in range(400):
        solver.step(s0, s1, control, None, 0.0025)
        s0, s1 = s1, s0
    q = s0.joint_q.numpy()
    assert np.isfinite(q).all() and q[-1] < scene.q_upper[-1] + 1.0


# ------------------------------------------------------------------------------------------------
# 4. Errors
# ------------------------------------------------------------------------------------------------


def _edited_reacher(tmp_path: Path, edit, name: str = "broken.usda") -> Path:
    from pxr import Usd

    path = tmp_path / name
    path.write_text((SCENES / "reacher.usda").read_text())
    stage = Usd.Stage.Open(str(path))
    edit(stage)
    stage.GetRootLayer().Save()
    return path


def _spherical(stage):
    from pxr import Sdf, UsdPhysics

    stage.RemovePrim("/reacher/joints/interArm")
    joint = UsdPhysics.SphericalJoint.Define(stage, "/reacher/joints/ball")
    joint.CreateBody0Rel().SetTargets([Sdf.Path("/reacher/arm1")])
    joint.CreateBody1Rel().SetTargets([Sdf.Path("/reacher/arm2")])


def _no_root(stage):
    from pxr import UsdPhysics

    stage.GetPrimAtPath("/reacher").RemoveAPI(UsdPhysics.ArticulationRootAPI)


BAD_SCENES = {
    "missing": (lambda tmp: tmp / "nope.usda", "no such"),
    "directory": (lambda tmp: tmp, "directory"),
    "text": (
        lambda tmp: (tmp / "notes.usda", (tmp / "notes.usda").write_text("just some text\n"))[0],
        "not a",
    ),
    "txt_ext": (
        lambda tmp: (tmp / "notes.txt", (tmp / "notes.txt").write_text("text\n"))[0],
        "not a USD",
    ),
    # a .urdf is a robot file now (tests/test_robots.py); an unknown suffix is still refused
    "suffix": (
        lambda tmp: (tmp / "robot.obj", (tmp / "robot.obj").write_text("v 0 0 0"))[0],
        "not a USD",
    ),
    "no_articulation": (lambda tmp: _edited_reacher(tmp, _no_root), "ArticulationRootAPI"),
    "spherical": (lambda tmp: _edited_reacher(tmp, _spherical), "PhysicsSphericalJoint"),
    "zero_mass": (
        lambda tmp: _edited_reacher(
            tmp, lambda s: s.GetPrimAtPath("/reacher/arm2").GetAttribute("physics:mass").Set(0.0)
        ),
        "mass",
    ),
    "negative_mass": (
        lambda tmp: _edited_reacher(
            tmp, lambda s: s.GetPrimAtPath("/reacher/arm2").GetAttribute("physics:mass").Set(-1.0)
        ),
        "mass",
    ),
    "missing_mass": (
        lambda tmp: _edited_reacher(
            tmp, lambda s: s.GetPrimAtPath("/reacher/arm1").RemoveProperty("physics:mass")
        ),
        "mass",
    ),
    "negative_inertia": (
        lambda tmp: _edited_reacher(
            tmp,
            lambda s: (
                s.GetPrimAtPath("/reacher/arm1")
                .GetAttribute("physics:diagonalInertia")
                .Set((0.001, -0.001, 0.001))
            ),
        ),
        "inertia",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_SCENES))
def test_bad_scene_files_raise_one_line_scene_error(case, tmp_path):
    make, needle = BAD_SCENES[case]
    path = make(tmp_path)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    message = str(info.value)
    assert path.name in message and needle in message and "\n" not in message, message


@pytest.mark.parametrize(
    "variant, flag",
    [
        (Variant(ee_mass=-1.0), "ee_mass: must be >= 0 (got -1.0)"),
        (Variant(ee_mass=float("nan")), "ee_mass"),
        (Variant(link_length=0.0), "link_length: must be > 0"),
        (Variant(link_length=-0.5), "link_length: must be > 0"),
        (Variant(link_scale=0.0), "link_scale: must be > 0"),
        (Variant(link_scale=-2.0), "link_scale: must be > 0"),
    ],
)
def test_bad_variants_raise_user_error_naming_the_field(variant, flag):
    with pytest.raises(UserError, match=re.escape(flag)):
        variant.validate()
    scene = load_scene(SCENES / "reacher.usda")
    with pytest.raises(UserError, match=re.escape(flag)):
        scene.build_model([Variant(), variant])


@pytest.mark.parametrize(
    "case", ["missing", "text", "suffix", "no_articulation", "spherical", "negative_mass"]
)
def test_bad_scene_files_on_the_command_line_exit_2_with_one_line(case, tmp_path, capsys):
    from warp_critic.cli.main import main

    make, _ = BAD_SCENES[case]
    path = make(tmp_path)
    code = main(
        [
            "meta-train",
            str(path),
            "--iterations",
            "1",
            "--out",
            str(tmp_path / "run"),
            "--device",
            "cpu",
        ]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        code == 2
        and len(err) == 1
        and path.name in err[0]
        and err[0].startswith("warp-critic: error:")
    ), err


# ------------------------------------------------------------------------------------------------
# 5. Training defaults and content hash: from the file's content, not its name
# ------------------------------------------------------------------------------------------------

DEFAULT_LINE = re.compile(
    r"^\s*custom \S+ (" + "|".join(re.escape(a.usd) for a in schema.ATTRIBUTES) + r") = .*\n",
    re.M,
)


def test_scene_defaults_are_read_exactly():
    reacher = load_scene(SCENES / "reacher.usda")
    assert reacher.defaults == dict(
        goals=[[1.0, 0.5], [-1.0, -0.5], [0.5, -1.0], [-0.5, 1.0]],
        horizon=50,
        dt=0.01,
        substeps=2,
        max_torque=[20.0, 20.0],
        qd_scale=5.0,
        alpha=3e-4,
        lr=1e-3,
        gravity=9.81,
        iterations=400,
        inner_steps=3,
        critic_input="full",
        start_std=0.0,
        home_starts=0,
    )
    assert type(reacher.defaults["horizon"]) is int and type(reacher.defaults["dt"]) is float
    np.testing.assert_array_equal(reacher.home, [0.0, 0.0])
    kuka = load_scene(SCENES / "kuka.usda")
    d = kuka.defaults
    assert (d["dt"], d["substeps"], d["gravity"], d["alpha"], d["lr"]) == (
        0.0025,
        4,
        0.0,
        3e-4,
        3e-3,
    )  # exact
    # the reported KUKA configuration (RESULTS.md, against the paper's Table 1) is the scene's default
    assert (
        d["iterations"],
        d["inner_steps"],
        d["critic_input"],
        d["start_std"],
        d["home_starts"],
    ) == (3000, 3, "relative", 0.4, 2)
    assert type(d["iterations"]) is int and type(d["home_starts"]) is int
    assert d["max_torque"] == [20.0, 150.0, 8.0, 40.0, 1.5, 2.0, 1.0]
    assert len(d["goals"]) == 4 and all(len(g) == kuka.dof for g in d["goals"])
    assert d["goals"][2] == [0.3, -0.4, -0.3, -1.0, 0.2, 0.4, 0.0]
    np.testing.assert_array_equal(kuka.home, np.zeros(7))
    point = load_scene(SCENES / "point_mass.usda")
    assert point.defaults == dict(
        goals=[[1.0, 1.0]],
        horizon=20,
        dt=0.05,
        substeps=1,
        max_torque=[5.0, 5.0],
        qd_scale=2.0,
        alpha=1e-3,
        lr=3e-3,
        gravity=9.81,
    )
    # the cached scene hands out copies
    reacher.defaults["goals"].append([0.0, 0.0])
    reacher.home[0] = 1.0
    assert len(reacher.defaults["goals"]) == 4 and reacher.home[0] == 0.0
    hashes = {s.content_hash for s in (reacher, kuka, point)}
    assert len(hashes) == 3 and all(re.fullmatch(r"[0-9a-f]{64}", h) for h in hashes)


def test_renamed_and_moved_copy_has_the_same_defaults_home_and_hash(tmp_path):
    original = load_scene(SCENES / "reacher.usda")
    (tmp_path / "elsewhere").mkdir()
    for path in (tmp_path / "myrobot.usda", tmp_path / "elsewhere" / "reacher.usda"):
        path.write_bytes((SCENES / "reacher.usda").read_bytes())
        copy = load_scene(path)
        assert copy is not original and copy.path == path.resolve()
        assert copy.defaults == original.defaults
        np.testing.assert_array_equal(copy.home, original.home)
        assert copy.content_hash == original.content_hash
    assert load_scene(tmp_path / "myrobot.usda").name == "myrobot"


def test_content_hash_changes_with_any_value_and_ignores_the_folder_of_assets(tmp_path):
    original = load_scene(SCENES / "reacher.usda").content_hash
    heavier = _edited_reacher(
        tmp_path,
        lambda s: s.GetPrimAtPath("/reacher/arm2").GetAttribute("physics:mass").Set(1.001),
        "heavier.usda",
    )
    assert load_scene(heavier).content_hash != original
    slower = _edited_reacher(
        tmp_path,
        lambda s: s.GetPrimAtPath("/reacher").GetAttribute("warp_critic:dt").Set(0.02),
        "slower.usda",
    )
    assert load_scene(slower).defaults["dt"] == 0.02
    # training defaults are resolved into each run's config: changing one does not change the hash
    assert load_scene(slower).content_hash == original
    same = _edited_reacher(tmp_path, lambda s: None, "same.usda")
    assert load_scene(same).content_hash == original

    # an asset path relative to the scene (flattening makes it absolute) does not tie the hash to the folder
    def texture(stage):
        from pxr import Sdf

        stage.GetPrimAtPath("/reacher/base/geom").CreateAttribute(
            "note:texture", Sdf.ValueTypeNames.Asset
        ).Set(Sdf.AssetPath("./wood.png"))

    textured = _edited_reacher(tmp_path, texture, "textured.usda")
    (tmp_path / "moved").mkdir()
    moved = tmp_path / "moved" / "renamed.usda"
    moved.write_bytes(textured.read_bytes())
    assert load_scene(moved).content_hash == load_scene(textured).content_hash != original


def test_scene_without_default_attributes_loads_with_empty_defaults(tmp_path):
    text = (SCENES / "reacher.usda").read_text()
    stripped = DEFAULT_LINE.sub("", text)
    assert len(text.splitlines()) - len(stripped.splitlines()) == len(schema.ATTRIBUTES) == 15
    path = tmp_path / "plain.usda"
    path.write_text(stripped)
    scene = load_scene(path)
    assert scene.defaults == {}
    np.testing.assert_array_equal(scene.home, [0.0, 0.0])
    # the hash leaves the training defaults out, not the home pose (the simulation starts there)
    assert scene.dof == 2 and scene.content_hash != load_scene(SCENES / "reacher.usda").content_hash

    # a scene authoring only some of them: only those keys
    path = tmp_path / "some.usda"
    path.write_text(
        stripped.replace(
            "custom string warp_critic:endEffectorBody",
            "custom int warp_critic:horizon = 7\n    custom string warp_critic:endEffectorBody",
        )
    )
    assert load_scene(path).defaults == {"horizon": 7}


def _set_root(attr: str, value, type_name: str | None = None):
    def edit(stage):
        from pxr import Sdf

        prim = stage.GetPrimAtPath("/reacher")
        if type_name is not None:  # re-create with another type
            prim.RemoveProperty(attr)
            prim.CreateAttribute(attr, getattr(Sdf.ValueTypeNames, type_name), custom=True)
        prim.GetAttribute(attr).Set(value)

    return edit


BAD_DEFAULTS = {
    "nan_dt": ("warp_critic:dt", float("nan"), None, "finite"),
    "zero_dt": ("warp_critic:dt", 0.0, None, "> 0"),
    "inf_gravity": ("warp_critic:gravity", float("inf"), None, "finite"),
    "negative_lr": ("warp_critic:lr", -1e-3, None, "> 0"),
    "negative_horizon": ("warp_critic:horizon", -5, None, "positive integer"),
    "zero_substeps": ("warp_critic:substeps", 0, None, "positive integer"),
    "fractional_horizon": ("warp_critic:horizon", 2.5, "Double", "positive integer"),
    "string_qd_scale": ("warp_critic:qdScale", "fast", "String", "number"),
    "goals_wrong_length": ("warp_critic:goals", [1.0, 0.5, -1.0], None, "G x 2"),
    "no_goals": ("warp_critic:goals", [], None, "G x 2"),
    "goal_outside_limits": (
        "warp_critic:goals",
        [1.0, 0.5, 0.5, 3.5],
        None,
        "goal 1 has interArm = 3.5",
    ),
    "nan_goal": ("warp_critic:goals", [1.0, float("nan")], None, "finite"),
    "torque_wrong_length": ("warp_critic:maxTorque", [1.0, 2.0, 3.0], None, "1 or 2 values"),
    "negative_torque": ("warp_critic:maxTorque", [5.0, -1.0], None, "> 0"),
    "home_wrong_length": ("warp_critic:homePose", [0.0], None, "needs 2 values"),
    "home_outside_limits": ("warp_critic:homePose", [-3.0, 0.0], None, "baseHinge = -3.0"),
}


@pytest.mark.parametrize("case", sorted(BAD_DEFAULTS))
def test_bad_default_attributes_raise_one_line_scene_error(case, tmp_path):
    attr, value, type_name, needle = BAD_DEFAULTS[case]
    path = _edited_reacher(tmp_path, _set_root(attr, value, type_name), f"{case}.usda")
    with pytest.raises(SceneError) as info:
        load_scene(path)
    message = str(info.value)
    assert path.name in message and attr in message and needle in message and "\n" not in message, (
        message
    )


def test_one_torque_bound_for_all_joints_is_accepted(tmp_path):
    path = _edited_reacher(tmp_path, _set_root("warp_critic:maxTorque", [7.5]), "one_torque.usda")
    assert load_scene(path).defaults["max_torque"] == [7.5]


# ------------------------------------------------------------------------------------------------
# 6. One schema: the loader, the writer, the scenes and the README agree
# ------------------------------------------------------------------------------------------------


def test_readme_attribute_table_is_the_schema():
    readme = (ROOT / "README.md").read_text()
    assert load_tool("make_scenes").readme_with_table(readme) == readme, (
        "README.md's attribute table differs from warp_critic/physics/schema.py: "
        "run python tools/make_scenes.py --readme"
    )
    for attr in schema.ATTRIBUTES:
        assert f"| `{attr.usd}` | {attr.type} | `{attr.key}` " in readme, attr.usd


def test_shipped_scenes_author_only_schema_attributes_with_its_types():
    known = {a.usd: a.type for a in schema.ATTRIBUTES}
    known.update({schema.EE_ATTR: "string", schema.TIP_ATTR: "float3", schema.EFFORT_ATTR: "float"})
    for name in ("point_mass", "reacher", "kuka"):
        authored = re.findall(
            r"custom (\S+) (warp_critic:\w+) =", (SCENES / f"{name}.usda").read_text()
        )
        assert authored and all(known.get(attr) == kind for kind, attr in authored), (
            name,
            authored,
        )
    # the writer takes its keys from the schema, and checks values with its rules
    from warp_critic.physics.scene_writer import write_defaults

    robot = load_tool("make_scenes").ROBOTS["reacher"]
    bad = dataclasses.replace(robot, defaults={**robot.defaults, "horizn": 5})
    with pytest.raises(AssertionError, match="horizn"):
        write_defaults("reacher", bad, None)
    far = dataclasses.replace(robot, defaults={**robot.defaults, "goals": ((0.0, 4.0),)})
    with pytest.raises(ValueError, match="goal 0 has interArm = 4.0"):
        write_defaults("reacher", far, None)


def test_edited_scene_file_is_read_again_in_the_same_process(tmp_path):
    path = tmp_path / "robot.usda"
    text = (SCENES / "reacher.usda").read_text()
    path.write_text(text)
    before = load_scene(path)
    path.write_text(text.replace("warp_critic:horizon = 50", "warp_critic:horizon = 7"))
    after = load_scene(path)
    assert (before.defaults["horizon"], after.defaults["horizon"]) == (50, 7)


# Prints the content hashes of three copies of an instanced scene, loaded one after the other.
_HASH_SCRIPT = """
import json, shutil, sys
from pathlib import Path
from warp_critic.physics.load import load_scene
src, out = Path(sys.argv[1]), Path(sys.argv[2])
hashes = []
for k in range(3):
    shutil.copy(src, out / f"copy{k}.usda")
    hashes.append(load_scene(out / f"copy{k}.usda").content_hash)
print(json.dumps(hashes))
"""

# The same for Newton's own instanced asset, through the hash function alone (newton's loader
# refuses its fixed root joint).
_NEWTON_HASH_SCRIPT = """
import json, sys
from pathlib import Path
from pxr import Usd
from warp_critic.physics.scene_hash import content_hash
path = Path(sys.argv[1])
print(json.dumps([content_hash(path, Usd.Stage.Open(str(path))) for _ in range(3)]))
"""


def _instanced(stage):
    """Three links get a visual child that instances its own prototype (a class prim)."""
    from pxr import UsdGeom

    for k, link in enumerate(("base", "arm1", "arm2")):
        stage.CreateClassPrim(f"/decor_{k}")
        UsdGeom.Sphere.Define(stage, f"/decor_{k}/ball").CreateRadiusAttr(0.01 * (k + 1))
        prim = stage.DefinePrim(f"/reacher/{link}/decor")
        prim.GetReferences().AddInternalReference(f"/decor_{k}")
        prim.SetInstanceable(True)


def _run_json(script: str, *args) -> list[str]:
    done = subprocess.run(
        [sys.executable, "-c", script, *map(str, args)], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.slow
@pytest.mark.subprocess
def test_instanced_scene_hashes_the_same_in_every_process(tmp_path):
    """USD numbers instance prototypes in a new order per stage; the hash must not see it."""
    source = _edited_reacher(tmp_path, _instanced, "instanced.usda")
    hashes = []
    for run in ("a", "b"):
        (tmp_path / run).mkdir()
        hashes += _run_json(_HASH_SCRIPT, source, tmp_path / run)
    assert len(set(hashes)) == 1, hashes
    plain = load_scene(SCENES / "reacher.usda").content_hash
    assert hashes[0] == load_scene(source).content_hash != plain


@pytest.mark.slow
@pytest.mark.subprocess
def test_newton_instanced_asset_hashes_the_same_in_every_process():
    asset = Path(newton.__file__).parent / "examples" / "assets" / "cartpole_single_pendulum.usda"
    assert "instanceable = true" in asset.read_text()
    hashes = _run_json(_NEWTON_HASH_SCRIPT, asset) + _run_json(_NEWTON_HASH_SCRIPT, asset)
    assert len(set(hashes)) == 1, hashes
