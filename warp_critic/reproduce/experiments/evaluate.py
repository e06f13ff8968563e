"""Batched meta-test (Algorithm 3) of many run directories, goals and dynamics variants in ONE model.

:func:`evaluate` takes jobs -- a run directory (any method, any seed), its goals and a dynamics
:class:`~warp_critic.physics.scene.Variant` -- and lays ALL their ``goals x inits`` worlds side by side in one
gradient-free :class:`~warp_critic.physics.simulator.Simulator` with a variant per world (split into batches
of whole jobs only above ``max_worlds``). Each world's fresh policy descends its own run's critic
(``metatest.build_test_critic``: ours, or ``-Q`` of a baseline) with its own run's learning rate, for
the same number of policy updates, horizon and initial state (rest at zero, as ``meta-test``) for every
job. Every job with ``G`` goals starts from the same ``G x inits`` policy initialisations
(``policy.init`` from ``torch.Generator().manual_seed(seed)``, exactly as ``meta-test`` draws them for
explicit goals), so the methods, seeds and variants see identical goals and inits.

Per world this is :func:`warp_critic.evaluation.metatest.meta_test` (tests compare the two): the worlds are
independent, each critic sees only its own worlds, and the per-world learning rate multiplies each
world's gradient. Independent, but not to the last bit of every world: torch sums the policy's
last-layer bias gradient over the horizon on a ``(T, W, dof)`` tensor, and its vectorised and
remainder paths add in different orders, so a job's errors move by about 1e-6 (relative) with the
width of the batch it is in. The same jobs with the same ``max_worlds`` give the same numbers to the
bit; another ``max_worlds`` can differ in the sixth digit (measured on the KUKA, 2026-12-07: 8e-7;
``docs/journal/probes.md``).

A world whose state goes non-finite (a light or short link at the scene's ``dt`` under a policy that
slams it into its limits) does not stop the evaluation: its final error is ``inf`` (``before`` too
when the untrained policy already diverged) and it is counted in ``"diverged"``. The other worlds
are independent of it, so their numbers are what they would be without it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from warp_critic.core import interrupts
from warp_critic.core.errors import UserError
from warp_critic.learning.critic_inputs import rollout_data_of
from warp_critic.physics.inertia import NominalInertia
from warp_critic.physics.scene import Variant
from warp_critic.reproduce.experiments.descent import (
    BatchProgress,
    descend,
    fingerprint,
    run_key,
)

#: Task fields every run of one evaluation must share (they define the dynamics and the policy's scaling).
SHARED_FIELDS = ("dt", "substeps", "gravity", "max_torque", "qd_scale")


@dataclass
class Job:
    key: Any  # the caller's label, e.g. ("table1", 0, "ours", 3)
    run_dir: str
    goals: torch.Tensor  # (G, dof) rad
    variant: Variant
    alpha_scale: float = 1.0  # the policies' step size: the run's own alpha times this

    @property
    def G(self) -> int:
        return int(self.goals.shape[0])


class MultiCritic(torch.nn.Module):
    """Several critics over consecutive world slices: ``L(q, qd, tau, g)`` on ``(..., W, dof)``
    inputs; the trajectory's rollout data (``history``, ``dynamics``) reach the critics that read
    them (:func:`~warp_critic.learning.critic_inputs.rollout_data_of`)."""

    def __init__(self, segments: list[tuple[torch.nn.Module, int, int]]):
        super().__init__()
        self.critics = torch.nn.ModuleList([c for c, _, _ in segments])
        self.bounds = [(a, b) for _, a, b in segments]
        # what any of them reads, once each (the losses pass it all; forward slices it per critic)
        self.rollout_data = tuple(
            dict.fromkeys(d for c in self.critics for d in rollout_data_of(c))
        )

    def torque_metric(self, q: torch.Tensor) -> torch.Tensor | None:
        """Each critic's torque metric on its worlds (the identity where it has none), or
        ``None`` where no critic has one: ``q (..., W, dof)`` -> ``(..., W, dof, dof)``."""
        parts = [getattr(c, "torque_metric", lambda _: None) for c in self.critics]
        metrics = [m(q[..., a:b, :]) for m, (a, b) in zip(parts, self.bounds)]
        if all(m is None for m in metrics):
            return None
        eye = torch.eye(q.shape[-1], dtype=q.dtype, device=q.device)
        return torch.cat(
            [
                m if m is not None else eye.expand(*q.shape[:-2], b - a, -1, -1)
                for m, (a, b) in zip(metrics, self.bounds)
            ],
            dim=-3,
        )

    def forward(self, q, qd, tau, g, **data):
        outs = []
        for c, (a, b) in zip(self.critics, self.bounds):
            args = [x[..., a:b, :] for x in (q, qd, tau, g)]
            extra = {d.key: data[d.key][..., a:b, :] for d in rollout_data_of(c)}
            outs.append(c(*args, **extra))
        return torch.cat(outs, dim=-1)


@dataclass
class _Run:
    ckpt: dict
    cfg: Any  # TaskConfig
    critic: torch.nn.Module | None = None
    alpha: float | None = None
    steps: int | None = None


def load_runs(run_dirs) -> dict[str, _Run]:
    from warp_critic.running.rundir import RunDir
    from warp_critic.running.task import TaskConfig

    runs = {}
    for rd in dict.fromkeys(str(r) for r in run_dirs):
        ckpt = RunDir.open(rd).load_checkpoint(require=("config", "dof", "scene", "method"))
        runs[rd] = _Run(ckpt, TaskConfig.from_dict(ckpt["config"]))
    first = next(iter(runs.values()))
    for rd, r in runs.items():
        if (
            r.ckpt.get("scene_hash") != first.ckpt.get("scene_hash")
            or r.ckpt["dof"] != first.ckpt["dof"]
        ):
            raise UserError(
                f"{rd}: trained on another scene than {next(iter(runs))}; evaluate one scene at a time"
            )
        for f in SHARED_FIELDS:
            if getattr(r.cfg, f) != getattr(first.cfg, f):
                raise UserError(
                    f"{rd}: {f} {getattr(r.cfg, f)!r} differs from {getattr(first.cfg, f)!r} of the other runs"
                )
    return runs


def _std(x: np.ndarray) -> float:
    """The spread of finite errors; ``nan`` (no spread) where a world diverged (numpy's would be
    ``nan`` too, with a warning from ``inf - inf``)."""
    return float(x.std()) if np.isfinite(x).all() else float("nan")


def pool_errors(errs: list[np.ndarray], dof: int) -> dict:
    """Pool final squared errors (one (G, K) array per seed) into a cell: MSE over joints. A
    diverged world (``inf``) makes the cell's mean ``inf``; ``diverged`` counts them."""
    mse = np.concatenate([e.ravel() for e in errs]) / dof
    return {
        "mse_mean": float(mse.mean()),
        "mse_std": _std(mse),
        "diverged": int((~np.isfinite(mse)).sum()),
        "mse_per_seed": [float(e.mean() / dof) for e in errs],
        "mse_std_per_seed": [_std(e / dof) for e in errs],
        "n": int(mse.size),
    }


