#!/usr/bin/env python
"""Regenerate ``scenes/*.usda`` from the one table of numbers below.

Usage: ``python tools/make_scenes.py [OUT_DIR]`` (default: ``scenes/`` next to this folder);
``python tools/make_scenes.py --readme`` rewrites the README's attribute table from the schema.

Every number of every robot lives in :data:`ROBOTS` (plus the few shared constants above it), so a
change to a robot is one edit here followed by a re-run. The reacher and the KUKA iiwa7 copy the
URDFs shipped with ``differentiable-robot-model`` (``diff_robot_data/2link_robot.urdf`` and
``diff_robot_data/kuka_iiwa/urdf/iiwa7.urdf``) number for number.

The robots' links, joints and training defaults are :class:`~warp_critic.physics.scene_writer.Robot`
tables; :func:`~warp_critic.physics.scene_writer.write_robot` writes them (its module docstring
gives the conventions of the written USD).
"""

from __future__ import annotations

import sys
from pathlib import Path

from warp_critic.core.generated import replace_block
from warp_critic.physics import schema
from warp_critic.physics.scene_writer import Joint, Link, Robot, write_robot

# ================================================================================================
# THE TABLE. Units: m, kg, kg*m^2, rad, N*m (N for prismatic), N*m*s/rad (N*s/m).
# ================================================================================================

PASSIVE_DAMPING = 0.5  # N*m*s/rad on every revolute joint (both URDFs: <dynamics damping="0.5"/>)

# Joint-limit penalty gains [N*m/rad, N*m*s/rad] (prismatic: N/m, N*s/m), applied by newton only
# while a joint is outside its limits. Explicit (semi-implicit Euler) integration at dt = 2.5 ms is
# stable when dt*sqrt(ke/I) < 2 and the total damping rate dt*(kd + damping)/I stays below ~1,
# for the smallest inertia I about a limited axis: the iiwa wrist (joint 7, I = 0.0029 kg*m^2)
# allows ke = 1000 with kd = 0.5 (spectral radius 0.91 per step, kd = 10 would diverge); the
# reacher's smallest axis inertia is 0.25 kg*m^2 and the point mass has 1 kg, so kd = 10 is fine.

IIWA_LIMITS = (
    2.9670597283903604,
    2.0943951023931953,
    2.9670597283903604,
    2.0943951023931953,
    2.9670597283903604,
    2.0943951023931953,
    3.0543261909900763,
)
HALF_PI, PI = 1.5707963267948966, 3.141592653589793


