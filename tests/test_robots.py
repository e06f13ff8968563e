"""Robot files people already have: URDF, MJCF and plain USD through newton's importers.

Real robots nobody here wrote (``example-robot-data``: Franka Panda, UR5), newton's own example
assets (cartpole USD and URDF; the ant is floating-base), and a two-link
arm whose derived defaults are computed here by hand.
"""

from __future__ import annotations

import math
import sysconfig
from pathlib import Path

import newton.examples
import numpy as np
import pytest
import torch
from helpers import C1, C2, E1, E2, HI, I1, I2, L1, LO, M1, M2, TWO_LINK

from warp_critic.cli.main import main
from warp_critic.core.errors import SceneError
from warp_critic.physics import derive
from warp_critic.physics.robot import RobotOptions, load_robot

# newton ships its example assets and the test extra installs example-robot-data: no fallbacks
NEWTON_ASSETS = Path(newton.examples.get_asset("cartpole.urdf")).parent
ROBOT_DATA = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix/share/example-robot-data/robots"

needs_assets = pytest.mark.skipif(
    not NEWTON_ASSETS.is_dir(), reason="newton example assets missing"
)
needs_robot_data = pytest.mark.skipif(
    not ROBOT_DATA.is_dir(), reason="example-robot-data not installed (pip install -e '.[test]')"
)
PANDA_ARM = ",".join(f"panda_joint{i}" for i in range(1, 8))

TWO_LINK_MJCF = """<mujoco model="arm2"><worldbody>
  <body name="l1"><joint name="j1" type="hinge" axis="0 1 0" range="-60 60" limited="true"/>
    <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.05"/>
    <body name="l2" pos="0.5 0 0"><joint name="j2" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.04"/></body></body>
</worldbody></mujoco>
"""