def default_steps(run_dir: str) -> int:
    """The number of policy updates the run's own meta-test would take (ours: inner steps x lifetime)."""
    runs = load_runs([run_dir])
    cfg = runs[str(run_dir)].ckpt["config"]
    if runs[str(run_dir)].ckpt.get("method", "ours") == "ours":
        return int(cfg.get("inner_steps", 1)) * int(cfg.get("policy_lifetime", 1))
    return int(cfg.get("inner_steps", 1))


def batches(jobs: list[Job], inits: int, max_worlds: int) -> list[list[int]]:
    """Job indices grouped into batches of at most ``max_worlds`` worlds (whole jobs; a bigger job alone)."""
    out: list[list[int]] = []
    cur: list[int] = []
    n = 0
    for i, j in enumerate(jobs):
        w = j.G * inits
        if cur and n + w > max_worlds:
            out.append(cur)
            cur, n = [], 0
        cur.append(i)
        n += w
    if cur:
        out.append(cur)
    return out


def evaluate(
    jobs: list[Job],
    *,
    inits: int,
    steps: int,
    seed: int = 1,
    device: str = "auto",
    horizon: int | None = None,
    max_worlds: int = 4096,
    progress: bool = True,
    at: tuple[int, ...] = (),
    resume: Path | None = None,
    save_every: float = 300.0,
) -> dict:
    """Meta-test every job; returns ``{"errors": [(G, inits) final ||q_T-g||^2 per job], "before": [...],
    "dof", "horizon", "steps", "alphas": {run_dir: alpha}, "worlds", "batches", "diverged"}``
    (``inf`` errors for diverged worlds, module docstring; ``"diverged"``: their count).

    ``at``: policy-update counts (each in ``1..steps``) after which the errors are also kept, in
    ``"errors_at": {n: [(G, inits) per job]}`` -- one descent of ``steps`` updates read at several
    budgets (a world that diverged by ``n`` is ``inf`` from ``n`` on).

    ``resume``: a folder for this evaluation's progress (:mod:`.descent`): each batch done,
    and every ``save_every`` seconds (wall) a running batch's policies, so that a call killed part
    way goes on where it was, to the same numbers."""
    from warp_critic.physics.simulator import STANDARD_GRAVITY
    from warp_critic.running.loop import progress_bar
    from warp_critic.running.scenefile import find_run_scene

    if not jobs:
        raise UserError("nothing to evaluate")
    if any(not 1 <= int(n) <= steps for n in at):
        raise UserError(f"budgets {sorted(at)}: each must be between 1 and the {steps} steps")
    runs = load_runs([j.run_dir for j in jobs])
    first = next(iter(runs.values()))
    cfg0 = first.cfg
    scene = find_run_scene(first.ckpt, jobs[0].run_dir)  # by content: a moved scene is found
    if horizon is None:
        hs = {r.cfg.horizon for r in runs.values()}
        if len(hs) > 1:
            raise UserError(f"the runs were trained with different horizons {sorted(hs)}; give one")
        horizon = hs.pop()
    gravity = cfg0.gravity if cfg0.gravity is not None else STANDARD_GRAVITY
    groups = batches(jobs, inits, max_worlds)
    errors: list[np.ndarray | None] = [None] * len(jobs)
    before: list[np.ndarray | None] = [None] * len(jobs)
    errors_at: dict[int, list[np.ndarray | None]] = {n: [None] * len(jobs) for n in at}
    inits_cache: dict[int, dict] = {}
    diverged = 0
    bar = progress_bar(len(groups), enabled=progress, desc="meta-test batches")
    try:
        kept = {"steps": steps, "inits": inits, "seed": int(seed), "horizon": horizon}
        kept.update(at=sorted(int(n) for n in at), device=device)  # what a batch's files depend on
        dirs = {str(j.run_dir) for j in jobs}
        # a run's name in the batch files: STAGE/run/seedN, or its whole path where two share that
        name_of = run_key if len({run_key(d) for d in dirs}) == len(dirs) else str
        for b, group in enumerate(groups):
            batch = [jobs[i] for i in group]
            saved = None
            if resume is not None:
                saved = BatchProgress(resume, b, fingerprint(batch, runs, kept, name_of))
            done = saved.finished() if saved is not None else None
            if done is not None:
                (err0, err, bad, err_at), alphas = done
                named = {name_of(j.run_dir): str(j.run_dir) for j in batch}
                for key, alpha in alphas.items():
                    runs[named[key]].alpha = alpha
            else:
                sim, policy = _batch_model(scene, batch, inits, cfg0, gravity, device)
                critic, rate, goal, p = _batch_inputs(
                    batch, runs, policy, inits, seed, inits_cache, sim.torch_device
                )
                err0, err, bad, err_at = descend(
                    sim, policy, critic, rate, goal, p, horizon, steps, at, saved, save_every
                )
                if saved is not None:
                    rds = {str(j.run_dir) for j in batch}  # each one's alpha set by _batch_inputs
                    alphas = {name_of(rd): a for rd in rds if (a := runs[rd].alpha) is not None}
                    saved.finish((err0, err, bad, err_at), alphas)
            diverged += bad
            _split(errors, group, jobs, inits, err)
            _split(before, group, jobs, inits, err0)
            for n, e in err_at.items():
                _split(errors_at[n], group, jobs, inits, e)
            bar.update(1)
            interrupts.check()  # a signal whose KeyboardInterrupt a callback swallowed
    finally:
        bar.close()
    return {
        "errors": errors,
        "before": before,
        "dof": scene.dof,
        "horizon": horizon,
        "steps": steps,
        "alphas": {rd: r.alpha for rd, r in runs.items()},
        "worlds": sum(j.G * inits for j in jobs),
        "batches": len(groups),
        "diverged": diverged,
        **({"errors_at": errors_at} if at else {}),
    }


