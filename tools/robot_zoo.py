#!/usr/bin/env python
"""Robot zoo: import every robot file of the installed robot-description packages and print a table.

The files: example-robot-data's URDFs (``robots/*/urdf/*.urdf``), differentiable-robot-model's data
(``diff_robot_data/**/*.urdf``), gymnasium's MuJoCo assets (``envs/mujoco/assets/*.xml``) and, where
dm_control is installed (not by the test extra), its control suite's and Kinova arm's MJCF files
(``suite/*.xml``, ``third_party/kinova/*.xml``); with ``--menagerie DIR`` instead, the 46
fixed-base arm and hand files of a MuJoCo Menagerie checkout (:data:`MENAGERIE`; ``--only`` names
them ``DIR.STEM``, e.g. ``franka_fr3.fr3``). Each is
imported as ``warp-critic import`` would (``load_robot`` and its derived defaults); the table gives the
file, the trained DoF, ``dt x substeps`` and the verdict: ``ok`` (with the import's notes: props
dropped, an arm chain chosen) or the one-line reason it was refused.

``--only STEM,..`` keeps those files. ``--train ITERATIONS`` then meta-trains each imported robot for that many
iterations on the CPU, and the KUKA scene in the same run, and prints per robot: s/iteration and its
ratio to the KUKA's, the untrained MSE and the MSE after the 3 meta-test updates (goal std 0.1,
``--goals`` goals x ``--inits`` fresh policies). ``--floor`` adds the open-loop floor on the same
meta-test goals: the MSE of open-loop torques optimised through the model within the run's torque
bounds and horizon (``--floor-iterations`` Adam steps at each of two step sizes, the better per goal:
``warp_critic/reproduce/experiments/reach.py``), an upper bound of the best any controller reaches. Without
``--train``, ``--floor`` reads the newest run of each robot (and of the KUKA) in ``--runs-dir``, as a
``--train`` pass left it, and prints the table with its floor. A ``--train`` pass is resumable: a
robot (or the KUKA) with a meta-tested run of as many iterations in ``--runs-dir`` is read, not
trained again, so an interrupted pass continues where it stopped when run again.

    python tools/robot_zoo.py                                   # the import table
    python tools/robot_zoo.py --train 50 --only xarm7,z1,reacher --runs-dir runs/zoo
    python tools/robot_zoo.py --floor --only xarm7,z1,reacher --runs-dir runs/zoo   # floors afterwards
    python tools/robot_zoo.py --menagerie ../mujoco_menagerie   # Menagerie's arms and hands

The import pass takes a few minutes on a 2-core CPU.
"""

from __future__ import annotations

import contextlib
import difflib
import io
import json
import sys
import sysconfig
import time
from pathlib import Path

from warp_critic.cli.flags import ToolParser, comma_list, user_message

ROOT = Path(__file__).resolve().parents[1]
PROG = "robot_zoo"
PURELIB = Path(sysconfig.get_paths()["purelib"])
PACKAGES = {
    "example-robot-data": (
        PURELIB / "cmeel.prefix/share/example-robot-data/robots",
        "*/urdf/*.urdf",
    ),
    "differentiable-robot-model": (PURELIB / "diff_robot_data", "**/*.urdf"),
    "gymnasium": (PURELIB / "gymnasium/envs/mujoco/assets", "*.xml"),
    "dm_control": (PURELIB / "dm_control", "suite/*.xml", "third_party/kinova/*.xml"),
}
# MuJoCo Menagerie's fixed-base arm and hand files (``--menagerie DIR``: a checkout of the
# repository or of a fork such as kevinzakka/mujoco_menagerie), relative to its root: each robot's
# own files, and the scene files that add props beside the robot
MENAGERIE = (
    "agilex_piper/piper.xml", "aloha/aloha.xml", "arx_l5/arx_l5.xml",
    "dynamixel_2r/dynamixel_2r.xml", "flexiv_rizon4/flexiv_rizon4.xml",
    "franka_emika_panda/panda.xml", "franka_emika_panda/panda_nohand.xml",
    "franka_emika_panda/hand.xml", "franka_emika_panda/mjx_panda.xml",
    "franka_emika_panda/scene.xml", "franka_fr3/fr3.xml", "franka_fr3_v2/fr3v2.xml",
    "i2rt_yam/yam.xml", "kinova_gen3/gen3.xml", "kuka_iiwa_14/iiwa14.xml",
    "leap_hand/left_hand.xml", "leap_hand/right_hand.xml",
    "low_cost_robot_arm/low_cost_robot_arm.xml", "rethink_robotics_sawyer/sawyer.xml",
    "robotiq_2f85/2f85.xml", "robotiq_2f85/scene.xml", "robotiq_2f85_v4/2f85.xml",
    "robotstudio_so101/so101.xml", "shadow_dexee/shadow_dexee.xml",
    "shadow_hand/left_hand.xml", "shadow_hand/right_hand.xml", "shadow_hand/scene_right.xml",
    "tetheria_aero_hand_open/left_hand.xml", "tetheria_aero_hand_open/right_hand.xml",
    "trossen_vx300s/vx300s.xml", "trossen_wx250s/wx250s.xml",
    "trossen_wxai/trossen_ai_bimanual.xml", "trs_so_arm100/so_arm100.xml",
    "ufactory_lite6/lite6.xml", "ufactory_lite6/lite6_gripper_narrow.xml",
    "ufactory_lite6/lite6_gripper_wide.xml", "ufactory_xarm7/xarm7.xml",
    "ufactory_xarm7/xarm7_nohand.xml", "ufactory_xarm7/hand.xml", "umi_gripper/umi_gripper.xml",
    "unitree_z1/z1.xml", "unitree_z1/z1_gripper.xml", "universal_robots_ur10e/ur10e.xml",
    "universal_robots_ur5e/ur5e.xml", "wonik_allegro/left_hand.xml", "wonik_allegro/right_hand.xml",
)  # fmt: skip
FLOOR_LRS = (0.1, 0.03)  # Adam step sizes of the open-loop search (reach.best_open_loop_floor)


