"""Training the two learned critics of the landscape analysis on the point mass (section 4.2).

* ``L_critic`` (ours, Algorithm 2) through the package's :func:`warp_critic.learning.outer.meta_loss` (inner step
  :func:`warp_critic.learning.inner.inner_update` with the constant-force policy);
* ``Q_sup`` (Algorithm 1): TD learning on a :class:`~warp_critic.methods.replay.ReplayBuffer` with
  :func:`warp_critic.learning.losses.td_loss`, the policy moved by the gradient of ``sum_t Q_sup``.

Both return the critic as a loss module ``C(q, qd, a, g)`` (goal-relative ones wrapped in
:class:`~warp_critic.analysis.landscape.problem.GoalRelative`). Details: ``docs/landscape.md``.
"""

from __future__ import annotations

import numpy as np
import torch

from warp_critic.analysis.landscape.problem import GoalRelative, constant_force
from warp_critic.core.errors import DivergenceError
from warp_critic.learning.critic import Critic
from warp_critic.learning.inner import policy_fn
from warp_critic.learning.losses import critic_loss, td_loss
from warp_critic.learning.networks import Normalizer
from warp_critic.learning.outer import meta_loss
from warp_critic.learning.rollout import rollout
from warp_critic.methods.replay import ReplayBuffer, rewards


def make_critic(sim, cfg, seed: int) -> Critic:
    """The paper's critic network for the point mass, initialised as after ``torch.manual_seed(seed)``;
    torch's global random state is left as it was."""
    norm = Normalizer.from_limits(
        sim.q_lower, sim.q_upper, torch.full((2,), cfg.range, device=sim.torch_device), cfg.qd_scale
    )
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        return Critic(2, norm).to(sim.torch_device)


def _random_forces(W: int, cfg, gen: torch.Generator, device) -> torch.Tensor:
    return ((torch.rand(W, 2, generator=gen) * 2 - 1) * cfg.range).to(device)


def sample_tasks(cfg, q0: torch.Tensor, goal: torch.Tensor, gen: torch.Generator):
    """The training task of every world for one iteration: ``(q0 (W, 2), goals (W, 2))``.

    The paper's setting (defaults: ``train_goals = ()``, ``goal_std = start_std = 0``) returns the fixed
    initial states ``q0`` and the one goal ``goal (1, 2)`` for every world, without drawing random numbers.
    Otherwise each world draws, independently every iteration, its goal uniformly from
    ``{goal} + train_goals`` plus ``goal_std * N(0, I)`` and its initial state ``q0 + start_std * N(0, I)``
    (at rest). Background: ``docs/landscape.md``, "Generalisation to unseen goals".
    """
    W, dev = q0.shape[0], q0.device
    goals = goal.expand(W, -1)
    if cfg.train_goals:
        pool = torch.tensor([tuple(cfg.goal), *cfg.train_goals], dtype=q0.dtype)
        goals = pool[torch.randint(len(pool), (W,), generator=gen)].to(dev)
    if cfg.goal_std > 0:
        goals = goals + (cfg.goal_std * torch.randn(W, 2, generator=gen)).to(dev)
    if cfg.start_std > 0:
        q0 = q0 + (cfg.start_std * torch.randn(W, 2, generator=gen)).to(dev)
    return q0, goals


def varied_tasks(cfg) -> bool:
    """Whether the training goals or initial states are drawn anew every iteration (not the paper's)."""
    return bool(cfg.train_goals) or cfg.goal_std > 0 or cfg.start_std > 0


def _progress(cfg, it: int) -> bool:
    return not cfg.quiet and (it % 50 == 0 or it == cfg.iterations - 1)


