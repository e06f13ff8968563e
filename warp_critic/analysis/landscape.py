r"""The 2-D illustration of section 4.2 ("Illustration: Shape of L_critic", Figure 1 and the
exploration figure) on the Newton point mass ``scenes/point_mass.usda``.

Problem
-------
* Scene: planar point mass, two prismatic joints ``x, y`` (1 kg mass; a 0.001 kg carriage rides along
  ``x``, so the effective masses are ``m_x = 1.001`` kg, ``m_y = 1`` kg), no damping, no gravity in the
  plane.
* Policy: two parameters, the constant force ``a_t = pi_theta(s_t) = theta = [theta_1, theta_2]`` (N) --
  the 2-D version of the paper's 1-D ``a_t = theta``. Rollouts start at rest.
* Task cost (the paper's ``L_task = (s_T - g)^2``): ``||q_T - g||^2``.
* Analytic optimum: Featherstone with semi-implicit Euler and ``substeps`` physics steps of ``dt`` per
  control step gives, for ``N = T * substeps`` physics steps of a constant force from rest,
  ``qd_k = k dt theta / m`` and ``q_N = q_0 + dt^2 theta / m * (1 + 2 + ... + N) = q_0 + theta dt^2 N (N+1) / (2 m)``.
  Hence ``theta* = 2 m (g - q_0) / (dt^2 N (N+1))`` per axis (:func:`analytic_gain`, :func:`analytic_optimum`).
  The joint limits (+-5 m) are never reached for the default range of ``theta``.

Methods (all three landscapes are functions of ``theta``)
---------------------------------------------------------
* ``Q_true(theta)``: the task cost of rolling ``theta`` out, ``||q_T(theta) - g||^2``; since the cost is
  terminal, the cost-to-go is the same at every step along the rollout, so the summed
  ``sum_t Q_true(s_t, theta)`` is ``T`` times this (same shape); we show the task cost itself.
  Its gradient is taken through the differentiable Newton model (one backward pass over all grid worlds).
* ``L_critic`` (ours, Algorithm 2): ``M(s, a, g, phi)`` = :class:`warp_critic.networks.Critic`. Each
  meta-iteration draws fresh ``theta ~ U[-R, R]^2`` for ``inits_per_state`` worlds per initial state (two
  initial states, one goal), rolls them out (states as data), takes the inner step
  ``theta_new = theta - alpha * grad_theta sum_t M(s_t, theta, g)`` (kept as a function of ``phi``), rolls
  ``theta_new`` out through the differentiable Newton model, and updates ``phi`` with Adam on the mean
  ``||q_T(theta_new) - g||^2`` (second order, through the inner step). The ``theta_new`` of every world and
  iteration is the exploration trace.
* ``Q_sup`` (Algorithm 1): same architecture, goal-conditioned as the paper says by feeding ``s - g``
  (joint positions minus goal; the critic's goal input is fed zeros). Persistent policies
  (``inits_per_state`` per initial state, ``theta ~ U[-R, R]^2`` at the start). Each iteration: roll the
  policies out, add the transitions to a replay buffer, take ``sup_fit_steps`` Adam steps on the TD error
  ``sum_t (Q(s_t, a_t) - (r_t + gamma Q'(s_{t+1}, a_{t+1})))^2`` (minibatches; ``Q'`` = the network at the
  start of the iteration, i.e. a target network; ``gamma = 1``; the last step's target is ``r_{T-1}``),
  then ``theta <- clip(theta - sup_alpha * grad_theta sum_t Q(s_t - g, theta), -R, R)`` with the states as
  data. Rewards are costs (minimised): terminal ``r_{T-1} = ||q_T - g||^2`` (default, the task cost) or
  ``running`` ``r_t = ||q_{t+1} - g||^2``.

Landscapes: a ``grid x grid`` lattice over ``[-R, R]^2`` is rolled out as ``grid^2`` parallel worlds of one
forward-only (``differentiable=False``) simulator from the evaluation initial state (the first initial
state). The states do not depend on the goal, so one rollout serves all goals. ``L_critic`` and ``Q_sup``
are summed along each rollout, ``sum_t C(s_t, theta)``, and differentiated with respect to ``theta``
with the states as data (torch autograd) -- exactly the policy gradient each critic gives.

Note: for the critics the colour (``sum_t C(s_t(theta), theta)``, the states depend on ``theta``) is *not*
the potential of the arrows (the policy gradient with the states as data, as in the paper). They can
disagree: e.g. with the defaults ours' summed value is lowest near ``(1, 0.5)`` while its arrows lead to
``theta* = (1.91, 1.90)``. The descent check below follows the arrows, since that is what a policy
trained with the critic does.

Generalisation: with one training goal the critic's goal input never varies during training, so nothing
ties its landscape to ``g``; in our runs neither ours (``--ours-goal-input absolute`` or ``relative``) nor
``Q_sup`` moves its minimum to the unseen goals' optima (see the printed table).

Quantitative check: from every grid point, run normalised-gradient descent on the *precomputed* gradient
field (bilinear interpolation between grid points, clamped to the box), step sizes
``eta_k = h * 0.98^k`` (``h`` the grid spacing) for 300 steps. A start succeeds if it ends within
``tolerance`` (N) of the analytic optimum ``theta*`` of that goal. Q_true's fraction is ~1 by construction.
The field is evaluated on the grid only, so the check resolves the optimum to about a grid spacing.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from warp_critic.errors import UserError

__all__ = ["LandscapeConfig", "analytic_gain", "analytic_optimum", "descent_fraction", "run_landscape",
           "add_arguments", "run_from_args", "METHODS"]

METHODS = ("Q_true", "Q_sup", "L_critic")
SCENE = "scenes/point_mass.usda"
AXIS_MASS = (1.001, 1.0)  # effective masses of the x (mass + carriage) and y joints [kg]


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
    qd_scale: float = 2.0
    scene: str = SCENE
    quiet: bool = False
    extra: dict = field(default_factory=dict)


# ---------------------------------------------------------------------------------------------------
# analytic facts
# ---------------------------------------------------------------------------------------------------
def analytic_gain(dt: float, horizon: int, substeps: int = 1, mass=AXIS_MASS) -> np.ndarray:
    """Displacement per newton of constant force from rest after ``horizon`` control steps, per axis:
    ``dt^2 N (N+1) / (2 m)`` with ``N = horizon * substeps`` (semi-implicit Euler)."""
    n = horizon * substeps
    return dt * dt * n * (n + 1) / 2.0 / np.asarray(mass, dtype=np.float64)


def analytic_optimum(goal, q0, dt: float, horizon: int, substeps: int = 1) -> np.ndarray:
    """``theta* = (g - q_0) / gain``: the constant force that ends exactly at the goal."""
    return (np.asarray(goal, float) - np.asarray(q0, float)) / analytic_gain(dt, horizon, substeps)


# ---------------------------------------------------------------------------------------------------
# gradient descent on a precomputed field
# ---------------------------------------------------------------------------------------------------
def _bilinear(field: np.ndarray, axis: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """``field (n, n, 2)`` indexed ``[i1, i2]`` over ``axis`` (both dims) at ``pts (P, 2)`` -> ``(P, 2)``."""
    n = axis.size
    h = axis[1] - axis[0]
    u = np.clip((pts - axis[0]) / h, 0.0, n - 1 - 1e-9)
    i = np.floor(u).astype(int)
    f = u - i
    i0, i1 = i[:, 0], i[:, 1]
    f0, f1 = f[:, :1], f[:, 1:]
    return ((1 - f0) * (1 - f1) * field[i0, i1] + f0 * (1 - f1) * field[i0 + 1, i1]
            + (1 - f0) * f1 * field[i0, i1 + 1] + f0 * f1 * field[i0 + 1, i1 + 1])


def descend(field: np.ndarray, axis: np.ndarray, starts: np.ndarray, steps: int = 300,
            decay: float = 0.98) -> np.ndarray:
    """Normalised-gradient descent on the interpolated ``field`` from ``starts (P, 2)``; final points."""
    h = axis[1] - axis[0]
    lo, hi = axis[0], axis[-1]
    x = starts.astype(np.float64).copy()
    for k in range(steps):
        g = _bilinear(field, axis, x)
        norm = np.linalg.norm(g, axis=1, keepdims=True)
        d = np.where(norm > 1e-12, g / np.maximum(norm, 1e-12), 0.0)
        x = np.clip(x - h * decay ** k * d, lo, hi)
    return x


def descent_fraction(field: np.ndarray, axis: np.ndarray, optimum, tolerance: float) -> float:
    """Fraction of grid points from which :func:`descend` ends within ``tolerance`` of ``optimum``."""
    t1, t2 = np.meshgrid(axis, axis, indexing="ij")
    starts = np.stack([t1.ravel(), t2.ravel()], axis=1)
    final = descend(field, axis, starts)
    return float(np.mean(np.linalg.norm(final - np.asarray(optimum)[None], axis=1) <= tolerance))


# ---------------------------------------------------------------------------------------------------
# training
# ---------------------------------------------------------------------------------------------------
def _constant(theta):
    return lambda q, qd: theta


def _make_critic(sim, cfg, seed):
    from warp_critic.networks import Critic, Normalizer

    torch.manual_seed(seed)
    norm = Normalizer.from_limits(sim.q_lower, sim.q_upper,
                                  torch.full((2,), cfg.range, device=sim.torch_device), cfg.qd_scale)
    return Critic(2, norm).to(sim.torch_device)


def critic_sum(critic, q, qd, theta, goal, relative: bool = False):
    """``sum_t C(s_t, theta, g)`` per world; ``q, qd (T, W, 2)`` data, ``theta (W, 2)``, ``goal (W, 2)``.

    ``relative``: feed ``(q - g, qd, a, 0)`` instead of ``(q, qd, a, g)`` (the ``--ours-goal-input relative``
    variant, the same goal conditioning as ``Q_sup``)."""
    if relative:
        return sup_sum(critic, q, qd, theta, goal)
    T = q.shape[0]
    tau = theta.unsqueeze(0).expand(T, -1, -1)
    return critic(q, qd, tau, goal.unsqueeze(0).expand_as(q)).sum(0)


def sup_sum(qsup, q, qd, theta, goal):
    """``sum_t Q_sup(s_t - g, theta)`` per world (goal absorbed into the state; goal input zero)."""
    T = q.shape[0]
    g = goal.unsqueeze(0).expand_as(q)
    tau = theta.unsqueeze(0).expand(T, -1, -1)
    return qsup(q - g, qd, tau, torch.zeros_like(g)).sum(0)


def train_ours(cfg, sim, q0, goal, gen, log=print):
    """Algorithm 2 on one goal from the initial states ``q0 (W, 2)``; returns critic, trace, losses."""
    from warp_critic.rollout import rollout
    from warp_critic.errors import DivergenceError

    critic = _make_critic(sim, cfg, cfg.seed)
    opt = torch.optim.Adam(critic.parameters(), lr=cfg.lr)
    W = q0.shape[0]
    qd0 = torch.zeros_like(q0)
    goals = goal.expand(W, -1)
    trace_before, trace_new, losses = [], [], []
    for it in range(cfg.iterations):
        theta = ((torch.rand(W, 2, generator=gen) * 2 - 1) * cfg.range).to(q0.device).requires_grad_(True)
        data = rollout(sim, _constant(theta.detach()), q0, qd0, cfg.horizon, differentiable=False)
        inner = critic_sum(critic, data.q[:-1], data.qd[:-1], theta, goals, cfg.ours_goal_input == "relative").sum()
        (grad,) = torch.autograd.grad(inner, theta, create_graph=True)
        theta_new = theta - cfg.alpha * grad
        after = rollout(sim, _constant(theta_new), q0, qd0, cfg.horizon, differentiable=True)
        loss = ((after.q[-1] - goals) ** 2).sum(-1).mean()
        if not torch.isfinite(loss):
            raise DivergenceError(f"meta-training diverged at iteration {it} (lower --alpha or --lr)")
        opt.zero_grad()
        loss.backward()
        opt.step()
        trace_before.append(theta.detach().cpu().numpy())
        trace_new.append(theta_new.detach().cpu().numpy())
        losses.append(float(loss.detach()))
        if not cfg.quiet and (it % 50 == 0 or it == cfg.iterations - 1):
            log(f"  ours  it {it:4d}  task loss of theta_new {losses[-1]:.5f}")
    return critic, np.stack(trace_before), np.stack(trace_new), np.array(losses)


def train_sup(cfg, sim, q0, goal, gen, log=print):
    """Algorithm 1 (supervised TD learning of Q_sup on ``s - g``); returns Q_sup, theta trace, TD losses."""
    from warp_critic.rollout import rollout

    qsup = _make_critic(sim, cfg, cfg.seed + 1)
    target = _make_critic(sim, cfg, cfg.seed + 1)
    opt = torch.optim.Adam(qsup.parameters(), lr=cfg.lr)
    W = q0.shape[0]
    dev = q0.device
    qd0 = torch.zeros_like(q0)
    goals = goal.expand(W, -1)
    theta = ((torch.rand(W, 2, generator=gen) * 2 - 1) * cfg.range).to(dev)
    buf = {k: [] for k in ("q", "qd", "a", "r", "q1", "qd1", "a1", "last")}
    thetas, td_losses = [], []
    T = cfg.horizon
    for it in range(cfg.iterations):
        tr = rollout(sim, _constant(theta), q0, qd0, T, differentiable=False)
        cost = ((tr.q[1:] - goals) ** 2).sum(-1)  # (T, W): ||q_{t+1} - g||^2
        if cfg.sup_reward == "terminal":
            cost = torch.cat([torch.zeros_like(cost[:-1]), cost[-1:]], 0)
        last = torch.zeros(T, W, device=dev)
        last[-1] = 1.0
        a = tr.tau
        a1 = torch.cat([a[1:], a[-1:]], 0)
        for k, v in (("q", tr.q[:-1] - goals), ("qd", tr.qd[:-1]), ("a", a), ("r", cost),
                     ("q1", tr.q[1:] - goals), ("qd1", tr.qd[1:]), ("a1", a1), ("last", last)):
            buf[k].append(v.reshape(T * W, *v.shape[2:]))
        data = {k: torch.cat(v, 0) for k, v in buf.items()}
        n = data["r"].shape[0]
        target.load_state_dict(qsup.state_dict())
        for _ in range(cfg.sup_fit_steps):
            idx = torch.randint(0, n, (min(cfg.sup_batch, n),), generator=gen).to(dev)
            z = torch.zeros_like(data["q"][idx])
            with torch.no_grad():
                nxt = target(data["q1"][idx], data["qd1"][idx], data["a1"][idx], z)
                y = data["r"][idx] + (1 - data["last"][idx]) * nxt
            pred = qsup(data["q"][idx], data["qd"][idx], data["a"][idx], z)
            td = ((pred - y) ** 2).mean()
            opt.zero_grad()
            td.backward()
            opt.step()
        td_losses.append(float(td.detach()))
        th = theta.clone().requires_grad_(True)
        val = sup_sum(qsup, tr.q[:-1], tr.qd[:-1], th, goals).sum()
        (g,) = torch.autograd.grad(val, th)
        theta = (theta - cfg.sup_alpha * g).clamp(-cfg.range, cfg.range).detach()
        thetas.append(theta.cpu().numpy())
        if not cfg.quiet and (it % 50 == 0 or it == cfg.iterations - 1):
            log(f"  Q_sup it {it:4d}  TD loss {td_losses[-1]:.5f}")
    return qsup, np.stack(thetas), np.array(td_losses)


# ---------------------------------------------------------------------------------------------------
# landscapes
# ---------------------------------------------------------------------------------------------------
def compute_landscapes(cfg, eval_sim, grad_sim, critic, qsup, goals: np.ndarray, q0_eval: np.ndarray):
    """Values ``(G, 3, n, n)`` and gradients ``(G, 3, n, n, 2)`` indexed ``[goal, method, i1, i2]``."""
    from warp_critic.rollout import rollout

    n = cfg.grid
    dev = eval_sim.torch_device
    axis = np.linspace(-cfg.range, cfg.range, n)
    t1, t2 = np.meshgrid(axis, axis, indexing="ij")
    theta = torch.tensor(np.stack([t1.ravel(), t2.ravel()], 1), dtype=torch.float32, device=dev)
    P = n * n
    q0 = torch.tensor(q0_eval, dtype=torch.float32, device=dev).expand(P, -1).contiguous()
    qd0 = torch.zeros_like(q0)
    data = rollout(eval_sim, _constant(theta), q0, qd0, cfg.horizon, differentiable=False)
    qs, qds = data.q[:-1], data.qd[:-1]
    # Q_true gradient through the differentiable model (the goal enters only through the cost)
    th = theta.clone().requires_grad_(True)
    diff = rollout(grad_sim, _constant(th), q0, qd0, cfg.horizon, differentiable=True)
    qT = diff.q[-1]
    jac = []
    for j in range(2):  # dq_T/dtheta rows: q_T(theta) per axis
        (gj,) = torch.autograd.grad(qT[:, j].sum(), th, retain_graph=(j == 0))
        jac.append(gj)
    jac = torch.stack(jac, 1)  # (P, 2 [q axis], 2 [theta])
    qT_data = data.q[-1]
    values = np.zeros((len(goals), 3, n, n))
    grads = np.zeros((len(goals), 3, n, n, 2))
    for gi, g in enumerate(goals):
        gt = torch.tensor(g, dtype=torch.float32, device=dev).expand(P, -1)
        err = qT_data - gt
        values[gi, 0] = (err ** 2).sum(-1).reshape(n, n).cpu().numpy()
        grads[gi, 0] = (2 * torch.einsum("pj,pjk->pk", qT.detach() - gt, jac)).reshape(n, n, 2).cpu().numpy()
        ours_fn = sup_sum if cfg.ours_goal_input == "relative" else critic_sum
        for mi, (net, fn) in ((1, (qsup, sup_sum)), (2, (critic, ours_fn))):
            th = theta.clone().requires_grad_(True)
            v = fn(net, qs, qds, th, gt)
            (gr,) = torch.autograd.grad(v.sum(), th)
            values[gi, mi] = v.detach().reshape(n, n).cpu().numpy()
            grads[gi, mi] = gr.reshape(n, n, 2).cpu().numpy()
    return axis, values, grads


# ---------------------------------------------------------------------------------------------------
# outputs
# ---------------------------------------------------------------------------------------------------
def _colormap(values: np.ndarray) -> np.ndarray:
    """``(n1, n2)`` indexed ``[i1, i2]`` -> RGB image, row 0 = largest theta_2 (viridis, min-max)."""
    from matplotlib import colormaps

    v = values.T[::-1]
    lo, hi = float(np.min(v)), float(np.max(v))
    u = (v - lo) / (hi - lo) if hi > lo else np.zeros_like(v)
    return (colormaps["viridis"](u)[..., :3] * 255).astype(np.uint8)


def _goal_names(G):
    return ["train"] + [f"test{i}" for i in range(1, G)]


def write_recording(path, cfg, axis, values, grads, goals, optima, trace_new, ours_loss, sup_loss, fractions):
    from warp_critic.recording import Recorder, rrb

    names = _goal_names(len(goals))
    n = axis.size
    rows = [rrb.Horizontal(*[rrb.Spatial2DView(origin=f"/landscape/{gn}/{m}", name=f"{gn}: {m}")
                             for m in METHODS]) for gn in names]
    blueprint = rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(*rows),
            rrb.Vertical(rrb.Spatial2DView(origin="/trace", name="theta_new during meta-training"),
                         rrb.TimeSeriesView(origin="/train", name="training losses")),
            column_shares=[3, 1]),
        collapse_panels=True)
    rec = Recorder(path, application_id="warp-critic landscape", blueprint=blueprint)
    try:
        i1, i2 = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        origins = np.stack([i1.ravel() + 0.5, (n - 1 - i2).ravel() + 0.5], 1).astype(np.float32)
        h = axis[1] - axis[0]

        def to_px(theta):
            theta = np.atleast_2d(theta)
            return np.stack([(theta[:, 0] - axis[0]) / h + 0.5, (n - 1) - (theta[:, 1] - axis[0]) / h + 0.5], 1)

        for gi, gn in enumerate(names):
            for mi, m in enumerate(METHODS):
                base = f"landscape/{gn}/{m}"
                rec.image(f"{base}/value", _colormap(values[gi, mi]), static=True)
                rec.tensor(f"{base}/raw", values[gi, mi].astype(np.float32), dim_names=["theta_1", "theta_2"],
                           static=True)
                d = -grads[gi, mi].reshape(-1, 2)
                norm = np.linalg.norm(d, axis=1, keepdims=True)
                d = np.where(norm > 0, d / np.maximum(norm, 1e-12), 0.0) * 0.8
                d[:, 1] *= -1  # image rows grow downwards
                rec.arrows2d(f"{base}/descent_direction", origins, d.astype(np.float32),
                             colors=np.array([[255, 255, 255]] * len(d), dtype=np.uint8), static=True)
                rec.points2d(f"{base}/optimum", to_px(optima[gi]).astype(np.float32),
                             colors=[[255, 0, 0]], radii=[0.4], static=True)
                rec.text(f"{base}/fraction", f"descent success fraction: {fractions[gi][m]:.3f}")
        for it in range(trace_new.shape[0]):
            rec.set_time("iteration", it)
            rec.points2d("trace/theta_new", trace_new[it].astype(np.float32), radii=[0.04])
            rec.scalar("trace/theta_1_world0", float(trace_new[it, 0, 0]))
            rec.scalar("trace/theta_2_world0", float(trace_new[it, 0, 1]))
            rec.scalar("train/ours_task_loss", float(ours_loss[it]))
            if it < len(sup_loss):
                rec.scalar("train/sup_td_loss", float(sup_loss[it]))
        rec.reset_time()
        rec.points2d("trace/optimum", np.asarray(optima[0], np.float32)[None], colors=[[255, 0, 0]],
                     radii=[0.1], static=True)
    finally:
        rec.close()


def write_figures(out: Path, cfg, axis, values, grads, goals, optima, trace_new, init_states, fractions):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = _goal_names(len(goals))
    G = len(goals)
    fig, axes = plt.subplots(G, 3, figsize=(12, 4 * G), squeeze=False)
    T1, T2 = np.meshgrid(axis, axis, indexing="ij")
    ext = [axis[0], axis[-1], axis[0], axis[-1]]
    for gi in range(G):
        for mi, m in enumerate(METHODS):
            ax = axes[gi, mi]
            ax.imshow(values[gi, mi].T, origin="lower", extent=ext, cmap="viridis", aspect="equal")
            d = -grads[gi, mi]
            nrm = np.linalg.norm(d, axis=-1, keepdims=True)
            d = np.where(nrm > 0, d / np.maximum(nrm, 1e-12), 0.0)
            ax.quiver(T1, T2, d[..., 0], d[..., 1], color="white", scale=30, width=0.004)
            ax.plot(*optima[gi], marker="*", color="red", markersize=14)
            ax.set_title(f"{m}, goal {names[gi]} g=({goals[gi][0]:g},{goals[gi][1]:g})\n"
                         f"descent success {fractions[gi][m]:.2f}", fontsize=9)
            ax.set_xlabel("theta_1 (N)")
            ax.set_ylabel("theta_2 (N)")
    fig.tight_layout()
    fig.savefig(out / "landscape.png", dpi=90)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 6))
    K = trace_new.shape[0]
    colors = np.repeat(np.arange(K), trace_new.shape[1])
    sc = ax.scatter(trace_new[..., 0].ravel(), trace_new[..., 1].ravel(), c=colors, cmap="viridis", s=6)
    W = trace_new.shape[1]
    per = W // len(init_states)
    for si, s0 in enumerate(init_states):
        th = analytic_optimum(goals[0], s0, cfg.dt, cfg.horizon, cfg.substeps)
        ax.plot(*th, marker="**^sD"[si % 5], color=["red", "orange", "magenta", "cyan", "white"][si % 5],
                markeredgecolor="black", markersize=14, linestyle="none",
                label=f"theta* from q0=({s0[0]:g},{s0[1]:g})")
    fig.colorbar(sc, ax=ax, label="meta-iteration (dark -> light)")
    ax.set_xlim(axis[0] * 1.5, axis[-1] * 1.5)
    ax.set_ylim(axis[0] * 1.5, axis[-1] * 1.5)
    ax.set_xlabel("theta_1 (N)")
    ax.set_ylabel("theta_2 (N)")
    ax.set_title(f"theta_new during meta-training ({per} random inits x {len(init_states)} initial states)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "exploration.png", dpi=90)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------------
# driver
# ---------------------------------------------------------------------------------------------------
def run_landscape(cfg: LandscapeConfig) -> dict:
    """Train both critics, compute the landscapes, write ``landscape.rrd`` and the PNGs; returns results.

    Torch runs single-threaded meanwhile (restored afterwards): the networks are small and intra-op
    threads on a shared CPU made every step ~25x slower.
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _run_landscape(cfg)
    finally:
        torch.set_num_threads(threads)