def robot_files(menagerie: Path | None = None) -> list[tuple[str, Path]]:
    """(package, file) for every robot file found, sorted within each package; with
    ``menagerie`` (a MuJoCo Menagerie checkout) its :data:`MENAGERIE` files instead."""
    from warp_critic.core.errors import UserError

    if menagerie is not None:
        files = [menagerie / name for name in MENAGERIE]
        if not any(f.is_file() for f in files):
            raise UserError(f"--menagerie: {menagerie}: none of Menagerie's arm and hand files")
        return [("menagerie", f) for f in files if f.is_file()]
    found = []
    for package, (base, *patterns) in PACKAGES.items():
        if base.is_dir():
            found += [(package, p) for pattern in patterns for p in sorted(base.glob(pattern))]
    return found


def stem_of(package: str, path: Path) -> str:
    """A file's name for ``--only`` and its runs: its stem, or ``DIR.STEM`` for Menagerie (whose
    robots share stems such as ``scene`` and ``left_hand``)."""
    return f"{path.parent.name}.{path.stem}" if package == "menagerie" else path.stem


def short_reason(text: str, path: Path) -> str:
    return text.replace(f"{path.resolve()}: ", "").replace(f"{path}: ", "")


def import_one(path: Path) -> dict:
    """Import ``path`` with the derived defaults; the notes the import wrote are kept."""
    from warp_critic.core.errors import UserError
    from warp_critic.physics.robot import load_robot

    notes = io.StringIO()
    t0 = time.perf_counter()
    row: dict = {"file": path.name, "path": path}
    with contextlib.redirect_stderr(notes):
        try:
            scene = load_robot(path)
            d = scene.defaults
            row.update(dof=scene.dof, dt=d["dt"], substeps=d["substeps"], verdict="ok")
        except UserError as exc:
            row.update(dof=None, verdict="refused: " + short_reason(str(exc), path))
        except Exception as exc:  # a bug to report, not a user mistake: the table says so
            row.update(dof=None, verdict=f"ERROR {type(exc).__name__}: {exc}"[:160])
    said = [
        short_reason(line.removeprefix("warp-critic: warning: "), path)
        for line in notes.getvalue().splitlines()
        if line.startswith("warp-critic: warning: ") and "mesh file" not in line
    ]
    if said and row["verdict"] == "ok":
        row["verdict"] += " (" + "; ".join(s.split(" (--joints")[0] for s in said) + ")"
    if any(not line.startswith("warp-critic: ") for line in notes.getvalue().splitlines()):
        row["verdict"] += " [other output on stderr]"  # a Python warning leaking: a bug
    row["seconds"] = time.perf_counter() - t0
    return row


def finished_run(runs_dir: Path, run: str, iterations: int) -> Path | None:
    """The newest run ``RUN-STAMP`` in ``runs_dir`` that was trained for ``iterations`` and
    meta-tested (a rerun of the same command resumes after it), if any."""
    for out in sorted(runs_dir.glob(f"{run}-*/metatest-zoo.json"), reverse=True):
        try:
            config = json.loads((out.parent / "config.json").read_text())
        except (OSError, ValueError):
            continue
        if out.parent.name.rsplit("-", 2)[0] == run and config.get("iterations") == iterations:
            return out.parent
    return None


