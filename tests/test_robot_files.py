"""Robot files nobody here wrote, from three packages (gymnasium's MuJoCo assets,
differentiable-robot-model's data, example-robot-data): each imports at dt >= 1 ms, stable by
model (armature, damping, limit springs), or is refused in one line for a reason that is true.

Covered: an MJCF with actuators and unactuated bodies beside the robot (reacher, pusher), an MJCF
with an unactuated joint in the chain (inverted double pendulum), MJCF floating bases (ant), a
hand on a fixed palm (Allegro), an arm with a hand (iiwa7 + Allegro, Jaco), and arms that a
random-torque probe used to refuse or step at a fraction of a millisecond (xArm7, Z1, Fetch).
"""

from __future__ import annotations

import math
import sysconfig
from pathlib import Path

import numpy as np
import pytest

from warp_critic.cli.main import main
from warp_critic.core.errors import SceneError
from warp_critic.physics import derive
from warp_critic.physics.balance import upright_joints
from warp_critic.physics.robot import RobotOptions, load_robot

PURELIB = Path(sysconfig.get_paths()["purelib"])
GYM = PURELIB / "gymnasium/envs/mujoco/assets"
DRM = PURELIB / "diff_robot_data"
ERD = PURELIB / "cmeel.prefix/share/example-robot-data/robots"

pytestmark = pytest.mark.skipif(
    not (GYM.is_dir() and DRM.is_dir() and ERD.is_dir()),
    reason="robot-file packages missing (pip install -e '.[test]')",
)


def _run(argv, capfd) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capfd.readouterr()
    return code, out, err


def _stable_at_a_normal_step(scene) -> dict:
    """The derived defaults, checked: dt >= 1 ms (at most 10 substeps of the 0.01 s control
    period), and the random-torque probe stays finite and inside its energy cap there."""
    d = scene.defaults
    assert d["dt"] >= 1e-3 - 1e-12 and d["substeps"] <= 10, (d["dt"], d["substeps"])
    assert d["dt"] * d["substeps"] == pytest.approx(derive.CONTROL_PERIOD)
    assert derive.stable(scene, d["dt"], d["substeps"], np.array(d["max_torque"]), 9.81)
    assert np.all(scene.armature > 0) and np.all(scene.damping >= 0)
    return d


# ------------------------------------------------------------------------------------------------
# MJCF: what the file actuates
# ------------------------------------------------------------------------------------------------


def test_gym_reacher_drops_its_target_and_keeps_the_files_model(capfd):
    """The target's slide joints have no actuator: the body is dropped (one note line); the file's
    armature 1 and damping 1 (its default class) are kept; the motors' gear 200 x ctrlrange 1
    caps the effort."""
    scene = load_robot(GYM / "reacher.xml")
    err = capfd.readouterr().err
    notes = [line for line in err.splitlines() if "dropped" in line]
    assert len(notes) == 1 and "target" in notes[0], err
    assert scene.joint_names == ["joint0", "joint1"] and "target" not in scene.body_names
    np.testing.assert_allclose(scene.armature, [1.0, 1.0])
    np.testing.assert_allclose(scene.damping, [1.0, 1.0])
    np.testing.assert_allclose(scene.effort_limit, [200.0, 200.0])
    d = _stable_at_a_normal_step(scene)
    assert np.all(np.array(d["max_torque"]) <= 200.0)
    # joint0 is continuous: its goals are drawn within +-pi of home
    assert scene.q_upper[0] >= 1e9
    assert np.all(np.abs(np.array(d["goals"])[:, 0] - scene.home[0]) <= math.pi)


def test_gym_pusher_drops_object_and_goal_and_caps_by_ctrlrange():
    scene = load_robot(GYM / "pusher.xml")
    assert scene.dof == 7 and not {"object", "goal"} & set(scene.body_names)
    np.testing.assert_allclose(scene.effort_limit, 2.0)  # gear 1 x ctrlrange +-2
    np.testing.assert_allclose(scene.armature, 0.04)  # the file's default class
    np.testing.assert_allclose(scene.damping, [1.0, 1.0, 0.1, 0.1, 0.1, 0.1, 0.1])
    d = _stable_at_a_normal_step(scene)
    assert np.all(np.array(d["max_torque"]) <= 2.0)


