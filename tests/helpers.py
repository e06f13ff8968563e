"""Shared test code that is not a fixture: the tiny run settings, the loader of ``tools/`` and
``bench/`` scripts, ``warp-critic`` in a child process, the hand-made two-link arm and the paper's
own dynamics model. Every test module imports from here (``from helpers import ...``), never from
another test module; fixtures and the scenes' paths are in ``conftest.py``, the misuse table's
machinery in ``misuse_table.py``.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
from conftest import REACHER, ROOT

# ------------------------------------------------------------------------------------------------
# tiny run settings: as command-line flags, and as configs for the library calls
# ------------------------------------------------------------------------------------------------

# one world per goal, 3 steps: the cheapest run a command accepts (add --iterations)
TINY_ONE_WORLD = ["--horizon", "3", "--worlds-per-goal", "1", "--device", "cpu"]

# meta-training on two reacher goals, 2 worlds each, 6 steps (the flags of ``tiny_cfg``)
TINY_TRAIN = [
    "--goals",
    "0.5,0.3;-0.4,0.2",
    "--worlds-per-goal",
    "2",
    "--horizon",
    "6",
    "--device",
    "cpu",
]

# a baseline on one reacher goal with a small critic and replay (the flags of ``tiny_baseline_cfg``
# but its iterations and checkpoints: no learning expected)
TINY_BASELINE = [
    "--goals",
    "0.5,0.3",
    "--worlds-per-goal",
    "2",
    "--horizon",
    "5",
    "--device",
    "cpu",
    "--critic-hidden",
    "32",
    "--updates-per-iteration",
    "3",
    "--batch-size",
    "8",
    "--warmup-iterations",
    "1",
]


def tiny_cfg(out: Path, **kw):
    """``TrainConfig`` of ``TINY_TRAIN``: 3 iterations, a checkpoint every one, recorded every 2nd,
    into ``out``; ``kw`` overrides fields."""
    from warp_critic.methods.ours import TrainConfig

    cfg = TrainConfig(
        scene=REACHER,
        goals=[[0.5, 0.3], [-0.4, 0.2]],
        worlds_per_goal=2,
        horizon=6,
        iterations=3,
        device="cpu",
        out=str(out),
        checkpoint_every=1,
        record_every=2,
    )
    for k, v in kw.items():
        setattr(cfg, k, v)
    return cfg


def tiny_baseline_cfg(out: Path, method: str, **kw):
    """``method``'s config (the registry's: ``BaselineConfig`` for DDPG, ``MetaCriticConfig``, ...)
    of ``TINY_BASELINE``: 3 iterations, a checkpoint every one, into ``out``; ``kw`` overrides fields
    (its own only: a field of another method's config is a mistake of the test)."""
    from dataclasses import fields

    from warp_critic.methods import method as method_of

    config = method_of(method).config
    unknown = set(kw) - {f.name for f in fields(config)}
    assert not unknown, f"{method}'s config has no {sorted(unknown)}"
    cfg = config(
        scene=REACHER,
        method=method,
        goals=[[0.5, 0.3]],
        worlds_per_goal=2,
        horizon=5,
        iterations=3,
        device="cpu",
        out=str(out),
        critic_hidden=32,
        updates_per_iteration=3,
        batch_size=8,
        warmup_iterations=1,
        checkpoint_every=1,
    )
    for k, v in kw.items():
        setattr(cfg, k, v)
    return cfg


def variants_train_argv(  # the ranges hold under saturated torques at this dt and horizon
    out: Path,
    *extra: str,
    iterations: int = 4,
    ranges: str = "arm1.mass=0.25..6; arm2.stretch=0.7..2",
) -> list[str]:
    """``meta-train`` argv of a tiny reacher run over dynamics variants (``--train-variants``)."""
    return [
        "meta-train",
        REACHER,
        "--iterations",
        str(iterations),
        "--horizon",
        "8",
        "--worlds-per-goal",
        "2",
        "--lr-schedule",
        "constant",
        "--checkpoint-every",
        "2",
        "--train-variants",
        ranges,
        "--device",
        "cpu",
        "--out",
        str(out),
        *extra,
    ]


# ------------------------------------------------------------------------------------------------
# scripts and the command line
# ------------------------------------------------------------------------------------------------


def load_tool(name: str, folder: str = "tools") -> ModuleType:
    """The script ``ROOT/folder/name.py`` as a module (its ``main(argv)`` is then callable)."""
    spec = importlib.util.spec_from_file_location(name, ROOT / folder / f"{name}.py")
    assert spec is not None and spec.loader is not None, (folder, name)
    tool = importlib.util.module_from_spec(spec)
    sys.modules[name] = tool  # a script's dataclasses look their module up
    spec.loader.exec_module(tool)
    return tool


def cli_command() -> list[str]:
    """The argv prefix that starts ``warp-critic`` in a child process: the installed entry point of
    this interpreter's environment, else ``python -m warp_critic.cli.main``."""
    exe = shutil.which("warp-critic", path=str(Path(sys.executable).parent))
    return [exe] if exe else [sys.executable, "-m", "warp_critic.cli.main"]


def cli_env(env: dict | None = None) -> dict:
    """This process's environment with one torch thread (as the tests run) and ``env`` on top."""
    return {**os.environ, "WARP_CRITIC_TORCH_THREADS": "1", **(env or {})}


def run_cli(
    *args: str,
    env: dict | None = None,
    timeout: float = 600,
    command: list[str] | None = None,
    **kw,
) -> subprocess.CompletedProcess:
    """``warp-critic ARGS`` in a child process, to its end; stdout and stderr captured as text.
    ``command`` replaces the argv prefix (default :func:`cli_command`)."""
    return subprocess.run(
        [*(command or cli_command()), *args],
        env=cli_env(env),
        capture_output=True,
        text=True,
        timeout=timeout,
        **kw,
    )


def start_cli(
    *args: str, env: dict | None = None, command: list[str] | None = None, **kw
) -> subprocess.Popen:
    """``warp-critic ARGS`` started in a child process with stdout and stderr as text pipes."""
    return subprocess.Popen(
        [*(command or cli_command()), *args],
        env=cli_env(env),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kw,
    )


# ------------------------------------------------------------------------------------------------
# a planar two-link URDF arm turning about +y (gravity along -z acts on it), its parameters in SI
# ------------------------------------------------------------------------------------------------

M1, C1, I1, L1 = 2.0, 0.25, 0.05, 0.5  # kg, m (com from joint 1), kg m^2 (about y), m
M2, C2, I2 = 1.0, 0.2, 0.02
E1, E2 = 50.0, 3.0  # effort limits, N m
LO, HI = np.array([-1.0, -0.5]), np.array([1.0, 1.5])  # joint limits, rad
TWO_LINK = f"""<robot name="twolink">
  <link name="base"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 1 0"/><limit lower="{LO[0]}" upper="{HI[0]}" effort="{E1}" velocity="10"/></joint>
  <link name="l1"><inertial><origin xyz="{C1} 0 0"/><mass value="{M1}"/>
    <inertia ixx="0.01" iyy="{I1}" izz="{I1}" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><geometry><mesh filename="meshes/l1.stl"/></geometry></visual></link>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="{L1} 0 0"/>
    <axis xyz="0 1 0"/><limit lower="{LO[1]}" upper="{HI[1]}" effort="{E2}" velocity="10"/></joint>
  <link name="l2"><inertial><origin xyz="{C2} 0 0"/><mass value="{M2}"/>
    <inertia ixx="0.005" iyy="{I2}" izz="{I2}" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><geometry><mesh filename="meshes/l2.stl"/></geometry></visual></link>
  <joint name="tool" type="fixed"><parent link="l2"/><child link="tcp"/><origin xyz="0.4 0 0"/></joint>
  <link name="tcp"/>
</robot>
"""

# ------------------------------------------------------------------------------------------------
# the paper's own dynamics model (differentiable-robot-model): the independent reference
# ------------------------------------------------------------------------------------------------


def drm_robot(name: str):
    """The paper's model of ``kuka`` or ``reacher`` from the URDFs its package ships, on the CPU."""
    import differentiable_robot_model as pkg
    from differentiable_robot_model.robot_model import DifferentiableRobotModel

    data = Path(pkg.__file__).resolve().parents[1] / "diff_robot_data"
    urdf = {
        "kuka": data / "kuka_iiwa" / "urdf" / "iiwa7.urdf",
        "reacher": data / "2link_robot.urdf",
    }[name]
    return DifferentiableRobotModel(str(urdf), name, device="cpu")


def drm_step(robot, q, qd, tau, dt, substeps):
    """``substeps`` semi-implicit Euler steps of ``dt`` s of the paper's model (gravity and damping
    on): the next ``(q, qd)``, (B, dof) in rad and rad/s, from torques ``tau`` (B, dof) in N m."""
    for _ in range(substeps):
        qdd = robot.compute_forward_dynamics(
            q.float(), qd.float(), tau * 1.0, include_gravity=True, use_damping=True
        ).double()
        qd = qd + dt * qdd
        q = q + dt * qd
    return q, qd


# ------------------------------------------------------------------------------------------------
# the baselines' agents (TD3, SAC)
# ------------------------------------------------------------------------------------------------

# the baselines' tiny CLI settings, with a smaller actor and a checkpoint every iteration
TINY_AGENT = [*TINY_BASELINE, "--actor-hidden", "16", "--checkpoint-every", "1"]


def filled_buffer():
    """A reacher-sized replay buffer (2 joints) full of seeded random rows, none terminal."""
    import torch

    from warp_critic.methods.replay import ReplayBuffer

    buf = ReplayBuffer(64, 2, "cpu")
    rows = torch.randn(64, buf.data.shape[1], generator=torch.Generator().manual_seed(2))
    rows[:, buf.slices["done"]] = 0.0
    buf._add_rows(rows)
    return buf


def refused_in_one_line(tmp_path, capsys, argv: list[str], fragment: str) -> None:
    """``warp-critic *argv`` exits 2 with one stderr line holding ``fragment`` and writes no run."""
    from warp_critic.cli.main import main

    try:
        code = main([*argv, "--out", str(tmp_path / "run"), "--device", "cpu", "--iterations", "1"])
    except SystemExit as e:  # argparse's own errors exit from the parser
        code = e.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and fragment in err[0], err
    assert not (tmp_path / "run").exists()


def straight_and_resumed(tmp_path, method: str) -> tuple[Path, list[list[dict]]]:
    """``warp-critic baseline METHOD`` on the reacher for 3 iterations straight, and for 2 then
    resumed to 3; returns the straight run's directory and both runs' metrics rows."""
    import json

    from warp_critic.cli.main import main

    straight, part = tmp_path / "straight", tmp_path / "part"
    argv = ["baseline", method, REACHER, *TINY_AGENT]
    assert main([*argv, "--iterations", "3", "--out", str(straight)]) == 0
    assert main([*argv, "--iterations", "2", "--out", str(part)]) == 0
    assert main([*argv, "--iterations", "3", "--out", str(part), "--resume"]) == 0
    rows = [
        [json.loads(x) for x in (d / "metrics.jsonl").read_text().splitlines()]
        for d in (straight, part)
    ]
    return straight, rows


def reacher_normalizer(max_torque, qd_scale: float = 5.0):
    """The policy/critic normaliser over the reacher's joint limits (+-2.97 rad)."""
    import torch

    from warp_critic.learning.networks import Normalizer

    lim = torch.tensor([2.97, 2.97])
    return Normalizer.from_limits(-lim, lim, torch.tensor(max_torque), qd_scale)


# ------------------------------------------------------------------------------------------------
# a hand-written robot file
# ------------------------------------------------------------------------------------------------

INERTIA = 'ixx="0.01" iyy="0.05" izz="0.05" ixy="0" ixz="0" iyz="0"'
LIMIT = 'lower="-1" upper="1" effort="5" velocity="1"'


def urdf(
    inertia: str = INERTIA, mass: str = "2", limit: str = LIMIT, j2: str = "", extra: str = ""
):
    """A planar two-link arm (j1, j2 about +y); the arguments replace link l1's inertial or j1's
    limit, ``j2`` is added inside joint j2, ``extra`` inside <robot>."""
    return f"""<robot name="r"><link name="base"/>
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 1 0"/>
  <limit {limit}/></joint>
<link name="l1"><inertial><origin xyz="0.2 0 0"/><mass value="{mass}"/><inertia {inertia}/>
  </inertial></link>
<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.5 0 0"/>
  <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="3" velocity="1"/>{j2}</joint>
<link name="l2"><inertial><origin xyz="0.2 0 0"/><mass value="1"/>
  <inertia ixx="0.005" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>
{extra}</robot>
"""


# a URDF <mimic> for joint j2 of :func:`urdf`: j2 = 0.5 j1 + 0.1
MIMIC = '<mimic joint="j1" multiplier="0.5" offset="0.1"/>'
