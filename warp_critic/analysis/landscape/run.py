"""The landscape analysis end to end (section 4.2, Figure 1): settings, checks, training, landscapes,
descent check and outputs. Entry point :func:`run_landscape`; background: ``docs/landscape.md``.

Library code: the caller starts Warp and sets torch's threads (:func:`warp_critic.core.runtime.init`; the
CLI does). One torch thread is much faster here: the networks are small.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from warp_critic.analysis import checks
from warp_critic.analysis.landscape.fields import (
    METHODS,
    compute_landscapes,
    descent_fraction,
    memory_bytes,
)
from warp_critic.analysis.landscape.outputs import goal_names, write_figures, write_recording
from warp_critic.analysis.landscape.problem import analytic_optimum, default_scene
from warp_critic.analysis.landscape.training import train_ours, train_sup
from warp_critic.core.errors import FieldError, UserError
from warp_critic.core.runtime import check_seed

GOAL_INPUTS = ("absolute", "relative")
# the landscapes' arrays, in the order the outputs take them
GRIDS = ("axis", "values", "grads", "goals", "optima")
SUP_REWARDS = ("terminal", "running")


@dataclass
class LandscapeConfig:
    out: Path = Path("runs/analysis-landscape")
    iterations: int = 300
    grid: int = 21
    range: float = 5.0  # R: theta in [-R, R]^2 (N)
    seed: int = 0
    device: str = "cpu"
    horizon: int = 20
    dt: float = 0.05
    substeps: int = 1
    alpha: float = 1.0
    lr: float = 1e-3
    inits_per_state: int = 4
    goal: tuple = (1.0, 1.0)
    test_goals: tuple = ((-1.5, 0.5), (0.5, -1.5))
    init_states: tuple = ((0.0, 0.0), (-0.5, 0.5))
    sup_alpha: float = 0.05
    sup_fit_steps: int = 10
    sup_batch: int = 512
    sup_reward: str = "terminal"
    tolerance: float = 0.5
    ours_goal_input: str = "absolute"
    # the training-task distribution (docs/landscape.md, "Generalisation to unseen goals"); the defaults
    # are the paper's one goal from the fixed initial states
    train_goals: tuple = ()  # extra training goals; each world draws one of {goal} + train_goals per iteration
    goal_std: float = 0.0  # Gaussian noise added to each world's training goal per iteration (m)
    start_std: float = (
        0.0  # Gaussian noise added to each world's initial position per iteration (m)
    )
    qd_scale: float = 2.0
    scene: Path = field(default_factory=default_scene)
    quiet: bool = False

    def validate(self) -> LandscapeConfig:
        """Check every setting before any work; :class:`~warp_critic.core.errors.FieldError` names the field.

        The grid is refused when the estimated memory of its ``grid^2`` parallel worlds (plus the replay
        buffer of ``Q_sup``) exceeds the free memory of the device; the message gives the estimate.
        """
        for name in (
            "iterations",
            "horizon",
            "substeps",
            "inits_per_state",
            "sup_fit_steps",
            "sup_batch",
        ):
            checks.integer(name, getattr(self, name), 1)
        checks.integer("grid", self.grid, 3)
        check_seed(self.seed)
        for name in ("range", "dt", "alpha", "lr", "sup_alpha", "tolerance", "qd_scale"):
            checks.number(name, getattr(self, name), positive=True)
        for name in ("goal_std", "start_std"):
            checks.number(name, getattr(self, name), lo=0.0)
        for name, pairs in (
            ("goal", [self.goal]),
            ("test_goals", self.test_goals),
            ("init_states", self.init_states),
            ("train_goals", self.train_goals),
        ):
            for p in pairs:
                if len(p) != 2:
                    raise FieldError(name, f"expects X,Y pairs, got {p!r}")
                for v in p:
                    checks.number(name, v)
        if len(self.init_states) < 1:
            raise FieldError("init_states", "needs at least one X,Y pair")
        if self.sup_reward not in SUP_REWARDS:
            raise FieldError(
                "sup_reward", f"must be one of {', '.join(SUP_REWARDS)}, got {self.sup_reward!r}"
            )
        if self.ours_goal_input not in GOAL_INPUTS:
            raise FieldError(
                "ours_goal_input",
                f"must be one of {', '.join(GOAL_INPUTS)}, got {self.ours_goal_input!r}",
            )
        checks.out_dir("out", self.out)
        worlds = len(self.init_states) * self.inits_per_state
        replay = float(self.iterations) * self.horizon * worlds * (7 * 2 + 2) * 4
        checks.memory(
            "iterations", self.iterations, replay, self.device, " for Q_sup's replay buffer"
        )
        checks.memory(
            "grid",
            self.grid,
            memory_bytes(self.grid, self.horizon, self.substeps) + replay,
            self.device,
            f" for {self.grid}^2 parallel worlds over {self.horizon} steps",
        )
        return self


def run_landscape(cfg: LandscapeConfig) -> dict:
    """Train both critics, compute the landscapes, write ``landscape.rrd``, the PNGs and ``landscape.npz``.

    Returns the arrays (``axis``, ``values``, ``grads``, ``goals``, ``optima``, ``trace_new``, ...), the
    descent ``fractions`` per goal and method, ``goal_names``, ``wall_s`` and ``out``.
    """
    from warp_critic.physics.load import load_scene

    cfg.validate()
    t_start = time.time()
    log = (lambda *a: None) if cfg.quiet else print
    out = Path(cfg.out)
    scene = load_scene(cfg.scene)
    if scene.dof != 2:
        raise UserError(
            f"{cfg.scene}: the landscape analysis needs a 2-DoF scene, got {scene.dof} DoF"
        )
    out.mkdir(parents=True, exist_ok=True)
    trained = _train_critics(cfg, scene, log)
    fields = _landscapes(cfg, scene, trained)
    _write_outputs(out, cfg, trained, fields)
    wall = time.time() - t_start
    names = goal_names(len(fields["goals"]))
    if not cfg.quiet:
        _print_summary(out, cfg, fields, names, wall)
    return {
        **{k: fields[k] for k in (*GRIDS, "fractions")},
        **{k: trained[k] for k in ("trace_new", "trace_before", "ours_loss", "sup_loss")},
        "goal_names": names,
        "wall_s": wall,
        "out": out,
    }


def _simulator(cfg: LandscapeConfig, scene, worlds: int, differentiable: bool):
    """``worlds`` copies of the point mass at the analysis' time step."""
    from warp_critic.physics.scene import Variant
    from warp_critic.physics.simulator import Simulator

    return Simulator(
        scene,
        [Variant()] * worlds,
        dt=cfg.dt,
        substeps=cfg.substeps,
        device=cfg.device,
        differentiable=differentiable,
    )


