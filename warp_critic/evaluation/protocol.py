"""The paper's evaluation protocol (Table 1), pooled over meta-train seeds, and the paper's numbers.

Table 1 of the paper reports "the mean squared error between last state and goal over 10 new goals,
5 seeds and 5 new policy initialization", for new goals sampled "at a distance of N(0, std)" around
two of the four training goals, std = 0.1 .. 1.0. :func:`run_protocol` runs exactly that over one
run directory per meta-train seed: for every goal-noise reading and std, each run's critic trains
``inits`` fresh policies (model-free, :func:`warp_critic.evaluation.metatest.meta_test`) for the same
``num_goals`` goals and the same initialisations (``seed``), and the final errors of all runs are
pooled into one cell. It works for any method's run directory (ours or any registered baseline).

Each cell holds two aggregations over the joints of the final error:

* ``mse_*``: ``mean_j (q_T,j - g_j)^2`` -- the paper's metric; compare with :data:`PAPER_TABLE1`;
* ``sq_*``: ``||q_T - g||^2`` -- the task loss (the sum over the joints, ``dof`` times the MSE).

"At a distance of N(0, std)" reads two ways (``goal_noise``): ``per-joint`` draws ``N(g, std^2 I)``,
``distance`` moves the goal by ``d ~ N(0, std^2)`` along a random direction (see
:func:`warp_critic.evaluation.metatest.sample_goals`).

The paper's Tables 1-3 (KUKA: new goals, end-effector masses, end-effector link lengths) are data in
:mod:`warp_critic.evaluation.paper`.

Library code: nothing is printed (progress goes to the optional ``log`` callback), and a bad setting
raises :class:`~warp_critic.core.errors.FieldError` naming the :class:`ProtocolConfig` field, before any
meta-test runs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from warp_critic.core.errors import FieldError, UserError
from warp_critic.evaluation.paper import GOAL_NOISE, PAPER_TABLE1, TABLE1_STDS
from warp_critic.methods import method
from warp_critic.running.rundir import RunDir

#: The kind of the JSON that ``warp-critic score --out`` writes (:meth:`ProtocolResult.to_dict`).
RESULT_KIND = "warp-critic/score-v1"
# ------------------------------------------------------------------------------------------------
# settings and results
# ------------------------------------------------------------------------------------------------


@dataclass
class ProtocolConfig:
    """The protocol's settings; the defaults are the paper's Table 1 (all ten stds, both readings)."""

    run_dirs: list[str] = field(default_factory=list)  # one meta-trained run per seed, pooled
    stds: list[float] = field(default_factory=lambda: list(TABLE1_STDS))  # goal stds (rad)
    goal_noise: list[str] = field(
        default_factory=lambda: list(GOAL_NOISE)
    )  # readings, see GOAL_NOISE
    around: list[int] | None = field(
        default_factory=lambda: [0, 1]
    )  # training goals to sample around; None = all
    num_goals: int = 10  # new goals per cell
    inits: int = 5  # fresh policy initialisations per goal
    seed: int = 1  # seed of the goals and the policy initialisations (the same for every run)
    device: str = "auto"
    write_run_json: bool = (
        True  # each run's meta-test JSON goes to RUN_DIR/table-<reading>-<std>.json
    )

    def validate(self) -> None:
        """Raise :class:`FieldError` (or :class:`UserError` for a missing run) on a bad setting."""
        validate(self)


@dataclass
class Cell:
    """One (reading, std) cell: the errors of every run's policies, pooled."""

    reading: str
    std: float
    dof: int
    mse_mean: float  # mean_j (q_T,j - g_j)^2, the paper's metric, mean over goals x inits x runs
    mse_std: float
    sq_mean: float  # ||q_T - g||^2 (dof x the MSE)
    sq_std: float
    mse_mean_per_run: list[float]  # each run's own mean (the spread over seeds)
    n: int  # policies pooled: runs x goals x inits


