"""Dynamics variants of any link do exactly what they say: checked against the paper's own model
(``differentiable-robot-model``) with the same change made to its link parameters, over a rollout."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import torch
from conftest import ROOT
from helpers import drm_robot, drm_step

from warp_critic.core.errors import FieldError
from warp_critic.physics.link_changes import parse_changes
from warp_critic.physics.load import load_scene
from warp_critic.physics.scene import Variant
from warp_critic.physics.simulator import Simulator


def _set(robot, link: str, **values) -> None:
    """Replace DRM link parameters (mass, com, inertia_mat, trans) keeping their dtype and shape."""
    body = robot._bodies[robot._name_to_idx_map[link]]
    for name, value in values.items():
        owner = body if name == "trans" else body.inertia
        old = getattr(owner, name)()
        new = torch.as_tensor(value, dtype=old.dtype).reshape(old.shape)
        setattr(owner, name, lambda new=new: new)
        if name == "trans":  # a fixed joint's pose is set once, at construction
            body.joint_pose.set_translation(new.reshape(1, 3))


def _rollouts(scene_name, changes, drm_changes, H, dt, substeps, scale, seed=0):
    """(ours: base world, changed world; DRM: base, changed) final q and the motion, same torques."""
    scene = load_scene(ROOT / "scenes" / f"{scene_name}.usda")
    sim = Simulator(
        scene, [Variant(), Variant(changes=changes)], dt=dt, substeps=substeps, device="cpu"
    )
    gen = torch.Generator().manual_seed(seed)
    dof = scene.dof
    q0 = (torch.rand(1, dof, generator=gen) - 0.5) * 0.6
    taus = torch.randn(H, 1, dof, generator=gen) * scale
    q, qd = q0.repeat(2, 1), torch.zeros(2, dof)
    with torch.no_grad():
        for t in range(H):
            q, qd = sim.step(q, qd, taus[t].repeat(2, 1))
    out = [q[0].double(), q[1].double()]
    for change in (None, drm_changes):
        robot = drm_robot(scene_name)
        if change:
            for link, values in change.items():
                _set(robot, link, **values)
        qr, qdr = q0.double(), torch.zeros(1, dof, dtype=torch.float64)
        for t in range(H):
            qr, qdr = drm_step(robot, qr, qdr, taus[t], dt, substeps)
        out.append(qr[0])
    return out, (q[1] - q0[0]).abs().max().item()


KUKA_STEPS = dict(H=15, dt=0.0025, substeps=4, scale=torch.tensor([40, 40, 20, 20, 5, 3, 1.0]))
REACHER_STEPS = dict(H=40, dt=0.01, substeps=2, scale=torch.tensor([3.0, 3.0]))


@pytest.mark.slow
@pytest.mark.parametrize(
    "scene_name, changes, drm_changes, steps",
    [
        ("kuka", "iiwa_link_7.mass=7", {"iiwa_link_7": {"mass": 7.0}}, KUKA_STEPS),
        ("kuka", "iiwa_link_7.mass=0", {"iiwa_link_7": {"mass": 0.0}}, KUKA_STEPS),
        ("reacher", "arm1.mass=3", {"arm1": {"mass": 3.0}}, REACHER_STEPS),
        ("reacher", "arm1.offset=1.6", {"arm2": {"trans": [1.6, 0.0, 0.0]}}, REACHER_STEPS),
        (
            "reacher",  # stretched: COM x1.6 along the link, second moment along it x1.6^2
            "arm1.stretch=1.6",
            {
                "arm2": {"trans": [1.6, 0.0, 0.0]},
                "arm1": {
                    "com": [0.8, 0.0, 0.0],
                    "inertia_mat": torch.diag(
                        torch.tensor([0.001, 0.0005 * (1 + 1.6**2), 0.0005 * (1 + 1.6**2)])
                    ),
                },
            },
            REACHER_STEPS,
        ),
        (
            "reacher",
            "arm2.mass+=2:scale",
            {"arm2": {"mass": 3.0, "inertia_mat": torch.eye(3) * 0.003}},
            REACHER_STEPS,
        ),
    ],
)
def test_link_change_matches_paper_model(scene_name, changes, drm_changes, steps):
    (ours, ours_changed, ref, ref_changed), motion = _rollouts(
        scene_name, changes, drm_changes, **steps
    )
    assert motion > 0.3, "the test needs motion"
    assert torch.allclose(ours, ref, atol=1e-3)
    assert torch.allclose(ours_changed, ref_changed, atol=1e-3)
    # and the change matters: the changed robot moves differently from the trained one
    assert (ref_changed - ref).abs().max() > 1e-2


def test_ee_frame_offset_changes_the_tip_only():
    """An offset of the massless end-effector frame (the paper's iiwa_link_ee): joint-space dynamics
    bitwise unchanged, the tip where the paper model's moved iiwa_link_ee frame is."""
    scene = load_scene(ROOT / "scenes" / "kuka.usda")
    sim = Simulator(
        scene, [Variant(), Variant(changes="ee.offset+=0.5")], dt=0.0025, substeps=4, device="cpu"
    )
    gen = torch.Generator().manual_seed(3)
    q = ((torch.rand(1, 7, generator=gen) - 0.5) * 0.6).repeat(2, 1)
    qd = torch.zeros(2, 7)
    with torch.no_grad():
        for _ in range(10):
            tau = (torch.randn(1, 7, generator=gen) * 20.0).repeat(2, 1)
            q, qd = sim.step(q, qd, tau)
    assert torch.equal(q[0], q[1]) and torch.equal(qd[0], qd[1])
    tips = sim.tip_positions(q)
    robot = drm_robot("kuka")
    base = robot.compute_forward_kinematics(q[:1], "iiwa_link_ee")[0][0].double()
    _set(robot, "iiwa_link_ee", trans=[0.0, 0.0, 0.545])
    moved = robot.compute_forward_kinematics(q[:1], "iiwa_link_ee")[0][0].double()
    assert torch.allclose(torch.as_tensor(tips[0]).double(), base, atol=1e-5)
    assert torch.allclose(torch.as_tensor(tips[1]).double(), moved, atol=1e-5)
    assert (moved - base).norm() == pytest.approx(0.5, abs=1e-5)


def test_legacy_fields_are_the_same_changes():
    """--ee-mass is a point mass at the tip and --link-length a stretch of the end-effector link."""
    scene = load_scene(ROOT / "scenes" / "reacher.usda")
    old = scene.world_builder(Variant(ee_mass=0.7, link_length=1.4))
    new = scene.world_builder(Variant(changes="ee.stretch=1.4; ee.point-mass+=0.7@tip"))
    for attr in ("body_mass", "body_com", "body_inertia", "joint_X_p"):
        a, b = getattr(old, attr), getattr(new, attr)
        flat_a = np.array([np.ravel(np.array(x, dtype=np.float64)) for x in a])
        flat_b = np.array([np.ravel(np.array(x, dtype=np.float64)) for x in b])
        assert np.allclose(flat_a, flat_b, atol=1e-6), attr
    assert scene.tip_offset_of(Variant(changes="ee.stretch*=2; ee.offset+=0.5")) == pytest.approx(
        [2.5, 0.0, 0.0]
    )


@pytest.mark.parametrize(
    "text, message",
    [
        ("ee.mass", "expected LINK.WHAT=VALUE"),
        ("ee.size=1", "unknown change 'size'"),
        ("ee.mass=-1", "must be >= 0"),
        ("ee.mass=1:bogus", "mode 'bogus' does not apply to mass"),
        ("ee.offset=0", "must be > 0"),
        ("ee.point-mass=1", "a point mass is added"),
        ("ee.point-mass+=1@1,2", "@POINT is x,y,z"),
        ("ee.mass=nan", "finite"),
    ],
)
def test_bad_link_change_text_is_one_field_error(text, message):
    with pytest.raises(FieldError, match="variant") as err:
        parse_changes(text)
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(
    "text, message",
    [
        ("link9.mass=1", "unknown link 'link9' (links: ee, arm1, arm2)"),
        ("arm2.mass=0:scale", "scaling the inertia needs"),
        ("arm1.offset+=-2", "the new length -1 m must be > 0"),
    ],
)
def test_bad_link_change_against_the_scene(text, message):
    scene = load_scene(ROOT / "scenes" / "reacher.usda")
    with pytest.raises(FieldError, match="variant") as err:
        scene.build_model([Variant(changes=text)])
    assert message in str(err.value)


@pytest.mark.slow
@pytest.mark.subprocess
@pytest.mark.parametrize(
    "argv, words",
    [
        (
            ["baseline", "ddpg", "SCENE", "--iterations", "1", "--variant", "arm7.mass=1"],
            "unknown link 'arm7'",
        ),
        (
            ["meta-train", "SCENE", "--iterations", "1", "--variant", "arm1.offset*=0"],
            "must be > 0",
        ),
        (["meta-test", "RUN", "--variant", "ee.mass"], "expected LINK.WHAT=VALUE"),
    ],
)
def test_bad_variant_flag_is_one_line_exit_2(tmp_path, argv, words):
    """The CLI: one line naming --variant, exit 2, before anything runs."""
    scene = str(ROOT / "scenes" / "reacher.usda")
    argv = [scene if a == "SCENE" else str(tmp_path / "none") if a == "RUN" else a for a in argv]
    out = tmp_path / ("r.json" if argv[0] == "meta-test" else "r")
    cmd = [sys.executable, "-m", "warp_critic.cli.main", *argv, "--out", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("warp-critic: error: --variant:"), lines
    assert words in lines[0]
    assert not out.exists()