def train_ours(cfg, sim, q0, goal, gen, log=print):
    """Algorithm 2 on one goal from the initial states ``q0 (W, 2)``: every iteration fresh
    ``theta ~ U[-R, R]^2``, one inner step, Adam on the task loss of ``theta_new``. With
    ``train_goals`` / ``goal_std`` / ``start_std`` each world's goal and initial state are drawn anew every
    iteration (:func:`sample_tasks`).

    Returns ``(critic, theta_before (K, W, 2), theta_new (K, W, 2), task losses (K,))``.
    """
    net = make_critic(sim, cfg, cfg.seed)
    critic = GoalRelative(net) if cfg.ours_goal_input == "relative" else net
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    W = q0.shape[0]
    qd0 = torch.zeros_like(q0)
    trace_before, trace_new, losses = [], [], []
    for it in range(cfg.iterations):
        theta = _random_forces(W, cfg, gen, q0.device).requires_grad_(True)
        q0_it, goals = sample_tasks(cfg, q0, goal, gen)
        res = meta_loss(
            critic,
            constant_force,
            {"theta": theta},
            sim,
            q0_it,
            qd0,
            goals,
            horizon=cfg.horizon,
            alpha=cfg.alpha,
            inner_steps=1,
        )
        if not torch.isfinite(res.loss):
            raise DivergenceError(
                f"meta-training diverged at iteration {it} (lower --alpha or --lr)"
            )
        opt.zero_grad()
        res.loss.backward()
        opt.step()
        trace_before.append(theta.detach().cpu().numpy())
        trace_new.append(res.params_new["theta"].cpu().numpy())
        losses.append(float(res.loss.detach()))
        if _progress(cfg, it):
            log(f"  ours  it {it:4d}  task loss of theta_new {losses[-1]:.5f}")
    return critic, np.stack(trace_before), np.stack(trace_new), np.array(losses)


def sup_costs(traj, goals, kind: str) -> tuple[torch.Tensor, torch.Tensor]:
    """``(cost, done)`` ``(T, W)`` of ``Q_sup``: ``terminal`` ``||q_T - g||^2`` at the last step only (the task
    cost) or ``running`` ``||q_{t+1} - g||^2`` at every step; no bootstrap past the last step either way."""
    cost, done = rewards(traj, goals, "sparse", -1.0)
    if kind == "running":
        cost = rewards(traj, goals, "dense", -1.0)[0]
    return cost, done


def train_sup(cfg, sim, q0, goal, gen, log=print):
    """Algorithm 1: ``Q_sup(s - g, a)`` learned by TD on every transition seen so far, persistent policies.

    Each iteration: roll the policies out, add the transitions to the replay buffer, ``sup_fit_steps``
    Adam steps on the TD error of minibatches (target network = ``Q_sup`` at the start of the iteration,
    ``gamma = 1``), then ``theta <- clip(theta - sup_alpha * grad_theta sum_t Q_sup(s_t - g, theta), -R, R)``
    with the rollout's states as data. The policy is a constant force, so the next action ``a'`` of a
    stored transition is its own action. With ``train_goals`` / ``goal_std`` / ``start_std`` every iteration
    rolls each persistent policy out from a freshly drawn initial state towards a freshly drawn goal
    (:func:`sample_tasks`, the same distribution as ours).

    Returns ``(Q_sup, theta after each iteration (K, W, 2), TD losses (K,))``.
    """
    net, target_net = make_critic(sim, cfg, cfg.seed + 1), make_critic(sim, cfg, cfg.seed + 1)
    qsup, target = GoalRelative(net), GoalRelative(target_net)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    W = q0.shape[0]
    dev = q0.device
    qd0 = torch.zeros_like(q0)
    theta = _random_forces(W, cfg, gen, dev)
    buf = ReplayBuffer(cfg.iterations * cfg.horizon * W, q0.shape[1], dev)  # keeps every transition
    thetas, td_losses = [], []
    for it in range(cfg.iterations):
        params = {"theta": theta}
        q0_it, goals = sample_tasks(cfg, q0, goal, gen)
        tr = rollout(
            sim, policy_fn(constant_force, params), q0_it, qd0, cfg.horizon, differentiable=False
        )
        cost, done = sup_costs(tr, goals, cfg.sup_reward)
        buf.add_trajectory(tr, goals, cost, done)
        target_net.load_state_dict(net.state_dict())
        for _ in range(cfg.sup_fit_steps):
            b = buf.sample(min(cfg.sup_batch, buf.size), gen)
            with torch.no_grad():
                q_next = target(b["q2"], b["qd2"], b["tau"], b["goal"])
            td = td_loss(
                qsup(b["q"], b["qd"], b["tau"], b["goal"]),
                b["reward"],
                b["done"],
                q_next,
                gamma=1.0,
            )
            opt.zero_grad()
            td.backward()
            opt.step()
        td_losses.append(float(td.detach()))
        params = {"theta": theta.clone().requires_grad_(True)}
        (g,) = torch.autograd.grad(
            critic_loss(qsup, constant_force, params, tr, goals).sum(), params["theta"]
        )
        theta = (theta - cfg.sup_alpha * g).clamp(-cfg.range, cfg.range).detach()
        thetas.append(theta.cpu().numpy())
        if _progress(cfg, it):
            log(f"  Q_sup it {it:4d}  TD loss {td_losses[-1]:.5f}")
    return qsup, np.stack(thetas), np.array(td_losses)
