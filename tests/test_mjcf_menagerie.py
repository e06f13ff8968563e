"""MuJoCo Menagerie's arms and hands, on small MJCF files written here (Menagerie is no package).

What Menagerie's files do that the importer must follow (issue 55): grippers driven by a tendon,
coupled by an ``<equality><joint>`` or closed into a linkage by ``<equality><connect>`` (the arm
trains, the gripper is locked at home, one note says so); a single chain's jaw (locked); two arms
(refused naming ``--joints``); ``<include>`` (followed by the actuation reader too; a scene's free
props dropped); the ``home`` keyframe; ``<plugin>`` actuators; ``/`` and ``.`` in names; meshes
(needed only where a body's inertia comes from them; a missing one is a note; drawn); position
servos (their gains are not the robot's); a derived torque bound's note; rounding-size inertia
errors repaired with a note.
"""

from __future__ import annotations

import numpy as np
import pytest

from warp_critic.cli.main import main
from warp_critic.physics.robot import RobotOptions, load_robot

INERTIAL = '<inertial pos="0.1 0 0" mass="{m}" diaginertia="{i} {i} {i}"/>'


def link(name: str, joint: str, pos: str = "0 0 0", axis: str = "0 1 0", kind: str = "hinge",
         rng: str = "-1 1", inner: str = "", m: float = 1.0, i: float = 0.01) -> str:  # fmt: skip
    """One body with one joint and an inertial; ``inner``: its children."""
    return (
        f'<body name="{name}" pos="{pos}">{INERTIAL.format(m=m, i=i)}'
        f'<joint name="{joint}" type="{kind}" axis="{axis}" range="{rng}"/>{inner}</body>'
    )


def fingers(pos: str = "0.3 0 0") -> str:
    """A hand body (welded to its parent) with two slide fingers."""
    return (
        f'<body name="hand" pos="{pos}">{INERTIAL.format(m=0.5, i=0.001)}'
        + link("left", "finger_l", "0.05 0.02 0", "0 1 0", "slide", "0 0.04", m=0.05, i=1e-4)
        + link("right", "finger_r", "0.05 -0.02 0", "0 -1 0", "slide", "0 0.04", m=0.05, i=1e-4)
        + "</body>"
    )


def arm(hand: str = "", actuators: str = "", extra: str = "", name: str = "arm") -> str:
    """A two-joint arm (a1, a2) with motors, and ``hand`` at its end."""
    motors = '<motor joint="a1" gear="10" ctrlrange="-2 2"/><motor joint="a2" ctrlrange="-5 5"/>'
    body = link("l1", "a1", "0 0 0.1", "0 0 1", inner=link("l2", "a2", "0.3 0 0", inner=hand))
    return (
        f'<mujoco model="{name}"><compiler angle="radian"/><worldbody>{body}</worldbody>'
        f"<actuator>{motors}{actuators}</actuator>{extra}</mujoco>"
    )


def write(tmp_path, name: str, text: str):
    path = tmp_path / name
    path.write_text(text)
    return path


def _run(argv: list[str], capfd) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capfd.readouterr()
    return code, out, err


TENDON = (
    '<tendon><fixed name="split"><joint joint="finger_l" coef="0.5"/>'
    '<joint joint="finger_r" coef="0.5"/></fixed></tendon>'
)
COUPLED = '<equality><joint joint1="finger_r" joint2="finger_l"/></equality>'
LINKAGE = '<equality><connect body1="left" body2="right" anchor="0 0 0"/></equality>'


