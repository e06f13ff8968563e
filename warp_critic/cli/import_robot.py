"""``warp-critic import``: a robot file (URDF, MJCF, USD) written as a warp-critic scene.

The work is :func:`warp_critic.physics.load.load_any` (the file read, checked and given the model it
lacks) and :func:`warp_critic.physics.export.write_scene`; registered in
``warp_critic/cli/main.py``'s ``build_parser``. :func:`derived_rules_epilog` is the rules text that
``meta-train``, ``baseline`` and ``import`` print under ``--help``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from warp_critic.core.errors import UserError

__all__ = ["add_parser", "cmd_import", "derived_rules_epilog"]


def cmd_import(args: argparse.Namespace) -> int:
    from warp_critic.physics.export import write_scene
    from warp_critic.physics.file_format import file_format
    from warp_critic.physics.load import load_any

    robot = args.robot
    if Path(robot).is_file() and file_format(robot) == "scene":
        raise UserError(
            f"{robot}: already a warp-critic scene (it has warp_critic attributes); "
            "import reads robot files (.urdf, MJCF .xml, .usd/.usda without them)"
        )
    tip = args.tip_offset
    if tip is not None and len(tip) != 3:
        raise UserError(f"--tip-offset: needs 3 values x,y,z (got {len(tip)})")
    joints = None if args.joints is None else [n for n in args.joints.split(",") if n.strip()]
    scene = load_any(
        robot,
        ee_body=args.ee_body,
        tip_offset=tip,
        joints=joints,
        lock_mimic=args.lock_mimic,
        repair_inertia=args.repair_inertia,
        home=args.home,
    )
    gravity = args.gravity
    if gravity is not None and not (math.isfinite(gravity) and gravity >= 0):
        raise UserError(f"--gravity: must be a finite number >= 0 m/s^2 (got {gravity:g})")
    out = write_scene(scene, args.out, gravity=gravity)
    for repair in getattr(scene, "import_repairs", ()):
        print(f"repaired: {repair}")
    from warp_critic.cli import signals

    signals.note(f"the scene {out} was written whole")
    ee = scene.body_names[scene.ee_body]
    reach = float(math.hypot(*scene.tip_offset))
    # a hand fixed to the last link is merged into it: the tip is the hand's frame, offset from it
    tip_text = f" + a tip {reach:.3g} m out in its frame" if reach > 0 else ""
    print(f"scene: {out} ({scene.dof} joints, end effector {ee}{tip_text})")
    print(f"meta-train: warp-critic meta-train {out}")
    return 0


def derived_rules_epilog() -> str:
    """The rules of the defaults derived for a robot file, for ``--help``."""
    from warp_critic.physics.derive import RULES

    model = ("armature", "damping", "limit_gains")
    lines = [
        "robot files (.urdf, MJCF .xml, .usd/.usda without warp_critic attributes):",
        "the model where the file says nothing (written into the imported scene's joints):",
    ]
    lines += [f"  {key}: {RULES[key]}" for key in model]
    lines.append("defaults derived from the robot (each overridden by its flag):")
    lines += [f"  {key}: {rule}" for key, rule in RULES.items() if key not in model]
    return "\n".join(lines)


def add_parser(sub) -> None:
    """Add ``import`` to the subcommands ``sub`` of the ``warp-critic`` parser."""
    from warp_critic.physics.robot_checks import IMPORT_RULES

    im = sub.add_parser(
        "import",
        help="write a robot file (URDF, MJCF, USD) as a scene with the derived defaults",
        description="Import a fixed-base robot (.urdf, MJCF .xml, .usd/.usda without warp_critic "
        "attributes) with newton's importer and write it as a warp-critic scene whose "
        "warp_critic:* attributes hold the defaults derived from the robot; edit them there. "
        "Trained are the joints the file actuates: an MJCF's <actuator> joints (gear x ctrlrange, "
        "capped by forcerange, caps the torque), a URDF's <transmission> joints and joints with a "
        "non-zero effort limit. An MJCF's <include>s are followed and its props (jointed bodies "
        "outside the actuated robot: targets, objects) dropped with a note; its 'home' keyframe is "
        "the home; an unactuated trained joint is refused (--joints locks it); an arm with a hand "
        "or gripper (tendon-driven, coupled or a linkage) trains the arm chain up to the hand, the "
        "gripper locked at home, and a single chain's last joints named as a gripper's (gripper, "
        "jaw, finger, claw) are locked (--joints picks others); two arms are refused (--joints "
        "picks one); a hand on a fixed palm trains every finger. A URDF root without a joint to the world is fixed; a "
        "free or floating joint is refused.",
        epilog=IMPORT_RULES + "\n" + derived_rules_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    im.add_argument("robot", help="robot file: .urdf, MJCF .xml, .usd/.usda")
    im.add_argument(
        "--out", required=True, help="the scene file to write (.usda); never overwritten"
    )
    im.add_argument(
        "--ee-body",
        default=None,
        help="the end-effector body (default: an arm with a hand: the hand; else the last body "
        "of the longest chain)",
    )
    im.add_argument(
        "--tip-offset",
        default=None,
        type=_floats,
        metavar="X,Y,Z",
        help="the tip (m) in the end-effector body frame (default: 0,0,0)",
    )
    im.add_argument(
        "--joints",
        default=None,
        metavar="NAME,..",
        help="train only these joints; the others are locked at the home pose, applied before "
        "any other joint check (default: the joints the file actuates; an arm with a hand: the arm "
        "chain)",
    )
    im.add_argument(
        "--home",
        default=None,
        type=_named_floats,
        metavar="NAME=V,..",
        help="the home pose of these joints (rad, or m for a slider), inside their limits; the "
        "goals, torque bounds and model defaults are derived around it (default: the file's own "
        "pose inside the limits, else mid-range)",
    )
    im.add_argument(
        "--lock-mimic",
        action="store_true",
        help="lock each coupled (mimic) joint where the coupling puts it at the home pose, "
        "instead of refusing the file",
    )
    im.add_argument(
        "--repair-inertia",
        action="store_true",
        help="project each invalid inertia to the nearest valid one (same principal axes), "
        "instead of refusing the file",
    )
    im.add_argument(
        "--gravity",
        default=None,
        type=float,
        metavar="M/S2",
        help="derive the torque bounds and dt under this gravity (0: a torque-mode, gravity-"
        "compensated arm; default 9.81); written as the scene's gravity",
    )
    im.set_defaults(func=cmd_import)


def _named_floats(text: str) -> dict[str, float]:
    out: dict[str, float] = {}
    for part in (p.strip() for p in text.split(",")):
        name, eq, value = part.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not part or not eq or not name.strip() or not math.isfinite(number):
            raise argparse.ArgumentTypeError(f"expected NAME=number,.. (got {part!r})")
        if name.strip() in out:
            raise argparse.ArgumentTypeError(f"joint {name.strip()!r} given twice")
        out[name.strip()] = number
    return out


def _floats(text: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers x,y,z (got {text!r})") from None
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"must be finite numbers (got {text!r})")
    return values
