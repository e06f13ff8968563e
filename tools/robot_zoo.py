#!/usr/bin/env python
"""Robot zoo: import every robot file of the installed robot-description packages and print a table.

The files: example-robot-data's URDFs (``robots/*/urdf/*.urdf``), differentiable-robot-model's data
(``diff_robot_data/**/*.urdf``) and gymnasium's MuJoCo assets (``envs/mujoco/assets/*.xml``). Each is
imported as ``warp-critic import`` would (``load_robot`` and its derived defaults); the table gives the
file, the trained DoF, ``dt x substeps`` and the verdict: ``ok`` (with the import's notes: props
dropped, an arm chain chosen) or the one-line reason it was refused.

``--only STEM,..`` keeps those files. ``--train ITERATIONS`` then meta-trains each imported robot for that many
iterations on the CPU, and the KUKA scene in the same run, and prints per robot: s/iteration and its
ratio to the KUKA's, the untrained MSE and the MSE after the 3 meta-test updates (goal std 0.1,
``--goals`` goals x ``--inits`` fresh policies).

    python tools/robot_zoo.py                                   # the import table
    python tools/robot_zoo.py --train 50 --only xarm7,z1,reacher --runs-dir runs/zoo

The import pass takes a few minutes on a 2-core CPU.
"""

from __future__ import annotations

import contextlib
import io
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
}


def robot_files() -> list[tuple[str, Path]]:
    """(package, file) for every robot file found, sorted within each package."""
    found = []
    for package, (base, pattern) in PACKAGES.items():
        if base.is_dir():
            found += [(package, p) for p in sorted(base.glob(pattern))]
    return found


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


def train_one(scene: str, out: Path, iterations: int, goals: int, inits: int) -> dict:
    """Meta-train ``scene`` for ``iterations`` and meta-test it at goal std 0.1."""
    from warp_critic.evaluation.metatest import MetaTestConfig, meta_test
    from warp_critic.methods.ours import TrainConfig, meta_train

    cfg = TrainConfig(scene=scene, iterations=iterations, device="cpu", out=str(out))
    with contextlib.redirect_stderr(io.StringIO()):
        res = meta_train(cfg, progress=False, record=False)
    rows = res.metrics
    per_it = sum(r["seconds"] for r in rows[1:]) / max(len(rows) - 1, 1)  # the first compiles
    tc = MetaTestConfig(
        run_dir=str(out), num_goals=goals, inits=inits, goal_std=0.1, device="cpu",
        out=str(out / "metatest-zoo.json"),
    )  # fmt: skip
    result = meta_test(tc)
    return {
        "s_per_it": per_it,
        "mse_before": result["mse_mean_before"],
        "mse_after": result["mse_mean"],
    }


def main(argv: list[str] | None = None) -> int:
    p = ToolParser(prog=PROG, description=__doc__.split("\n\n")[0])
    p.add_argument("--train", type=int, default=0, metavar="ITERATIONS", help="meta-train each")
    p.add_argument(
        "--only", type=comma_list(str), default=None, help="file stems to import and train"
    )
    p.add_argument("--goals", type=int, default=4, help="meta-test goals (std 0.1)")
    p.add_argument("--inits", type=int, default=2, help="fresh policies per meta-test goal")
    p.add_argument("--runs-dir", type=Path, default=ROOT / "runs" / "zoo")
    args = p.parse_args(argv)
    if args.train < 0:
        p.error(f"--train: must be >= 0 (got {args.train})")

    from warp_critic.core import runtime
    from warp_critic.core.errors import UserError

    runtime.init()
    rows = []
    print(f"{'package':27s} {'file':45s} {'DoF':>3s} {'dt x sub-steps':>15s} {'s':>5s}  verdict")
    for package, path in robot_files():
        if args.only is not None and path.stem not in args.only:
            continue
        row = import_one(path)
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
    chosen = [r for r in ok if args.only is None or r["path"].stem in args.only]
    try:
        args.runs_dir.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        kuka = train_one(
            str(ROOT / "scenes" / "kuka.usda"), args.runs_dir / f"kuka-{stamp}", args.train,
            args.goals, args.inits,
        )  # fmt: skip
        print(f"\nmeta-train {args.train} iterations (CPU), meta-test at goal std 0.1:")
        print(f"{'robot':40s} {'DoF':>3s} {'s/it':>6s} {'x KUKA':>6s} {'MSE untrained':>13s} "
              f"{'MSE after 3 updates':>19s}")  # fmt: skip
        print(f"{'kuka.usda (scenes/)':40s} {7:3d} {kuka['s_per_it']:6.2f} {1.0:6.2f} "
              f"{kuka['mse_before']:13.4f} {kuka['mse_after']:19.4f}", flush=True)  # fmt: skip
        for r in chosen:
            out = args.runs_dir / f"{r['path'].stem}-{stamp}"
            with contextlib.redirect_stderr(io.StringIO()):
                t = train_one(str(r["path"]), out, args.train, args.goals, args.inits)
            print(f"{r['file']:40s} {r['dof']:3d} {t['s_per_it']:6.2f} "
                  f"{t['s_per_it'] / kuka['s_per_it']:6.2f} {t['mse_before']:13.4f} "
                  f"{t['mse_after']:19.4f}", flush=True)  # fmt: skip
    except UserError as e:
        print(f"{PROG}: error: {user_message(e)}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