@pytest.mark.slow
@pytest.mark.parametrize(
    "how, actuators, extra",
    [
        ("tendon", '<general tendon="split" ctrlrange="0 255"/>', TENDON),
        ("equality", '<position joint="finger_l" kp="100"/>', COUPLED),
        ("linkage", '<position joint="finger_l" kp="100"/>', LINKAGE),
    ],
)
def test_an_arm_with_a_gripper_trains_the_arm_with_the_gripper_locked(
    how, actuators, extra, tmp_path, capfd
):
    path = write(tmp_path, f"{how}.xml", arm(fingers(), actuators, extra))
    scene = load_robot(path)
    err = capfd.readouterr().err
    assert scene.joint_names == ["a1", "a2"], how
    notes = [line for line in err.splitlines() if "an arm with a hand" in line]
    assert len(notes) == 1 and "finger_l, finger_r" in notes[0] and "locked at home" in notes[0]
    assert "--joints" in notes[0], err


def test_a_linkage_through_a_trained_joint_is_refused_after_joint_selection(tmp_path, capfd):
    text = arm(fingers(), '<position joint="finger_l" kp="100"/>', LINKAGE)
    path = write(tmp_path, "loop.xml", text)
    code, _, err = _run(["import", str(path), "--out", str(tmp_path / "s.usda"),
                         "--joints", "a1,a2,finger_l"], capfd)  # fmt: skip
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "closed kinematic loop" in err and "'finger_l'" in err and "connect" in err


def test_a_single_chains_jaw_is_locked_and_the_end_effector_holds_it(tmp_path, capfd):
    jaw = link("jaw", "jaw_joint", "0.3 0 0", rng="0 1", m=0.1, i=1e-4)
    path = write(tmp_path, "jaw.xml", arm(jaw, '<motor joint="jaw_joint" ctrlrange="-1 1"/>'))
    scene = load_robot(path)
    err = capfd.readouterr().err
    assert scene.joint_names == ["a1", "a2"]
    assert scene.body_names[scene.ee_body] == "l2"
    assert "an arm with a jaw" in err and "jaw_joint" in err


def test_two_arms_are_refused_naming_joints(tmp_path, capfd):
    motors = "".join(f'<motor joint="{j}" ctrlrange="-1 1"/>' for j in ("a1", "a2", "b1", "b2"))
    motors += '<motor joint="finger_l"/><motor joint="finger_r"/>'
    motors += '<motor joint="gl"/><motor joint="gr"/>'
    hand_b = fingers().replace('"hand"', '"hand_b"').replace('"left"', '"left_b"')
    hand_b = hand_b.replace('"right"', '"right_b"').replace("finger_l", "gl")
    hand_b = hand_b.replace("finger_r", "gr")
    left = link(
        "l1", "a1", "0 0.5 0.1", "0 0 1", inner=link("l2", "a2", "0.3 0 0", inner=fingers())
    )
    right = link("r1", "b1", "0 -0.5 0.1", "0 0 1", inner=link("r2", "b2", "0.3 0 0", inner=hand_b))
    text = (
        f'<mujoco model="two"><worldbody>{left}{right}</worldbody>'
        f"<actuator>{motors}</actuator></mujoco>"
    )
    code, _, err = _run(["import", str(write(tmp_path, "two.xml", text)),
                         "--out", str(tmp_path / "s.usda")], capfd)  # fmt: skip
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "2 arms (a1..a2 and b1..b2)" in err and "--joints" in err


def test_include_is_followed_and_a_scenes_prop_is_dropped(tmp_path, capfd):
    robot = arm()
    write(tmp_path, "robot.xml", robot)
    scene_text = (
        '<mujoco model="scene"><include file="robot.xml"/><worldbody>'
        '<body name="cube" pos="1 0 0"><freejoint name="cube_free"/>'
        '<geom type="box" size="0.02 0.02 0.02"/></body></worldbody></mujoco>'
    )
    scene = load_robot(write(tmp_path, "scene.xml", scene_text))
    err = capfd.readouterr().err
    assert scene.joint_names == ["a1", "a2"]
    assert "dropped 1 bodies" in err and "cube" in err
    # the included file's motors bound the torques: gear 10 x ctrl 2, and ctrl 5
    np.testing.assert_allclose(scene.effort_limit, [20.0, 5.0])


