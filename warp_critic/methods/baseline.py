"""The baselines' protocol: the :class:`Agent` a baseline implements (its networks, its exploration
and its one gradient update) and :func:`train_baseline`, which runs every baseline (DDPG,
Meta-Critic, TD3: any entry of the method registry with ``baseline=True``); their shared config
is :class:`~warp_critic.methods.baseline_config.BaselineConfig` (each method may subclass it),
meta-test's ``alpha`` search is
:mod:`warp_critic.methods.alpha_search`, and everything around the step (run directory, resume, metrics, recording, checkpoints) is the shared harness
:class:`warp_critic.running.loop.Session`, the same as ours.

Protocol (the paper's section 5, same as our meta-training so that ``warp-critic meta-test RUN_DIR``
compares like with like):

* the same scenes, training goals, horizon, ``dt``, ``substeps``, ``max_torque``, ``qd_scale`` and
  gravity and training distribution (start states, home starts, dynamics variant): the shared fields of
  :class:`~warp_critic.running.task.TaskConfig` (``None`` = the scene's defaults);
* goal-conditioned as in the paper ("the state becomes ``s - g``"): actor and Q see
  ``x = [(q - g) / q_half_range, qd / qd_scale]`` (the scene :class:`~warp_critic.learning.networks.Normalizer`
  scales) and the action ``tau / max_torque``;
* experience comes from ``W = goals x worlds_per_goal`` Newton worlds stepped in parallel by ONE
  forward-only :class:`~warp_critic.physics.simulator.Simulator` (``differentiable=False``; no model
  gradient is ever used by a baseline). Every iteration is one episode per world from
  the task's start states (as in meta-training), ``horizon`` control steps with the agent's
  exploration (:meth:`Agent.explore`: DDPG's actor plus noise, or a
  stochastic policy's sample); the
  ``W * horizon`` transitions go to the replay buffer, then ``updates_per_iteration`` gradient
  updates follow (default: ``horizon``, i.e. one update per control step of the batch of worlds),
  then a noise-free evaluation rollout of the actor gives ``task_loss`` = mean ``||q_T - g||^2``
  (``task_loss_explore``: the same for the noisy episodes).
* warm-up (``warmup_iterations``, default 5): the first iterations explore with uniformly random
  torques in ``+-max_torque`` and update only Q (as Spinning Up's ``start_steps`` / TD3's
  ``start_timesteps``). Without it the actor follows ``dQ/da`` of a Q fitted to a few episodes near
  the start state and saturates its torques within a few iterations; ``0`` gives Lillicrap et al.'s
  original schedule.

Reward (documented choice, field ``reward``):

* ``dense`` (default): ``r_t = -||q_{t+1} - g||^2`` (rad^2) for every step. The episode end is a
  time limit, not a terminal state (the state carries no time), so the TD target bootstraps at
  the last step too: ``y = r + gamma Q'(s', mu'(s'))`` everywhere.
* ``sparse``: ``r_t = 0`` except ``r_{T-1} = -||q_T - g||^2``; the last step is terminal
  (``done = 1``, no bootstrap) -- the paper's task loss as a reward.

``reward_scale`` multiplies the reward (default 1).

Meta-test (the paper: "we use the critics (q-functions) that were trained during meta-train"):
:func:`test_critic_from_checkpoint` returns ``L(q, qd, tau, g) = -Q(s - g, a)``, which fresh
policies DESCEND with ``inner_steps`` plain gradient steps of size ``alpha``. A Q function has no
natural scale for such a step (our critic learns its scale jointly with ``alpha``), so unless
the config's ``metatest_alpha`` is given, ``alpha`` is SELECTED at every checkpoint by a grid search
(half-decades ``1e-6 .. 1``) on the training goals with exactly the meta-test protocol (fresh
policies, zero initial state, ``inner_steps`` updates, final squared error); the chosen value is
stored in the checkpoint (``selected_alpha``) and meta-test's ``alpha`` still overrides it. The error of that
search (``fresh_policy_loss``) is the baseline's analogue of our ``task_loss`` and is logged at
checkpoint iterations.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import torch

from warp_critic.core.errors import DivergenceError
from warp_critic.learning.losses import final_error
from warp_critic.learning.networks import Normalizer
from warp_critic.learning.rollout import Trajectory, rollout
from warp_critic.methods.alpha_search import ALPHA_GRID, fresh_policy_errors
from warp_critic.methods.baseline_config import BaselineConfig
from warp_critic.methods.replay import ReplayBuffer, rewards
from warp_critic.running.config import filled
from warp_critic.running.loop import Callback, Session, TrainResult
from warp_critic.running.task import Task

if TYPE_CHECKING:  # a type only: importing it loads Newton (seconds)
    from warp_critic.physics.simulator import Simulator


class Agent(Protocol):
    """What :func:`train_baseline` needs of a baseline: one seed's networks, optimisers and update.

    All tensors are per world: ``q, qd, g`` ``(W, dof)`` [rad, rad/s, rad], torques ``(W, dof)`` [N m].
    """

    @property
    def actor(self) -> torch.nn.Module:
        """The deterministic policy ``(q, qd, g) -> tau`` of the noise-free evaluation rollouts."""
        ...

    @property
    def q(self) -> torch.nn.Module:
        """The critic ``(q, qd, tau, g) -> (W,)`` that meta-test's fresh policies ascend (``L = -Q``):
        saved as the checkpoint's ``q_state``, and what the ``alpha`` grid search runs with."""
        ...

    def begin_episode(self, worlds: int, gen: torch.Generator) -> None:
        """Before every exploration episode of ``worlds`` worlds (e.g. reset an OU process)."""

    def explore(
        self, q: torch.Tensor, qd: torch.Tensor, g: torch.Tensor, gen: torch.Generator
    ) -> torch.Tensor:
        """The exploration torques ``(W, dof)`` in ``+-max_torque``, drawing from ``gen`` only."""
        ...

    def update(
        self, buffer: ReplayBuffer, gen: torch.Generator, train_actor: bool = True
    ) -> dict[str, float]:
        """One gradient update from ``buffer`` (``train_actor`` False: warming up, no actor step)."""
        ...

    def state_dict(self) -> dict: ...

    def load_state_dict(self, state: dict) -> None: ...


