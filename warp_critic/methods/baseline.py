"""The baselines' protocol and their one training step (DDPG, Meta-Critic); their config is
:class:`~warp_critic.methods.baseline_config.BaselineConfig`, meta-test's ``alpha`` search is
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
  the task's start states (as in meta-training), ``horizon`` control steps with exploration noise; the
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
``alpha`` is given, ``alpha`` is SELECTED at every checkpoint by a grid search (half-decades
``1e-6 .. 1``) on the training goals with exactly the meta-test protocol (fresh policies, zero
initial state, ``inner_steps`` updates, final squared error); the chosen value is stored in the
checkpoint's ``config`` (``alpha``) and meta-test's ``alpha`` still overrides it. The error of that
search (``fresh_policy_loss``) is the baseline's analogue of our ``task_loss`` and is logged at
checkpoint iterations.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch

from warp_critic.core.errors import DivergenceError
from warp_critic.learning.losses import final_error
from warp_critic.learning.networks import Normalizer
from warp_critic.learning.rollout import Trajectory, rollout
from warp_critic.methods.alpha_search import ALPHA_GRID, fresh_policy_errors
from warp_critic.methods.baseline_config import BaselineConfig
from warp_critic.methods.replay import ExplorationNoise, ReplayBuffer, rewards
from warp_critic.physics.simulator import Simulator
from warp_critic.running.config import filled
from warp_critic.running.loop import Callback, Session, TrainResult


@dataclass
class BaselineStepResult:
    """What the recorder reads: the exploration rollout and the noise-free rollout after the updates."""

    before: Trajectory | None
    after: Trajectory | None
    params_new: Any = None


AgentFactory = Callable[[BaselineConfig, int, Normalizer, Any], Any]


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

    ``make_agent(cfg, dof, norm, device)`` returns an agent with ``actor``, ``q``,
    ``update(buffer, gen, train_actor) -> dict`` (one gradient update), ``state_dict()`` and
    ``load_state_dict()``. With ``cfg.seeds`` the seeds' episodes run in one simulator (one agent,
    replay buffer and noise process per seed, each drawing from its own seed's generator), and each
    seed writes the run directory a single-seed run would.
    """
    with Session(
        cfg, differentiable=False, given=given, require=("agent_state", "buffer", "selected_alpha")
    ) as session:
        filled_cfg, task = session.cfg, session.task  # the scene's defaults filled in
        assert isinstance(filled_cfg, BaselineConfig)
        cfg = filled_cfg
        horizon, inner_steps = (
            filled(cfg.horizon, "horizon"),
            filled(cfg.inner_steps, "inner_steps"),
        )
        S, sim, norm, goal, dof, dev = (
            task.S,
            task.sim,
            task.norm,
            task.goal,
            task.scene.dof,
            task.device,
        )
        gens, agents, buffers, noises = [], [], [], []
        for i in range(S):  # each seed's draws in the order of a single-seed run
            gens.append(session.seed(i))
            agents.append(make_agent(cfg, dof, norm, dev))
            buffers.append(
                ReplayBuffer(min(cfg.buffer_size, cfg.iterations * task.Wc * horizon), dof, dev)
            )
            noises.append(
                ExplorationNoise(
                    cfg.noise, cfg.noise_std, cfg.ou_theta, (task.Wc, dof), gens[-1], dev
                )
            )
            session.seeded(i)
        alphas = [cfg.alpha] * S
        for i in range(S):
            ckpt = session.restore(i)
            if ckpt is not None:
                with session.loading(i):
                    agents[i].load_state_dict(ckpt["agent_state"])
                    buffers[i].load_state_dict(ckpt["buffer"])
                    alphas[i] = float(ckpt["selected_alpha"]) if cfg.alpha is None else cfg.alpha
        q0, qd0 = task.home, torch.zeros_like(task.home)
        n_updates = cfg.n_updates()
        # the alpha search runs one seed's worlds at a time (as in a single-seed run)
        eval_sim = (
            sim
            if S == 1
            else Simulator(
                task.scene,
                sim.variants[: task.Wc],
                dt=filled(cfg.dt, "dt"),
                substeps=filled(cfg.substeps, "substeps"),
                device=cfg.device,
                differentiable=False,
                gravity=filled(cfg.gravity, "gravity"),
            )
        )

        def select_alpha(i: int) -> tuple[float, float, dict]:
            grid = [cfg.alpha] if cfg.alpha is not None else list(ALPHA_GRID)
            sl = task.copy(i)
            errs = fresh_policy_errors(
                agents[i].q,
                norm,
                eval_sim,
                goal[sl],
                horizon,
                inner_steps,
                grid,
                session.runs[i].cfg.seed + 1,
                q0=task.home[sl],
            )
            best = min(range(len(grid)), key=lambda k: errs[k])
            return grid[best], errs[best], {f"{a:.3g}": e for a, e in zip(grid, errs)}

        def per_seed(fn):
            """A rollout policy over all worlds from one function per seed ``fn(i, q, qd, goal)``."""
            if S == 1:
                return lambda q, qd: fn(0, q, qd, goal)
            return lambda q, qd: torch.cat(
                [fn(i, q[task.copy(i)], qd[task.copy(i)], goal[task.copy(i)]) for i in range(S)]
            )

        def step(it: int):
            nonlocal q0
            if cfg.start_std:
                q0 = torch.cat([task.start_states(g, i) for i, g in enumerate(gens)])
            # 1. one episode in every world with exploration noise (forward-only simulator)
            for n in noises:
                n.reset()
            warmup = it < cfg.warmup_iterations

            def explore(i, q, qd, g):
                if warmup:  # uniform in [-max_torque, max_torque]
                    u = torch.rand(q.shape, generator=gens[i]).to(q.device) * 2 - 1
                    return u * norm.max_torque
                tau = agents[i].actor(q, qd, g) + noises[i].sample() * norm.max_torque
                return torch.maximum(torch.minimum(tau, norm.max_torque), -norm.max_torque)

            with torch.no_grad():
                explore_traj = rollout(sim, per_seed(explore), q0, qd0, horizon)
            r, done = rewards(explore_traj, goal, cfg.reward, cfg.reward_scale)
            rows: list[dict[str, Any]] = []
            for i in range(S):
                sl = task.copy(i)
                part = Trajectory(
                    explore_traj.q[:, sl], explore_traj.qd[:, sl], explore_traj.tau[:, sl]
                )
                buffers[i].add_trajectory(part, goal[sl], r[:, sl], done[:, sl])
                # 2. gradient updates from the replay buffer
                stats: dict[str, float] = {}
                counts: dict[str, int] = {}
                if buffers[i].size >= cfg.batch_size:
                    for _ in range(n_updates):
                        for k, v in (
                            agents[i].update(buffers[i], gens[i], train_actor=not warmup).items()
                        ):
                            stats[k] = stats.get(k, 0.0) + v / n_updates
                            counts[k] = counts.get(k, 0) + 1
                for k, c in counts.items():  # a value some updates report (TD3's delayed actor)
                    if c < n_updates:  # is the mean over those updates
                        stats[k] *= n_updates / c
                if not all(math.isfinite(v) for v in stats.values()):
                    raise DivergenceError(
                        "non-finite loss: " + ", ".join(f"{k} {v}" for k, v in stats.items())
                    )
                rows.append(stats)
            # 3. noise-free evaluation of the actors
            with torch.no_grad():
                eval_traj = rollout(
                    sim,
                    per_seed(lambda i, q, qd, g: agents[i].actor(q, qd, g)),
                    q0,
                    qd0,
                    horizon,
                )
            per_world = final_error(eval_traj.q[-1], goal)
            explore_err = final_error(explore_traj.q[-1], goal)
            for i, stats in enumerate(rows):
                sl = task.copy(i)
                row: dict[str, Any] = {
                    "task_loss": per_world[sl].mean().item(),
                    "task_loss_per_goal": task.per_goal(per_world[sl]).tolist(),
                    "task_loss_explore": explore_err[sl].mean().item(),
                    "return_explore": r[:, sl].sum(0).mean().item(),
                    "buffer_size": buffers[i].size,
                    **stats,
                }
                if (it + 1) % cfg.checkpoint_every == 0 or it + 1 == cfg.iterations:
                    alphas[i], fresh_loss, search = select_alpha(i)
                    row.update(
                        {
                            "alpha": alphas[i],
                            "fresh_policy_loss": fresh_loss,
                            "alpha_search": search,
                        }
                    )
                rows[i] = row
            return rows, BaselineStepResult(explore_traj, eval_traj)

        def state(i: int) -> dict:
            a = agents[i]
            return {
                "critic_hidden": cfg.critic_hidden,
                "actor_hidden": cfg.actor_hidden,
                "q_state": a.q.state_dict(),
                "actor_state": a.actor.state_dict(),
                "agent_state": a.state_dict(),
                "buffer": buffers[i].state_dict(),
                "selected_alpha": alphas[i],
            }

        def describe(row: dict) -> str:
            extra = (
                f" | fresh policies {row['fresh_policy_loss']:.4f} (alpha {row['alpha']:.2g})"
                if "fresh_policy_loss" in row
                else ""
            )
            return f"task {row['task_loss']:.4f} (explore {row['task_loss_explore']:.3f}){extra}"

        result = session.run(
            step, state, callbacks=callbacks, progress=progress, record=record, describe=describe
        )
    for i, res in enumerate(result.seeds):
        res.model = agents[i]
    return result