def test_an_included_actuator_section_decides_what_is_driven(tmp_path, capfd):
    """The top file holds no <actuator>: the reader sees the included one, so the undriven a2 is
    refused as such instead of every joint counting as driven."""
    body = link("l1", "a1", "0 0 0.1", "0 0 1", inner=link("l2", "a2", "0.3 0 0"))
    write(tmp_path, "act.xml", '<mujoco><actuator><motor joint="a1"/></actuator></mujoco>')
    text = f'<mujoco model="m"><include file="act.xml"/><worldbody>{body}</worldbody></mujoco>'
    code, _, err = _run(["import", str(write(tmp_path, "top.xml", text)),
                         "--out", str(tmp_path / "s.usda")], capfd)  # fmt: skip
    assert code == 2 and "underactuated: joint 'a2'" in err, err


def test_the_home_keyframe_is_the_home(tmp_path, capfd):
    key = '<keyframe><key name="home" qpos="0.7 -0.4"/><key name="other" qpos="0 0"/></keyframe>'
    scene = load_robot(write(tmp_path, "key.xml", arm(extra=key)))
    np.testing.assert_allclose(scene.home, [0.7, -0.4])
    given = load_robot(tmp_path / "key.xml", RobotOptions(home=(("a1", 0.2),)))
    np.testing.assert_allclose(given.home, [0.2, -0.4])  # --home wins over the keyframe


def test_a_plugin_actuator_drives_its_joint_with_its_force_range(tmp_path, capfd):
    plugin = '<plugin joint="a2" plugin="mujoco.pid" instance="pid" forcerange="-0.9 0.5"/>'
    text = arm(actuators=plugin).replace('<motor joint="a2" ctrlrange="-5 5"/>', "")
    scene = load_robot(write(tmp_path, "plugin.xml", text))
    np.testing.assert_allclose(scene.effort_limit, [20.0, 0.9])


@pytest.mark.slow
def test_names_with_slashes_and_dots_import_and_write(tmp_path, capfd):
    """Shadow's DEX-EE names joints F0/J0 (newton's labels join names with '/'); DRM's Allegro
    names a link link_9.0, not a valid USD prim name."""
    body = link("F0/base", "F0/J0", "0 0 0.1", "0 0 1", inner=link("link_9.0", "F0/J1", "0.3 0 0"))
    text = (
        f'<mujoco model="names"><worldbody>{body}</worldbody><actuator>'
        '<motor joint="F0/J0"/><motor joint="F0/J1"/></actuator></mujoco>'
    )
    out = tmp_path / "names.usda"
    code, stdout, err = _run(["import", str(write(tmp_path, "n.xml", text)), "--out", str(out)],
                             capfd)  # fmt: skip
    assert code == 0, err
    from pxr import Usd

    stage = Usd.Stage.Open(str(out))
    prims = {p.GetName() for p in stage.Traverse()}
    assert {"link_9_0", "F0_J0", "F0_J1"} <= prims, prims
    ee = stage.GetDefaultPrim().GetAttribute("warp_critic:endEffectorBody").Get()
    assert ee == "link_9_0" and "end effector link_9.0" in stdout
    from warp_critic.physics.load import load_scene

    written = load_scene(out)
    assert written.joint_names == ["F0_J0", "F0_J1"]
    assert written.body_names[written.ee_body] == "link_9_0"


def test_one_articulation_for_fingers_hanging_from_the_world(tmp_path, capfd):
    fingers_ = "".join(
        link(f"f{k}", f"j{k}", f"0 {0.1 * k} 0", inner=link(f"g{k}", f"k{k}", "0.2 0 0"))
        for k in range(3)
    )
    motors = "".join(f'<motor joint="{j}{k}" ctrlrange="-1 1"/>' for k in range(3) for j in "jk")
    text = (
        f'<mujoco model="hand"><worldbody>{fingers_}</worldbody>'
        f"<actuator>{motors}</actuator></mujoco>"
    )
    scene = load_robot(write(tmp_path, "hand.xml", text))
    assert scene.dof == 6
    from warp_critic.physics import derive

    sim = derive._simulator(scene, 1, 1e-3, 1, 0.0)
    assert derive.mass_matrices(sim, scene.home[None]).shape == (1, 6, 6)