@dataclass
class ProtocolResult:
    """All cells of a protocol run; ``to_dict`` is its JSON form."""

    runs: list[str]
    stds: list[float]
    goal_noise: list[str]
    around: list[int] | None
    num_goals: int
    inits: int
    seed: int
    cells: list[Cell] = field(default_factory=list)
    seconds: float = 0.0

    def cell(self, reading: str, std: float) -> Cell:
        for c in self.cells:
            if c.reading == reading and c.std == std:
                return c
        raise KeyError((reading, std))

    def to_dict(self) -> dict[str, Any]:
        return {"kind": RESULT_KIND, **asdict(self)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ProtocolResult:
        d = dict(d)
        d.pop("kind", None)
        d["cells"] = [Cell(**c) for c in d.get("cells", [])]
        return cls(**d)


# ------------------------------------------------------------------------------------------------
# validation and the protocol
# ------------------------------------------------------------------------------------------------


def _is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def check_settings(pc: ProtocolConfig) -> None:
    """Check every setting but the run directories (no I/O): :class:`FieldError` naming the field."""
    from warp_critic.core.runtime import check_seed

    if isinstance(pc.stds, (str, bytes)) or not pc.stds:
        raise FieldError("stds", "give one or more goal stds")
    for s in pc.stds:
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not math.isfinite(s) or s < 0:
            raise FieldError("stds", f"every goal std must be a finite number >= 0 (got {s!r})")
    if isinstance(pc.goal_noise, str) or not pc.goal_noise:
        raise FieldError("goal_noise", f"give a list of one or more of {', '.join(GOAL_NOISE)}")
    for r in pc.goal_noise:
        if r not in GOAL_NOISE:
            raise FieldError("goal_noise", f"must be one of {', '.join(GOAL_NOISE)} (got {r!r})")
    if pc.around is not None:
        if isinstance(pc.around, (str, bytes)) or not all(_is_int(i) and i >= 0 for i in pc.around):
            raise FieldError(
                "around", f"must be training-goal indices >= 0, or None for all (got {pc.around!r})"
            )
    for name in ("num_goals", "inits"):
        v = getattr(pc, name)
        if not _is_int(v) or v < 1:
            raise FieldError(name, f"must be an integer >= 1 (got {v!r})")
    check_seed(pc.seed, "seed")


def validate(pc: ProtocolConfig) -> list[dict | None]:
    """Check every setting and every run directory; returns each run's ``config.json`` (or ``None``).

    Raises :class:`FieldError` (``stds``, ``goal_noise``, ``around``, ``num_goals``, ``inits``,
    ``seed``, ``run_dirs``) or the :class:`UserError` of an unreadable run directory, before any
    meta-test runs.
    """
    check_settings(pc)
    if isinstance(pc.run_dirs, (str, Path)) or not pc.run_dirs:
        raise FieldError(
            "run_dirs", "give a list of one or more run directories (one per meta-train seed)"
        )

    runs = []
    seen: dict[str, str] = {}  # a run's identity (its run id, else its folder) -> the name given
    methods: dict[str, str] = {}  # method -> the first run of it
    for run in pc.run_dirs:
        path = Path(run)
        if not path.is_dir():
            raise UserError(f"{run}: run directory not found")
        if not (path / "checkpoint.pt").is_file():
            raise UserError(f"{run}: no checkpoint.pt in this run directory")
        config = _read_config(path)
        marker = RunDir(path).marker()
        for key in (str(path.resolve()), str(marker.get("run_id") or "")):
            if key and key in seen:
                raise FieldError(
                    "run_dirs",
                    f"{run} is the run {seen[key]} again (the same folder or a copy of it): "
                    "each run is one seed and is pooled once",
                )
        seen.update({str(path.resolve()): str(run), str(marker.get("run_id") or ""): str(run)})
        seen.pop("", None)
        name = str(marker.get("method") or (config or {}).get("method") or "ours")
        methods.setdefault(name, str(run))
        if len(methods) > 1:
            (a, first), (b, _) = list(methods.items())[:2]
            raise FieldError(
                "run_dirs",
                f"{first} is a run of {a} and {run} of {b}: the runs pooled are seeds of one "
                "method's critic (score each method on its own)",
            )
        n_train = len(config["goals"]) if config and config.get("goals") else None
        for i in pc.around or []:
            if n_train is not None and i >= n_train:
                raise FieldError(
                    "around",
                    f"training goal {i} does not exist: {run} has {n_train} training goals",
                )
        runs.append(config)
    scenes = {
        (Path(c.get("scene", "?")).stem, len(c["goals"][0])) for c in runs if c and c.get("goals")
    }
    if len(scenes) > 1:
        raise UserError(
            "the run directories are for different scenes ("
            + ", ".join(f"{s}, {d} dof" for s, d in sorted(scenes))
            + "); pool runs of one scene"
        )
    return runs


def _read_config(run_dir: Path) -> dict | None:
    """``RUN_DIR/config.json`` (the run's resolved config), or ``None`` when it is absent or unreadable
    (meta-test then reports the run's problem itself)."""
    import json

    try:
        config = json.loads((run_dir / "config.json").read_text())
    except (OSError, ValueError):
        return None
    return config if isinstance(config, dict) else None


def run_protocol(pc: ProtocolConfig, log: Callable[[str], None] | None = None) -> ProtocolResult:
    """Meta-test every run at every (reading, std) and pool the final errors over the runs.

    Every run sees the same goals and policy initialisations (``pc.seed``). ``log`` receives one line
    per run and cell. Raises :class:`FieldError` / :class:`UserError` for bad settings before any work.
    """
    import time

    import numpy as np

    from warp_critic.evaluation.metatest import MetaTestConfig, meta_test

    validate(pc)
    t0 = time.perf_counter()
    around = list(pc.around) if pc.around else None
    result = ProtocolResult(
        runs=[str(r) for r in pc.run_dirs],
        stds=[float(s) for s in pc.stds],
        goal_noise=list(pc.goal_noise),
        around=around,
        num_goals=pc.num_goals,
        inits=pc.inits,
        seed=pc.seed,
    )
    for reading in result.goal_noise:
        for std in result.stds:
            errs, per_run, dof = [], [], 0
            for run in result.runs:
                out = str(Path(run) / f"table-{reading}-{std}.json") if pc.write_run_json else None
                tc = MetaTestConfig(
                    run_dir=run,
                    num_goals=pc.num_goals,
                    goal_std=std,
                    goal_noise=reading,
                    around=around,
                    inits=pc.inits,
                    seed=pc.seed,
                    device=pc.device,
                    out=out,
                )
                r = meta_test(tc, progress=None)
                dof = len(r["goals"][0])
                errs.append(np.asarray(r["final_error_all"], dtype=np.float64).ravel())
                per_run.append(float(r["mse_mean"]))
                if log:
                    log(
                        f"{run}: {reading} std {std:g}: MSE {r['mse_mean']:.4f} ({r['mse_std']:.4f}), "
                        f"sum sq. {r['mean']:.4f} ({r['std']:.4f})"
                    )
            sq = np.concatenate(errs)
            result.cells.append(
                Cell(
                    reading=reading,
                    std=std,
                    dof=dof,
                    mse_mean=float(sq.mean() / dof),
                    mse_std=float(sq.std() / dof),
                    sq_mean=float(sq.mean()),
                    sq_std=float(sq.std()),
                    mse_mean_per_run=per_run,
                    n=int(sq.size),
                )
            )
    result.seconds = time.perf_counter() - t0
    return result


# ------------------------------------------------------------------------------------------------
# formatting
# ------------------------------------------------------------------------------------------------


def format_table(
    result: ProtocolResult, paper: str | None = "ours", per_run: bool = True
) -> list[str]:
    """Markdown rows ``mean(std)`` per (reading, metric), then (``per_run``) each run's MSE.

    ``paper``: a key of :data:`PAPER_TABLE1` whose row is added first (only when every std of the
    result is one of Table 1's), or ``None`` for no paper row.
    """
    if paper is not None and paper not in PAPER_TABLE1:
        raise FieldError(
            "paper", f"must be one of {', '.join(PAPER_TABLE1)} or None (got {paper!r})"
        )
    stds, readings = result.stds, result.goal_noise
    lines = [
        "| goal noise | metric | " + " | ".join(f"std={s:g}" for s in stds) + " |",
        "|" + "---|" * (len(stds) + 2),
    ]
    row = PAPER_TABLE1.get(paper or "", {})
    if paper is not None and all(s in row for s in stds):
        lines.append(
            f"| {method(paper).paper_label} | MSE | "
            + " | ".join(f"{row[s][0]:g}({row[s][1]:g})" for s in stds)
            + " |"
        )
    for reading in readings:
        for metric, label in (("mse", "MSE"), ("sq", "sum sq.")):
            cells = [result.cell(reading, s) for s in stds]
            values = [
                f"{getattr(c, metric + '_mean'):.3f}({getattr(c, metric + '_std'):.3f})"
                for c in cells
            ]
            lines.append(f"| {reading} | {label} | " + " | ".join(values) + " |")
    if per_run:
        lines += ["", "MSE per run (spread over seeds):"]
        for reading in readings:
            for s in stds:
                c = result.cell(reading, s)
                lines.append(
                    f"  {reading:9s} std {s:g}: "
                    + " ".join(f"{v:.3f}" for v in c.mse_mean_per_run)
                    + f"   (n = {c.n} policies)"
                )
    return lines
