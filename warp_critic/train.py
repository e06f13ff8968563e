"""Training loop: model-based meta-learning of the critic (the paper's Algorithm 2).

Reads top to bottom: set up scene, worlds and networks -> (resume) -> for each outer iteration:
fresh policies, inner update with the critic, rollout of the updated policies through the
differentiable Newton model, critic update -> metrics, checkpoints and recording through callbacks.

Run directory layout (shared with the baselines so ``warp-critic meta-test RUN_DIR`` works on all):
``config.json``, ``checkpoint.pt`` (atomic), ``metrics.jsonl``, ``recording.rrd``.
"""

from __future__ import annotations

import json
import math
import random
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from .config import TrainConfig, atomic_write_text
from .errors import DivergenceError, UserError
from .networks import Critic, MLPPolicy, Normalizer, POLICY_INIT_SCHEMES, detach_params, init_policy
from .outer import OuterResult, meta_loss
from .scene import Scene, Variant, load_scene
from .simulator import Simulator

CHECKPOINT_KIND = "warp-critic/checkpoint-v1"


# ------------------------------------------------------------------------------------------------
# shared set-up helpers (also used by meta-test and the baselines)
# ------------------------------------------------------------------------------------------------

def seed_everything(seed: int) -> torch.Generator:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)
    return torch.Generator().manual_seed(seed)


def rng_state(gen: torch.Generator) -> dict:
    """Random-number state to store in a checkpoint (our generator and torch's global one)."""
    return {"rng_state": gen.get_state(), "torch_rng_state": torch.get_rng_state()}


def restore_rng(gen: torch.Generator, ckpt: dict) -> None:
    """Inverse of :func:`rng_state`: a resumed run draws the same numbers as an uninterrupted one."""
    gen.set_state(ckpt["rng_state"])
    torch.set_rng_state(ckpt["torch_rng_state"])


def goals_tensor(goals: list[list[float]], scene: Scene, device, flag: str = "--goals") -> torch.Tensor:
    """Validate goals against the scene (dimension, joint limits) -> ``(G, dof)``."""
    g = torch.tensor(goals, dtype=torch.float32)
    if g.ndim != 2 or g.shape[1] != scene.dof:
        raise UserError(f"{flag}: each goal needs {scene.dof} joint values for {scene.name} (got {list(g.shape)[-1] if g.ndim == 2 else g.shape})")
    lo, hi = torch.as_tensor(scene.q_lower, dtype=torch.float32), torch.as_tensor(scene.q_upper, dtype=torch.float32)
    outside = (g < lo) | (g > hi)
    if bool(outside.any()):
        i, j = (int(x) for x in torch.nonzero(outside)[0])
        raise UserError(f"{flag}: goal {i} joint {j} = {g[i, j]:.3f} is outside the joint limits "
                        f"[{lo[j]:.3f}, {hi[j]:.3f}] of {scene.name}")
    return g.to(device)


def max_torque_tensor(max_torque: list[float], scene: Scene, device) -> torch.Tensor:
    t = torch.tensor(max_torque, dtype=torch.float32)
    if t.numel() == 1:
        t = t.expand(scene.dof).clone()
    if t.numel() != scene.dof:
        raise UserError(f"--max-torque needs 1 or {scene.dof} values for {scene.name} (got {t.numel()})")
    t = torch.minimum(t, torch.as_tensor(scene.effort_limit, dtype=torch.float32))
    return t.to(device)


def atomic_torch_save(obj, path: Path) -> None:
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(obj, tmp)
    tmp.replace(path)