@pytest.fixture(scope="module")
def two_link(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("robots") / "twolink.urdf"
    path.write_text(TWO_LINK)
    return path


def _run(argv, capfd) -> tuple[int, str]:
    code = main(argv)
    return code, capfd.readouterr().err


# ------------------------------------------------------------------------------------------------
# loading: URDF, MJCF, USD
# ------------------------------------------------------------------------------------------------


def test_urdf_loads_with_fixed_links_merged_and_one_missing_mesh_warning(two_link, capfd):
    scene = load_robot(two_link)
    err = capfd.readouterr().err
    assert scene.dof == 2 and scene.joint_names == ["j1", "j2"]
    assert scene.body_names == ["l1", "l2"]
    # the deepest body is the welded tcp: merged into l2, the tip at its origin
    assert scene.body_names[scene.ee_body] == "l2"
    np.testing.assert_allclose(scene.tip_offset, [0.4, 0.0, 0.0], atol=1e-6)
    warnings = [line for line in err.splitlines() if "warning" in line]
    assert len(warnings) == 1 and "meshes/l1.stl" in warnings[0], err


def test_options_choose_ee_tip_and_lock_joints_at_home(two_link):
    scene = load_robot(two_link, RobotOptions(ee_body="l1", tip_offset=(0.1, 0.0, 0.0)))
    assert scene.body_names[scene.ee_body] == "l1"
    np.testing.assert_allclose(scene.tip_offset, [0.1, 0, 0], atol=1e-7)
    locked = load_robot(two_link, RobotOptions(joints=("j1",)))
    assert locked.dof == 1 and locked.joint_names == ["j1"]
    # j2 is welded at its home (mid-range 0.5 rad): the tcp, 0.4 m out on l2, is now on l1
    assert locked.body_names[locked.ee_body] == "l1"
    home2 = 0.5 * (LO[1] + HI[1])
    expect = [L1 + 0.4 * math.cos(home2), 0.0, -0.4 * math.sin(home2)]
    np.testing.assert_allclose(locked.tip_offset, expect, atol=1e-5)
    with pytest.raises(SceneError, match="'j9' is not a movable joint"):
        load_robot(two_link, RobotOptions(joints=("j9",)))
    with pytest.raises(SceneError, match="names 0 of the bodies"):
        load_robot(two_link, RobotOptions(ee_body="nowhere"))


def test_mjcf_loads_and_a_continuous_joint_reaches_the_networks_wrapped(tmp_path):
    from warp_critic.learning.networks import Normalizer

    path = tmp_path / "arm2.xml"
    path.write_text(TWO_LINK_MJCF)
    scene = load_robot(path)
    assert scene.dof == 2 and scene.body_names == ["l1", "l2"]
    assert scene.q_upper[0] == pytest.approx(math.radians(60), rel=1e-5)
    assert scene.q_upper[1] >= 1e9  # no limits: newton's +-1e10
    norm = Normalizer.from_limits(
        torch.tensor(scene.q_lower, dtype=torch.float32),
        torch.tensor(scene.q_upper, dtype=torch.float32),
        torch.ones(2),
        5.0,
    )
    q = torch.tensor([[0.3, 0.5], [0.3, 0.5 + 2 * math.pi], [0.3, -math.pi + 0.01]])
    x = norm.q(q)
    assert x[0, 1] == pytest.approx(0.5 / math.pi, abs=1e-5)  # an angle, not q / 1e10
    assert x[1, 1] == pytest.approx(x[0, 1].item(), abs=1e-5)  # wrapped
    assert x[2, 1] == pytest.approx((-math.pi + 0.01) / math.pi, abs=1e-5)
    assert x[0, 0] == pytest.approx(0.3 / math.radians(60), rel=1e-5)  # limited joints as before
    goal = torch.tensor([[0.3, 0.5 - 2 * math.pi]])
    assert norm.dq(q[:1], goal)[0, 1] == pytest.approx(0.0, abs=1e-5)


@needs_assets
def test_newton_cartpole_usd_and_urdf_load_without_edits():
    usd = load_robot(NEWTON_ASSETS / "cartpole_single_pendulum.usda")
    assert usd.dof == 2 and usd.joint_names == ["slider_to_cart", "cart_to_pole"]
    urdf = load_robot(NEWTON_ASSETS / "cartpole.urdf")
    assert urdf.dof == 3 and urdf.q_upper[1] >= 1e9  # continuous pole joints


# ------------------------------------------------------------------------------------------------
# derived defaults, against hand-computed values for the two-link arm
# ------------------------------------------------------------------------------------------------


def _link_mass(q2: float) -> np.ndarray:
    """The links' joint-space mass matrix (no armature)."""
    m11 = I1 + I2 + M1 * C1**2 + M2 * (L1**2 + C2**2 + 2 * L1 * C2 * math.cos(q2))
    m12 = I2 + M2 * (C2**2 + L1 * C2 * math.cos(q2))
    return np.array([[m11, m12], [m12, I2 + M2 * C2**2]])


# a URDF authors no armature: 0.05 x the largest M_ii at home (q2 = mid-range 0.5), on each joint
ARMATURE = 0.05 * float(np.diag(_link_mass(0.5 * (LO[1] + HI[1]))).max())


def _hand_mass(q2: float) -> np.ndarray:
    """The mass matrix newton steps with: the links' and the derived armature."""
    return _link_mass(q2) + ARMATURE * np.eye(2)


def _hand_mass_diag(q2: float) -> np.ndarray:
    return np.diag(_hand_mass(q2))


def _hand_gravity(q: np.ndarray, g: float = 9.81) -> np.ndarray:
    """dV/dq with V = g sum m z, a point (x, 0, 0) turned by q about +y at z = -x sin q."""
    q1, q2 = q
    g2 = -g * M2 * C2 * math.cos(q1 + q2)
    g1 = -g * (M1 * C1 * math.cos(q1) + M2 * L1 * math.cos(q1)) + g2
    return np.array([g1, g2])


def test_derived_home_goals_torques_and_energy_cap_by_hand(two_link):
    scene = load_robot(two_link)
    home = 0.5 * (LO + HI)
    np.testing.assert_allclose(scene.home, home)
    d = scene.defaults
    # goals: 4 seeded draws in home +- min(range/4, 1)
    u = np.random.default_rng(0).uniform(-1.0, 1.0, size=(4, 2))
    goals = np.clip(home + u * np.minimum((HI - LO) / 4, 1.0), LO, HI)
    np.testing.assert_allclose(d["goals"], goals, atol=1e-6)
    # torque bounds: min(effort, 50 M_jj(home) + max |g_j| over home and goals); this arm's pushes
    # together stay below A_COUPLED, so the coupling cap is 1 here (checked by hand, tested below)
    hold = np.abs([_hand_gravity(q) for q in np.vstack([home, goals])]).max(axis=0)
    push = np.minimum([E1, E2], 50.0 * _hand_mass_diag(home[1]))
    assert (np.abs(np.linalg.inv(_hand_mass(home[1]))) @ push).max() < derive.A_COUPLED
    expect = np.minimum([E1, E2], 50.0 * _hand_mass_diag(home[1]) + hold)
    np.testing.assert_allclose(d["max_torque"], expect, rtol=1e-4)
    assert d["max_torque"][1] == pytest.approx(E2)  # the effort limit binds on the light joint
    # the stability probe's energy cap: 10 (sum tau min(range, 2 pi) + g m_total 2 R)
    tau = np.array(d["max_torque"])
    reach = math.hypot(L1 + C2 * math.cos(home[1]), C2 * math.sin(home[1]))
    cap = 10 * (float(np.sum(tau * (HI - LO))) + 9.81 * (M1 + M2) * 2 * reach)
    assert derive.energy_cap(scene, tau) == pytest.approx(cap, rel=1e-4)
    # gravity on; horizon, learning rates, iterations, ... as authored for the KUKA
    assert d["gravity"] == 9.81
    from conftest import KUKA

    from warp_critic.physics.load import load_scene

    kuka = load_scene(KUKA).defaults
    for key in derive.KUKA:
        assert d[key] == kuka[key], key


def test_coupled_pushes_are_capped_by_hand(two_link, monkeypatch):
    """c = min(1, A_COUPLED / max_i sum_j |M^-1|_ij p_j) scales the pushes, not the gravity hold."""
    scene = load_robot(two_link)
    home = scene.home
    goals = np.array(scene.defaults["goals"])
    hold = np.abs([_hand_gravity(q) for q in np.vstack([home, goals])]).max(axis=0)
    push = np.minimum([E1, E2], 50.0 * _hand_mass_diag(home[1]))
    worst = (np.abs(np.linalg.inv(_hand_mass(home[1]))) @ push).max()
    monkeypatch.setattr(derive, "A_COUPLED", worst / 4)
    expect = np.minimum([E1, E2], push / 4 + hold)
    np.testing.assert_allclose(derive.torque_bounds(scene, goals), expect, rtol=1e-4)
    assert derive.torque_bounds(scene, goals)[0] < 50.0 * _hand_mass_diag(home[1])[0] + hold[0]


@pytest.mark.slow
def test_derived_torques_follow_the_runs_gravity_by_hand(two_link, tmp_path):
    """--gravity 0 (a torque-mode arm): the bounds lose the holding share, min(effort, push), and a
    run under it trains with those bounds; the defaults at 9.81 stay as they were."""
    import json

    scene = load_robot(two_link)
    push = np.minimum([E1, E2], 50.0 * _hand_mass_diag(scene.home[1]))
    at_zero = scene.defaults_at(0.0)
    np.testing.assert_allclose(at_zero["max_torque"], push, rtol=1e-4)
    assert at_zero["gravity"] == 0.0 and at_zero["goals"] == scene.defaults["goals"]
    assert scene.defaults_at(9.81) == scene.defaults
    assert at_zero["max_torque"][0] < scene.defaults["max_torque"][0]  # the held shoulder
    _first_iteration(str(two_link), tmp_path / "run", "--gravity", "0")
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    np.testing.assert_allclose(config["max_torque"], at_zero["max_torque"])
    assert config["derived_defaults"]["max_torque"]["value"] == config["max_torque"]


def test_derived_armature_and_damping_by_hand(two_link):
    """A URDF authors no armature and (here) no damping: a = 0.05 max_i M_ii(home) on every joint,
    b_j = 2/s (M_jj(home) + a); the simulator steps with them (its mass matrix holds a)."""
    scene = load_robot(two_link)
    home = scene.home
    np.testing.assert_allclose(scene.armature, [ARMATURE, ARMATURE], rtol=1e-4)
    np.testing.assert_allclose(
        scene.damping, 2.0 * (np.diag(_link_mass(home[1])) + ARMATURE), rtol=1e-4
    )
    sim = derive._simulator(scene, 1, 1e-3, 1, 0.0)
    np.testing.assert_allclose(
        derive.mass_matrices(sim, home[None])[0], _hand_mass(home[1]), rtol=1e-4
    )


def test_urdf_limit_gains_are_critically_damped_springs_by_hand(two_link):
    """ke = m w^2, kd = 2 m w with m = 1 / (M^-1(home))_jj, the inertia a joint moves with the
    other free; a URDF authors no gains (newton would give 1e4 and 10 to every joint)."""
    scene = load_robot(two_link)
    m = 1.0 / np.diag(np.linalg.inv(_hand_mass(scene.home[1])))
    w = derive.LIMIT_OMEGA
    np.testing.assert_allclose(scene.limit_ke, m * w**2, rtol=1e-4)
    np.testing.assert_allclose(scene.limit_kd, 2 * m * w, rtol=1e-4)
    assert m[0] < _hand_mass_diag(scene.home[1])[0]  # joint 1 moves less with joint 2 free


def test_derived_time_step_is_the_first_stable_halving(two_link):
    scene = load_robot(two_link)
    d = scene.defaults
    tau = np.array(d["max_torque"])
    assert d["dt"] * d["substeps"] == pytest.approx(derive.CONTROL_PERIOD)
    assert derive.stable(scene, d["dt"], d["substeps"], tau, 9.81)
    assert d["substeps"] in derive.SUBSTEPS  # at least the KUKA's 4 substeps, dt >= 1 ms
    before = derive.SUBSTEPS[: derive.SUBSTEPS.index(d["substeps"])]
    for n in before:  # the ones before (a longer dt) were not stable
        assert not derive.stable(scene, derive.CONTROL_PERIOD / n, n, tau, 9.81)
    # a stiffer limit needs a smaller dt: the probe sees the dynamics, not a constant
    assert not derive.stable(scene, 0.02, 1, tau * 50, 9.81)


# ------------------------------------------------------------------------------------------------
# refusals: one line, exit 2
# ------------------------------------------------------------------------------------------------

REFUSALS = {
    "no_mass.urdf": (
        '<robot name="r"><link name="base"/><joint name="j1" type="revolute"><parent link="base"/>'
        '<child link="l1"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="5" '
        'velocity="1"/></joint><link name="l1"/></robot>',
        "body 'l1' has no mass",
    ),
    "fixed_only.urdf": (
        '<robot name="r"><link name="base"/><joint name="j1" type="fixed"><parent link="base"/>'
        '<child link="l1"/></joint><link name="l1"><inertial><mass value="1"/><inertia ixx="0.1" '
        'iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link></robot>',
        "no movable joint",
    ),
    "ball.xml": (
        '<mujoco model="b"><worldbody><body name="l1"><joint name="b" type="ball"/><geom '
        'type="capsule" fromto="0 0 0 0.5 0 0" size="0.05"/></body></worldbody></mujoco>',
        "'b' is a ball joint",
    ),
    "loop.xml": (
        '<mujoco model="l"><worldbody><body name="a"><joint name="ja" type="hinge" axis="0 1 0"/>'
        '<geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.05"/></body><body name="b" '
        'pos="1 0 0"><joint name="jb" type="hinge" axis="0 1 0"/><geom type="capsule" '
        'fromto="0 0 0 -0.5 0 0" size="0.05"/></body></worldbody><equality><connect body1="a" '
        'body2="b" anchor="0.5 0 0"/></equality></mujoco>',
        "closed kinematic loop",
    ),
    "free.xml": (
        '<mujoco model="f"><worldbody><body name="torso"><freejoint name="root"/><geom '
        'type="sphere" size="0.1"/><body name="leg"><joint name="hip" type="hinge"/><geom '
        'type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/></body></body></worldbody></mujoco>',
        "floating base",
    ),
}


@pytest.mark.parametrize("name", sorted(REFUSALS))
def test_refusal_is_one_line_exit_2(name, tmp_path, capfd):
    text, reason = REFUSALS[name]
    path = tmp_path / name
    path.write_text(text)
    code, err = _run(["meta-train", str(path), "--out", str(tmp_path / "run")], capfd)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert err.startswith("warp-critic: error: ") and reason in err, err
    assert not (tmp_path / "run").exists()


@needs_assets
@pytest.mark.parametrize(
    "asset", ["nv_ant.xml", "ant.usda", "boxes_fourbar.usda"]
)  # quadruped.urdf: a URDF cannot say that its base floats; its root is fixed (pinocchio's reading)
def test_newton_assets_that_are_not_fixed_base_arms_are_refused(asset, tmp_path, capfd):
    code, err = _run(
        ["meta-train", str(NEWTON_ASSETS / asset), "--out", str(tmp_path / "run")], capfd
    )
    reason = "closed kinematic loop" if "fourbar" in asset else "floating base"
    assert code == 2 and len(err.strip().splitlines()) == 1 and reason in err, err


# ------------------------------------------------------------------------------------------------
# import and round trip
# ------------------------------------------------------------------------------------------------


def _first_iteration(scene: str, out: Path, *extra: str) -> dict:
    import json

    code = main(
        [
            "meta-train",
            scene,
            "--iterations",
            "1",
            "--horizon",
            "4",
            "--worlds-per-goal",
            "2",
            "--device",
            "cpu",
            "--out",
            str(out),
            *extra,
        ]
    )
    assert code == 0
    return json.loads((out / "metrics.jsonl").read_text().splitlines()[0])


@pytest.mark.slow
def test_import_round_trip_trains_to_the_same_first_iteration(two_link, tmp_path, capfd):
    out = tmp_path / "twolink.usda"
    code, err = _run(["import", str(two_link), "--out", str(out)], capfd)
    assert code == 0 and out.is_file(), err
    text = out.read_text()
    assert "warp_critic:goals" in text and "warp_critic:maxTorque" in text
    code, err = _run(["import", str(two_link), "--out", str(out)], capfd)
    assert code == 2 and "never overwrites" in err and len(err.strip().splitlines()) == 1
    from warp_critic.physics.load import load_scene

    scene, robot = load_scene(out), load_robot(two_link)
    assert not getattr(scene, "derived", False)  # a plain scene now: its attributes are the truth
    assert scene.defaults == robot.defaults
    a = _first_iteration(str(two_link), tmp_path / "a")
    b = _first_iteration(str(out), tmp_path / "b")
    for key in ("task_loss", "task_loss_before"):
        assert a[key] == pytest.approx(b[key], rel=1e-3), key
    assert a["task_loss"] != a["task_loss_before"]


@pytest.mark.slow
def test_run_config_states_each_derived_default_with_its_rule(two_link, tmp_path, capfd):
    import json

    _first_iteration(str(two_link), tmp_path / "run", "--ee-body", "l1", "--joints", "j1,j2")
    err = capfd.readouterr().err
    summary = [line for line in err.splitlines() if "derived defaults" in line]
    assert len(summary) == 1 and "max_torque" in summary[0] and "dt" in summary[0], err
    derived = json.loads((tmp_path / "run" / "config.json").read_text())["derived_defaults"]
    assert set(derived) >= {"home", "goals", "max_torque", "dt", "substeps", "gravity"}
    assert "horizon" not in derived  # given on the command line: not derived
    assert all(entry["rule"] for entry in derived.values())
    # meta-test finds the robot again with the run's robot options (end effector l1)
    out = tmp_path / "metatest.json"
    argv = ["meta-test", str(tmp_path / "run"), "--num-goals", "2", "--inits", "1"]
    code, err = _run([*argv, "--goal-std", "0.1", "--device", "cpu", "--out", str(out)], capfd)
    assert code == 0 and out.is_file(), err


@pytest.mark.slow
def test_load_task_scene_logs_the_derived_defaults_and_prints_nothing(two_link, capfd, caplog):
    import dataclasses
    import logging

    from warp_critic.methods.ours import TrainConfig
    from warp_critic.running.task import load_task_scene

    cfg = TrainConfig(scene=str(two_link), device="cpu", ee_body="l1", joints="j1,j2")
    with caplog.at_level(logging.INFO, logger="warp_critic"):
        filled, _ = load_task_scene(cfg)
        load_task_scene(cfg, announce=False)
    assert "derived defaults" not in capfd.readouterr().err  # the command line prints, not this
    said = [r.getMessage() for r in caplog.records if "derived defaults" in r.getMessage()]
    assert len(said) == 1 and "max_torque" in said[0] and "dt" in said[0], said
    assert set(filled.derived_defaults) >= {"home", "goals", "max_torque", "dt"}
    assert filled.to_dict()["derived_defaults"] == filled.derived_defaults
    # a record of the run, not a setting: no flag, no range check, not compared on --resume
    assert "derived_defaults" not in {f.name for f in dataclasses.fields(filled)}
    assert cfg.derived_defaults == {}


# ------------------------------------------------------------------------------------------------
# real robots nobody here wrote
# ------------------------------------------------------------------------------------------------


@needs_robot_data
@pytest.mark.parametrize(
    "urdf, extra, dof",
    [
        ("panda_description/urdf/panda.urdf", ["--joints", PANDA_ARM], 7),
        ("ur_description/urdf/ur5_robot.urdf", [], 6),
    ],
)
def test_real_robot_takes_one_meta_train_iteration(urdf, extra, dof, tmp_path):
    import json

    row = _first_iteration(str(ROBOT_DATA / urdf), tmp_path / "run", *extra)
    assert math.isfinite(row["task_loss"])
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert len(config["goals"][0]) == dof and len(config["max_torque"]) == dof


@pytest.mark.slow
def test_panda_rollout_and_gradients_match_the_paper_model(tmp_path):
    """60 physics steps on the Panda (differentiable-robot-model's own URDF, imported by newton):
    states and d loss / d (torques, q0, qd0) vs autograd through differentiable-robot-model."""
    import differentiable_robot_model as pkg
    from differentiable_robot_model.robot_model import DifferentiableRobotModel

    from warp_critic.physics.scene import Variant
    from warp_critic.physics.simulator import Simulator

    urdf = (
        Path(pkg.__file__).resolve().parents[1]
        / "diff_robot_data"
        / "panda_description"
        / "urdf"
        / "panda_no_gripper.urdf"
    )
    scene = load_robot(urdf)
    assert scene.dof == 7
    dt, substeps, H = 0.001, 4, 15  # 60 physics steps
    sim = Simulator(scene, [Variant()] * 2, dt=dt, substeps=substeps, device="cpu")
    gen = torch.Generator().manual_seed(0)
    home = torch.tensor(scene.home, dtype=torch.float32)
    q0 = (home + (torch.rand(2, 7, generator=gen) - 0.5) * 0.6).requires_grad_()
    qd0 = torch.randn(2, 7, generator=gen).requires_grad_()
    scale = torch.tensor([80.0, 80.0, 60.0, 60.0, 10.0, 10.0, 4.0])  # moves it through the armature
    taus = (torch.randn(H, 2, 7, generator=gen) * scale).requires_grad_()
    wq, wqd = torch.randn(H, 2, 7, generator=gen), torch.randn(H, 2, 7, generator=gen)
    roll = sim.begin_rollout()
    q, qd, loss = q0, qd0, 0.0
    for t in range(H):
        q, qd = roll.step(q, qd, taus[t])
        loss = loss + (q * wq[t]).sum() + 0.1 * (qd * wqd[t]).sum()
    grads = torch.autograd.grad(loss, [taus, q0, qd0])
    motion = (q - q0).abs().max().item()

    # the file authors no armature and no damping: newton steps with the derived ones (a_j, b_j),
    # (M(q) + diag(a)) qdd = tau - b qd - c(q, qd) - g(q), the paper model's M, c and g
    robot = DifferentiableRobotModel(str(urdf), "panda", device="cpu")
    armature = torch.diag(torch.tensor(scene.armature, dtype=torch.float32))
    damping = torch.tensor(scene.damping, dtype=torch.float32)
    assert bool((armature.diagonal() > 0).all() and (damping > 0).all())
    qr, qdr, loss_r = q0.double(), qd0.double(), 0.0
    for t in range(H):
        for _ in range(substeps):
            qf, qdf = qr.float(), qdr.float()
            bias = robot.compute_inverse_dynamics(
                qf, qdf, torch.zeros_like(qf), include_gravity=True, use_damping=False
            )
            mass = robot.compute_lagrangian_inertia_matrix(qf) + armature
            force = taus[t] - damping * qdf - bias
            qdd = torch.linalg.solve(mass, force.unsqueeze(-1)).squeeze(-1).double()
            qdr = qdr + dt * qdd
            qr = qr + dt * qdr
        loss_r = loss_r + (qr * wq[t]).sum() + 0.1 * (qdr * wqd[t]).sum()
    ref = torch.autograd.grad(loss_r, [taus, q0, qd0])
    assert motion > 0.1, "the test needs motion"
    lo, hi = torch.tensor(scene.q_lower), torch.tensor(scene.q_upper)
    assert bool(((q > lo) & (q < hi)).all()), "stay inside the limits (the paper model has none)"
    assert torch.allclose(q.double(), qr, atol=1e-3)
    for name, g, r in zip(("tau", "q0", "qd0"), grads, ref):
        rel = ((g.double() - r).norm() / r.norm()).item()
        assert rel < 1e-3, f"gradient w.r.t. {name} off by {rel:.2e}"
