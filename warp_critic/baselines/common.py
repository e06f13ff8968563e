"""Shared parts of the baselines (DDPG, Meta-Critic): config, networks, replay buffer, exploration
noise, rewards, the training loop, checkpoints, and the Q critic used at meta-test.

Protocol (the paper's section 5, same as our meta-training so that ``warp-critic meta-test RUN_DIR``
compares like with like):

* the same scenes, training goals, horizon, ``dt``, ``substeps``, ``max_torque``, ``qd_scale`` and
  gravity (``None`` flags = the scene's :data:`~warp_critic.config.SCENE_DEFAULTS`);
* goal-conditioned as in the paper ("the state becomes ``s - g``"): actor and Q see
  ``x = [(q - g) / q_half_range, qd / qd_scale]`` (the scene :class:`~warp_critic.networks.Normalizer`
  scales) and the action ``tau / max_torque``;
* experience comes from ``W = goals x worlds_per_goal`` Newton worlds stepped in parallel by ONE
  forward-only :class:`~warp_critic.simulator.Simulator` (``differentiable=False``; no model
  gradient is ever used by a baseline). Every iteration is one episode per world from
  ``q = qd = 0`` (as in meta-training), ``horizon`` control steps with exploration noise; the
  ``W * horizon`` transitions go to the replay buffer, then ``updates_per_iteration`` gradient
  updates follow (default: ``horizon``, i.e. one update per control step of the batch of worlds),
  then a noise-free evaluation rollout of the actor gives ``task_loss`` = mean ``||q_T - g||^2``
  (``task_loss_explore``: the same for the noisy episodes).
* warm-up (``--warmup-iterations``, default 5): the first iterations explore with uniformly random
  torques in ``+-max_torque`` and update only Q (as Spinning Up's ``start_steps`` / TD3's
  ``start_timesteps``). Without it the actor follows ``dQ/da`` of a Q fitted to a few episodes near
  the start state and saturates its torques within a few iterations; ``0`` gives Lillicrap et al.'s
  original schedule.

Reward (documented choice, flag ``--reward``):

* ``dense`` (default): ``r_t = -||q_{t+1} - g||^2`` (rad^2) for every step. The episode end is a
  time limit, not a terminal state (the state carries no time), so the TD target bootstraps at
  the last step too: ``y = r + gamma Q'(s', mu'(s'))`` everywhere.
* ``sparse``: ``r_t = 0`` except ``r_{T-1} = -||q_T - g||^2``; the last step is terminal
  (``done = 1``, no bootstrap) -- the paper's task loss as a reward.

``--reward-scale`` multiplies the reward (default 1).

Meta-test (the paper: "we use the critics (q-functions) that were trained during meta-train"):
:func:`test_critic_from_checkpoint` returns ``L(q, qd, tau, g) = -Q(s - g, a)``, which fresh
policies DESCEND with ``inner_steps`` plain gradient steps of size ``alpha``. A Q function has no
natural scale for such a step (our critic learns its scale jointly with ``alpha``), so unless
``--alpha`` is given, ``alpha`` is SELECTED at every checkpoint by a grid search (half-decades
``1e-6 .. 1``) on the training goals with exactly the meta-test protocol (fresh policies, zero
initial state, ``inner_steps`` updates, final squared error); the chosen value is stored in the
checkpoint's ``config`` (``alpha``) and ``meta-test --alpha`` still overrides it. The error of that
search (``fresh_policy_loss``) is the baseline's analogue of our ``task_loss`` and is logged at
checkpoint iterations.
"""

from __future__ import annotations

import copy
import inspect
import json
import math
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Callable

import torch
from torch import nn

