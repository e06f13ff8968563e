"""Meta-test budget sweep: how many critic-gradient steps, at what step size, each method's critic
is given at meta-test -- chosen per method on the training goals, never on the reporting goals.

The paper's Algorithm 3 trains a fresh policy on the learned critic "while not done"; the report's
tables give every method's fresh policies the same ``inner_steps`` (3) updates, ours' meta-training
regime. This sweep makes the "while not done" visible and gives every method its own best budget:

The choice and the sweep are :mod:`warp_critic.reproduce.experiments.budget`'s (``reproduce
--beyond`` runs them as stages); this module is the standalone ``warp-critic budget`` command's
driver, on the meta-trainings of a reproduce folder:

1. **Choosing** (:func:`sweep_method`): for every method, every meta-trained seed and every step-size
   scale ``s`` (the run's own meta-test ``alpha`` times ``s``), fresh policies on the run's own
   training goals (``inits`` initialisations per goal, drawn from :data:`CHOOSE_BUDGET_SEED`, a seed that
   draws nothing else: :mod:`warp_critic.evaluation.seed_uses`) descend the critic for
   ``max(budgets)`` updates; the error is read after every budget ``N``. The curve is the mean MSE
   over the joints (rad^2) over seeds x goals x inits, per ``(s, N)``.
2. :func:`choose`: each method's budget is the ``(s, N)`` of the lowest curve value (ties: fewer
   steps, then the smaller step).
3. **Reporting** (:func:`report_method`): new goals sampled as the paper's Table 1 (``num_goals`` per
   std around training goals ``around``, goal seed ``report_seed + column``, which must have chosen
   nothing) and scored at each method's own chosen budget; ours also at each baseline's chosen
   ``N`` (with ours' best step size at that ``N`` on the training goals).

A diverged world (non-finite state) makes its ``(s, N)`` cell ``inf``: never chosen.

Library code: nothing is printed (progress goes to the optional ``log`` callback); a bad setting
raises :class:`~warp_critic.core.errors.FieldError` naming the :class:`BudgetConfig` field.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from warp_critic.core.errors import FieldError
from warp_critic.core.runtime import check_device, check_seed
from warp_critic.evaluation.seed_uses import CHOOSE_BUDGET_SEED, chose
from warp_critic.reproduce.experiments.budget import (
    ALPHA_SCALES,
    BUDGETS,
    best_scale_at,
    choose,
    envelope,
    mean_mse,
    numeric_keys,
    sweep,
)

RESULT_KIND = "warp-critic/metatest-budget-v1"


@dataclass
class BudgetConfig:
    """The sweep's settings (module docstring)."""

    runs: dict[str, list[str]] = field(default_factory=dict)  # method -> per-seed run directories
    budgets: list[int] = field(default_factory=lambda: list(BUDGETS))
    alpha_scales: list[float] = field(default_factory=lambda: list(ALPHA_SCALES))
    inits: int = 5  # fresh policy initialisations per goal
    choose_seed: int = CHOOSE_BUDGET_SEED  # initialisations on the training goals
    report_seed: int = 1000  # goal seed of the reporting goals (column c: report_seed + c)
    report_stds: list[float] = field(default_factory=lambda: [0.1, 0.5, 1.0])  # rad
    num_goals: int = 10  # reporting goals per std
    around: list[int] = field(default_factory=lambda: [0, 1])  # training goals sampled around
    goal_noise: str = "per-joint"
    device: str = "auto"
    max_worlds: int = 4096

    def validate(self) -> None:
        if not self.runs:
            raise FieldError("runs", "no method's runs given")
        if "ours" not in self.runs:
            raise FieldError(
                "runs", "ours' runs are needed (ours is also scored at the baselines' budgets)"
            )
        for m, dirs in self.runs.items():
            if not dirs:
                raise FieldError("runs", f"{m}: no run directory")
        if not self.budgets or any(int(n) != n or n < 1 for n in self.budgets):
            raise FieldError("budgets", f"{self.budgets}: positive whole step counts expected")
        if len(set(self.budgets)) != len(self.budgets):
            raise FieldError("budgets", f"{self.budgets}: a step count given twice")
        if not self.alpha_scales or any(
            not (math.isfinite(s) and s > 0) for s in self.alpha_scales
        ):
            raise FieldError(
                "alpha_scales", f"{self.alpha_scales}: positive finite scales expected"
            )
        for name in ("inits", "num_goals", "max_worlds"):
            if getattr(self, name) < 1:
                raise FieldError(name, f"{getattr(self, name)}: at least 1")
        if not self.report_stds or any(not s > 0 for s in self.report_stds):
            raise FieldError("report_stds", f"{self.report_stds}: positive stds expected")
        reporting = [self.report_seed + c for c in range(len(self.report_stds))]
        if self.choose_seed in reporting:
            raise FieldError(
                "report_seed",
                f"{self.report_seed}: the reporting goals' seeds {reporting} include the choosing "
                f"seed {self.choose_seed}",
            )
        for name in ("choose_seed", "report_seed"):
            check_seed(getattr(self, name), name)
        check_device(self.device)
        for s in reporting:
            if chose(s):
                raise FieldError(
                    "report_seed",
                    f"goal seed {s} chose {chose(s)[0].what.split(' (')[0]} "
                    "(warp_critic/evaluation/seed_uses.py): it cannot report",
                )

    def settings(self) -> dict[str, Any]:
        """What the results depend on besides the runs (a resumed sweep must match it)."""
        d = asdict(self)
        d.pop("runs")
        d.pop("device")
        d.pop("max_worlds")
        return d


