"""Robot files that are physically invalid or not what their name says, through the real command line.

Each case writes a small robot file (URDF or MJCF text, or bytes) into the test's directory and runs
``warp-critic import`` (or ``meta-train`` on the robot file) in-process:

* a refusal: exit code 2, exactly one stderr line ``warp-critic: error: ...`` naming the body or
  joint and the value (no traceback, no newton warning), nothing written;
* a repair on request (``--lock-mimic``, ``--repair-inertia``) or a file read as what it is: exit 0,
  no stderr line at all (newton's generic "Inertia validation corrected" warning must not leak), the
  scene written, and what was repaired recorded in it (``warp_critic:importRepairs``).

Before these checks (2b7c77a) every case here was accepted silently or refused with a wrong reason.
"""

from __future__ import annotations

import random
import sysconfig
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from helpers import INERTIA, LIMIT, MIMIC, urdf

from warp_critic.cli.main import main


def mjcf(actuator: str = "", equality: str = "") -> str:
    return f"""<mujoco model="arm2"><worldbody>
  <body name="l1"><joint name="j1" type="hinge" axis="0 1 0" range="-60 60" limited="true"/>
    <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.05"/>
    <body name="l2" pos="0.5 0 0"><joint name="j2" type="hinge" axis="0 1 0" range="-60 60"/>
      <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.04"/></body></body>
</worldbody>{actuator}{equality}</mujoco>
"""


TRIANGLE = 'ixx="0.001" iyy="0.001" izz="1.0" ixy="0" ixz="0" iyz="0"'
EQ_JOINT = '<equality><joint joint1="j2" joint2="j1" polycoef="0 1 0 0 0"/></equality>'
XACRO = (
    '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro"><xacro:property name="l" '
    'value="0.5"/><link name="base"/><link name="l1"><inertial><mass value="${l}"/></inertial>'
    "</link></robot>\n"
)
RANDOM = random.Random(0).randbytes(512)


@dataclass
class Case:
    id: str
    file: str  # the robot file's name
    content: str | bytes
    says: tuple[str, ...]  # in the one error line
    extra: tuple[str, ...] = ()  # more import flags
    command: str = "import"