def test_gym_double_pendulum_is_underactuated_and_joints_locks_the_poles(tmp_path, capfd):
    """Only the cart's slider has a motor: refused in one line naming the first unactuated hinge;
    ``--joints slider`` (applied before any check) trains the cart with the poles locked."""
    path = GYM / "inverted_double_pendulum.xml"
    out = tmp_path / "cart.usda"
    code, _, err = _run(["import", str(path), "--out", str(out)], capfd)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "underactuated: joint 'hinge' has no actuator" in err and str(path) in err
    assert not out.exists()
    scene = load_robot(path, RobotOptions(joints=("slider",)))
    assert scene.joint_names == ["slider"]
    np.testing.assert_allclose(scene.effort_limit, [500.0])  # gear 500 x ctrlrange +-1
    _stable_at_a_normal_step(scene)


def test_gym_ant_is_a_floating_base_in_one_line(tmp_path, capfd):
    code, _, err = _run(["import", str(GYM / "ant.xml"), "--out", str(tmp_path / "a.usda")], capfd)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert err.startswith("warp-critic: error: ") and "floating base" in err, err


# ------------------------------------------------------------------------------------------------
# URDF: hands, arms with hands, arms
# ------------------------------------------------------------------------------------------------


def test_allegro_hand_on_a_fixed_palm_trains_every_finger():
    """Four chains on a palm that no joint moves: a hand, not a floating base. The file's damping
    (3-10 N m s/rad on 1e-4 kg m^2 fingers) is kept; the armature makes it one step's time constant
    (newton integrates damping explicitly)."""
    scene = load_robot(DRM / "allegro/urdf/allegro_hand_description_left.urdf")
    assert scene.dof == 16
    assert scene.damping.max() == pytest.approx(10.0)
    step = derive.CONTROL_PERIOD / derive.SUBSTEPS[0]
    assert np.all(scene.armature >= scene.damping * step * (1 - 1e-4) - 1e-3)
    _stable_at_a_normal_step(scene)


def test_iiwa_with_allegro_trains_the_arm_chain_and_says_so(capfd):
    # its finger link_9.0's inertia breaks the triangle inequality: refused unless repaired
    # (tests/test_robot_misuse.py), so imported here with --repair-inertia
    scene = load_robot(DRM / "kuka_iiwa/urdf/iiwa7_allegro.urdf", RobotOptions(repair_inertia=True))
    err = capfd.readouterr().err
    notes = [line for line in err.splitlines() if "an arm with a hand" in line]
    assert len(notes) == 1 and "--joints" in notes[0] and "16 joints" in notes[0], err
    assert scene.dof == 7 and all(n.startswith("iiwa_joint_") for n in scene.joint_names)
    # the end effector is the hand: palm_link, welded to iiwa_link_7 (merged into it, the tip at
    # the palm's origin)
    assert scene.body_names[scene.ee_body] == "iiwa_link_7"
    assert np.linalg.norm(scene.tip_offset) > 0.01
    _stable_at_a_normal_step(scene)


def test_jaco_trains_its_arm_with_goals_near_home_and_real_bounds():
    scene = load_robot(DRM / "kinova_description/urdf/jaco_clean.urdf")
    assert scene.dof == 6 and not any("finger" in n for n in scene.joint_names)
    d = _stable_at_a_normal_step(scene)
    goals = np.array(d["goals"])
    assert np.all(np.abs(goals - scene.home) <= derive.GOAL_REACH + 1e-9)
    assert min(d["max_torque"]) > 1.0  # N m: every joint can move its links (was 0.04 at the base)
    # its mid-range home is the arm pointing straight up (joints 2 and 3 at pi): balanced, said
    joints, growth = upright_joints(scene, derive.GRAVITY)
    assert [scene.joint_names[j] for j in joints] == ["j2n6s300_joint_2", "j2n6s300_joint_3"]
    assert np.allclose(scene.home[joints], math.pi) and growth > 10.0