def _run_landscape(cfg: LandscapeConfig) -> dict:
    import warp as wp

    from warp_critic.scene import Variant, load_scene
    from warp_critic.simulator import Simulator

    wp.config.quiet = True
    t_start = time.time()
    log = (lambda *a: None) if cfg.quiet else print
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    scene = load_scene(cfg.scene)
    if scene.dof != 2:
        raise UserError(f"{cfg.scene}: the landscape analysis needs a 2-DoF scene, got {scene.dof} DoF")
    gen = torch.Generator().manual_seed(cfg.seed)
    init_states = np.asarray(cfg.init_states, dtype=np.float64)
    W = len(init_states) * cfg.inits_per_state
    train_sim = Simulator(scene, [Variant()] * W, dt=cfg.dt, substeps=cfg.substeps, device=cfg.device,
                          differentiable=True)
    dev = train_sim.torch_device
    q0 = torch.tensor(np.repeat(init_states, cfg.inits_per_state, axis=0), dtype=torch.float32, device=dev)
    goal = torch.tensor(cfg.goal, dtype=torch.float32, device=dev)[None]

    log(f"meta-training L_critic (ours): {cfg.iterations} iterations, {W} worlds")
    critic, trace_before, trace_new, ours_loss = train_ours(cfg, train_sim, q0, goal, gen, log)
    log(f"training Q_sup (Algorithm 1): {cfg.iterations} iterations, {W} worlds")
    qsup, sup_thetas, sup_loss = train_sup(cfg, train_sim, q0, goal, gen, log)

    P = cfg.grid ** 2
    eval_sim = Simulator(scene, [Variant()] * P, dt=cfg.dt, substeps=cfg.substeps, device=cfg.device,
                         differentiable=False)
    grad_sim = Simulator(scene, [Variant()] * P, dt=cfg.dt, substeps=cfg.substeps, device=cfg.device,
                         differentiable=True)
    goals = np.asarray([cfg.goal, *cfg.test_goals], dtype=np.float64)
    q0_eval = init_states[0]
    axis, values, grads = compute_landscapes(cfg, eval_sim, grad_sim, critic, qsup, goals, q0_eval)
    optima = np.stack([analytic_optimum(g, q0_eval, cfg.dt, cfg.horizon, cfg.substeps) for g in goals])
    fractions = [{m: descent_fraction(grads[gi, mi], axis, optima[gi], cfg.tolerance)
                  for mi, m in enumerate(METHODS)} for gi in range(len(goals))]
    if not (np.isfinite(values).all() and np.isfinite(grads).all()):
        raise UserError("non-finite landscape values: lower --alpha / --lr or the --range")
    write_recording(out / "landscape.rrd", cfg, axis, values, grads, goals, optima, trace_new, ours_loss,
                    sup_loss, fractions)
    write_figures(out, cfg, axis, values, grads, goals, optima, trace_new, init_states, fractions)
    np.savez(out / "landscape.npz", axis=axis, values=values, grads=grads, goals=goals, optima=optima,
             trace_new=trace_new, trace_before=trace_before, ours_loss=ours_loss, sup_loss=sup_loss,
             sup_thetas=sup_thetas)
    wall = time.time() - t_start
    names = _goal_names(len(goals))
    if not cfg.quiet:
        print(f"descent success fraction (normalised-gradient descent on the field from each of the "
              f"{P} grid points, success = within {cfg.tolerance:g} N of theta*):")
        print(f"  {'goal':<22} {'theta*':>16} " + " ".join(f"{m:>9}" for m in METHODS))
        for gi, gn in enumerate(names):
            g = goals[gi]
            print(f"  {gn + f' ({g[0]:g},{g[1]:g})':<22} {f'({optima[gi][0]:.2f},{optima[gi][1]:.2f})':>16} "
                  + " ".join(f"{fractions[gi][m]:9.3f}" for m in METHODS))
        print(f"wrote {out / 'landscape.rrd'}, {out / 'landscape.png'}, {out / 'exploration.png'} "
              f"({wall:.1f} s)")
    return {"axis": axis, "values": values, "grads": grads, "goals": goals, "optima": optima,
            "fractions": fractions, "trace_new": trace_new, "trace_before": trace_before,
            "ours_loss": ours_loss, "sup_loss": sup_loss, "goal_names": names, "wall_s": wall,
            "out": out}