def test_a_position_servos_gains_are_not_the_robots(tmp_path, capfd):
    servo = arm().replace("<motor joint=\"a2\" ctrlrange=\"-5 5\"/>", '<position joint="a2" '
                          'kp="4500" kv="450" forcerange="-12 12"/>')  # fmt: skip
    scene = load_robot(write(tmp_path, "servo.xml", servo))
    from warp_critic.physics.variants import Variant

    model = scene.build_model([Variant()])
    assert not np.any(model.joint_target_ke.numpy()) and not np.any(model.joint_target_kd.numpy())
    np.testing.assert_allclose(scene.effort_limit, [20.0, 12.0])


MESH = '<asset><mesh name="m" file="{file}"/></asset>'
GEOM = '<geom type="mesh" mesh="m" contype="0" conaffinity="0"/>'


def _stl(path) -> None:
    """A binary STL tetrahedron."""
    import struct

    v = [(0, 0, 0), (0.1, 0, 0), (0, 0.1, 0), (0, 0, 0.1)]
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    data = b"\0" * 80 + struct.pack("<I", len(faces))
    for f in faces:
        data += struct.pack("<3f", 0, 0, 0)
        for k in f:
            data += struct.pack("<3f", *v[k])
        data += b"\0\0"
    path.write_bytes(data)


def _mesh_arm(file: str, inertial: bool = True) -> str:
    text = arm().replace(INERTIAL.format(m=1.0, i=0.01) + '<joint name="a2"',
                         (INERTIAL.format(m=1.0, i=0.01) if inertial else "") + GEOM
                         + '<joint name="a2"')  # fmt: skip
    return text.replace("<worldbody>", MESH.format(file=file) + "<worldbody>")


def test_a_missing_mesh_is_one_note_unless_the_inertia_needs_it(tmp_path, capfd):
    scene = load_robot(write(tmp_path, "missing.xml", _mesh_arm("gone.stl")))
    err = capfd.readouterr().err
    notes = [line for line in err.splitlines() if "gone.stl" in line]
    assert scene.dof == 2 and len(notes) == 1 and "missing" in notes[0], err
    code, _, err = _run(["import", str(write(tmp_path, "needs.xml", _mesh_arm("gone.stl", False))),
                         "--out", str(tmp_path / "s.usda")], capfd)  # fmt: skip
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "body 'l2'" in err and "no <inertial>" in err and "gone.stl" in err


@pytest.mark.slow
def test_meshes_are_drawn_not_simulated(tmp_path, capfd):
    _stl(tmp_path / "tet.stl")
    scene = load_robot(write(tmp_path, "drawn.xml", _mesh_arm("tet.stl")))
    from warp_critic.physics.robot_meshes import link_meshes
    from warp_critic.physics.variants import Variant

    assert scene.build_model([Variant()]).shape_count == 0  # the mesh geom left the model
    meshes = link_meshes(scene)
    assert len(meshes) == 1 and meshes[0][0] == scene.body_names.index("l2")
    assert meshes[0][2].shape == (4, 3) and meshes[0][3].shape == (4, 3)
    # written into the imported scene for drawing: a visual mesh, no mass, no collision
    from warp_critic.physics.export import write_scene
    from warp_critic.physics.load import load_scene

    written = load_scene(write_scene(scene, tmp_path / "drawn.usda"))
    model = written.build_model([Variant()])
    assert model.shape_count == 1 and np.asarray(model.shape_source[0].indices).size == 12
    np.testing.assert_allclose(
        model.body_mass.numpy(), scene.build_model([Variant()]).body_mass.numpy()
    )
    # its body's inertia comes from the mesh: simulated (4 vertices: the tetrahedron's mass)
    needs = load_robot(write(tmp_path, "needs_drawn.xml", _mesh_arm("tet.stl", False)))
    assert needs.build_model([Variant()]).shape_count == 1


