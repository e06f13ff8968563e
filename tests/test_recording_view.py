"""What a run's recording draws: the robot from its own shapes (line strips without them), placed by
the body poses, and a camera that frames it (warp_critic.running.recording_view)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import rerun as rr
from conftest import KUKA, POINT_MASS, REACHER

from warp_critic.running.recording_view import (
    CAPSULE,
    CYLINDER,
    SPHERE,
    RobotDrawing,
    camera_for,
    quat_mul,
    quat_rotate,
)


def drawing_of(scene_path: str) -> tuple[RobotDrawing, object]:
    from warp_critic.core import runtime
    from warp_critic.physics.load import load_scene
    from warp_critic.physics.variants import Variant

    runtime.init()
    scene = load_scene(scene_path)
    model = scene.build_model([Variant(), Variant()])
    return RobotDrawing.from_model(model, 2, scene.ee_body, scene.tip_offset_of()), model


def test_quaternions_rotate_and_compose():
    qz = np.array([0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)])  # 90 degrees about z
    assert np.allclose(quat_rotate(qz, np.array([1.0, 0, 0])), [0, 1, 0])
    assert np.allclose(quat_rotate(quat_mul(qz, qz), np.array([1.0, 0, 0])), [-1, 0, 0])


@pytest.mark.parametrize(
    "scene,kinds",
    [(KUKA, {CAPSULE}), (REACHER, {CAPSULE}), (POINT_MASS, {SPHERE})],
)
def test_the_robot_is_drawn_from_its_own_shapes_once(scene, kinds):
    d, model = drawing_of(scene)
    B = model.body_count // 2
    assert set(d.kind.tolist()) == kinds and d.has_shapes
    assert (d.body >= 0).all() and (d.body < B).all()  # one world's shapes, by its own bodies
    assert len(d.kind) == int((model.shape_body.numpy() >= 0).sum()) // 2
    if scene != POINT_MASS:
        assert d.static_kind.tolist() == [CYLINDER]  # the base, once for both worlds


def test_a_reacher_link_capsule_spans_its_link():
    """At zero angles the reacher lies along x: its first capsule runs from the base to x = 1 m."""
    d, model = drawing_of(REACHER)
    B = model.body_count // 2
    poses = np.tile([0.0, 0, 0, 0, 0, 0, 1], (B, 1))
    poses[1, 0] = 1.0  # the second link's frame at the end of the first
    rec = rr.RecordingStream("test")
    logged = {}
    rec.log = lambda entity, arch, static=False: logged.__setitem__(entity, arch)  # type: ignore[method-assign]
    d.log_arm(rec, "arm", poses, (255, 0, 0))
    caps = logged["arm/capsules"]
    start = caps.translations.as_arrow_array().to_pylist()
    length = caps.lengths.as_arrow_array().to_pylist()
    quat = np.array(caps.quaternions.as_arrow_array().to_pylist())
    ends = np.array(start) + np.array(length)[:, None] * quat_rotate(quat, np.array([0.0, 0, 1]))
    first = int(np.argmin([s[0] for s in start]))
    assert np.allclose(start[first], [0, 0, 0], atol=1e-6)
    assert np.allclose(ends[first], [1, 0, 0], atol=1e-6)


def test_a_robot_without_shapes_is_drawn_as_line_strips_along_its_links():
    d, model = drawing_of(KUKA)
    bare = dataclasses.replace(d, kind=d.kind[:0], body=d.body[:0])
    B = model.body_count // 2
    poses = np.tile([0.0, 0, 0, 0, 0, 0, 1], (B, 1))
    poses[:, 2] = np.arange(B) * 0.2
    rec = rr.RecordingStream("test")
    logged = {}
    rec.log = lambda entity, arch, static=False: logged.__setitem__(entity, arch)  # type: ignore[method-assign]
    bare.log_arm(rec, "arm", poses, (255, 0, 0))
    assert list(logged) == ["arm/links"]
    strips = logged["arm/links"].strips.as_arrow_array().to_pylist()
    assert len(strips) == len(d.links) + 1 == B  # parent -> child for each joint, and the tip
    assert np.allclose(strips[-1][1], d.tip_of(poses))


def test_the_camera_looks_at_the_centre_from_above_for_a_planar_robot():
    points = np.array([[0.0, 0, 0], [2, 2, 0], [2, 0, 0]])
    flat = camera_for(points, planar=True)
    side = camera_for(points, planar=False)
    for cam in (flat, side):
        target = np.array(cam.look_target.as_arrow_array().to_pylist()[0])
        assert np.allclose(target, [1, 1, 0])
    up = np.array(flat.position.as_arrow_array().to_pylist()[0]) - [1, 1, 0]
    assert up[2] > 2 * abs(up[0]) and up[2] > 2 * abs(up[1])
    oblique = np.array(side.position.as_arrow_array().to_pylist()[0]) - [1, 1, 0]
    assert abs(oblique[0]) > 0.3 * np.linalg.norm(oblique)


def test_a_mesh_robot_logs_its_meshes_once_then_only_their_transforms(mesh_arm):
    """Each link mesh's geometry is logged once, statically, per entity; a later pose logs only
    its transform (a small recording); no line strips; the camera frames the meshes' extent."""
    from warp_critic.core import runtime
    from warp_critic.physics.load import load_any
    from warp_critic.physics.variants import Variant

    runtime.init()
    scene = load_any(str(mesh_arm))
    model = scene.build_model([Variant(), Variant()])
    d = RobotDrawing.from_model(model, 2, scene.ee_body, scene.tip_offset_of())
    assert d.mesh_body.tolist() == [0, 1] and d.has_shapes and len(d.kind) == 0
    assert d.mesh_vertices[0].shape == (26, 3) and d.mesh_indices[0].shape == (48, 3)
    rec = rr.RecordingStream("test")
    logged: list = []
    rec.log = lambda entity, arch, static=False: logged.append((entity, arch, static))  # type: ignore[method-assign]
    poses = np.tile([0.0, 0, 0, 0, 0, 0, 1], (2, 1))
    poses[1, :3] = [0.5, 0.2, 0.1]
    d.log_arm(rec, "arm", poses, (255, 0, 0))
    first = [(e, type(a).__name__, s) for e, a, s in logged]
    assert ("arm/meshes/1", "Mesh3D", True) in first and ("arm/meshes/0", "Mesh3D", True) in first
    assert not any("links" in e for e, _, _ in first)
    logged.clear()
    poses[1, :3] = [0.4, 0.3, 0.1]
    d.log_arm(rec, "arm", poses, (255, 0, 0))
    assert [(e, type(a).__name__, s) for e, a, s in logged] == [
        ("arm/meshes/0", "Transform3D", False),
        ("arm/meshes/1", "Transform3D", False),
    ]
    moved = logged[1][1].translation.as_arrow_array().to_pylist()[0]
    assert np.allclose(moved, [0.4, 0.3, 0.1])  # the second link's mesh sits at its body
    # the camera frames the second link's far end, 0.5 m beyond its body origin
    assert d.points(poses)[:, 0].max() == pytest.approx(0.9, abs=1e-5)


