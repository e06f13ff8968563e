"""dm_control's MJCF arms (its control suite), where dm_control is installed: the test extra does not
install it (a 56 MB wheel and 13 packages, about 360 MB). Each file imports at the KUKA's step or is
refused in one line for a true reason."""

from __future__ import annotations

import sysconfig
from pathlib import Path

import pytest

from warp_critic.cli.main import main
from warp_critic.physics.robot import RobotOptions, load_robot

SUITE = Path(sysconfig.get_paths()["purelib"]) / "dm_control" / "suite"
pytestmark = pytest.mark.skipif(
    not SUITE.is_dir(), reason="dm_control not installed: its MJCF files are tested where it is"
)
ARM = ["arm_root", "arm_shoulder", "arm_elbow", "arm_wrist"]


def test_reacher_and_finger_import_at_the_kukas_step_the_spinner_dropped(capfd):
    reacher = load_robot(SUITE / "reacher.xml")
    assert reacher.dof == 2 and reacher.defaults["dt"] == 0.0025
    finger = load_robot(SUITE / "finger.xml")
    assert list(finger.joint_names) == ["proximal", "distal"]  # the spinner's hinge is not trained
    assert finger.defaults["substeps"] == 4
    # the file's motors: gear 30 and 15 x ctrlrange 1 cap the bounds
    assert finger.defaults["max_torque"][0] <= 30.0 and finger.defaults["max_torque"][1] <= 15.0
    assert "spinner" in capfd.readouterr().err


@pytest.mark.parametrize(
    "name, reason",
    [
        ("acrobot", "underactuated: joint 'shoulder' has no actuator (no <actuator> drives it)"),
    ],
)  # fmt: skip
def test_unactuated_joints_are_refused_in_one_line_naming_why(name, reason, tmp_path, capfd):
    code = main(["import", str(SUITE / f"{name}.xml"), "--out", str(tmp_path / "s.usda")])
    err = capfd.readouterr().err.strip()
    assert code == 2 and reason in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "s.usda").exists()


def test_the_manipulators_arm_imports_with_its_hand_locked(capfd):
    """Its hand's thumb is driven through tendon 'grasp': the gripper is locked at home with a
    note, without --joints."""
    assert list(load_robot(SUITE / "manipulator.xml").joint_names) == ARM
    assert "an arm with a hand" in capfd.readouterr().err
    scene = load_robot(SUITE / "manipulator.xml", RobotOptions(joints=tuple(ARM)))
    assert list(scene.joint_names) == ARM
    # the file's motors: gear 12, 8, 4, 2 x ctrlrange 1
    assert all(b <= g for b, g in zip(scene.effort_limit, [12.0, 8.0, 4.0, 2.0]))
