#!/usr/bin/env python
"""Which dynamics variants stay stable at a scene's dt? Prints one line per variant.

Each variant (``--variant`` syntax, :mod:`warp_critic.physics.link_changes`; several joined by ``|``,
``nominal`` for the scene as it is) gets ``--worlds``
rollouts of the scene's horizon from the home pose under saturated torques ``+-max_torque`` whose
random signs (seeded) are redrawn every ``--hold`` control steps -- the bang-bang a badly trained
policy plays, slamming the joints into their limits. Per variant: how many rollouts went non-finite
and the largest joint speed |qd| [rad/s or m/s] any reached. One such world stops a training run
(``warp-critic: diverged``), so a ``--train-variants`` range belongs inside what this finds stable.

Usage::

    python tools/probe_variants.py scenes/reacher.usda \\
        --variants "nominal | arm1.mass=0.25:keep; arm2.mass=0.25:keep | arm1.stretch=1; arm2.stretch=0.6"
    python tools/probe_variants.py scenes/reacher.usda --substeps 4 --dt 0.005 --variants ...
"""

from __future__ import annotations

import sys

import torch

from warp_critic.cli.flags import ToolParser, user_message

PROG = "probe_variants"


def probe(task, scene, changes: str, *, worlds: int, hold: int, seed: int):
    """``(non-finite rollouts, max |qd|)`` of one variant (module docstring); ``task``: the scene's
    filled :class:`~warp_critic.running.task.TaskConfig` (dt, substeps, gravity, torque bounds,
    horizon)."""
    from warp_critic.physics.link_changes import parse_changes
    from warp_critic.physics.simulator import Simulator
    from warp_critic.physics.variants import Variant
    from warp_critic.running.task_inputs import max_torque_tensor

    variant = Variant(changes=parse_changes(changes)) if changes else Variant()
    sim = Simulator(
        scene,
        [variant] * worlds,
        dt=task.dt,
        substeps=task.substeps,
        device="cpu",
        differentiable=False,
        gravity=task.gravity,
        graphs=False,
    )
    bound = max_torque_tensor(task.max_torque, scene)
    gen = torch.Generator().manual_seed(seed)
    q = torch.as_tensor(scene.home, dtype=torch.float32).expand(worlds, -1).clone()
    qd = torch.zeros_like(q)
    bad = torch.zeros(worlds, dtype=torch.bool)
    fastest = 0.0
    with torch.no_grad():
        for t in range(task.horizon):
            if t % hold == 0:
                sign = torch.randint(0, 2, q.shape, generator=gen).float() * 2 - 1
            q, qd = sim.step(q, qd, sign * bound)
            finite = torch.isfinite(q).all(-1) & torch.isfinite(qd).all(-1)
            bad |= ~finite
            if bool(finite.any()):
                fastest = max(fastest, float(qd[finite].abs().max()))
    return int(bad.sum()), fastest


def main(argv=None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("scene", help="a scene file (scenes/*.usda) or a robot file")
    p.add_argument(
        "--variants",
        required=True,
        help="variants joined by '|' ('nominal': the scene as it is)",
    )
    p.add_argument("--worlds", type=int, default=32, help="rollouts per variant")
    p.add_argument("--hold", type=int, default=5, help="control steps a torque sign is held")
    p.add_argument("--dt", type=float, default=None, help="physics step [s] (default: the scene's)")
    p.add_argument("--substeps", type=int, default=None, help="default: the scene's")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.worlds < 1 or args.hold < 1:
        p.error("--worlds and --hold must be >= 1")
    from warp_critic.core import runtime
    from warp_critic.core.errors import UserError
    from warp_critic.running.task import TaskConfig, load_task_scene

    try:
        runtime.init()
        task, scene = load_task_scene(
            TaskConfig(scene=args.scene, dt=args.dt, substeps=args.substeps), announce=False
        )
        print(
            f"{scene.name}: dt {task.dt:g} s x {task.substeps}, {args.worlds} rollouts, "
            f"hold {args.hold}"
        )
        for changes in [v.strip() for v in args.variants.split("|")]:
            changes = "" if changes == "nominal" else changes
            bad, fastest = probe(
                task, scene, changes, worlds=args.worlds, hold=args.hold, seed=args.seed
            )
            verdict = "stable" if bad == 0 and fastest < 1e3 else "UNSTABLE"
            print(
                f"{changes or '(nominal)'}: non-finite {bad}/{args.worlds}, max |qd| "
                f"{fastest:.3g}: {verdict}"
            )
    except UserError as e:
        p.exit(2, f"{PROG}: error: {user_message(e)}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