def train_one(scene: str, out: Path, iterations: int, goals: int, inits: int) -> dict:
    """Meta-train ``scene`` for ``iterations`` and meta-test it at goal std 0.1; a run of it that
    finished with as many iterations in ``out``'s folder is read instead (resumable chunks)."""
    from warp_critic.evaluation.metatest import MetaTestConfig, meta_test

    done = finished_run(out.parent, out.name.rsplit("-", 2)[0], iterations)
    if done is not None:
        return read_run(done) | {"out": done}
    from warp_critic.methods.ours import TrainConfig, meta_train

    cfg = TrainConfig(scene=scene, iterations=iterations, device="cpu", out=str(out))
    with contextlib.redirect_stderr(io.StringIO()):
        meta_train(cfg, progress=False, record=False)
    tc = MetaTestConfig(
        run_dir=str(out), num_goals=goals, inits=inits, goal_std=0.1, device="cpu",
        out=str(out / "metatest-zoo.json"),
    )  # fmt: skip
    meta_test(tc)
    return read_run(out) | {"out": out}


def read_run(out: Path) -> dict:
    """What a trained and meta-tested run directory holds: s/iteration (the first compiles and is
    left out), the meta-test's MSE before and after the updates, its goals and the trained DoF."""
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines() if line]
    result = json.loads((out / "metatest-zoo.json").read_text())
    return {
        "s_per_it": sum(r["seconds"] for r in rows[1:]) / max(len(rows) - 1, 1),
        "mse_before": result["mse_mean_before"],
        "mse_after": result["mse_mean"],
        "goals": result["goals"],
        "dof": len(result["goals"][0]),
    }


def newest_run(runs_dir: Path, stem: str) -> Path:
    """The newest ``STEM-STAMP`` run directory in ``runs_dir`` that was meta-tested."""
    from warp_critic.core.errors import UserError

    runs = sorted(p.parent for p in runs_dir.glob(f"{stem}-*/metatest-zoo.json"))
    if not runs:
        raise UserError(f"--runs-dir: {runs_dir}: no meta-tested run of {stem} (--train first)")
    return runs[-1]


def floor_mse(out: Path, goals: list, iterations: int) -> float:
    """The open-loop floor's MSE (mean over the goals and joints of the squared final error) on
    ``goals`` with the run's model, torque bounds and horizon."""
    import torch

    from warp_critic.physics.scene import Variant
    from warp_critic.reproduce.experiments.reach import best_open_loop_floor

    g = torch.as_tensor(goals, dtype=torch.float32)
    with contextlib.redirect_stderr(io.StringIO()):
        best = best_open_loop_floor(
            str(out), [Variant()], g, iterations=iterations, lrs=list(FLOOR_LRS)
        )
    return float(best.mean()) / g.shape[1]


def print_header(args) -> None:
    floor = f" {'open-loop floor':>15s}" if args.floor else ""
    print(f"{'robot':40s} {'DoF':>3s} {'s/it':>6s} {'x KUKA':>6s} {'MSE untrained':>13s} "
          f"{'MSE after 3 updates':>19s}{floor}", flush=True)  # fmt: skip


def print_row(name: str, out: Path, t: dict, kuka: dict, args) -> None:
    """One robot's row; with ``--floor`` its open-loop floor on the meta-test's goals."""
    floor = f" {floor_mse(out, t['goals'], args.floor_iterations):15.4g}" if args.floor else ""
    print(f"{name:40s} {t['dof']:3d} {t['s_per_it']:6.2f} {t['s_per_it'] / kuka['s_per_it']:6.2f} "
          f"{t['mse_before']:13.4g} {t['mse_after']:19.4g}{floor}", flush=True)  # fmt: skip


def floors_of_runs(args) -> int:
    """``--floor`` without ``--train``: the table of the newest runs in ``--runs-dir``."""
    stems = args.only or sorted(
        {p.parent.name.rsplit("-", 2)[0] for p in args.runs_dir.glob("*-*-*/metatest-zoo.json")}
        - {"kuka"}
    )
    kuka_dir = newest_run(args.runs_dir, "kuka")
    kuka = read_run(kuka_dir)
    print(
        f"the newest runs in {args.runs_dir}, meta-test at goal std 0.1, with the open-loop floor:"
    )
    print_header(args)
    print_row("kuka.usda (scenes/)", kuka_dir, kuka, kuka, args)
    for stem in stems:
        out = newest_run(args.runs_dir, stem)
        print_row(stem, out, read_run(out), kuka, args)
    return 0