ROBOTS: dict[str, Robot] = {
    # Planar point mass: world -x-> carriage -y-> mass. The carriage is a light slider (1 g) so the
    # point's effective mass is 1.001 kg along x and 1 kg along y. Moves in the horizontal x-y
    # plane, so newton's gravity (-z) does no work.
    "point_mass": Robot(
        links=(
            Link("carriage", 1e-3, (0.0, 0.0, 0.0), (1e-6, 1e-6, 1e-6, 0.0, 0.0, 0.0), 0.0),
            Link("mass", 1.0, (0.0, 0.0, 0.0), (1e-3, 1e-3, 1e-3, 0.0, 0.0, 0.0), 0.0),
        ),
        joints=(
            Joint(
                "slide_x",
                "prismatic",
                None,
                "carriage",
                (0, 0, 0),
                (0, 0, 0),
                "X",
                -5.0,
                5.0,
                10.0,
                0.0,
            ),
            Joint(
                "slide_y",
                "prismatic",
                "carriage",
                "mass",
                (0, 0, 0),
                (0, 0, 0),
                "Y",
                -5.0,
                5.0,
                10.0,
                0.0,
            ),
        ),
        ee="mass",
        tip=(0.0, 0.0, 0.0),
        limit_ke=1000.0,
        limit_kd=10.0,
        point_visual={"mass": 0.05},
        defaults=dict(
            goals=((1.0, 1.0),),
            horizon=20,
            dt=0.05,
            substeps=1,
            max_torque=(5.0, 5.0),
            qd_scale=2.0,
            alpha=1e-3,
            lr=3e-3,
            gravity=9.81,
            home=(0.0, 0.0),
        ),
    ),
    # diff_robot_data/2link_robot.urdf
    "reacher": Robot(
        links=(
            Link("arm1", 1.0, (0.5, 0.0, 0.0), (0.001, 0.001, 0.001, 0.0, 0.0, 0.0), 0.025),
            Link("arm2", 1.0, (0.5, 0.0, 0.0), (0.001, 0.001, 0.001, 0.0, 0.0, 0.0), 0.025),
        ),
        joints=(
            Joint(
                "baseHinge",
                "revolute",
                None,
                "arm1",
                (0, 0, 0.15),
                (0, 0, 0),
                "Z",
                -2.9670597283903604,
                2.9670597283903604,
                20.0,
                PASSIVE_DAMPING,
            ),
            Joint(
                "interArm",
                "revolute",
                "arm1",
                "arm2",
                (1, 0, 0),
                (0, 0, 0),
                "Z",
                -2.9670597283903604,
                2.9670597283903604,
                20.0,
                PASSIVE_DAMPING,
            ),
        ),
        ee="arm2",
        tip=(1.0, 0.0, 0.0),
        limit_ke=1000.0,
        limit_kd=10.0,
        base_visual=(0.05, 0.15),
        # Goals in joint space (rad), four per robot as in the paper's section 5 (the paper does not
        # list its goals; these are spread over the workspace, well inside the limits).
        defaults=dict(
            goals=((1.0, 0.5), (-1.0, -0.5), (0.5, -1.0), (-0.5, 1.0)),
            horizon=50,
            dt=0.01,
            substeps=2,
            max_torque=(20.0, 20.0),
            qd_scale=5.0,
            alpha=3e-4,
            lr=1e-3,
            gravity=9.81,
            home=(0.0, 0.0),
            # reported (RESULTS.md): 3 inner steps at alpha 3e-4, 400 iterations
            iterations=400,
            inner_steps=3,
            critic_input="full",
            start_std=0.0,
            home_starts=0,
        ),
    ),
    # diff_robot_data/kuka_iiwa/urdf/iiwa7.urdf (iiwa_link_0 is welded to the world and dropped)
    "kuka": Robot(
        links=(
            Link(
                "iiwa_link_1",
                3.4525,
                (0, -0.03, 0.12),
                (0.02183, 0.007703, 0.02083, 0, 0, -0.003887),
            ),
            Link(
                "iiwa_link_2",
                3.4821,
                (0.0003, 0.059, 0.042),
                (0.02076, 0.02179, 0.00779, 0, -0.003626, 0),
            ),
            Link(
                "iiwa_link_3", 4.05623, (0, 0.03, 0.13), (0.03204, 0.00972, 0.03042, 0, 0, 0.006227)
            ),
            Link(
                "iiwa_link_4",
                3.4822,
                (0, 0.067, 0.034),
                (0.02178, 0.02075, 0.007785, 0, 0, -0.003625),
            ),
            Link(
                "iiwa_link_5",
                2.1633,
                (0.0001, 0.021, 0.076),
                (0.01287, 0.005708, 0.01112, 0, 0, -0.003946),
            ),
            Link(
                "iiwa_link_6",
                2.3466,
                (0, 0.0006, 0.0004),
                (0.006509, 0.006259, 0.004527, 0, 0, 0.00031891),
            ),
            Link("iiwa_link_7", 3.129, (0, 0, 0.02), (0.01464, 0.01465, 0.002872, 0.0005912, 0, 0)),
        ),
        joints=tuple(
            Joint(
                f"iiwa_joint_{i + 1}",
                "revolute",
                None if i == 0 else f"iiwa_link_{i}",
                f"iiwa_link_{i + 1}",
                xyz,
                rpy,
                "Z",
                -IIWA_LIMITS[i],
                IIWA_LIMITS[i],
                300.0,
                PASSIVE_DAMPING,
            )
            for i, (xyz, rpy) in enumerate(
                [
                    ((0, 0, 0.15), (0, 0, 0)),
                    ((0, 0, 0.19), (HALF_PI, 0, PI)),
                    ((0, 0.21, 0), (HALF_PI, 0, PI)),
                    ((0, 0, 0.19), (HALF_PI, 0, 0)),
                    ((0, 0.21, 0), (-HALF_PI, PI, 0)),
                    ((0, 0.06070, 0.19), (HALF_PI, 0, 0)),
                    ((0, 0.081, 0.06070), (-HALF_PI, PI, 0)),
                ]
            )
        ),
        ee="iiwa_link_7",
        tip=(0.0, 0.0, 0.045),
        limit_ke=1000.0,
        limit_kd=0.5,
        base_visual=(0.1, 0.15),
        # Torque bounds scaled to the joints (mass-matrix diagonal at home 0.14, 6.35, 0.089, 1.39,
        # 0.030, 0.051, 0.0029 kg m^2): joints 1-6 peak at 24-140 rad/s^2. The URDF's 300 N·m would
        # let the wrist reach 1e5 rad/s^2 and slam into its limits. The last joint is limited by its
        # 0.5 N·m·s/rad damping rather than its inertia: 1 N·m gives it 2 rad/s (the earlier 0.1 N·m
        # allowed only 0.2 rad/s, i.e. 0.1 rad in a 0.5 s rollout). Gravity 0: a perfectly
        # gravity-compensated robot (the iiwa's torque mode).
        defaults=dict(
            goals=(
                (0.5, 0.4, 0.0, -0.8, 0.0, 0.5, 0.0),
                (-0.5, 0.6, 0.3, -0.6, 0.0, 0.3, 0.0),
                (0.3, -0.4, -0.3, -1.0, 0.2, 0.4, 0.0),
                (-0.3, -0.6, 0.0, -0.4, -0.2, 0.6, 0.0),
            ),
            horizon=50,
            dt=0.0025,
            substeps=4,
            max_torque=(20.0, 150.0, 8.0, 40.0, 1.5, 2.0, 1.0),
            qd_scale=5.0,
            alpha=3e-4,
            lr=3e-3,
            gravity=0.0,
            home=(0.0,) * 7,
            # reported against the paper's Table 1 (RESULTS.md): the goal-relative critic,
            # random starts 0.4 rad with 2 of 4 worlds per goal at home, 3 inner steps
            iterations=3000,
            inner_steps=3,
            critic_input="relative",
            start_std=0.4,
            home_starts=2,
        ),
    ),
}