from ..config import FALLBACK_DEFAULTS, SCENE_DEFAULTS, SerializableConfig, TrainConfig, atomic_write_text
from ..errors import DivergenceError, UserError
from ..losses import critic_loss, final_error
from ..networks import MLPPolicy, Normalizer, init_policy
from ..inner import inner_update, policy_fn
from ..rollout import Trajectory, rollout
from ..scene import Variant, load_scene
from ..simulator import Simulator
from .networks import METHODS, Actor, NegQ, QNetwork, _GoalInput, soft_update, test_critic_from_checkpoint  # noqa: F401
from .replay import NOISE_KINDS, REWARD_KINDS, ExplorationNoise, ReplayBuffer, rewards  # noqa: F401
from ..train import (CHECKPOINT_KIND, Progress, atomic_torch_save, goals_tensor, open_metrics, read_metrics,
                     load_checkpoint, max_torque_tensor, restore_rng, rng_state, seed_everything)

ALPHA_GRID = tuple(10.0 ** (k / 2) for k in range(-12, 1))  # 1e-6, 3.2e-6, ..., 0.32, 1


# ------------------------------------------------------------------------------------------------
# configuration
# ------------------------------------------------------------------------------------------------

@dataclass
class BaselineConfig(SerializableConfig):
    """DDPG / Meta-Critic training. ``None`` = the scene's default (as for meta-train).

    Defaults follow the published DDPG settings (Lillicrap et al. 2015): Adam with actor lr 1e-4 and
    critic lr 1e-3, gamma 0.99, minibatch 64, replay buffer 1e6, Ornstein-Uhlenbeck exploration
    noise (theta 0.15, sigma 0.2), final layers initialised in +-3e-3. Two documented deviations:
    tau = 5e-3 (TD3-era DDPG implementations; 1e-3 lags too far behind in runs of a few thousand
    updates) and no L2 weight decay on Q by default (``--critic-weight-decay 1e-2`` restores it);
    plus a 5-iteration random-action warm-up (``--warmup-iterations 0`` disables it).
    Meta-Critic settings follow Zhou et al. 2020's code: meta-critic lr 1e-3, weight decay 1e-4,
    2 x 100 hidden units, virtual step size = the actor lr.
    """

    scene: str = field(default="scenes/kuka.usda", metadata={"help": "USD scene file"})
    method: str = field(default="ddpg", metadata={"help": "ddpg or meta-critic"})
    goals: list[list[float]] | None = field(default=None, metadata={"help": "training goals in joint space: inline '0.1,0.2;0.3,0.4' or a .json/.txt file (one goal per line)"})
    iterations: int = field(default=300, metadata={"help": "training iterations (one episode in every world, then the gradient updates)"})
    horizon: int | None = field(default=None, metadata={"help": "control steps per episode"})
    dt: float | None = field(default=None, metadata={"help": "physics time step (s)"})
    substeps: int | None = field(default=None, metadata={"help": "physics steps per control step"})
    worlds_per_goal: int = field(default=4, metadata={"help": "parallel worlds (episodes) per goal and iteration"})
    max_torque: list[float] | None = field(default=None, metadata={"help": "per-joint torque bound of the actor (N·m), comma-separated or one value"})
    qd_scale: float | None = field(default=None, metadata={"help": "velocity normalisation (rad/s)"})
    gravity: float | None = field(default=None, metadata={"help": "gravity along -z (m/s^2); 0 = a perfectly gravity-compensated robot (as meta-train's scene default)"})
    # -- DDPG ------------------------------------------------------------------------------------
    actor_lr: float = field(default=1e-4, metadata={"help": "actor learning rate (Adam)"})
    critic_lr: float = field(default=1e-3, metadata={"help": "Q learning rate (Adam)"})
    critic_weight_decay: float = field(default=0.0, metadata={"help": "L2 weight decay on Q (Lillicrap et al.: 1e-2)"})
    tau: float = field(default=5e-3, metadata={"help": "soft target update rate, in (0, 1] (Lillicrap et al.: 1e-3)"})
    gamma: float = field(default=0.99, metadata={"help": "discount factor, in (0, 1]"})
    batch_size: int = field(default=64, metadata={"help": "minibatch size"})
    buffer_size: int = field(default=1_000_000, metadata={"help": "replay buffer capacity (transitions)"})
    warmup_iterations: int = field(default=5, metadata={"help": "first iterations explore with uniformly random torques and train only Q (the actor starts once Q has seen varied actions; 0 = Lillicrap et al.)"})
    updates_per_iteration: int | None = field(default=None, metadata={"help": "gradient updates per iteration (default: the horizon)"})
    noise: str = field(default="ou", metadata={"help": "exploration noise: ou (Ornstein-Uhlenbeck) or gaussian"})
    noise_std: float = field(default=0.2, metadata={"help": "noise scale (OU sigma or Gaussian std) as a fraction of max_torque"})
    ou_theta: float = field(default=0.15, metadata={"help": "OU mean reversion per control step"})
    reward: str = field(default="dense", metadata={"help": "dense: r_t = -||q_{t+1}-g||^2 every step; sparse: only -||q_T-g||^2 at the end"})
    reward_scale: float = field(default=1.0, metadata={"help": "multiply the reward by this"})
    actor_hidden: int = field(default=64, metadata={"help": "actor hidden units (2 tanh layers)"})
    critic_hidden: int = field(default=400, metadata={"help": "Q hidden units (2 ELU layers)"})
    # -- Meta-Critic -----------------------------------------------------------------------------
    aux_lr: float = field(default=1e-3, metadata={"help": "meta-critic only: learning rate of the auxiliary loss h_omega (Adam)"})
    aux_weight_decay: float = field(default=1e-4, metadata={"help": "meta-critic only: weight decay of h_omega"})
    aux_hidden: int = field(default=100, metadata={"help": "meta-critic only: h_omega hidden units (2 ReLU layers)"})
    aux_weight: float = field(default=1.0, metadata={"help": "meta-critic only: weight of the auxiliary loss in the actor update"})
    virtual_lr: float | None = field(default=None, metadata={"help": "meta-critic only: SGD step of the virtual actor updates (default: --actor-lr)"})
    # -- meta-test defaults stored in the checkpoint ---------------------------------------------
    alpha: float | None = field(default=None, metadata={"help": "policy learning rate meta-test uses with -Q (default: grid search on the training goals at every checkpoint)"})
    inner_steps: int = field(default=1, metadata={"help": "meta-test's default number of fresh-policy updates with -Q (as meta-train's inner steps)"})
    # -- run -------------------------------------------------------------------------------------
    seed: int = field(default=0, metadata={"help": "random seed (fixes everything on CPU)"})
    cpu_threads: int = field(default=1, metadata={"help": "torch CPU threads while training (small minibatch updates run fastest on 1; 0 = torch's default)"})
    device: str = field(default="auto", metadata={"help": "cpu, cuda or auto (cuda when present)"})
    out: str | None = field(default=None, metadata={"help": "run directory (default runs/<scene>-<method>)"})
    checkpoint_every: int = field(default=10, metadata={"help": "write a checkpoint every N iterations"})
    record_every: int = field(default=50, metadata={"help": "record rollouts every N iterations"})
    resume: bool = field(default=False, metadata={"help": "continue the run in --out from its last checkpoint"})

    # -- helpers -----------------------------------------------------------------------------
    def scene_name(self) -> str:
        return Path(self.scene).stem

    def with_scene_defaults(self) -> "BaselineConfig":
        d = {**FALLBACK_DEFAULTS, **SCENE_DEFAULTS.get(self.scene_name(), {})}
        for key in ("goals", "horizon", "dt", "substeps", "max_torque", "qd_scale", "gravity"):
            if getattr(self, key) is None:
                setattr(self, key, copy.deepcopy(d.get(key)))
        if self.out is None:
            self.out = f"runs/{self.scene_name()}-{self.method}"
        return self

    def n_updates(self) -> int:
        return self.updates_per_iteration if self.updates_per_iteration is not None else self.horizon

    def validate(self, dof: int | None = None) -> None:
        """Raise a one-line :class:`UserError` naming the flag."""
        if self.method not in METHODS:
            raise UserError(f"method must be one of {', '.join(METHODS)} (got {self.method!r})")
        positive = {"iterations": self.iterations, "horizon": self.horizon, "dt": self.dt,
                    "substeps": self.substeps, "worlds-per-goal": self.worlds_per_goal,
                    "qd-scale": self.qd_scale, "actor-lr": self.actor_lr, "critic-lr": self.critic_lr,
                    "batch-size": self.batch_size, "buffer-size": self.buffer_size,
                    "updates-per-iteration": self.updates_per_iteration,
                    "actor-hidden": self.actor_hidden, "critic-hidden": self.critic_hidden,
                    "aux-lr": self.aux_lr, "aux-hidden": self.aux_hidden, "virtual-lr": self.virtual_lr,
                    "alpha": self.alpha, "inner-steps": self.inner_steps, "reward-scale": self.reward_scale,
                    "checkpoint-every": self.checkpoint_every, "record-every": self.record_every}
        for name, value in positive.items():
            if value is not None and not (_finite(value) and value > 0):
                raise UserError(f"--{name} must be > 0 (got {value})")
        non_negative = {"gravity": 9.81 if self.gravity is None else self.gravity,
                        "cpu-threads": self.cpu_threads, "warmup-iterations": self.warmup_iterations,
                        "critic-weight-decay": self.critic_weight_decay, "noise-std": self.noise_std,
                        "aux-weight-decay": self.aux_weight_decay, "aux-weight": self.aux_weight}
        for name, value in non_negative.items():
            if not (_finite(value) and value >= 0):
                raise UserError(f"--{name} must be >= 0 (got {value})")
        for name, value in (("gamma", self.gamma), ("tau", self.tau)):
            if not (_finite(value) and 0 < value <= 1):
                raise UserError(f"--{name} must be in (0, 1] (got {value})")
        if not (_finite(self.ou_theta) and 0 <= self.ou_theta <= 1):
            raise UserError(f"--ou-theta must be in [0, 1] (got {self.ou_theta})")
        if self.noise not in NOISE_KINDS:
            raise UserError(f"--noise must be ou or gaussian (got {self.noise!r})")
        if self.reward not in REWARD_KINDS:
            raise UserError(f"--reward must be dense or sparse (got {self.reward!r})")
        if self.max_torque is not None and any(not (_finite(t) and t > 0) for t in self.max_torque):
            raise UserError(f"--max-torque must be > 0 (got {self.max_torque})")
        if dof is not None and self.max_torque is not None and len(self.max_torque) not in (1, dof):
            raise UserError(f"--max-torque needs 1 or {dof} values (got {len(self.max_torque)})")