# ---------------------------------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------------------------------
def _pair(text: str):
    parts = [p for p in str(text).split(",") if p.strip()]
    vals = [float(p) for p in parts]
    if len(vals) != 2 or not all(math.isfinite(v) for v in vals):
        raise ValueError
    return tuple(vals)


def _pairs(text: str):
    return tuple(_pair(p) for p in str(text).split(";") if p.strip())


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the flags of ``warp-critic analyze landscape`` to ``parser``."""
    d = LandscapeConfig()
    A = parser.add_argument
    A("--out", type=Path, default=d.out, metavar="DIR",
      help=f"output folder for landscape.rrd, landscape.png, exploration.png (default {d.out})")
    A("--iterations", type=int, default=d.iterations, metavar="N",
      help=f"meta-training iterations of ours, and training iterations of Q_sup (>= 1; default {d.iterations})")
    A("--grid", type=int, default=d.grid, metavar="N",
      help=f"landscape grid points per axis, N^2 parallel worlds (>= 3; default {d.grid})")
    A("--range", type=float, default=d.range, metavar="R",
      help=f"policy parameters (constant forces) span [-R, R]^2 N (> 0; default {d.range})")
    A("--seed", type=int, default=d.seed, metavar="S", help=f"random seed (default {d.seed})")
    A("--device", type=str, default=d.device, metavar="DEV", help=f"cpu, cuda or auto (default {d.device})")
    A("--horizon", type=int, default=d.horizon, metavar="T", help=f"control steps per rollout (>= 1; default {d.horizon})")
    A("--dt", type=float, default=d.dt, metavar="S", help=f"physics time step in s (> 0; default {d.dt})")
    A("--substeps", type=int, default=d.substeps, metavar="N",
      help=f"physics steps per control step (>= 1; default {d.substeps})")
    A("--alpha", type=float, default=d.alpha, metavar="LR", help=f"inner policy learning rate of ours (> 0; default {d.alpha})")
    A("--lr", type=float, default=d.lr, metavar="LR", help=f"Adam learning rate of both critics (> 0; default {d.lr})")
    A("--inits-per-state", type=int, default=d.inits_per_state, metavar="K",
      help=f"random policy initialisations per initial state (worlds = 2K; >= 1; default {d.inits_per_state})")
    A("--goal", type=str, default="1,1", metavar="X,Y", help="training goal in m (default 1,1)")
    A("--test-goals", type=str, default="-1.5,0.5;0.5,-1.5", metavar="X,Y;X,Y",
      help="unseen goals in m, ';'-separated (default -1.5,0.5;0.5,-1.5)")
    A("--init-states", type=str, default="0,0;-0.5,0.5", metavar="X,Y;X,Y",
      help="initial positions (at rest) used in training; the first one is also the landscapes' (default 0,0;-0.5,0.5)")
    A("--sup-alpha", type=float, default=d.sup_alpha, metavar="LR",
      help=f"policy learning rate of Q_sup's policy update (> 0; default {d.sup_alpha})")
    A("--sup-fit-steps", type=int, default=d.sup_fit_steps, metavar="N",
      help=f"TD minibatch steps per Q_sup iteration (>= 1; default {d.sup_fit_steps})")
    A("--sup-reward", type=str, default=d.sup_reward, choices=("terminal", "running"),
      help="Q_sup cost: terminal ||q_T-g||^2 (the task cost) or running ||q_{t+1}-g||^2 (default terminal)")
    A("--ours-goal-input", type=str, default=d.ours_goal_input, choices=("absolute", "relative"),
      help="how L_critic sees the goal: absolute M(s, a, g) (the paper's) or relative M(s - g, a), "
           "like Q_sup (default absolute)")
    A("--tolerance", type=float, default=d.tolerance, metavar="N",
      help=f"success radius around theta* for the descent check, in N (> 0; default {d.tolerance})")


def _positive(name, value, integer=False, minimum=None):
    ok = value is not None and (math.isfinite(value) if not integer else True)
    if ok:
        ok = value >= minimum if minimum is not None else value > 0
    if not ok:
        bound = f">= {minimum}" if minimum is not None else "> 0"
        raise UserError(f"{name} must be {bound}, got {value!r}")
    return value


def config_from_args(args: argparse.Namespace) -> LandscapeConfig:
    for flag, attr in (("--goal", "goal"), ("--test-goals", "test_goals"), ("--init-states", "init_states")):
        text = getattr(args, attr)
        try:
            val = _pair(text) if attr == "goal" else _pairs(text)
        except ValueError:
            raise UserError(f"{flag} expects {'X,Y' if attr == 'goal' else 'X,Y;X,Y;...'} with finite numbers, "
                            f"got {text!r}") from None
        setattr(args, "_" + attr, val)
    if len(args._init_states) < 1:
        raise UserError("--init-states needs at least one X,Y pair")
    for i in ("iterations", "horizon", "substeps", "inits_per_state", "sup_fit_steps"):
        _positive("--" + i.replace("_", "-"), getattr(args, i), integer=True, minimum=1)
    _positive("--grid", args.grid, integer=True, minimum=3)
    for f in ("range", "dt", "alpha", "lr", "sup_alpha", "tolerance"):
        _positive("--" + f.replace("_", "-"), getattr(args, f))
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out} exists and is not a folder")
    from warp_critic.simulator import resolve_device

    device = resolve_device(args.device)
    return LandscapeConfig(out=out, iterations=args.iterations, grid=args.grid, range=args.range, seed=args.seed,
                           device=device, horizon=args.horizon, dt=args.dt, substeps=args.substeps,
                           alpha=args.alpha, lr=args.lr, inits_per_state=args.inits_per_state,
                           goal=args._goal, test_goals=args._test_goals, init_states=args._init_states,
                           sup_alpha=args.sup_alpha, sup_fit_steps=args.sup_fit_steps,
                           sup_reward=args.sup_reward, tolerance=args.tolerance,
                           ours_goal_input=args.ours_goal_input)


def run_from_args(args: argparse.Namespace) -> int:
    """Validate the parsed flags, run :func:`run_landscape` and return the exit code (0)."""
    run_landscape(config_from_args(args))
    return 0