@pytest.mark.slow
def test_a_derived_torque_bound_says_so_and_follows_gravity(tmp_path, capfd):
    text = arm().replace('<motor joint="a2" ctrlrange="-5 5"/>', '<motor joint="a2"/>')
    scene = load_robot(write(tmp_path, "free.xml", text))
    at_981 = scene.defaults["max_torque"]
    err = capfd.readouterr().err
    notes = [line for line in err.splitlines() if "no torque bound" in line]
    assert len(notes) == 1 and "1 of 2 joints" in notes[0] and "a2" in notes[0], err
    assert "--max-torque" in notes[0] and "9.81" in notes[0]
    at_0 = scene.defaults_at(0.0)["max_torque"]
    assert at_0[1] < at_981[1]  # a2 holds the link against gravity at 9.81 only
    assert at_0[0] == pytest.approx(at_981[0]) and at_0[0] <= 20.0  # a1: capped by the file's
    # warp-critic import --gravity 0 writes the bounds derived under it, and its gravity
    from warp_critic.physics.load import load_scene

    out = tmp_path / "g0.usda"
    code, _, err = _run(["import", str(tmp_path / "free.xml"), "--out", str(out),
                         "--gravity", "0"], capfd)  # fmt: skip
    assert code == 0, err
    written = load_scene(out).defaults
    assert written["gravity"] == 0.0
    np.testing.assert_allclose(written["max_torque"], at_0, rtol=1e-5)
    code, _, err = _run(["import", str(tmp_path / "free.xml"), "--out", str(tmp_path / "n.usda"),
                         "--gravity", "-1"], capfd)  # fmt: skip
    assert code == 2 and "--gravity" in err and len(err.strip().splitlines()) == 1


TRIANGLE_ROUNDING = 'ixx="0.00306" iyy="0.02364" izz="0.0269" ixy="0" ixz="0" iyz="0"'


def _urdf(l1_inertia: str, frame: str = "") -> str:
    inertia = 'ixx="0.01" iyy="0.05" izz="0.05" ixy="0" ixz="0" iyz="0"'
    links = "".join(
        f'<link name="{n}"><inertial><mass value="1"/><inertia {i}/></inertial></link>'
        for n, i in (("base", inertia), ("l1", l1_inertia), ("l2", inertia))
    )
    joints = "".join(
        f'<joint name="{j}" type="revolute"><parent link="{p}"/><child link="{c}"/>'
        f'<origin xyz="{x} 0 0"/><axis xyz="0 1 0"/>'
        '<limit lower="-1" upper="1" effort="5" velocity="1"/></joint>'
        for j, p, c, x in (("j1", "base", "l1", 0), ("j2", "l1", "l2", 0.5))
    )
    return f'<robot name="r">{links}{joints}{frame}</robot>'


def test_rounding_size_inertia_errors_are_repaired_with_a_note(tmp_path, capfd):
    frame = (
        '<link name="tool"><inertial><mass value="0"/><inertia ixx="0.001" iyy="0.001" '
        'izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link><joint name="t" type="fixed">'
        '<parent link="l2"/><child link="tool"/></joint>'
    )
    scene = load_robot(write(tmp_path, "r.urdf", _urdf(TRIANGLE_ROUNDING, frame)))
    err = capfd.readouterr().err
    lines = err.strip().splitlines()
    tri = [line for line in lines if "body l1" in line]
    assert len(tri) == 1 and "0.74%" in tri[0] and "kg m^2" in tri[0], err
    assert any("body tool" in line and "no mass" in line for line in lines), err
    assert scene.dof == 2 and len(scene.import_repairs) == 2
    gross = 'ixx="0.001" iyy="0.001" izz="1.0" ixy="0" ixz="0" iyz="0"'
    code, _, err = _run(["import", str(write(tmp_path, "g.urdf", _urdf(gross))),
                         "--out", str(tmp_path / "s.usda")], capfd)  # fmt: skip
    assert code == 2 and "triangle inequality" in err and "--repair-inertia" in err