def _train_critics(cfg: LandscapeConfig, scene, log) -> dict:
    """Meta-train L_critic (ours) and train Q_sup on the training worlds (``len(init_states) x
    inits_per_state``): the critics, ours' policy traces and both loss curves, and the initial states
    as an array (K, 2) in m."""
    gen = torch.Generator().manual_seed(cfg.seed)
    init_states = np.asarray(cfg.init_states, dtype=np.float64)
    W = len(init_states) * cfg.inits_per_state
    train_sim = _simulator(cfg, scene, W, differentiable=True)
    dev = train_sim.torch_device
    q0 = torch.tensor(
        np.repeat(init_states, cfg.inits_per_state, axis=0), dtype=torch.float32, device=dev
    )
    goal = torch.tensor(cfg.goal, dtype=torch.float32, device=dev)[None]

    if cfg.train_goals or cfg.goal_std > 0 or cfg.start_std > 0:
        log(
            f"training tasks drawn every iteration: goals {[tuple(cfg.goal), *cfg.train_goals]} + N(0, "
            f"{cfg.goal_std:g}^2), initial states {[tuple(q) for q in cfg.init_states]} + N(0, {cfg.start_std:g}^2)"
        )
    log(f"meta-training L_critic (ours): {cfg.iterations} iterations, {W} worlds")
    critic, trace_before, trace_new, ours_loss = train_ours(cfg, train_sim, q0, goal, gen, log)
    log(f"training Q_sup (Algorithm 1): {cfg.iterations} iterations, {W} worlds")
    qsup, sup_thetas, sup_loss = train_sup(cfg, train_sim, q0, goal, gen, log)
    return {
        "init_states": init_states,
        "critic": critic,
        "trace_before": trace_before,
        "trace_new": trace_new,
        "ours_loss": ours_loss,
        "qsup": qsup,
        "sup_thetas": sup_thetas,
        "sup_loss": sup_loss,
    }