@dataclass
class BaselineStepResult:
    """What the recorder reads: the exploration rollout and the noise-free rollout after the updates."""

    before: Trajectory | None
    after: Trajectory | None
    params_new: Any = None


AgentFactory = Callable[[BaselineConfig, int, Normalizer, Any], Agent]


def train_baseline(
    cfg: BaselineConfig,
    make_agent: AgentFactory,
    *,
    callbacks: list[Callback] | None = None,
    progress: bool = True,
    record: bool = True,
    given: set[str] | None = None,
) -> TrainResult:
    """Run (or resume) a baseline; returns the run directory, metrics and agent (``result.model``).

    ``make_agent(cfg, dof, norm, device)`` returns an :class:`Agent`. With ``cfg.seeds`` the seeds'
    episodes run in one simulator (one agent and replay buffer per seed, each drawing from its own
    seed's generator), and each seed writes the run directory a single-seed run would.
    """
    with Session(
        cfg, differentiable=False, given=given, require=("agent_state", "buffer", "selected_alpha")
    ) as session:
        run = _BaselineRun(session, make_agent)  # set-up, then the checkpoint's states (resume)
        result = session.run(
            run.step,
            run.state,
            callbacks=callbacks,
            progress=progress,
            record=record,
            describe=_describe,
        )
    for i, res in enumerate(result.seeds):
        res.model = run.agents[i]
    return result