def load_checkpoint(run_dir: str | Path) -> dict:
    """Load ``RUN_DIR/checkpoint.pt`` or raise a one-line :class:`UserError`."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise UserError(f"{run_dir}: run directory not found")
    path = run_dir / "checkpoint.pt"
    if not path.is_file():
        raise UserError(f"{run_dir}: no checkpoint.pt in this run directory")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as e:  # corrupt / not a torch file
        raise UserError(f"{path}: cannot read checkpoint ({type(e).__name__})") from None
    if not isinstance(ckpt, dict) or ckpt.get("kind") != CHECKPOINT_KIND:
        raise UserError(f"{path}: not a warp-critic checkpoint")
    return ckpt


# ------------------------------------------------------------------------------------------------
# the loop
# ------------------------------------------------------------------------------------------------

@dataclass
class IterationInfo:
    iteration: int
    metrics: dict
    result: OuterResult
    goal_index: torch.Tensor  # (W,) goal id of each world


@dataclass
class TrainResult:
    run_dir: Path
    metrics: list[dict] = field(default_factory=list)
    critic: Critic | None = None


Callback = Callable[[IterationInfo], None]


def meta_train(cfg: TrainConfig, callbacks: list[Callback] | None = None, progress: bool = True,
               record: bool = True) -> TrainResult:
    """Run (or resume) meta-training; returns the run directory, metrics and critic.

    ``callbacks`` are called after every iteration with an :class:`IterationInfo`. With ``record``
    the run is recorded to ``RUN_DIR/recording.rrd`` (:class:`warp_critic.recording.TrainingRecorder`;
    a resumed run re-logs its earlier metrics, so the file always covers the whole run).
    """
    cfg.with_scene_defaults()
    cfg.validate()
    scene = load_scene(cfg.scene)
    cfg.validate(scene.dof)
    run_dir = Path(cfg.out)
    ckpt = None
    if cfg.resume:
        ckpt = load_checkpoint(run_dir)
        saved = TrainConfig.from_dict(ckpt["config"])
        if Path(saved.scene).name != Path(cfg.scene).name:
            raise UserError(f"--resume: {run_dir} was trained on {saved.scene}, not {cfg.scene}")
        # a moved or copied run directory records where it now is
        saved.iterations, saved.resume, saved.device, saved.out = cfg.iterations, True, cfg.device, cfg.out
        cfg = saved
    elif (run_dir / "checkpoint.pt").exists():
        raise UserError(f"--out {run_dir}: already holds a run (use --resume to continue it, or another --out)")
    run_dir.mkdir(parents=True, exist_ok=True)

    gen = seed_everything(cfg.seed)
    variant = Variant(ee_mass=cfg.ee_mass, link_length=cfg.link_length, link_scale=cfg.link_scale)
    goals = goals_tensor(cfg.goals, scene, "cpu")
    G, K = goals.shape[0], cfg.worlds_per_goal
    W = G * K
    sim = Simulator(scene, [variant] * W, dt=cfg.dt, substeps=cfg.substeps, device=cfg.device,
                    differentiable=True, gravity=cfg.gravity)
    dev = sim.torch_device
    goal_index = torch.arange(G, device=dev).repeat_interleave(K)
    slot = torch.arange(K, device=dev).repeat(G)  # index of each world among its goal's worlds
    goal = goals.to(dev)[goal_index]  # (W, dof)
    norm = Normalizer.from_limits(sim.q_lower, sim.q_upper, max_torque_tensor(cfg.max_torque, scene, dev), cfg.qd_scale)
    critic = Critic(scene.dof, norm, inputs=cfg.critic_input).to(dev)
    policy = MLPPolicy(norm)
    opt = torch.optim.Adam(critic.parameters(), lr=cfg.lr)

    def lr_at(it: int) -> float:
        if cfg.lr_schedule == "cosine":  # decay to 10% of --lr at the last iteration
            return cfg.lr * (0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * it / max(cfg.iterations - 1, 1))))
        return cfg.lr
    q0, qd0 = sim.zeros(), sim.zeros()
    q_lo, q_hi = 0.95 * sim.q_lower, 0.95 * sim.q_upper

    away = (slot >= cfg.home_starts).float().unsqueeze(1)  # (W, 1): 0 for the worlds kept at home

    def new_start_states() -> torch.Tensor:  # (W, dof) joint positions around home, inside the limits
        noise = torch.randn(W, scene.dof, generator=gen).to(dev) * cfg.start_std * away
        return torch.clamp(noise, q_lo, q_hi)

    def new_policies():
        return init_policy(W, 2 * scene.dof, scene.dof, generator=gen, device=dev)

    params = new_policies()
    start, history = 0, []
    if ckpt is not None:
        critic.load_state_dict(ckpt["critic_state"])
        opt.load_state_dict(ckpt["optimizer_state"])
        restore_rng(gen, ckpt)
        params = {k: v.to(dev) for k, v in ckpt["policy_params"].items()}
        start = ckpt["iteration"] + 1
        history = read_metrics(run_dir / "metrics.jsonl", upto=start)
    cfg.save(run_dir / "config.json")
    callbacks = list(callbacks or [])
    recorder = None
    if record:
        from .recording import TrainingRecorder

        recorder = TrainingRecorder(run_dir / "recording.rrd", sim, goals, history,
                                    record_every=cfg.record_every, last_iteration=cfg.iterations - 1)
        callbacks.append(recorder)

    def save_checkpoint(iteration: int) -> None:
        atomic_torch_save({
            "kind": CHECKPOINT_KIND, "method": "ours", "scene": scene.name, "scene_path": str(cfg.scene),
            "dof": scene.dof, "config": cfg.to_dict(), "iteration": iteration,
            "critic_state": critic.state_dict(), "critic_hidden": critic.net[0].out_features,
            "critic_input": critic.inputs,
            "optimizer_state": opt.state_dict(), **rng_state(gen),
            "policy_params": {k: v.cpu() for k, v in params.items()},
            "metrics": history[-1] if history else {},
        }, run_dir / "checkpoint.pt")

    metrics_file = open_metrics(run_dir / "metrics.jsonl", history)
    bar = Progress(cfg.iterations, enabled=progress)
    try:
        for it in range(start, cfg.iterations):
            t0 = time.perf_counter()
            if cfg.policy_init == "fresh":  # Algorithm 2: new random policies every iteration ...
                fresh = new_policies()
                if cfg.policy_lifetime == 1:
                    params = fresh
                else:  # ... or, staggered, in the worlds whose policy has reached its lifetime
                    reset = (it + slot) % cfg.policy_lifetime == 0  # (W,)
                    params = {k: torch.where(reset.view(-1, *[1] * (v.dim() - 1)), fresh[k], v)
                              for k, v in params.items()}
            if cfg.start_std:
                q0 = new_start_states()
            theta = detach_params(params)
            try:
                res = meta_loss(critic, policy, theta, sim, q0, qd0, goal, horizon=cfg.horizon, alpha=cfg.alpha,
                                inner_steps=cfg.inner_steps, running_weight=cfg.running_weight,
                                velocity_weight=cfg.velocity_weight)
                opt.zero_grad(set_to_none=True)
                res.loss.backward()
                grad_norm = _grad_norm(critic)
                if not (math.isfinite(res.loss.item()) and math.isfinite(grad_norm)):
                    raise DivergenceError("non-finite task loss or critic gradient")
            except DivergenceError as e:
                raise DivergenceError(f"iteration {it}: {e} -- stopped; the last good checkpoint in "
                                      f"{run_dir} is kept", world=e.world, step=e.step) from None
            if cfg.clip_grad:
                torch.nn.utils.clip_grad_norm_(critic.parameters(), cfg.clip_grad)
            for group in opt.param_groups:
                group["lr"] = lr_at(it)
            opt.step()
            if cfg.policy_init == "persistent" or cfg.policy_lifetime > 1:  # lifetime > 1 implies fresh
                params = res.params_new
            before = ((res.before.q[-1] - goal) ** 2).sum(-1)
            per_goal = torch.zeros(G, device=dev).index_add_(0, goal_index, res.per_world) / K
            row = {"iteration": it, "task_loss": res.per_world.mean().item(),
                   "task_loss_before": before.mean().item(),
                   "task_loss_per_goal": per_goal.tolist(), "grad_norm": grad_norm,
                   "seconds": time.perf_counter() - t0}
            history.append(row)
            metrics_file.write(json.dumps(row) + "\n")
            metrics_file.flush()
            info = IterationInfo(it, row, res, goal_index)
            for cb in callbacks:
                cb(info)
            bar.update(it + 1, f"task {row['task_loss']:.4f} (before {row['task_loss_before']:.3f}) {row['seconds']:.2f}s/it")
            if (it + 1) % cfg.checkpoint_every == 0 or it + 1 == cfg.iterations:
                save_checkpoint(it)
    finally:
        metrics_file.close()
        bar.close()
        if recorder is not None:
            recorder.close()
    return TrainResult(run_dir, history, critic)


def _grad_norm(module: torch.nn.Module) -> float:
    total = 0.0
    for p in module.parameters():
        if p.grad is not None:
            total += float(p.grad.detach().pow(2).sum())
    return math.sqrt(total)


def open_metrics(path: Path, history: list[dict]):
    """(Re)write ``metrics.jsonl`` with the rows kept from before a resume; returns the open file."""
    f = open(path, "w")
    for row in history:
        f.write(json.dumps(row) + "\n")
    f.flush()
    return f


def read_metrics(path: Path, upto: int) -> list[dict]:
    """Rows of ``metrics.jsonl`` with ``iteration < upto`` (what a resumed run keeps)."""
    if not path.exists():
        return []
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return [r for r in rows if r["iteration"] < upto]


class Progress:
    """A dependency-free progress bar on stderr."""

    def __init__(self, total: int, enabled: bool = True, width: int = 24):
        import sys

        self.total, self.enabled, self.width, self.out = total, enabled, width, sys.stderr
        self.tty = self.out.isatty()
        self.last = 0.0

    def update(self, n: int, text: str) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if self.tty or n == self.total or now - self.last > 5.0:
            filled = int(self.width * n / max(self.total, 1))
            line = f"[{'#' * filled}{'.' * (self.width - filled)}] {n}/{self.total} {text}"
            self.out.write(("\r" + line) if self.tty else line + "\n")
            self.out.flush()
            self.last = now

    def close(self) -> None:
        if self.enabled and self.tty:
            self.out.write("\n")