README_BEGIN, README_END = "<!-- scene-schema:begin -->", "<!-- scene-schema:end -->"


def readme_with_table(text: str) -> str:
    """``text`` (the README) with the block between the markers replaced by the schema's table."""
    return replace_block(text, README_BEGIN, README_END, schema.markdown_table(), "README.md")


def main(argv: list[str]) -> int:
    from warp_critic.cli.flags import ToolParser

    root = Path(__file__).resolve().parent.parent
    p = ToolParser(prog="make_scenes", description=__doc__.split("\n\n")[0])
    p.add_argument("out_dir", nargs="?", metavar="OUT_DIR", help="where to write (default scenes/)")
    p.add_argument("--readme", action="store_true", help="rewrite the README's attribute table")
    args = p.parse_args(argv[1:])
    if args.readme:
        if args.out_dir is not None:
            p.error("--readme takes no OUT_DIR")
        readme = root / "README.md"
        readme.write_text(readme_with_table(readme.read_text()))
        print(f"wrote the attribute table of {readme}")
        return 0
    out_dir = Path(args.out_dir) if args.out_dir is not None else root / "scenes"
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, robot in ROBOTS.items():
        path = out_dir / f"{name}.usda"
        if path.exists():
            path.unlink()  # Usd.Stage.CreateNew refuses to overwrite
        write_robot(name, robot, path)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