def _landscapes(cfg: LandscapeConfig, scene, trained: dict) -> dict:
    """Both critics' values and gradients over the ``grid x grid`` policy parameters for the training
    goal and the test goals, the analytic optima theta* and the descent fractions per goal and method."""
    P = cfg.grid**2
    eval_sim = _simulator(cfg, scene, P, differentiable=False)
    grad_sim = _simulator(cfg, scene, P, differentiable=True)
    goals = np.asarray([cfg.goal, *cfg.test_goals], dtype=np.float64)
    q0_eval = trained["init_states"][0]
    axis, values, grads = compute_landscapes(
        cfg, eval_sim, grad_sim, trained["critic"], trained["qsup"], goals, q0_eval
    )
    optima = np.stack(
        [analytic_optimum(g, q0_eval, cfg.dt, cfg.horizon, cfg.substeps) for g in goals]
    )
    fractions = [
        {
            m: descent_fraction(grads[gi, mi], axis, optima[gi], cfg.tolerance)
            for mi, m in enumerate(METHODS)
        }
        for gi in range(len(goals))
    ]
    if not (np.isfinite(values).all() and np.isfinite(grads).all()):
        raise UserError("non-finite landscape values: lower --alpha / --lr or the --range")
    return {
        "axis": axis,
        "values": values,
        "grads": grads,
        "goals": goals,
        "optima": optima,
        "fractions": fractions,
    }


def _write_outputs(out: Path, cfg: LandscapeConfig, trained: dict, fields: dict) -> None:
    """``landscape.rrd``, ``landscape.png``, ``exploration.png`` and ``landscape.npz`` in ``out``."""
    f, t = fields, trained
    grids = (f["axis"], f["values"], f["grads"], f["goals"], f["optima"])  # in GRIDS' order
    write_recording(
        out / "landscape.rrd",
        cfg,
        *grids,
        t["trace_new"],
        t["ours_loss"],
        t["sup_loss"],
        f["fractions"],
    )
    write_figures(out, cfg, *grids, t["trace_new"], t["init_states"], f["fractions"])
    np.savez(
        out / "landscape.npz",
        **dict(zip(GRIDS, grids)),
        **{k: t[k] for k in ("trace_new", "trace_before", "ours_loss", "sup_loss", "sup_thetas")},
    )


def _print_summary(out: Path, cfg: LandscapeConfig, fields: dict, names, wall: float) -> None:
    """The descent success fractions per goal and method, and the files written."""
    goals, optima, fractions = fields["goals"], fields["optima"], fields["fractions"]
    print(
        f"descent success fraction (normalised-gradient descent on the field from each of the "
        f"{cfg.grid**2} grid points, success = within {cfg.tolerance:g} N of theta*):"
    )
    print(f"  {'goal':<22} {'theta*':>16} " + " ".join(f"{m:>9}" for m in METHODS))
    for gi, gn in enumerate(names):
        g = goals[gi]
        print(
            f"  {gn + f' ({g[0]:g},{g[1]:g})':<22} {f'({optima[gi][0]:.2f},{optima[gi][1]:.2f})':>16} "
            + " ".join(f"{fractions[gi][m]:9.3f}" for m in METHODS)
        )
    print(
        f"wrote {out / 'landscape.rrd'}, {out / 'landscape.png'}, {out / 'exploration.png'} "
        f"({wall:.1f} s)"
    )