def main(argv: list[str] | None = None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("--train", type=int, default=0, metavar="ITERATIONS", help="meta-train each")
    p.add_argument(
        "--only", type=comma_list(str), default=None, help="file stems to import and train"
    )
    p.add_argument("--goals", type=int, default=4, help="meta-test goals (std 0.1)")
    p.add_argument("--inits", type=int, default=2, help="fresh policies per meta-test goal")
    p.add_argument("--runs-dir", type=Path, default=ROOT / "runs" / "zoo")
    p.add_argument("--menagerie", type=Path, default=None, metavar="DIR", help="a MuJoCo "
                   "Menagerie checkout: its fixed-base arm and hand files instead of the packages'")  # fmt: skip
    p.add_argument("--floor", action="store_true", help="add the open-loop floor (without --train: "
                   "of the newest runs in --runs-dir)")  # fmt: skip
    p.add_argument("--floor-iterations", type=int, default=100, help="Adam steps per step size")
    args = p.parse_args(argv)
    if args.train < 0:
        p.error(f"--train: must be >= 0 (got {args.train})")
    if args.floor_iterations < 1:
        p.error(f"--floor-iterations: must be >= 1 (got {args.floor_iterations})")
    if args.runs_dir.exists() and not args.runs_dir.is_dir():
        p.error(f"--runs-dir {args.runs_dir}: not a folder")

    from warp_critic.core import runtime
    from warp_critic.core.errors import UserError

    runtime.init()
    if args.floor and not args.train:
        try:
            return floors_of_runs(args)
        except UserError as e:
            print(f"{PROG}: error: {user_message(e)}", file=sys.stderr)
            return 2
    files = robot_files()
    unknown = [n for n in args.only or () if n not in {path.stem for _, path in files}]
    if unknown:  # a table of nothing would look like a zoo that imports nothing
        stems = sorted({path.stem for _, path in files})
        near = difflib.get_close_matches(unknown[0], stems, n=1)
        print(f"{PROG}: error: --only: no robot file named {', '.join(unknown)}"
              + (f" (did you mean {near[0]}?)" if near else
                 f"; of the {len(stems)} found{': ' if stems else ''}{', '.join(stems)}"),
              file=sys.stderr)  # fmt: skip
        return 2
    rows = []
    print(f"{'package':27s} {'file':45s} {'DoF':>3s} {'dt x sub-steps':>15s} {'s':>5s}  verdict")
    try:
        files = robot_files(args.menagerie)
    except UserError as e:
        print(f"{PROG}: error: {user_message(e)}", file=sys.stderr)
        return 2
    for package, path in files:
        if args.only is not None and stem_of(package, path) not in args.only:
            continue
        row = import_one(path) | {"package": package, "stem": stem_of(package, path)}
        if package == "menagerie":
            row["file"] = f"{path.parent.name}/{path.name}"
        rows.append(row)
        step = f"{row['dt'] * 1e3:.2f} ms x {row['substeps']}" if row["dof"] else "-"
        print(
            f"{package:27s} {row['file']:45s} {row['dof'] or '-':>3} {step:>15s} "
            f"{row['seconds']:5.1f}  {row['verdict']}",
            flush=True,
        )
    ok = [r for r in rows if r["dof"]]
    print(f"{len(ok)} of {len(rows)} files imported, all at dt >= 1 ms" if all(
        r["dt"] >= 1e-3 - 1e-12 for r in ok) else "some import below dt 1 ms")  # fmt: skip
    if not args.train:
        return 0
    chosen = [r for r in ok if args.only is None or r["stem"] in args.only]
    stems = [r["stem"] for r in chosen]
    for r in chosen:  # two packages' reacher.xml: their runs and rows named by package
        twin = stems.count(r["stem"]) > 1
        r["run"] = f"{r['package']}.{r['stem']}" if twin else r["stem"]
        r["name"] = f"{r['package']}/{r['file']}" if twin else r["file"]
    try:
        args.runs_dir.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        out = args.runs_dir / f"kuka-{stamp}"
        kuka = train_one(
            str(ROOT / "scenes" / "kuka.usda"), out, args.train, args.goals, args.inits
        )
        print(f"\nmeta-train {args.train} iterations (CPU), meta-test at goal std 0.1:")
        print_header(args)
        print_row("kuka.usda (scenes/)", kuka["out"], kuka, kuka, args)
        for r in chosen:
            out = args.runs_dir / f"{r['run']}-{stamp}"
            with contextlib.redirect_stderr(io.StringIO()):
                t = train_one(str(r["path"]), out, args.train, args.goals, args.inits)
            print_row(r["name"], t["out"], t, kuka, args)
    except UserError as e:
        print(f"{PROG}: error: {user_message(e)}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