@pytest.mark.slow
def test_robot_zoo_surveys_a_menagerie_checkout_folder(tmp_path, capsys):
    """tools/robot_zoo.py --menagerie DIR: a row per Menagerie file found there (named DIR/FILE),
    a folder with none of them refused in one line."""
    from tests.test_tools import load_tool

    zoo = load_tool("robot_zoo")
    checkout = tmp_path / "menagerie"
    (checkout / "dynamixel_2r").mkdir(parents=True)
    (checkout / "aloha").mkdir()
    (checkout / "dynamixel_2r" / "dynamixel_2r.xml").write_text(arm(name="two_r"))
    undriven = arm(name="al").replace('<motor joint="a2" ctrlrange="-5 5"/>', "")
    (checkout / "aloha" / "aloha.xml").write_text(undriven)
    assert zoo.main(["--menagerie", str(checkout)]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = {line.split()[1]: line for line in out[1:3]}
    assert set(rows) == {"dynamixel_2r/dynamixel_2r.xml", "aloha/aloha.xml"}, out
    assert "2.50 ms x 4" in rows["dynamixel_2r/dynamixel_2r.xml"]
    assert "refused: underactuated: joint 'a2'" in rows["aloha/aloha.xml"]
    assert out[-1] == "1 of 2 files imported, all at dt >= 1 ms"
    assert zoo.main(["--menagerie", str(tmp_path / "aloha_only_not_a_checkout")]) == 2
    assert "--menagerie" in capsys.readouterr().err


def test_robot_zoo_training_resumes_after_the_runs_it_finished(tmp_path):
    """A meta-tested run of the same robot and iteration count is read, not trained again; one of
    another count, or not meta-tested, or of another robot whose name it begins is not."""
    import json

    from tests.test_tools import load_tool

    zoo = load_tool("robot_zoo")

    def run(name: str, iterations: int, tested: bool = True):
        out = tmp_path / name
        out.mkdir()
        (out / "config.json").write_text(json.dumps({"iterations": iterations}))
        if tested:
            (out / "metatest-zoo.json").write_text("{}")
        return out

    run("ur5e-20261206-100000", 200)
    newest = run("ur5e-20261206-110000", 200)
    run("ur5e-20261206-120000", 50)
    run("ur5e-20261206-130000", 200, tested=False)
    run("ur5e_long-20261206-140000", 200)
    assert zoo.finished_run(tmp_path, "ur5e", 200) == newest
    assert zoo.finished_run(tmp_path, "ur5e", 1000) is None


def test_a_joint_pulled_by_a_spatial_tendon_is_refused_naming_it(tmp_path, capfd):
    """Tetheria's hand: its actuators pull spatial tendons routed through sites, which name no
    joint; the refusal says so instead of 'no actuator drives it'."""
    sites = '<site name="s1" pos="0.1 0 0"/>'
    text = arm().replace(
        '<motor joint="a2" ctrlrange="-5 5"/>', '<position tendon="pull" kp="10"/>'
    )
    text = text.replace('<joint name="a1"', sites + '<joint name="a1"', 1)
    text = text.replace('<joint name="a2"', '<site name="s2" pos="0.1 0 0"/><joint name="a2"', 1)
    text = text.replace(
        "<actuator>",
        '<tendon><spatial name="pull"><site site="s1"/><site site="s2"/></spatial></tendon><actuator>',
    )
    code, _, err = _run(["import", str(write(tmp_path, "spatial.xml", text)),
                         "--out", str(tmp_path / "s.usda")], capfd)  # fmt: skip
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "joint 'a2'" in err and "spatial tendons (pull)" in err