def wanted(chosen: dict[str, dict], curves: dict[str, dict]) -> dict[str, list[tuple[float, int]]]:
    """``method -> [(scale, N)]`` the reporting goals are scored at: each method's own choice, and
    ours at every other method's chosen ``N`` (with ours' best scale there)."""
    out = {m: [(c["scale"], c["steps"])] for m, c in chosen.items()}
    for m, c in chosen.items():
        if m != "ours":
            scale, _ = best_scale_at(curves["ours"], c["steps"])
            if (scale, c["steps"]) not in out["ours"]:
                out["ours"].append((scale, c["steps"]))
    return out


# ------------------------------------------------------------------------------------------------
# the meta-tests
# ------------------------------------------------------------------------------------------------


def sweep_method(cfg: BudgetConfig, method: str, resume: Path | None = None) -> dict[str, Any]:
    """Step 1 of the module docstring for one method
    (:func:`~warp_critic.reproduce.experiments.budget.sweep`); ``resume``: its progress folder."""
    return sweep(
        [str(d) for d in cfg.runs[method]],
        budgets=list(cfg.budgets),
        scales=list(cfg.alpha_scales),
        inits=cfg.inits,
        seed=cfg.choose_seed,
        device=cfg.device,
        max_worlds=cfg.max_worlds,
        resume=resume,
    )


def report_method(
    cfg: BudgetConfig, method: str, budgets: list[tuple[float, int]], resume: Path | None = None
) -> dict[str, Any]:
    """Step 3 for one method: the reporting goals at each ``(scale, N)`` of ``budgets``:
    ``{"cells": [{"scale", "steps", "std", "mse_mean", "mse_per_seed", "untrained"}], "seconds"}``;
    ``resume``: its progress folder (one sub-folder per reporting goal std)."""
    from warp_critic.physics.scene import Variant
    from warp_critic.reproduce.experiments.evaluate import Job, evaluate
    from warp_critic.reproduce.experiments.goals import draw_goals, train_goals_and_limits

    t = time.perf_counter()
    dirs = [str(d) for d in cfg.runs[method]]
    _, train_goals, lo, hi = train_goals_and_limits(dirs[0])
    scales = sorted({s for s, _ in budgets})
    cells = []
    for c, std in enumerate(cfg.report_stds):
        goals = draw_goals(
            train_goals,
            lo,
            hi,
            cfg.num_goals,
            std,
            cfg.around,
            cfg.goal_noise,
            cfg.report_seed + c,
        )
        jobs = [Job((rd, s), rd, goals, Variant(), alpha_scale=s) for s in scales for rd in dirs]
        ns = tuple(sorted({n for _, n in budgets}))
        r = evaluate(
            jobs,
            inits=cfg.inits,
            steps=max(ns),
            seed=cfg.report_seed + c,
            device=cfg.device,
            max_worlds=cfg.max_worlds,
            progress=False,
            at=ns,
            resume=resume / f"std{c}" if resume is not None else None,
        )
        for s, n in budgets:
            idx = [k for k, j in enumerate(jobs) if j.alpha_scale == s]
            cells.append(
                {
                    "scale": s,
                    "steps": n,
                    "std": std,
                    "mse_mean": mean_mse([r["errors_at"][n][k] for k in idx], r["dof"]),
                    "mse_per_seed": [mean_mse([r["errors_at"][n][k]], r["dof"]) for k in idx],
                    "untrained": mean_mse([r["before"][k] for k in idx], r["dof"]),
                }
            )
    return {"cells": cells, "seconds": time.perf_counter() - t}


# ------------------------------------------------------------------------------------------------
# the resumable driver
# ------------------------------------------------------------------------------------------------