REFUSED = [
    # couplings that would vanish
    Case("urdf-mimic", "r.urdf", urdf(j2=MIMIC), ("joint 'j2'", "0.1 + 0.5 x j1", "--lock-mimic")),
    Case("mjcf-equality-joint", "a.xml", mjcf(equality=EQ_JOINT), ("joint 'j2'", "--lock-mimic")),
    Case("mimic-meta-train", "r.urdf", urdf(j2=MIMIC), ("joint 'j2'",), command="meta-train"),
    # masses and inertias
    Case(
        "negative-ixx",
        "r.urdf",
        urdf(inertia=INERTIA.replace('"0.01"', '"-0.01"')),
        ("body 'l1'", "ixx=-0.01", "negative", "--repair-inertia"),
    ),
    Case(
        "triangle",
        "r.urdf",
        urdf(inertia=TRIANGLE),
        ("body 'l1'", "triangle inequality", "0.001 + 0.001 < 1", "--repair-inertia"),
    ),
    Case(
        "off-diagonal",
        "r.urdf",
        urdf(inertia=INERTIA.replace('ixy="0"', 'ixy="0.5"')),
        ("body 'l1'", "ixy=0.5", "not positive definite", "--repair-inertia"),
    ),
    Case(
        "ixx-inf",
        "r.urdf",
        urdf(inertia=INERTIA.replace('"0.01"', '"inf"')),
        ("body 'l1'", "ixx=inf", "not a finite number"),
    ),
    Case("mass-zero-inertia", "r.urdf", urdf(mass="0"), ("body 'l1'", "mass 0 kg", "inertia")),
    Case("mass-negative", "r.urdf", urdf(mass="-2"), ("body 'l1'", "mass -2 kg")),
    Case("mass-nan", "r.urdf", urdf(mass="nan"), ("body 'l1'", "mass nan kg")),
    Case(
        "mass-tiny", "r.urdf", urdf(mass="1e-9"), ("body 'l1'", "1e-09 kg", "outside 1e-06..1e+06")
    ),
    Case("mass-huge", "r.urdf", urdf(mass="1e30"), ("body 'l1'", "1e+30 kg", "outside")),
    Case(
        "inertia-meta-train",
        "r.urdf",
        urdf(inertia=TRIANGLE),
        ("body 'l1'", "--repair-inertia"),
        command="meta-train",
    ),
    # efforts and limits
    Case(
        "effort-zero",
        "r.urdf",
        urdf(limit=LIMIT.replace('"5"', '"0"')),
        ("joint 'j1'", "no actuator"),  # effort 0: not actuated, so the arm is underactuated
    ),
    Case(
        "effort-negative",
        "r.urdf",
        urdf(limit=LIMIT.replace('"5"', '"-5"')),
        ("joint 'j1'", "effort limit -5"),
    ),
    Case(
        "effort-nan",
        "r.urdf",
        urdf(limit=LIMIT.replace('"5"', '"nan"')),
        ("joint 'j1'", "effort limit nan"),
    ),
    Case(
        "lower-above-upper",
        "r.urdf",
        urdf(limit='lower="1" upper="-1" effort="5" velocity="1"'),
        ("joint 'j1'", "lower limit 1 > upper limit -1"),
    ),
    Case(
        "lower-equals-upper",
        "r.urdf",
        urdf(limit='lower="0.5" upper="0.5" effort="5" velocity="1"'),
        ("joint 'j1'", "cannot move", "0.5"),
    ),
    # names defined twice, an absurd tip
    Case(
        "link-twice",
        "r.urdf",
        urdf(
            extra='<link name="l2"><inertial><mass value="7"/><inertia '
            'ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>'
        ),
        ("link 'l2' is defined twice",),
    ),
    Case(
        "body-twice",
        "a.xml",
        mjcf().replace('<body name="l2"', '<body name="l1"'),
        ("body 'l1' is defined twice",),
    ),
    Case(
        "tip-offset-huge",
        "r.urdf",
        urdf(),
        ("--tip-offset", "1e+09 m", "at most 10 m"),
        extra=("--tip-offset", "1e9,0,0"),
    ),
    # formats read from the content
    Case("xacro", "r.xacro", XACRO, ("xacro", "expand it first")),
    Case("xacro-as-urdf", "r.urdf", XACRO, ("xacro", "expand it first")),
    Case("empty-usda", "e.usda", b"", ("is empty (0 bytes)",)),
    Case("empty-usd", "e.usd", b"", ("is empty (0 bytes)",)),
    Case(
        "unparsable-usda",
        "b.usda",
        '#usda 1.0\ndef Xform "a" {{{ garbage\n',
        ("not a readable USD file",),
    ),
    Case("random-bytes-usd", "b.usd", RANDOM, ("not a USD file",)),
    Case(
        "other-xml",
        "a.xml",
        "<sdf version='1.6'><model name='m'/></sdf>\n",
        ("root element is <sdf>", "not a URDF"),
    ),
]


def _run(argv: list[str], capfd) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capfd.readouterr()
    return code, out, err


def _argv(case: Case, robot: Path, tmp: Path) -> list[str]:
    if case.command == "import":
        return ["import", str(robot), "--out", str(tmp / "scene.usda"), *case.extra]
    return ["meta-train", str(robot), "--out", str(tmp / "run"), "--iterations", "1", *case.extra]