def _finite(x) -> bool:
    try:
        return math.isfinite(float(x))
    except (TypeError, ValueError):
        return False


def _gravity_kwargs(gravity: float | None) -> dict:
    """``gravity=`` for :class:`Simulator` (only passed when the simulator takes it)."""
    if gravity is None:
        return {}
    if "gravity" in inspect.signature(Simulator.__init__).parameters:
        return {"gravity": float(gravity)}
    if gravity != 9.81:
        raise UserError(f"--gravity {gravity}: this simulator has no gravity setting")
    return {}


# ------------------------------------------------------------------------------------------------
# networks (goal-conditioned: they see s - g)
# ------------------------------------------------------------------------------------------------

# ------------------------------------------------------------------------------------------------
# alpha for meta-test
# ------------------------------------------------------------------------------------------------

def fresh_policy_errors(qnet: QNetwork, norm: Normalizer, sim: Simulator, goal: torch.Tensor, horizon: int,
                        steps: int, alphas, seed: int) -> list[float]:
    """Meta-test's protocol on the training worlds, for every ``alpha``: fresh policies (the same
    initialisation for every alpha), ``steps`` descents of ``sum_t -Q``, mean final ``||q_T - g||^2``."""
    neg_q = NegQ(copy.deepcopy(qnet)).requires_grad_(False)
    dof, W = sim.dof, sim.worlds
    dev = sim.torch_device
    q0, qd0 = sim.zeros(), sim.zeros()
    gen = torch.Generator().manual_seed(seed)
    params = {k: v.requires_grad_(True) for k, v in init_policy(W, 2 * dof, dof, generator=gen, device=dev).items()}
    errors = []
    if steps == 1:  # one gradient serves every alpha
        policy = MLPPolicy(norm)
        traj = rollout(sim, policy_fn(policy, params), q0, qd0, horizon)
        loss = critic_loss(neg_q, policy, params, traj, goal).sum()
        grads = torch.autograd.grad(loss, list(params.values()))
    for alpha in alphas:
        try:
            if steps == 1:
                new = {k: (v - alpha * g).detach() for (k, v), g in zip(params.items(), grads)}
            else:
                new, _ = inner_update(neg_q, MLPPolicy(norm), params, sim, q0, qd0, goal, horizon=horizon, alpha=alpha,
                                      steps=steps, create_graph=False)
            after = rollout(sim, policy_fn(MLPPolicy(norm), new), q0, qd0, horizon)
            err = float(final_error(after.q[-1], goal).mean())
        except DivergenceError:
            err = math.inf
        errors.append(err if math.isfinite(err) else math.inf)
    return errors