class _BaselineRun:
    """One baseline run's per-seed agents, replay buffers and generators, and its iteration."""

    def __init__(self, session: Session, make_agent: AgentFactory):
        cfg, task = session.cfg, session.task  # the scene's defaults filled in
        assert isinstance(cfg, BaselineConfig)
        self.cfg, self.task, self.session = cfg, task, session
        self.horizon = filled(cfg.horizon, "horizon")
        self.gens: list[torch.Generator] = []
        self.agents: list[Agent] = []
        self.buffers: list[ReplayBuffer] = []
        capacity = min(cfg.buffer_size, cfg.iterations * task.Wc * self.horizon)
        for i in range(task.S):  # each seed's draws in the order of a single-seed run
            self.gens.append(session.seed(i))
            self.agents.append(make_agent(cfg, task.scene.dof, task.norm, task.device))
            self.buffers.append(ReplayBuffer(capacity, task.scene.dof, task.device))
            session.seeded(i)
        self.alphas = [cfg.metatest_alpha] * task.S
        for i in range(task.S):
            ckpt = session.restore(i)
            if ckpt is not None:
                with session.loading(i):
                    self.agents[i].load_state_dict(ckpt["agent_state"])
                    self.buffers[i].load_state_dict(ckpt["buffer"])
                    self.alphas[i] = (
                        float(ckpt["selected_alpha"])
                        if cfg.metatest_alpha is None
                        else cfg.metatest_alpha
                    )
        self.q0, self.qd0 = task.home, torch.zeros_like(task.home)
        self.eval_sim = _one_seed_simulator(cfg, task)

    # -- one iteration ------------------------------------------------------------------------------
    def step(self, it: int) -> tuple[list[dict], BaselineStepResult]:
        """One episode in every world with exploration, the gradient updates from each seed's replay
        buffer, then a noise-free evaluation episode; one metrics row per seed."""
        cfg, task = self.cfg, self.task
        if cfg.start_std:
            self.q0 = torch.cat([task.start_states(g, i) for i, g in enumerate(self.gens)])
        warmup = it < cfg.warmup_iterations
        explore_traj = self.explore(warmup)
        r, done = rewards(explore_traj, task.goal, cfg.reward, cfg.reward_scale)
        rows: list[dict[str, Any]] = []
        for i in range(task.S):
            sl = task.copy(i)
            part = Trajectory(
                explore_traj.q[:, sl], explore_traj.qd[:, sl], explore_traj.tau[:, sl]
            )
            self.buffers[i].add_trajectory(part, task.goal[sl], r[:, sl], done[:, sl])
            rows.append(self.train(i, warmup))
        with torch.no_grad():
            eval_traj = rollout(
                task.sim,
                self.per_seed(lambda i, q, qd, g: self.agents[i].actor(q, qd, g)),
                self.q0,
                self.qd0,
                self.horizon,
            )
        per_world = final_error(eval_traj.q[-1], task.goal)
        explore_err = final_error(explore_traj.q[-1], task.goal)
        for i, stats in enumerate(rows):
            sl = task.copy(i)
            row: dict[str, Any] = {
                "task_loss": per_world[sl].mean().item(),
                "task_loss_per_goal": task.per_goal(per_world[sl]).tolist(),
                "task_loss_explore": explore_err[sl].mean().item(),
                "return_explore": r[:, sl].sum(0).mean().item(),
                "buffer_size": self.buffers[i].size,
                **stats,
            }
            if (it + 1) % cfg.checkpoint_every == 0 or it + 1 == cfg.iterations:
                self.alphas[i], fresh_loss, search = self.select_alpha(i)
                row.update({"alpha": self.alphas[i], "fresh_policy_loss": fresh_loss})
                row["alpha_search"] = search
            rows[i] = row
        return rows, BaselineStepResult(explore_traj, eval_traj)

    def explore(self, warmup: bool) -> Trajectory:
        """One episode in every world (forward-only simulator): each agent's :meth:`Agent.explore`,
        or in the warm-up uniformly random torques in ``+-max_torque``."""
        norm = self.task.norm
        for i, agent in enumerate(self.agents):
            agent.begin_episode(self.task.Wc, self.gens[i])

        def act(i: int, q: torch.Tensor, qd: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
            if warmup:  # uniform in [-max_torque, max_torque]
                u = torch.rand(q.shape, generator=self.gens[i]).to(q.device) * 2 - 1
                return u * norm.max_torque
            return self.agents[i].explore(q, qd, g, self.gens[i])

        with torch.no_grad():
            return rollout(self.task.sim, self.per_seed(act), self.q0, self.qd0, self.horizon)

    def train(self, i: int, warmup: bool) -> dict[str, float]:
        """Seed ``i``'s gradient updates from its replay buffer: the mean of each reported value."""
        cfg, n_updates = self.cfg, self.cfg.n_updates()
        stats: dict[str, float] = {}
        counts: dict[str, int] = {}
        if self.buffers[i].size >= cfg.batch_size:
            for _ in range(n_updates):
                out = self.agents[i].update(self.buffers[i], self.gens[i], train_actor=not warmup)
                for k, v in out.items():
                    stats[k] = stats.get(k, 0.0) + v / n_updates
                    counts[k] = counts.get(k, 0) + 1
        for k, c in counts.items():  # a value some updates report (TD3's delayed actor)
            if c < n_updates:  # is the mean over those updates
                stats[k] *= n_updates / c
        if not all(math.isfinite(v) for v in stats.values()):
            raise DivergenceError(
                "non-finite loss: " + ", ".join(f"{k} {v}" for k, v in stats.items())
            )
        return stats

    def per_seed(self, fn: Callable[..., torch.Tensor]) -> Callable[..., torch.Tensor]:
        """A rollout policy over all worlds from one function per seed ``fn(i, q, qd, goal)``."""
        task = self.task
        if task.S == 1:
            return lambda q, qd: fn(0, q, qd, task.goal)
        return lambda q, qd: torch.cat(
            [
                fn(i, q[task.copy(i)], qd[task.copy(i)], task.goal[task.copy(i)])
                for i in range(task.S)
            ]
        )

    def select_alpha(self, i: int) -> tuple[float, float, dict]:
        """Meta-test's step size for seed ``i``'s critic: the given one, or the grid's best."""
        cfg, task = self.cfg, self.task
        grid = [cfg.metatest_alpha] if cfg.metatest_alpha is not None else list(ALPHA_GRID)
        sl = task.copy(i)
        errs = fresh_policy_errors(
            self.agents[i].q,
            task.norm,
            self.eval_sim,
            task.goal[sl],
            self.horizon,
            filled(cfg.inner_steps, "inner_steps"),
            grid,
            self.session.runs[i].cfg.seed + 1,
            q0=task.home[sl],
        )
        best = min(range(len(grid)), key=lambda k: errs[k])
        return grid[best], errs[best], {f"{a:.3g}": e for a, e in zip(grid, errs)}

    # -- checkpoints --------------------------------------------------------------------------------
    def state(self, i: int) -> dict:
        a = self.agents[i]
        return {
            "critic_hidden": self.cfg.critic_hidden,
            "actor_hidden": self.cfg.actor_hidden,
            "q_state": a.q.state_dict(),
            "actor_state": a.actor.state_dict(),
            "agent_state": a.state_dict(),
            "buffer": self.buffers[i].state_dict(),
            "selected_alpha": self.alphas[i],
        }


def _one_seed_simulator(cfg: BaselineConfig, task: Task) -> Simulator:
    """The alpha search runs one seed's worlds at a time (as in a single-seed run)."""
    from warp_critic.physics.simulator import Simulator

    if task.S == 1:
        return task.sim
    return Simulator(
        task.scene,
        task.sim.variants[: task.Wc],
        dt=filled(cfg.dt, "dt"),
        substeps=filled(cfg.substeps, "substeps"),
        device=cfg.device,
        differentiable=False,
        gravity=filled(cfg.gravity, "gravity"),
    )


def _describe(row: dict) -> str:
    extra = (
        f" | fresh policies {row['fresh_policy_loss']:.4f} (alpha {row['alpha']:.2g})"
        if "fresh_policy_loss" in row
        else ""
    )
    return f"task {row['task_loss']:.4f} (explore {row['task_loss_explore']:.3f}){extra}"