def _split(out: list, group: list[int], jobs: list[Job], inits: int, err: np.ndarray) -> None:
    """Each job's ``(G, inits)`` slice of a batch's per-world ``err``, into ``out[job index]``."""
    start = 0
    for i in group:
        n = jobs[i].G * inits
        out[i] = err[start : start + n].reshape(jobs[i].G, inits).astype(np.float64)
        start += n


def _batch_model(scene, group: list[Job], inits: int, cfg0, gravity: float, device: str):
    """One simulator for a batch of jobs (each job's variant in ``G * inits`` worlds) and the
    policy network over its limits: ``(Simulator, MLPPolicy)``."""
    from warp_critic.learning.networks import MLPPolicy, Normalizer
    from warp_critic.physics.simulator import Simulator
    from warp_critic.running.task_inputs import max_torque_tensor

    variants = [job.variant for job in group for _ in range(job.G * inits)]
    sim = Simulator(
        scene,
        variants,
        dt=cfg0.dt,
        substeps=cfg0.substeps,
        device=device,
        differentiable=False,
        gravity=gravity,
    )
    dev = sim.torch_device
    norm = Normalizer.from_limits(
        sim.q_lower,
        sim.q_upper,
        max_torque_tensor(cfg0.max_torque, scene, dev),
        cfg0.qd_scale,
        NominalInertia(scene, device),
        sim.dynamics_size,
    )
    return sim, MLPPolicy(norm)


