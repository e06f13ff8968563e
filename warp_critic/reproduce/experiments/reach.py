"""The open-loop reachability floor of a dynamics variant: how close ANY controller with the policy's
torque bounds and horizon can bring the robot to a goal.

For every (variant, goal) world, open-loop torques ``(T, dof)`` are optimised through the
*differentiable* model (Adam on ``max_torque * tanh(u)``, from the meta-test start: the home pose at
rest), keeping the best final error seen per world. A world whose state goes non-finite (torques
the integrator cannot follow, e.g. on very light links) backtracks to half its best torques. This
is the computation of ``tools/diagnose_metatest.py --reachability``, batched over many variants.
It is an upper bound of the true floor (a local optimiser), so an error near it means the goal is
hard, not that the critic failed.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import torch

from warp_critic.core.errors import DivergenceError, UserError
from warp_critic.physics.scene import Variant


def open_loop_floor(
    run_dir: str,
    variants: list,
    goals: torch.Tensor,
    *,
    iterations: int,
    lr: float = 0.1,
    device: str = "cpu",
    u0: torch.Tensor | None = None,
) -> np.ndarray:
    """``(len(variants), G)`` best final ``||q_T - g||^2`` [rad^2] per variant and goal ``(G, dof)``,
    with the run's scene, horizon, time step, gravity and torque bounds. ``u0`` ``(T, V*G, dof)``,
    variant-major: the start of the pre-tanh torques (default zeros: no torque); the start's own
    error counts, so a start replaying a policy's torques gives at most that policy's error."""
    from warp_critic.learning.networks import Normalizer
    from warp_critic.learning.rollout import finite_worlds, rollout
    from warp_critic.physics.simulator import STANDARD_GRAVITY, Simulator
    from warp_critic.reproduce.experiments.evaluate import load_runs
    from warp_critic.running.scenefile import find_run_scene
    from warp_critic.running.task_inputs import max_torque_tensor

    run = load_runs([run_dir])[str(run_dir)]
    cfg = run.cfg
    scene = find_run_scene(run.ckpt, run_dir)
    G, V = goals.shape[0], len(variants)
    sim = Simulator(
        scene,
        [v for v in variants for _ in range(G)],
        dt=cfg.dt,
        substeps=cfg.substeps,
        device=device,
        differentiable=True,
        gravity=cfg.gravity if cfg.gravity is not None else STANDARD_GRAVITY,
    )
    dev = sim.torch_device
    norm = Normalizer.from_limits(
        sim.q_lower, sim.q_upper, max_torque_tensor(cfg.max_torque, scene, dev), cfg.qd_scale
    )
    target = goals.to(dev).repeat(V, 1)
    home = torch.as_tensor(scene.home, dtype=torch.float32, device=dev).expand(V * G, -1)
    shape = (cfg.horizon, V * G, scene.dof)
    if u0 is not None and tuple(u0.shape) != shape:
        raise ValueError(f"u0: shape {tuple(u0.shape)}, expected {shape}")
    start = torch.zeros(shape, device=dev) if u0 is None else u0.detach().to(dev, torch.float32)
    u = start.clone().requires_grad_(True)
    opt = torch.optim.Adam([u], lr=lr)
    best = torch.full((V * G,), float("inf"), device=dev)
    best_u = start.clone()  # each world's torques at its best error so far
    for _ in range(max(1, int(iterations))):
        steps = iter(range(cfg.horizon))

        def open_loop(q: torch.Tensor, qd: torch.Tensor, t: Iterator[int] = steps) -> torch.Tensor:
            return norm.max_torque * torch.tanh(u[next(t)])

        traj = rollout(
            sim,
            open_loop,
            home.clone(),
            torch.zeros_like(home),
            cfg.horizon,
            differentiable=True,
            check=False,
        )
        ok = finite_worlds(traj)
        err = ((traj.q[-1] - target) ** 2).sum(-1)
        better = ok & (err.detach() < best)
        best = torch.where(better, err.detach(), best)
        best_u[:, better] = u.detach()[:, better]
        opt.zero_grad()
        err[ok].sum().backward()
        opt.step()
        if not bool(ok.all()):
            # backtrack: saturated torques that the integrator cannot follow (light links) are no
            # controller's; such a world restarts from half its best torques, its moments cleared
            _backtrack(opt, u, best_u, ~ok)
    if not bool(torch.isfinite(best).all()):
        bad = int(torch.nonzero(~torch.isfinite(best))[0])
        raise DivergenceError(
            f"open-loop floor: world {bad} went non-finite at every step of the search", world=bad
        )
    return best.view(V, G).cpu().numpy()


def best_open_loop_floor(
    run_dir: str,
    variants: list,
    goals: torch.Tensor,
    *,
    iterations: int,
    lrs: list[float],
    device: str = "cpu",
) -> np.ndarray:
    """``(len(variants), G)``: per world, the best :func:`open_loop_floor` over the Adam learning
    rates ``lrs``. One rate does not suit every robot: on the reacher, 0.1 leaves goals that 0.03
    reaches to 1e-11 at the start's error, its elbow being too responsive for steps that size."""
    floors = [
        open_loop_floor(run_dir, variants, goals, iterations=iterations, lr=lr, device=device)
        for lr in lrs
    ]
    return np.minimum.reduce(floors)


def _backtrack(opt: torch.optim.Adam, u: torch.Tensor, best_u: torch.Tensor, bad) -> None:
    """Worlds ``bad`` ``(W,)`` of ``u`` ``(T, W, dof)``: back to half their best, Adam's moments zero."""
    with torch.no_grad():
        u[:, bad] = 0.5 * best_u[:, bad]
        for key in ("exp_avg", "exp_avg_sq"):
            opt.state[u][key][:, bad] = 0.0


def maps_floor(run_dir: str, s: dict, grid, train_goals, pairs: dict, variant, device: str) -> dict:
    """The open-loop reachability floor (MSE over the joints) of every goal of the goal grid ``(n, n,
    dof)`` and of every cell of the 2-D maps (mean over the training goals): what the best open-loop
    torques within the policy's bounds and horizon reach from home (:func:`best_open_loop_floor`).
    The maps stage's (:func:`~warp_critic.reproduce.experiments.maps.run_maps_stage`)."""
    its, lrs = int(s["reach_iterations"]), [float(x) for x in s["reach_lrs"]]

    def floor(variants: list, goals) -> np.ndarray:
        dof = goals.shape[1]
        return (
            best_open_loop_floor(run_dir, variants, goals, iterations=its, lrs=lrs, device=device)
            / dof
        )

    out = {"goals": floor([Variant()], grid.flatten(0, 1))[0].reshape(grid.shape[:2]).tolist()}
    for kind, values in pairs.items():
        out[kind] = floor([variant(kind, a, b) for a, b in values], train_goals).mean(1).tolist()
    return {"reach_floor": out, "reach_iterations": its, "reach_lrs": lrs}


def taken_floors(root: Path, floors_from: str) -> dict:
    """The reachability floors of the complete maps stage ``root/floors_from`` (the same grids and
    nominal runs: :func:`~warp_critic.reproduce.experiments.units.paper_maps_floors`), to take
    instead of computing them again, with ``reach_floor_from`` naming it."""
    from warp_critic.reproduce.engine.stages import read_stage

    done = (read_stage(root / floors_from) or {}).get("result", {})
    keys = ("reach_floor", "reach_iterations", "reach_lrs")
    if not all(k in done for k in keys):
        raise UserError(f"{root / floors_from}: no reachability floors to take")
    return {**{k: done[k] for k in keys}, "reach_floor_from": floors_from}