@pytest.mark.parametrize(
    "path",
    [
        ERD / "xarm_description/urdf/xarm7.urdf",
        ERD / "z1_description/urdf/z1.urdf",
        DRM / "fetch_description/urdf/fetch_arm_no_gripper.urdf",
    ],
    ids=lambda p: p.name,
)
def test_arms_refused_or_finely_stepped_before_import_at_a_normal_step(path):
    scene = load_robot(path)
    assert scene.dof >= 6
    d = _stable_at_a_normal_step(scene)
    assert d["substeps"] == 4, d["substeps"]  # the KUKA's dt, 2.5 ms
    assert upright_joints(scene, derive.GRAVITY)[0] == []  # gravity pulls their home pose one way


@pytest.mark.parametrize(
    "path, reason",
    [
        # a planar robot on three joints of one body (newton would merge them into a D6 joint)
        (GYM / "hopper.xml", "body 'torso' moves on 3 joints"),
        # an empty xacro output (the file holds a comment only)
        (ERD / "ur_description/urdf/ur3.urdf", "no <link> in the URDF"),
    ],
    ids=lambda v: v.name if isinstance(v, Path) else "",
)
def test_a_file_that_cannot_be_trained_never_gives_a_traceback(path, reason, tmp_path, capfd):
    code, _, err = _run(["import", str(path), "--out", str(tmp_path / "h.usda")], capfd)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err and str(path) in err and reason in err, err
    with pytest.raises(SceneError, match=reason):
        load_robot(path)


def test_import_writes_the_model_and_its_help_states_the_rules(tmp_path, capfd):
    """The written scene carries the file's armature and the derived damping/limit springs; the
    help states the armature, damping and torque rules."""
    from warp_critic.physics.load import load_scene

    out = tmp_path / "xarm7.usda"
    path = ERD / "xarm_description/urdf/xarm7.urdf"
    code, stdout, err = _run(["import", str(path), "--out", str(out)], capfd)
    assert code == 0 and out.is_file(), err
    robot, scene = load_robot(path), load_scene(out)
    np.testing.assert_allclose(scene.armature, robot.armature, rtol=1e-5)
    np.testing.assert_allclose(scene.damping, robot.damping, rtol=1e-5)
    np.testing.assert_allclose(scene.limit_ke, robot.limit_ke, rtol=1e-5)
    assert scene.defaults["dt"] == robot.defaults["dt"] >= 1e-3
    with pytest.raises(SystemExit):
        main(["import", "--help"])
    text = " ".join(capfd.readouterr().out.split())
    for rule in ("armature:", "damping:", "max_torque:", "gear x ctrlrange", "<transmission>"):
        assert rule in text, rule
    assert derive.RULES["armature"] in text and derive.RULES["damping"] in text


def test_robot_zoo_prints_a_row_per_file_with_its_verdict(capsys):
    """tools/robot_zoo.py --only: the table's rows (an import and a refusal), no training."""
    from helpers import load_tool

    zoo = load_tool("robot_zoo")
    # files no other test loads (a loaded file is cached, and its notes said once)
    assert zoo.main(["--only", "pusher_v5,inverted_pendulum"]) == 0
    rows = {line.split()[1]: line for line in capsys.readouterr().out.splitlines()[1:3]}
    assert set(rows) == {"pusher_v5.xml", "inverted_pendulum.xml"}, rows
    assert "2.50 ms x 4" in rows["pusher_v5.xml"], rows
    assert "dropped 2 bodies" in rows["pusher_v5.xml"] and "object, goal" in rows["pusher_v5.xml"]
    assert "refused: underactuated: joint 'hinge'" in rows["inverted_pendulum.xml"]