# ------------------------------------------------------------------------------------------------
# the loop
# ------------------------------------------------------------------------------------------------

@dataclass
class BaselineStepResult:
    """What the recorder reads: the exploration rollout and the noise-free rollout after the updates."""

    before: Trajectory | None
    after: Trajectory | None
    params_new: Any = None


@dataclass
class BaselineIterationInfo:
    iteration: int
    metrics: dict
    result: BaselineStepResult
    goal_index: torch.Tensor  # (W,)


@dataclass
class BaselineResult:
    run_dir: Path
    metrics: list[dict] = field(default_factory=list)
    agent: Any = None
    config: BaselineConfig | None = None


AgentFactory = Callable[[BaselineConfig, int, Normalizer, Any], Any]


def train_baseline(cfg: BaselineConfig, make_agent: AgentFactory, *, callbacks: list | None = None,
                   progress: bool = True, record: bool = True) -> BaselineResult:
    """Run (or resume) a baseline; returns the run directory, metrics and agent.

    ``make_agent(cfg, dof, norm, device)`` returns an agent with ``actor``, ``q``,
    ``update(buffer, gen) -> dict`` (one gradient update), ``state_dict()`` and ``load_state_dict()``.
    Writes ``config.json``, ``checkpoint.pt`` (atomic), ``metrics.jsonl`` and (``record``)
    ``recording.rrd`` to ``cfg.out``. Runs with ``cfg.cpu_threads`` torch threads (restored after).
    """
    threads = torch.get_num_threads()
    if cfg.cpu_threads:
        torch.set_num_threads(cfg.cpu_threads)
    try:
        return _train_baseline(cfg, make_agent, callbacks=callbacks, progress=progress, record=record)
    finally:
        torch.set_num_threads(threads)