@pytest.mark.slow
@pytest.mark.parametrize("case", REFUSED, ids=[c.id for c in REFUSED])
def test_refused_in_one_line_naming_the_body_or_joint(case, tmp_path, capfd):
    robot = tmp_path / case.file
    data = case.content.encode() if isinstance(case.content, str) else case.content
    robot.write_bytes(data)
    before = sorted(p.name for p in tmp_path.iterdir())
    code, _, err = _run(_argv(case, robot, tmp_path), capfd)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, err
    assert lines[0].startswith("warp-critic: error: "), err
    for part in case.says:
        assert part in lines[0], (part, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written


# ------------------------------------------------------------------------------------------------
# repairs on request, files read as what they are
# ------------------------------------------------------------------------------------------------


def _import(tmp_path, capfd, name: str, text: str, *flags: str, note: str | None = None):
    robot = tmp_path / name
    robot.write_text(text)
    out = tmp_path / f"{robot.name}.usda"  # USD keeps opened layers: a new name per import
    code, stdout, err = _run(["import", str(robot), "--out", str(out), *flags], capfd)
    if note is None:
        assert code == 0 and err == "", err  # no newton warning leaks
    else:  # the one note expected, and nothing else
        assert code == 0 and len(err.splitlines()) == 1 and note in err, err
    from pxr import Usd

    stage = Usd.Stage.Open(str(out))
    root = stage.GetDefaultPrim()
    attr = root.GetAttribute("warp_critic:importRepairs")
    repairs = list(attr.Get()) if attr and attr.HasAuthoredValue() else []
    return stdout, stage, repairs


@pytest.mark.slow
def test_repair_inertia_projects_to_the_nearest_valid_tensor_and_records_it(tmp_path, capfd):
    from warp_critic.physics.inertia_checks import inertia_problem, nearest_valid
    from warp_critic.physics.load import load_scene

    stdout, _, repairs = _import(
        tmp_path, capfd, "r.urdf", urdf(inertia=TRIANGLE), "--repair-inertia"
    )
    assert len(repairs) == 1 and "body l1" in repairs[0] and "izz=1 ->" in repairs[0], repairs
    assert f"repaired: {repairs[0]}" in stdout
    # the nearest valid principal moments of (0.001, 0.001, 1): moved along (1, 1, -1) onto the
    # plane I1 + I2 = I3, a third of the deficit 0.998 each
    J = nearest_valid(np.diag([0.001, 0.001, 1.0]))
    d = 0.998 / 3
    np.testing.assert_allclose(np.diag(J), [0.001 + d, 0.001 + d, 1.0 - d], rtol=1e-5)
    assert inertia_problem(J, moved=True) is None
    # and the written scene holds it (diagonalised, the principal moments)
    scene = load_scene(str(tmp_path / "r.urdf.usda"))
    from warp_critic.physics.variants import Variant

    model = scene.build_model([Variant()])
    moments = np.linalg.eigvalsh(model.body_inertia.numpy()[0].astype(np.float64))
    np.testing.assert_allclose(sorted(moments), sorted(np.diag(J)), rtol=1e-4)


def test_repair_inertia_makes_a_non_positive_definite_tensor_valid(tmp_path, capfd):
    from warp_critic.physics.inertia_checks import inertia_problem, nearest_valid

    bad = np.array([[0.01, 0.5, 0.0], [0.5, 0.05, 0.0], [0.0, 0.0, 0.05]])
    assert "not positive definite" in inertia_problem(bad, moved=True)
    J = nearest_valid(bad)
    assert inertia_problem(J, moved=True) is None
    # nearest: no valid tensor on a random sample of valid ones around it is closer
    rng = np.random.default_rng(0)
    for _ in range(200):
        K = J + 0.05 * rng.standard_normal((3, 3))
        K = 0.5 * (K + K.T)
        if inertia_problem(K, moved=True) is None:
            assert np.linalg.norm(K - bad) >= np.linalg.norm(J - bad) - 1e-9


def test_lock_mimic_welds_the_coupled_joint_where_the_coupling_puts_it(tmp_path, capfd):
    stdout, stage, repairs = _import(tmp_path, capfd, "r.urdf", urdf(j2=MIMIC), "--lock-mimic")
    # j1's home is mid-range 0: j2 = 0.1 + 0.5 x 0
    assert repairs == ["joint j2 locked at 0.1: coupled as j2 = 0.1 + 0.5 x j1 at j1's home 0"]
    assert "repaired: joint j2 locked at 0.1" in stdout and "(1 joints" in stdout
    joints = [p.GetName() for p in stage.Traverse() if p.GetTypeName() == "PhysicsRevoluteJoint"]
    assert joints == ["j1"]


def test_the_import_line_names_the_tip_beyond_the_end_effector_body(tmp_path, capfd):
    """A tip offset (a hand merged into the last link, or ``--tip-offset``) is said with the end
    effector body, so the body named is not taken for the tip."""
    stdout, _, _ = _import(tmp_path, capfd, "r.urdf", urdf(), "--tip-offset", "0,0,0.3")
    assert "(2 joints, end effector l2 + a tip 0.3 m out in its frame)" in stdout


@pytest.mark.slow
def test_urdf_saved_as_xml_imports_as_a_urdf_and_mjcf_ctrlrange_bounds_the_effort(tmp_path, capfd):
    stdout, _, repairs = _import(tmp_path, capfd, "arm.xml", urdf())
    assert "(2 joints, end effector l2)" in stdout and repairs == []
    motor = '<actuator><motor joint="j1" gear="2" ctrlrange="-3 3"/><motor joint="j2"/></actuator>'
    # an MJCF named .urdf; j2's motor gives no bound: its derived one is said
    derived = "no torque bound for 1 of 2 joints: their max_torque (j2 "
    _, stage, _ = _import(tmp_path, capfd, "arm.urdf", mjcf(actuator=motor), note=derived)
    effort = {
        p.GetName(): p.GetAttribute("warp_critic:effortLimit").Get()
        for p in stage.Traverse()
        if p.HasAttribute("warp_critic:effortLimit")
    }
    assert effort["j1"] == pytest.approx(6.0)  # gear 2 x ctrl 3, no forcerange
    assert effort["j2"] >= 1e5  # a motor without ctrlrange or forcerange: no bound, as before


@pytest.mark.slow
def test_effort_zero_on_a_joint_left_out_of_training_is_locked(tmp_path, capfd):
    stdout, _, _ = _import(
        tmp_path, capfd, "r.urdf", urdf(limit=LIMIT.replace('"5"', '"0"')), "--joints", "j2"
    )
    assert "(1 joints" in stdout


# ------------------------------------------------------------------------------------------------
# real files (example-robot-data, differentiable-robot-model's data; the test extra installs both)
# ------------------------------------------------------------------------------------------------

SITE = Path(sysconfig.get_paths()["purelib"])
REAL = {
    "iiwa7_allegro": (
        SITE / "diff_robot_data/kuka_iiwa/urdf/iiwa7_allegro.urdf",
        ("body 'link_9.0'", "triangle inequality", "--repair-inertia"),
    ),
    # the Panda's fingers are coupled (mimic): it imports by default (an arm with a hand: the
    # fingers are locked with the hand), and is refused when the fingers are to be trained
    "panda_fingers": (
        SITE / "cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf",
        ("joint 'panda_finger_joint2'", "--lock-mimic"),
    ),
}
EXTRA = {"panda_fingers": ["--joints", "panda_finger_joint1,panda_finger_joint2"]}


@pytest.mark.parametrize("name", sorted(REAL))
def test_real_files_with_invalid_parts_are_refused_by_default(name, tmp_path, capfd):
    path, says = REAL[name]
    assert path.is_file(), path  # installed by the test extra: no skip
    extra = EXTRA.get(name, [])
    code, _, err = _run(["import", str(path), "--out", str(tmp_path / "s.usda"), *extra], capfd)
    lines = [x for x in err.strip().splitlines() if "mesh file" not in x]  # the mesh warning
    assert code == 2 and len(lines) == 1 and lines[0].startswith("warp-critic: error: "), err
    for part in says:
        assert part in lines[0], (part, err)
    assert not (tmp_path / "s.usda").exists()


def test_the_panda_with_coupled_fingers_imports_as_an_arm(tmp_path, capfd):
    """A coupling between two locked joints is no concern: the Panda's mimic fingers are locked
    with its hand, so the arm imports without a repair flag."""
    path = REAL["panda_fingers"][0]
    out = tmp_path / "panda.usda"
    code, stdout, err = _run(["import", str(path), "--out", str(out)], capfd)
    assert code == 0 and out.is_file(), err
    assert "(7 joints" in stdout and "an arm with a hand" in err
