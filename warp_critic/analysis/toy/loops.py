"""The three critic-learning loops of the toy on one skeleton, and which fixed point each init reaches.

* supervised Q learning (Algorithm 1): fit ``phi`` by TD, one policy-gradient step on the fitted critic;
* ours (Algorithm 2): fit ``phi`` on the task loss after the inner step, ``theta <- theta_new(phi)``;
* Meta-Critic (Appendix A.3): fit ``phi`` by TD and ``beta`` so that the updated policy improves the TD
  critic, ``theta <- theta_new(beta)``.

Every iteration rolls the current policy out and trains the critic(s) to convergence on that rollout
(:func:`warp_critic.analysis.toy.fit.fit`). Loops are batched over ``theta0``. Details: ``docs/toy.md``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from warp_critic.analysis.toy.closed_forms import closed_form, fixed_points, nearest_fixed_point
from warp_critic.analysis.toy.fit import fit, gradient, newton_step
from warp_critic.analysis.toy.problem import (
    ALPHA,
    as_tensor,
    critic_objective,
    data_rollout,
    inner_step,
    meta_critic_loss,
    task_loss_after_inner_step,
    td_error,
    terminal_cost,
)

NEWTON_DAMPING = 0.8
"""Fraction of the Newton step taken by the default (curvature-normalised) supervised policy step."""

States = list[torch.Tensor]


# ---------------------------------------------------------------------------------------------------
# critic fits ("train to convergence") and policy updates
# ---------------------------------------------------------------------------------------------------
def fit_td(states: States, theta: torch.Tensor, g: float, phi0: torch.Tensor) -> torch.Tensor:
    """Supervised critic: ``phi`` minimising the TD error on the rollout ``states`` of ``theta``."""
    return fit(lambda p: td_error(p, states, theta.detach(), g), phi0)


def fit_ours(
    states: States,
    theta: torch.Tensor,
    s0: torch.Tensor,
    g: float,
    alpha: float,
    phi0: torch.Tensor,
) -> torch.Tensor:
    """Our critic: ``phi`` minimising ``L_task`` of ``theta_new(phi)``."""
    return fit(lambda p: task_loss_after_inner_step(p, theta, states, s0, g, alpha), phi0)


def fit_meta_critic(
    states: States, theta: torch.Tensor, phi: torch.Tensor, alpha: float, beta0: torch.Tensor
) -> torch.Tensor:
    """Meta-Critic: ``beta`` minimising the TD critic ``phi`` at ``theta_new(beta)``."""
    return fit(lambda b: meta_critic_loss(b, phi, theta, states, alpha), beta0)


def policy_step(
    theta: torch.Tensor, coef: torch.Tensor, states: States, policy_lr: float | None
) -> torch.Tensor:
    """One policy-gradient step on ``sum_t Q_coef(s_t, pi_theta(s_t))`` (states and coef as data):
    a plain learning rate, or (``policy_lr=None``) ``NEWTON_DAMPING`` times the Newton step."""
    objective = lambda th: critic_objective(coef.detach(), states, th)  # noqa: E731
    if policy_lr is not None:
        return theta.detach() - policy_lr * gradient(objective, theta)
    step = newton_step(objective, theta)
    return theta.detach() if step is None else theta.detach() - NEWTON_DAMPING * step


# ---------------------------------------------------------------------------------------------------
# one loop skeleton
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Method:
    """One learning loop: which critic parameters it fits and how the policy moves."""

    critics: tuple[str, ...]
    fit: Callable[
        [States, torch.Tensor, dict], dict
    ]  # (states, theta, critic params) -> fitted params
    step: Callable[
        [States, torch.Tensor, dict], torch.Tensor
    ]  # (states, theta, fitted params) -> theta


def method(
    name: str, s0: torch.Tensor, g: float, alpha: float = ALPHA, policy_lr: float | None = None
) -> Method:
    """The loop ``name`` (one of ``METHODS``) for the problem ``(s0, g)``."""
    if name == "supervised":
        return Method(
            ("phi",),
            lambda st, th, p: {"phi": fit_td(st, th, g, p["phi"])},
            lambda st, th, p: policy_step(th, p["phi"], st, policy_lr),
        )
    if name == "ours":
        return Method(
            ("phi",),
            lambda st, th, p: {"phi": fit_ours(st, th, s0, g, alpha, p["phi"])},
            lambda st, th, p: inner_step(th, st, p["phi"], alpha).detach(),
        )
    if name == "meta_critic":

        def fit_both(st, th, p):
            phi = fit_td(st, th, g, p["phi"])
            return {"phi": phi, "beta": fit_meta_critic(st, th, phi, alpha, p["beta"])}

        return Method(
            ("phi", "beta"),
            fit_both,
            lambda st, th, p: inner_step(th, st, p["phi"] + p["beta"], alpha).detach(),
        )
    raise ValueError(f"unknown toy method {name!r}")


def _converged(new: torch.Tensor, old: torch.Tensor, tol: float) -> bool:
    return bool(((new - old).abs() <= tol * (1.0 + old.abs())).all())


def loop(
    name: str,
    s0: float,
    g: float,
    theta0,
    iters: int,
    *,
    alpha: float = ALPHA,
    policy_lr: float | None = None,
    phi0: float = 0.0,
    beta0: float = 0.0,
    tol: float = 1e-13,
):
    """Run the loop ``name`` from every ``theta0`` (batched) until no ``theta`` moves or ``iters`` iterations.

    Returns ``(theta, critic_params, trace)``: final ``theta (B,)``, the critic parameters fitted at it
    (``{'phi'}`` or ``{'phi', 'beta'}``) and arrays ``(iterations, B)``: ``theta`` (starting with
    ``theta0``), the critic parameters and ``cost`` (``r_2``) at each iterate.
    """
    theta = as_tensor(theta0).reshape(-1)
    s0_t = as_tensor(s0)
    m = method(name, s0_t, g, alpha, policy_lr)
    params = {
        k: torch.full_like(theta, float(v))
        for k, v in (("phi", phi0), ("beta", beta0))
        if k in m.critics
    }
    trace: dict[str, list] = {"theta": [theta.clone()], **{k: [] for k in m.critics}, "cost": []}

    def fit_and_record(theta):
        nonlocal params
        states = data_rollout(s0_t, theta)
        params = m.fit(states, theta, params)
        for k, v in params.items():
            trace[k].append(v.clone())
        trace["cost"].append(terminal_cost(states, g))
        return states

    for _ in range(int(iters)):
        states = fit_and_record(theta)
        new = m.step(states, theta, params)
        done = _converged(new, theta, tol)
        theta = new
        trace["theta"].append(theta.clone())
        if done or not bool(torch.isfinite(theta).all()):
            break
    fit_and_record(theta)  # the critic at the final policy
    return theta, params, {k: torch.stack(v).numpy() for k, v in trace.items()}


def _first(theta, params, trace):
    return float(theta[0]), float(params["phi"][0]), {k: v[:, 0].copy() for k, v in trace.items()}


def run_supervised(
    s0: float,
    g: float,
    theta0: float = 0.1,
    iters: int = 500,
    policy_lr: float | None = None,
    phi0: float = 0.0,
    tol: float = 1e-13,
):
    """Run supervised Q learning (Algorithm 1) until ``theta`` stops moving or ``iters`` iterations.

    Each iteration: roll out ``pi_theta``; fit ``phi`` to the TD error to convergence; one policy-gradient
    step on ``sum_t Q_phi(s_t, pi_theta(s_t))`` (states as data). ``policy_lr=None`` uses the
    curvature-normalised step (learning rate ``0.2 / phi``); a float uses that fixed learning rate.

    Returns ``(theta, phi, trace)``: final policy parameter, the TD critic fitted at it, and a dict of
    arrays: ``theta`` (iterates, starting with ``theta0``), ``phi`` and ``cost`` (``r_2``) at each iterate.
    """
    return _first(
        *loop("supervised", s0, g, theta0, iters, policy_lr=policy_lr, phi0=phi0, tol=tol)
    )


def run_ours(
    s0: float,
    g: float,
    theta0: float = 0.1,
    iters: int = 500,
    alpha: float = ALPHA,
    phi0: float = 0.0,
    tol: float = 1e-13,
):
    """Run our model-based meta-learning of the critic (Algorithm 2) with ``theta <- theta_new`` each iteration.

    Each iteration: roll out ``pi_theta``; fit ``phi`` to convergence on ``L_task(theta_new(phi))`` (autograd
    through the inner step ``theta_new = theta - alpha grad_theta sum_t L_critic``); set ``theta = theta_new``.

    Returns ``(theta, phi, trace)`` like :func:`run_supervised` (``phi`` re-fitted at the final ``theta``;
    it is 0 at the optimum).
    """
    return _first(*loop("ours", s0, g, theta0, iters, alpha=alpha, phi0=phi0, tol=tol))


def run_meta_critic(
    s0: float,
    g: float,
    theta0: float = 0.1,
    iters: int = 500,
    alpha: float = ALPHA,
    phi0: float = 0.0,
    beta0: float = 0.0,
    tol: float = 1e-13,
):
    """Run the Meta-Critic loop of Appendix A.3 (TD critic ``phi`` plus meta critic ``beta``).

    Each iteration: roll out; fit ``phi`` by TD; fit ``beta`` so that ``theta_new(beta) = theta - alpha
    grad_theta sum_t (Q_phi + Q_beta)`` minimises ``sum_t Q_phi(s_t, theta_new)``; set ``theta = theta_new``.

    Returns ``(theta, phi, trace)`` where ``phi`` is the TD critic's parameter; the meta critic's ``beta``
    is in ``trace['beta']`` (its last entry is the value at the final policy, which there is flat in
    ``beta`` and keeps the previous iteration's value).
    """
    return _first(
        *loop("meta_critic", s0, g, theta0, iters, alpha=alpha, phi0=phi0, beta0=beta0, tol=tol)
    )


# ---------------------------------------------------------------------------------------------------
# which fixed point from which initialisation
# ---------------------------------------------------------------------------------------------------
def init_sweep(
    s0: float,
    g: float,
    thetas0=None,
    iters: int = 200,
    alpha: float = ALPHA,
    plain_lr: float = 0.05,
) -> list[dict]:
    """Run every loop from several ``theta0`` (batched) and name the fixed point each one ends at.

    Variants: ``supervised`` (normalised policy step), ``supervised/lr=<plain_lr>`` (plain learning rate),
    ``ours``, ``meta_critic``. Default inits: 0, the optimum, ``-2 s0/3``, ``-s0/2`` and offsets around them.
    Returns rows ``{'variant', 'theta0', 'theta', 'nearest', 'kind', 'distance'}``; ``distance`` is to the
    nearest listed fixed point (large = not converged / diverged).
    """
    fps = fixed_points(s0, g)
    cf = closed_form(s0, g)
    if thetas0 is None:
        base = [cf["optimal"], cf["supervised"], -s0 / 2.0]
        thetas0 = np.unique(
            np.r_[
                0.0,
                base,
                cf["optimal"] - 3,
                cf["optimal"] - 0.1,
                (cf["optimal"] + cf["supervised"]) / 2,
                cf["supervised"] + 2,
            ]
        )
    th0 = np.asarray(thetas0, dtype=np.float64)
    variants = {  # variant -> (method, plain policy learning rate)
        "supervised": ("supervised", None),
        f"supervised/lr={plain_lr:g}": ("supervised", plain_lr),
        "ours": ("ours", None),
        "meta_critic": ("meta_critic", None),
    }
    rows = []
    for variant, (name, lr) in variants.items():
        theta = loop(name, s0, g, th0, iters, alpha=alpha, policy_lr=lr)[0]
        for t0, t in zip(th0, theta.numpy()):
            if np.isfinite(t):
                fp, d = nearest_fixed_point(float(t), fps[name])
                rows.append(
                    {
                        "variant": variant,
                        "theta0": float(t0),
                        "theta": float(t),
                        "nearest": fp["theta"],
                        "kind": fp["kind"],
                        "distance": d,
                    }
                )
            else:
                rows.append(
                    {
                        "variant": variant,
                        "theta0": float(t0),
                        "theta": float(t),
                        "nearest": float("nan"),
                        "kind": "diverged",
                        "distance": float("inf"),
                    }
                )
    return rows