def _train_baseline(cfg: BaselineConfig, make_agent: AgentFactory, *, callbacks: list | None,
                    progress: bool, record: bool) -> BaselineResult:
    cfg.with_scene_defaults()
    cfg.validate()
    run_dir = Path(cfg.out)
    ckpt = None
    if cfg.resume:
        ckpt = load_checkpoint(run_dir)
        if ckpt.get("method") != cfg.method:
            raise UserError(f"--resume: {run_dir} holds a {ckpt.get('method')} run, not {cfg.method}")
        saved = BaselineConfig.from_dict(ckpt["baseline_config"])
        if Path(saved.scene).name != Path(cfg.scene).name:
            raise UserError(f"--resume: {run_dir} was trained on {saved.scene}, not {cfg.scene}")
        saved.iterations, saved.resume, saved.device, saved.out = cfg.iterations, True, cfg.device, cfg.out
        cfg = saved
    elif (run_dir / "checkpoint.pt").exists():
        raise UserError(f"--out {run_dir}: already holds a run (use --resume to continue it, or another --out)")
    scene = load_scene(cfg.scene)
    cfg.validate(scene.dof)
    run_dir.mkdir(parents=True, exist_ok=True)

    gen = seed_everything(cfg.seed)
    goals = goals_tensor(cfg.goals, scene, "cpu")
    G, K = goals.shape[0], cfg.worlds_per_goal
    W = G * K
    sim = Simulator(scene, [Variant()] * W, dt=cfg.dt, substeps=cfg.substeps, device=cfg.device,
                    differentiable=False, **_gravity_kwargs(cfg.gravity))
    dev = sim.torch_device
    goal_index = torch.arange(G, device=dev).repeat_interleave(K)
    goal = goals.to(dev)[goal_index]  # (W, dof)
    norm = Normalizer.from_limits(sim.q_lower, sim.q_upper, max_torque_tensor(cfg.max_torque, scene, dev), cfg.qd_scale)
    agent = make_agent(cfg, scene.dof, norm, dev)
    capacity = min(cfg.buffer_size, cfg.iterations * W * cfg.horizon)
    buffer = ReplayBuffer(capacity, scene.dof, dev)
    noise = ExplorationNoise(cfg.noise, cfg.noise_std, cfg.ou_theta, (W, scene.dof), gen, dev)
    q0, qd0 = sim.zeros(), sim.zeros()
    alpha = cfg.alpha
    start, history = 0, []
    if ckpt is not None:
        agent.load_state_dict(ckpt["agent_state"])
        buffer.load_state_dict(ckpt["buffer"])
        restore_rng(gen, ckpt)
        alpha = ckpt["selected_alpha"] if cfg.alpha is None else cfg.alpha
        start = ckpt["iteration"] + 1
        history = read_metrics(run_dir / "metrics.jsonl", upto=start)
    cfg.save(run_dir / "config.json")
    callbacks = list(callbacks or [])
    recorder = None
    if record:
        from ..recording import TrainingRecorder

        recorder = TrainingRecorder(run_dir / "recording.rrd", sim, goals, history, record_every=cfg.record_every,
                                    last_iteration=cfg.iterations - 1, method=cfg.method)
        callbacks.append(recorder)

    def select_alpha() -> tuple[float, float, dict]:
        alphas = [cfg.alpha] if cfg.alpha is not None else list(ALPHA_GRID)
        errs = fresh_policy_errors(agent.q, norm, sim, goal, cfg.horizon, cfg.inner_steps, alphas, cfg.seed + 1)
        best = min(range(len(alphas)), key=lambda i: errs[i])
        return alphas[best], errs[best], {f"{a:.3g}": e for a, e in zip(alphas, errs)}

    def save_checkpoint(iteration: int, alpha: float) -> None:
        # ``config``: what meta-test reads through TrainConfig.from_dict (scene, goals, horizon, dt,
        # substeps, alpha, inner_steps, max_torque, qd_scale, seed, ...) plus the baseline's own flags.
        config = {**TrainConfig.from_dict(cfg.to_dict()).to_dict(), **cfg.to_dict(), "alpha": alpha}
        atomic_torch_save({
            "kind": CHECKPOINT_KIND, "method": cfg.method, "scene": scene.name, "scene_path": str(cfg.scene),
            "dof": scene.dof, "config": config, "baseline_config": cfg.to_dict(), "iteration": iteration,
            "critic_hidden": cfg.critic_hidden, "actor_hidden": cfg.actor_hidden,
            "q_state": agent.q.state_dict(), "actor_state": agent.actor.state_dict(),
            "agent_state": agent.state_dict(), "buffer": buffer.state_dict(),
            **rng_state(gen),
            "selected_alpha": alpha, "metrics": history[-1] if history else {},
        }, run_dir / "checkpoint.pt")

    metrics_file = open_metrics(run_dir / "metrics.jsonl", history)
    bar = Progress(cfg.iterations, enabled=progress)
    n_updates = cfg.n_updates()
    try:
        for it in range(start, cfg.iterations):
            t0 = time.perf_counter()
            try:
                # 1. one episode in every world with exploration noise (forward-only simulator)
                noise.reset()
                actor = agent.actor
                warmup = it < cfg.warmup_iterations

                def explore(q, qd):
                    if warmup:  # uniform in [-max_torque, max_torque]
                        u = torch.rand(q.shape, generator=gen).to(q.device) * 2 - 1
                        return u * norm.max_torque
                    tau = actor(q, qd, goal) + noise.sample() * norm.max_torque
                    return torch.maximum(torch.minimum(tau, norm.max_torque), -norm.max_torque)

                with torch.no_grad():
                    explore_traj = rollout(sim, explore, q0, qd0, cfg.horizon)
                r, done = rewards(explore_traj, goal, cfg.reward, cfg.reward_scale)
                buffer.add_trajectory(explore_traj, goal, r, done)
                # 2. gradient updates from the replay buffer
                stats: dict[str, float] = {}
                if buffer.size >= cfg.batch_size:
                    for _ in range(n_updates):
                        for k, v in agent.update(buffer, gen, train_actor=not warmup).items():
                            stats[k] = stats.get(k, 0.0) + v / n_updates
                if not all(math.isfinite(v) for v in stats.values()):
                    raise DivergenceError("non-finite loss: " + ", ".join(f"{k} {v}" for k, v in stats.items()))
                # 3. noise-free evaluation of the actor
                with torch.no_grad():
                    eval_traj = rollout(sim, lambda q, qd: agent.actor(q, qd, goal), q0, qd0, cfg.horizon)
            except DivergenceError as e:
                raise DivergenceError(f"iteration {it}: {e} -- stopped; the last good checkpoint in "
                                      f"{run_dir} is kept", world=e.world, step=e.step) from None
            per_world = final_error(eval_traj.q[-1], goal)
            explore_err = final_error(explore_traj.q[-1], goal)
            per_goal = torch.zeros(G, device=dev).index_add_(0, goal_index, per_world) / K
            row = {"iteration": it, "task_loss": per_world.mean().item(),
                   "task_loss_per_goal": per_goal.tolist(),
                   "task_loss_explore": explore_err.mean().item(),
                   "return_explore": r.sum(0).mean().item(), "buffer_size": buffer.size, **stats}
            checkpoint_now = (it + 1) % cfg.checkpoint_every == 0 or it + 1 == cfg.iterations
            if checkpoint_now:
                alpha, fresh_loss, search = select_alpha()
                row.update({"alpha": alpha, "fresh_policy_loss": fresh_loss, "alpha_search": search})
            row["seconds"] = time.perf_counter() - t0
            history.append(row)
            metrics_file.write(json.dumps(row) + "\n")
            metrics_file.flush()
            info = BaselineIterationInfo(it, row, BaselineStepResult(explore_traj, eval_traj), goal_index)
            for cb in callbacks:
                cb(info)
            extra = f" | fresh policies {row['fresh_policy_loss']:.4f} (alpha {alpha:.2g})" if checkpoint_now else ""
            bar.update(it + 1, f"task {row['task_loss']:.4f} (explore {row['task_loss_explore']:.3f}) "
                               f"{row['seconds']:.2f}s/it{extra}")
            if checkpoint_now:
                save_checkpoint(it, alpha)
    finally:
        metrics_file.close()
        bar.close()
        if recorder is not None:
            recorder.close()
    return BaselineResult(run_dir, history, agent, cfg)
