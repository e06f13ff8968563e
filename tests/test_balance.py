"""A home pose that stands the arm upright in balance is said in one warning line (physics/balance).

A two-link arm whose links point up along +z, turning about y: at joint angles 0 it balances on end
(gravity torque 0, every lean falls); with the elbow's range centred at 1 rad the home pose is bent
and gravity pulls it one way; at gravity 0 nothing falls.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from warp_critic.physics import derive
from warp_critic.physics.balance import GROWTH, upright_joints, upright_note
from warp_critic.physics.robot import load_robot


def _upright_arm(elbow: tuple[float, float]) -> str:
    link = '<inertial><origin xyz="0 0 0.25"/><mass value="{m}"/><inertia ixx="0.02" iyy="0.02" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>'
    return f"""<robot name="upright">
  <link name="base"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 1 0"/><limit lower="-1.5" upper="1.5" effort="50" velocity="10"/></joint>
  <link name="l1">{link.format(m=2.0)}</link>
  <joint name="elbow" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.5"/>
    <axis xyz="0 1 0"/><limit lower="{elbow[0]}" upper="{elbow[1]}" effort="20" velocity="10"/></joint>
  <link name="l2">{link.format(m=1.0)}</link>
</robot>
"""


@pytest.fixture(scope="module")
def arms(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("balance")
    paths = {"upright": d / "upright.urdf", "bent": d / "bent.urdf"}
    paths["upright"].write_text(_upright_arm((-1.5, 1.5)))
    paths["bent"].write_text(_upright_arm((0.5, 1.5)))
    return paths


def test_an_arm_standing_on_end_is_balanced_and_said_in_one_line(arms):
    scene = load_robot(arms["upright"])
    assert np.allclose(scene.home, 0.0)
    joints, growth = upright_joints(scene, derive.GRAVITY)
    assert [scene.joint_names[j] for j in joints] == ["shoulder", "elbow"]
    # the fall grows by exp(lambda T), lambda^2 the largest -eigenvalue of M^-1 G: at least the
    # Rayleigh quotient of the whole arm falling as one rigid pendulum, m g c / I (3 kg, com
    # 0.417 m, I about the shoulder with its armature)
    m, c = 3.0, (2.0 * 0.25 + 1.0 * 0.75) / 3.0
    inertia = 0.02 + 2.0 * 0.25**2 + 0.02 + 1.0 * 0.75**2 + scene.armature[0]
    horizon = derive.KUKA_HORIZON * derive.CONTROL_PERIOD
    assert growth >= math.exp(math.sqrt(m * derive.GRAVITY * c / inertia) * horizon) * 0.999
    assert growth > GROWTH
    note = upright_note(scene, derive.GRAVITY)
    assert note is not None and "\n" not in note
    assert "shoulder = 0" in note and "elbow = 0" in note and "--gravity 0" in note


def test_a_bent_home_or_no_gravity_is_not_balanced(arms):
    bent = load_robot(arms["bent"])
    assert bent.home[1] == pytest.approx(1.0)
    assert upright_joints(bent, derive.GRAVITY)[0] == []
    assert upright_note(bent, derive.GRAVITY) is None
    upright = load_robot(arms["upright"])
    assert upright_joints(upright, 0.0) == ([], 1.0)


@pytest.mark.slow
def test_import_home_bends_the_arm_out_of_balance_and_bad_homes_are_one_line(
    arms, tmp_path, capsys
):
    """``warp-critic import --home``: the given joints start there (the goals around them), the
    warning goes; an unknown joint, a value outside the limits or a malformed list is one line."""
    from warp_critic.cli.main import main
    from warp_critic.physics.load import load_scene
    from warp_critic.physics.robot import RobotOptions

    bent = load_robot(arms["upright"], RobotOptions(home=(("shoulder", 0.8), ("elbow", -0.6))))
    assert bent.home.tolist() == pytest.approx([0.8, -0.6])
    goals = np.asarray(bent.defaults["goals"])
    assert np.all(np.abs(goals - bent.home) <= 1.0 + 1e-9)  # drawn around the given home
    assert upright_note(bent, derive.GRAVITY) is None
    out = tmp_path / "bent.usda"
    assert main(["import", str(arms["upright"]), "--out", str(out), "--home", "elbow=-0.6"]) == 0
    assert "upright in balance" not in capsys.readouterr().err
    assert load_scene(out).home.tolist() == pytest.approx([0.0, -0.6])
    for flag, words in (
        ("knee=0.1", "--home: "),
        ("elbow=2.0", "outside its limits [-1.5, 1.5]"),
        ("elbow", "expected NAME=number"),
        ("elbow=0.1,elbow=0.2", "given twice"),
        ("elbow=nan", "expected NAME=number"),
    ):
        argv = ["import", str(arms["upright"]), "--out", str(tmp_path / "x.usda"), "--home", flag]
        try:  # a flag's syntax is argparse's exit, a value the file refuses main's return code
            rc = main(argv)
        except SystemExit as e:
            rc = e.code
        assert rc == 2, flag
        err = capsys.readouterr().err.strip()
        assert words in err and len(err.splitlines()) == 1, err
        assert not (tmp_path / "x.usda").exists()
