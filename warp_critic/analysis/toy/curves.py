"""The appendix curves of the toy: each critic fitted at every ``theta`` of a grid, its value and the
policy gradient it gives (and the same with the critic frozen at the loop's converged value).
What the curves show and why: ``docs/toy.md``, "What the curves show"."""

from __future__ import annotations

import numpy as np
import torch

from warp_critic.analysis.toy.fit import gradient
from warp_critic.analysis.toy.loops import fit_meta_critic, fit_ours, fit_td, loop
from warp_critic.analysis.toy.problem import (
    ALPHA,
    METHODS,
    T,
    as_tensor,
    critic_objective,
    data_rollout,
    terminal_cost,
)

CURVE_KEYS = {  # method -> (value key, gradient key)
    "supervised": ("supervised_Q", "supervised_dQ"),
    "ours": ("ours_L", "ours_dL"),
    "meta_critic": ("meta_critic_Q", "meta_critic_dQ"),
}

BYTES_PER_POINT = 2000
"""Memory per grid point of :func:`curves` and the figures, generously (float64 arrays and autograd graphs)."""


def default_thetas(s0: float, g: float, n: int = 400) -> np.ndarray:
    """The plotting grid: ``n`` points from 5 below to 4 above the fixed points (``[-2, 8]`` for ``s0=-6, g=0``).

    Grid points that fall on a special point (``theta*``, ``-2 s0/3``, ``-s0/2``) are moved by a quarter step:
    there a critic fit is degenerate (flat objective: ``c = 0`` for ours, ``phi* = 0`` for the Meta-Critic's
    ``beta``) and the "converged critic" is not defined; those points are the degenerate fixed points
    listed by :func:`~warp_critic.analysis.toy.closed_forms.fixed_points`.
    """
    pts = np.array([(g - s0) / 2.0, -2.0 * s0 / 3.0, -s0 / 2.0])
    th = np.linspace(pts.min() - 5.0, pts.max() + 4.0, int(n))
    step = th[1] - th[0] if th.size > 1 else 1.0
    for p in pts:  # keep grid points off the special points, where a critic fit is degenerate
        near = np.abs(th - p) < 1e-6 * step
        th[near] += 0.25 * step
    return th


def converged_critics(
    s0: float, g: float, alpha: float = ALPHA, theta0: float = 0.1, iters: int = 500
) -> dict[str, tuple[float, float]]:
    """``{method: (phi, beta)}`` the loops converge to from ``theta0`` (``beta = 0`` but for the Meta-Critic)."""
    out = {}
    for m in METHODS:
        _, params, _ = loop(m, s0, g, theta0, iters, alpha=alpha)
        out[m] = (float(params["phi"][0]), float(params["beta"][0]) if "beta" in params else 0.0)
    return out


def curves(
    s0: float = -6.0,
    g: float = 0.0,
    thetas=None,
    alpha: float = ALPHA,
    converged: dict | None = None,
) -> dict[str, np.ndarray]:
    """Critic landscapes over a grid of ``theta`` (the appendix figures).

    For every grid ``theta`` the rollout of ``pi_theta`` is taken and each critic is trained to convergence on
    it (the same autograd fits as the loops). With ``c = s0 + s1 + 2 theta`` the returned arrays are:

    * ``theta``; ``Q_true = (s0 + 2 theta - g)^2`` (sum of rewards) and ``dQ_true = 4 (s0 + 2 theta - g)``;
    * ``supervised_phi``; ``supervised_Q = sum_{t=0}^{1} Q_phi(s_t, theta) + r_2`` and
      ``supervised_dQ = grad_theta sum_{t=0}^{1} Q_phi(s_t, theta) = 2 phi c`` (``phi``, ``s_t``, ``r_2`` as data:
      the policy gradient the loop follows);
    * ``ours_phi``, ``ours_L``, ``ours_dL``: the same for our ``L_critic`` (``phi`` fitted on ``L_task``);
    * ``meta_critic_phi``, ``meta_critic_beta``, ``meta_critic_Q``, ``meta_critic_dQ``: the same for the
      critic the Meta-Critic policy is trained with, ``Q_phi + Q_meta_beta``;
    * ``*_fixed`` variants of the value/gradient arrays: the same expressions with the critic parameter(s)
      frozen at the values the learning loop converged to (``converged``: ``{method: (phi, beta)}``;
      ``None`` runs the loops from ``theta0 = 0.1``, :func:`converged_critics`).

    Where a fit is degenerate (flat objective) the parameter stays at 0; ``ours_L`` has a pole where
    ``c = 0`` (``ours_phi ~ 1/c``) while ``ours_dL`` stays finite there.
    """
    if thetas is None:
        thetas = default_thetas(s0, g)
    th = as_tensor(thetas).reshape(-1)
    s0_t = as_tensor(s0)
    zeros = torch.zeros_like(th)
    states = data_rollout(s0_t, th)
    r2 = terminal_cost(states, g)
    c = states[0] + states[1] + 2 * th

    phi_sup = fit_td(states, th, g, zeros)
    phi_ours = fit_ours(states, th, s0_t, g, alpha, zeros)
    beta = fit_meta_critic(states, th, phi_sup, alpha, zeros)

    def value(coef):
        return critic_objective(coef, states, th) + r2

    def grad(coef):
        return gradient(lambda x: critic_objective(coef, states, x), th)

    if converged is None:
        converged = converged_critics(s0, g, alpha)
    fixed = {m: torch.full_like(th, float(sum(converged[m]))) for m in METHODS}

    out = {
        "theta": th,
        "Q_true": r2,
        "dQ_true": 4 * (states[T] - g),
        "c": c,
        "supervised_phi": phi_sup,
        "supervised_Q": value(phi_sup),
        "supervised_dQ": grad(phi_sup),
        "ours_phi": phi_ours,
        "ours_L": value(phi_ours),
        "ours_dL": grad(phi_ours),
        "meta_critic_phi": phi_sup,
        "meta_critic_beta": beta,
        "meta_critic_Q": value(phi_sup + beta),
        "meta_critic_dQ": grad(phi_sup + beta),
        "supervised_Q_fixed": value(fixed["supervised"]),
        "supervised_dQ_fixed": grad(fixed["supervised"]),
        "ours_L_fixed": value(fixed["ours"]),
        "ours_dL_fixed": grad(fixed["ours"]),
        "meta_critic_Q_fixed": value(fixed["meta_critic"]),
        "meta_critic_dQ_fixed": grad(fixed["meta_critic"]),
    }
    return {k: v.detach().numpy().copy() for k, v in out.items()}