def test_stl_files_read_binary_and_ascii_alike(tmp_path):
    from warp_critic.physics.robot_meshes import read_stl

    tri = np.array(
        [[[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 0, 0], [0, 1, 0], [0, 0, 1]]], np.float32
    )
    rows = np.zeros(2, np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    rows["v"] = tri
    (tmp_path / "b.stl").write_bytes(bytes(80) + (2).to_bytes(4, "little") + rows.tobytes())
    facets = "".join(
        "facet normal 0 0 0\nouter loop\n"
        + "".join(f"vertex {x} {y} {z}\n" for x, y, z in t)
        + "endloop\nendfacet\n"
        for t in tri
    )
    (tmp_path / "a.stl").write_text(f"solid t\n{facets}endsolid t\n")
    for name in ("a.stl", "b.stl"):
        v, f = read_stl(tmp_path / name)
        assert v.shape == (4, 3) and f.shape == (2, 3)  # the shared corners merged
        np.testing.assert_array_equal(v[f], tri)


def test_a_urdf_robot_is_drawn_from_its_link_meshes():
    """The UR5 of example-robot-data: a URDF imported without meshes is still drawn from them (its
    STL collision meshes; its visual .dae files are not read), one per moving link."""
    import sysconfig
    from pathlib import Path

    from warp_critic.core import runtime
    from warp_critic.physics.robot import load_robot
    from warp_critic.physics.robot_meshes import link_meshes
    from warp_critic.physics.variants import Variant

    robots = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"
    urdf = robots / "ur_description/urdf/ur5_robot.urdf"
    if not urdf.is_file():
        pytest.skip("example-robot-data missing (pip install -e '.[test]')")
    runtime.init()
    scene = load_robot(urdf)
    meshes = link_meshes(scene)
    # the base (welded to the world) and shoulder .. wrist 3
    assert [m[0] for m in meshes] == [-1, *range(6)]
    assert all(len(v) > 100 and f.max() < len(v) for _, _, v, f in meshes)
    model = scene.build_model([Variant(), Variant()])
    d = RobotDrawing.from_model(model, 2, scene.ee_body, scene.tip_offset_of(), meshes)
    assert d.mesh_body.tolist() == [-1, *range(6)] and d.has_shapes
    rec = rr.RecordingStream("test")
    logged: list = []
    rec.log = lambda entity, arch, static=False: logged.append((entity, type(arch).__name__))  # type: ignore[method-assign]
    d.log_static(rec, "base", (90, 90, 90))
    assert logged == [("base/meshes/0", "Mesh3D"), ("base/meshes/0", "Transform3D")]
    logged.clear()
    d.log_arm(rec, "arm", np.tile([0.0, 0, 0, 0, 0, 0, 1], (6, 1)), (255, 0, 0))
    meshes_logged = {e for e, _ in logged if "/meshes/" in e}
    assert meshes_logged == {f"arm/meshes/{i}" for i in range(1, 7)}  # the base's is not moved