def run_budget(
    cfg: BudgetConfig,
    out: Path,
    log: Callable[[str], None] | None = None,
    base: Path | None = None,
) -> dict[str, Any]:
    """Steps 1-3 for every method of ``cfg.runs``, resumable: ``out`` (JSON) is rewritten after each
    method's sweep and report, and a rerun with the same settings and runs skips what it holds; a
    sweep or report cut short goes on from the batches kept in ``OUT.progress/`` (removed at the
    end). ``base``: the run directories are written relative to it (the reproduce folder)."""
    from warp_critic.reproduce.experiments.evaluate import relpath

    cfg.validate()
    say = log or (lambda _: None)

    def shown(d: str) -> str:
        return relpath(d, base) if base is not None else str(d)

    runs = {m: [shown(d) for d in ds] for m, ds in cfg.runs.items()}
    result: dict[str, Any] = {"kind": RESULT_KIND, "settings": cfg.settings(), "runs": runs}
    if out.is_file():
        try:
            old = json.loads(out.read_text())
        except (OSError, ValueError, UnicodeDecodeError) as e:
            raise FieldError("out", f"{out}: not a readable JSON file ({e})") from None
        if not isinstance(old, dict) or old.get("kind") != RESULT_KIND:
            raise FieldError("out", f"{out}: holds another kind of result; not replacing it")
        if old.get("settings") != json.loads(json.dumps(cfg.settings())):
            raise FieldError("out", f"{out}: a sweep with other settings; choose another file")
        result = old
        result["runs"] = {**old.get("runs", {}), **runs}

    def save() -> None:
        tmp = out.with_suffix(".tmp")
        tmp.write_text(json.dumps(result, indent=1) + "\n")
        tmp.replace(out)

    progress = out.with_name(out.name + ".progress")
    sweeps = result.setdefault("sweep", {})
    for m in runs:
        if m in sweeps and sweeps[m].get("runs") == runs[m]:
            say(f"{m}: sweep kept from {out}")
            continue
        say(f"{m}: sweeping {len(cfg.alpha_scales)} step sizes to {max(cfg.budgets)} steps")
        sweeps[m] = {**sweep_method(cfg, m, progress / f"{m}-sweep"), "runs": runs[m]}
        sweeps[m]["alphas"] = {shown(k): v for k, v in sweeps[m]["alphas"].items()}
        say(f"{m}: {sweeps[m]['seconds']:.0f} s")
        save()
    curves = {m: numeric_keys(sweeps[m]["curve"]) for m in runs}
    chosen = {}
    for m in runs:
        s, n, err = choose(curves[m])
        chosen[m] = {"scale": s, "steps": n, "mse_train": err}
    result["chosen"] = chosen
    reports = result.setdefault("report", {})
    for m, budgets in wanted(chosen, curves).items():
        key = json.loads(json.dumps(budgets))
        if m in reports and reports[m].get("budgets") == key:
            continue
        say(f"{m}: reporting goals at (scale, steps) {budgets}")
        reports[m] = {**report_method(cfg, m, budgets, progress / f"{m}-report"), "budgets": key}
        save()
    save()
    shutil.rmtree(progress, ignore_errors=True)  # everything is in ``out`` now
    return result


# ------------------------------------------------------------------------------------------------
# the runs of a reproduce output, and the figure
# ------------------------------------------------------------------------------------------------


def runs_of_reproduce(out: Path, scene: str, methods: list[str] | None) -> dict[str, list[str]]:
    """``method -> per-seed run directories`` of the meta-training stages
    (:func:`~warp_critic.reproduce.experiments.naming.stage_name`) of a ``warp-critic reproduce``
    output folder, exactly one complete stage per method; ``methods`` None: every registered method
    (ours first) whose stage the folder holds."""
    from warp_critic.reproduce.experiments.naming import stage_name
    from warp_critic.reproduce.experiments.settings import SCENES
    from warp_critic.running.methods import names

    if scene not in SCENES:
        raise FieldError("scene", f"{scene!r}: unknown; one of {', '.join(SCENES)}")
    unknown = [m for m in methods or [] if m not in names()]
    if unknown:
        raise FieldError(
            "runs", f"unknown method(s) {', '.join(unknown)} (one of {', '.join(names())})"
        )
    runs = {}
    for m in names() if methods is None else methods:
        prefix = stage_name("metatrain", scene, m)
        found = sorted(p for p in out.glob(f"{prefix}-*") if (p / "stage.json").is_file())
        if not found and methods is None:
            continue
        if len(found) != 1:
            what = (
                "no complete stage"
                if not found
                else f"{len(found)} stages ({', '.join(p.name for p in found)})"
            )
            raise FieldError("from", f"{out}: {what} {prefix}-*; one expected")
        seeds = sorted((found[0] / "run").glob("seed*"), key=lambda p: int(p.name[4:] or 0))
        if not seeds:
            raise FieldError("from", f"{found[0]}: no run/seed* directories")
        runs[m] = [str(p) for p in seeds]
    if not runs:
        raise FieldError(
            "from",
            f"{out}: no complete stage {stage_name('metatrain', scene, '<method>')}-* here (a "
            "warp-critic reproduce output folder holds them; a published report's stages keep "
            "one seed's critic, too few to sweep)",
        )
    return runs


def plot_budget(result: dict[str, Any], path: Path, title: str) -> Path:
    """Error against meta-test steps per method: the best step size at each budget (solid), the
    chosen budget (a ring), the untrained policies (dotted); log-log, MSE in rad^2
    (:func:`~warp_critic.reproduce.report.budget.plot_curves`)."""
    from warp_critic.reproduce.report.budget import plot_curves

    per = {
        m: {
            **result["chosen"][m],
            "curve": envelope(numeric_keys(sw["curve"])),
            "untrained": sw["untrained"],
        }
        for m, sw in result["sweep"].items()
    }
    xlabel = "critic-gradient steps per fresh policy at meta-test (N; best step size at each N)"
    return plot_curves(per, path, title, xlabel)