def _batch_inputs(group: list[Job], runs: dict, policy, inits: int, seed: int, inits_cache, dev):
    """The batch's critics (each run's, over its worlds), per-world step sizes ``(W,)``, goals
    ``(W, dof)`` rad and initial policy parameters (the same for every job of ``G`` goals, from
    ``seed``): ``(MultiCritic, rates, goals, params)``."""
    from warp_critic.evaluation.metatest import build_test_critic

    segments, rates, goals, params = [], [], [], []
    start = 0
    for job in group:
        run = runs[str(job.run_dir)]
        if run.critic is None or next(run.critic.parameters()).device != dev:
            critic, defaults = build_test_critic(run.ckpt, policy.norm)
            run.critic = critic.to(dev).requires_grad_(False)
            alpha = defaults.get("alpha")
            if not (isinstance(alpha, (int, float)) and alpha > 0):
                raise UserError(f"{job.run_dir}: the run stores no usable policy learning rate")
            run.alpha = float(alpha)
        assert run.alpha is not None  # set with the critic above
        n = job.G * inits
        segments.append((run.critic, start, start + n))
        rates.append(torch.full((n,), run.alpha * float(job.alpha_scale)))
        goals.append(job.goals.to(torch.float32).repeat_interleave(inits, dim=0))
        if job.G not in inits_cache:
            gen = torch.Generator().manual_seed(int(seed))
            inits_cache[job.G] = policy.init(n, generator=gen, device="cpu")
        params.append(inits_cache[job.G])
        start += n
    goal = torch.cat(goals).to(dev)
    p = {k: torch.cat([x[k] for x in params]).to(dev).requires_grad_(True) for k in params[0]}
    return MultiCritic(segments), torch.cat(rates).to(dev), goal, p


def relpath(p, base: Path) -> str:
    try:
        return str(Path(p).resolve().relative_to(Path(base).resolve()))
    except ValueError:
        return str(p)
