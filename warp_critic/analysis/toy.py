r"""The 1-D analytic example of section 4.1 / Appendix A: which policy does each critic-learning loop recover?

Problem (paper, section 4.1)
----------------------------
* model ``s_{t+1} = f(s_t, a_t) = s_t + a_t``, policy ``a_t = pi_theta(s_t) = theta``, horizon ``T = 2``;
* sparse terminal *cost* ``r_2 = (s_2 - g)^2`` (``r_0 = r_1 = 0``, minimised), ``gamma = 1``;
* critic / Q function ``Q_phi(s_t, a_t) = phi_1 (s_t + a_t)^2`` (``L_critic`` has the same form);
* rollout of ``pi_theta``: ``s_1 = s_0 + theta``, ``s_2 = s_0 + 2 theta``, so the critic features along
  the rollout are ``(s_0 + a)^2 = s_1^2`` and ``(s_1 + a)^2 = s_2^2``;
* true cost ``Q_true(theta) = r_0 + r_1 + r_2 = (s_0 + 2 theta - g)^2``, optimum
  ``theta* = (g - s_0) / 2``.

Throughout, ``c(theta) = s_0 + s_1 + 2 theta = 2 s_0 + 3 theta`` is the policy gradient of the critic
objective per unit of ``2 phi``: ``grad_theta sum_{t=0}^{1} Q_phi(s_t, theta) = 2 phi c`` when the states
``s_t`` are treated as data (as the paper does).

Learning loops (each one is *run*, with torch autograd for every gradient)
--------------------------------------------------------------------------
Every iteration rolls out the current policy and trains the critic **to convergence** on that rollout
("we train the critics to convergence", Appendix A). All critic objectives below are quadratic in the
critic parameter, so "to convergence" is done with autograd Newton steps (gradient and curvature
from ``torch.autograd``), which is exact; where the curvature is zero the objective is flat in the
parameter (a degenerate rollout) and the parameter keeps its previous value.

(a) ``run_supervised`` -- supervised Q learning (Algorithm 1). Fit ``phi`` to the TD error
    ``delta = sum_{t=0}^{1} (Q(s_t,a_t) - (r_t + gamma * [Q(s_{t+1},a_{t+1}) if t+1 < T else r_T]))^2``
    on the current rollout, then take a policy-gradient step on ``sum_{t=0}^{1} Q_phi(s_t, pi_theta(s_t))``
    with ``s_t`` (and ``phi``) held as data. The step size is either a plain learning rate
    (``policy_lr=<float>``, Algorithm 1 literally) or, by default (``policy_lr=None``), a step
    normalised by the curvature ``4 phi`` of that objective: ``theta <- theta - 0.8 * grad / curv``
    (a learning rate ``alpha_k = 0.2 / phi_k``; the update is ``theta <- theta - 0.4 c``). The fixed
    points do not depend on the step size, but the plain step is fragile (see "Fixed points" below);
    the normalised one is robust. (Damping 0.5 would send ``theta_0 = 0`` to the degenerate point
    ``s_2 = 0`` in one step, and 1 -- "train the policy to convergence on the fitted critic" -- in
    two; 2/3 would jump to the fixed point in one step and hide the dynamics.)
(b) ``run_ours`` -- model-based meta-learning of the critic (Algorithm 2). Inner step
    ``theta_new(phi) = theta - alpha * grad_theta sum_{t=0}^{1} L_critic(s_t, theta)`` (rollout states
    as data, ``alpha = 1/2``); outer: roll ``theta_new`` out through the model and minimise
    ``L_task = (s_2^new - g)^2`` over ``phi`` by differentiating through the inner step; the policy is
    then the updated policy, ``theta <- theta_new(phi)``. This is what the paper's fixed-point argument
    assumes: the critic at convergence (``grad_phi L_task = 0``) *and* the policy at convergence
    (``grad_theta L_critic = 0``, i.e. ``theta_new = theta``).
(c) ``run_meta_critic`` -- the Meta-Critic of Zhou et al. (2020) as analysed in Appendix A.3. Two
    critics: ``Q = phi (s+a)^2`` fitted by TD exactly as in (a), and ``Q_meta = beta (s+a)^2``. The
    policy is updated with both, ``theta_new(beta) = theta - alpha grad_theta sum_t (Q + Q_meta)(s_t,
    theta)``, and ``beta`` is fitted so that the *updated* policy improves the TD critic:
    ``min_beta l(beta) = sum_{t=0}^{1} Q_phi(s_t, pi_{theta_new(beta)}(s_t))`` (states as data).
    Then ``theta <- theta_new(beta)``.

Closed forms (derived here; used by :func:`closed_form`)
--------------------------------------------------------
(a) ``phi*(theta) = s_2^2 r_2 / ((s_1^2 - s_2^2)^2 + s_2^4)`` (paper's formula; ``phi* >= 0``). The loop
    is stationary where ``phi* c = 0``. Generic fixed point ``c = 0``:
    ``theta = -(s_0 + s_1)/2`` with ``s_1 = s_0 + theta``  =>  ``theta_sup = -2 s_0 / 3``
    (= 4 for ``s_0 = -6``), where ``phi* = ((s_0 + 3 g) / s_0)^2``. It is optimal only if
    ``s_0 = -3 g`` (e.g. never for ``g = 0, s_0 != 0``). Degenerate fixed points, where the fitted critic
    vanishes (``phi* = 0``) and therefore gives no gradient: ``r_2 = 0`` (``theta = theta*``) and
    ``s_2 = 0`` (``theta = -s_0/2``).
(b) ``L_task(phi) = (s_0 + 2 theta - 4 alpha phi c - g)^2``  =>  ``phi* = (s_0 + 2 theta - g) / (4 alpha c)``
    ``= (s_0 + 2 theta - g) / (2 c)`` for ``alpha = 1/2`` -- the paper's formula. With that ``phi``,
    ``theta_new = (g - s_0)/2 = theta*`` exactly: the loop reaches the optimum in **one** iteration
    (from any ``theta_0`` with ``c != 0``) and then stays there with ``phi* = 0``. ``theta_ours = theta*``.
(c) ``grad_beta l = 0`` with ``phi != 0`` and ``c != 0`` gives ``s_0 + s_1 + 2 theta_new = 0``, i.e. the
    meta critic makes the updated policy jump to the minimiser of the TD critic:
    ``theta_new = -(s_0 + s_1)/2``, ``phi + beta* = 1 / (4 alpha)`` (``beta* = 1/2 - phi`` for
    ``alpha = 1/2``). The iteration is therefore ``theta_{k+1} = -s_0 - theta_k / 2`` (a contraction
    with factor -1/2) and its fixed point is ``theta_meta = -(s_0 + s_1)/2 = -2 s_0 / 3`` -- the same
    non-optimal point as supervised Q learning.

Where this differs from the paper's printed formulas (Appendix A.3), and why
---------------------------------------------------------------------------
The paper prints ``theta = -(s_0 + s_1) / (2 [(s_0 + a)^2 + (s_1 + a)^2])`` for the Meta-Critic. That
is not a fixed point of the Meta-Critic loop. The slips:

1. The policy update is written ``theta - 2 (phi + beta) ((s_0+a)^2 + (s_1+a)^2)``. The gradient of
   ``sum_t (phi + beta)(s_t + theta)^2`` is ``2 (phi + beta) ((s_0+a) + (s_1+a))``: the features
   should not be squared. (The learning rate is also dropped, i.e. ``alpha = 1`` there.)
2. In ``grad_beta l``, the sum over ``t`` of ``theta_new`` gives ``2 theta_new`` (it is then written
   ``2 theta (...)``, mixing the two terms), and the chain-rule factor ``d theta_new / d beta`` is not
   applied consistently.
3. The policy is stationary when ``(phi + beta) c = 0``. The paper takes the branch ``phi = -beta``
   and substitutes it into the ``beta`` optimality condition. But for ``phi != 0, c != 0`` that
   condition forces ``phi + beta = 1/(4 alpha) != 0``, which contradicts the branch; the consistent
   branch is ``c = 0``, i.e. ``theta = -(s_0 + s_1)/2``. (The printed formula also mixes units:
   ``theta`` ~ ``s / s^2``.)

Evidence: for ``s_0 = -6, g = 0`` the printed formula (with ``s_1 = s_0 + theta``, ``a = theta``) has the
single real solution ``theta ~= 0.0864`` (:func:`paper_meta_critic_theta`); one Meta-Critic iteration
from there moves to ``-(s_0 + s_1)/2 ~= 5.96`` and the loop converges to ``4 = -2 s_0 / 3``
(``tests/test_toy.py`` checks this), for every ``(s_0, g)`` tested.

Minor slips elsewhere, which do not change the results: in A.2 the sum is written to ``T = 2`` instead
of ``T - 1 = 1`` and a factor 2 is dropped in ``grad_phi L_task``; in A.1 the convergence condition
is once written with squared features. In section 4.1 / A.2 the division by ``c`` hides a second,
degenerate fixed point of our loop: at ``theta = -2 s_0 / 3`` (``c = 0``) the inner gradient vanishes
for *every* ``phi``, so ``L_task`` is flat in ``phi`` and ``theta`` does not move. It is unstable
(any ``c != 0`` is sent to ``theta*`` in one step) and is reached only by starting exactly there.

Fixed points and initialisations (see :func:`fixed_points`, and the sweep printed by :func:`run_toy`)
* supervised, normalised step (default): every ``theta_0`` converges to ``-2 s_0/3`` (factor -0.2 per
  iteration), except ``theta_0`` exactly on a degenerate point (``phi* = 0``) or on one of its
  (countably many) preimages, where it stays.
* supervised, plain learning rate: ``theta <- theta - lr 2 phi*(theta) c``. Since ``phi* >= 0`` the
  flow always moves towards ``-2 s_0/3``, but the degenerate points (double zeros of ``phi*``) lying
  between ``theta_0`` and ``-2 s_0/3`` capture it (slowly, algebraically): for ``s_0 = -6, g = 0``,
  ``theta_0 < 3`` creeps to ``3`` (the optimum, by accident: ``r_2 = 0`` there), ``theta_0 > 3`` goes
  to ``4``; and ``-2 s_0/3`` is only stable for ``lr < 1 / (3 phi*)`` (``phi* = 625`` for
  ``s_0 = 0.5, g = 4``), otherwise the iteration oscillates or diverges.
* ours: every ``theta_0 != -2 s_0/3`` reaches ``theta*`` after one iteration.
* Meta-Critic: every ``theta_0`` converges to ``-2 s_0/3``, except where an iterate lands exactly on
  a point with ``phi* = 0`` while ``beta = 0`` (then ``l`` is flat in ``beta``, ``beta`` keeps its value and
  the policy update is zero). Such landings are not exotic: the iteration ``theta <- -s_0 - theta/2``
  maps ``theta_0 = 0`` to ``-s_0`` (where, for ``g = 0``, ``beta* = 0`` exactly) and then to ``-s_0/2``
  (``s_2 = 0``, ``phi* = 0``): for ``s_0 = -6, g = 0`` the Meta-Critic started at ``theta_0 = 0`` stops at
  ``theta = 3`` (which happens to be optimal because ``g = 0``). That is why the default
  initialisation is ``theta_0 = 0.1``; the init sweep of :func:`run_toy` shows ``theta_0 = 0``.

What the curves show (:func:`curves`, the appendix figures)
-----------------------------------------------------------
The appendix plots, over a grid of ``theta``, the learned critic "after learning converged and the
optimal parameters ``phi_1`` have been computed" together with ``Q_true`` and the critic's
``theta``-gradient, i.e. ``sum_{t=0}^{1} Q_phi(s_t, theta) + r_2`` and
``grad_theta sum_{t=0}^{1} Q_phi(s_t, theta) = 2 phi c`` with ``phi`` held fixed at its converged value
(and ``s_t``, ``r_2`` as data, exactly the expression of A.1). Following the text, "converged" is the
critic trained to convergence on the rollout of ``pi_theta`` at *each* grid ``theta``:
``phi = phi*(theta)``. Then the plotted gradient is exactly the update the learning loop applies
at that ``theta``, and its zeros are the loop's fixed points: for ``s_0 = -6, g = 0`` the supervised
gradient is zero at ``theta = 3`` (``phi* = 0``; a touching zero, the gradient does not change
sign) and at ``theta = 4`` (sign change), ours only at ``theta = 3`` (``2 phi* c = s_0 + 2 theta - g``,
one quarter of ``dQ_true / dtheta``). This is what the appendix describes (two stationary points at
3 and 4 for supervised Q, one at 3 for ours).

The alternative reading -- ``phi`` frozen at the value the loop converged to and the curve drawn
over ``theta`` with that single ``phi`` -- is returned as the ``*_fixed`` arrays (dashed in the
figures). It cannot reproduce the appendix: for ``s_0 = -6, g = 0`` the supervised ``phi = 1`` gives a convex quadratic with a
single stationary point (gradient zero at 4 only), and our critic converges to ``phi = 0``, so its
value curve is exactly ``Q_true`` and its gradient is identically zero (the critic vanishes once the
policy is optimal: ``L_task = 0`` needs no further update).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from warp_critic.errors import UserError

__all__ = [
    "T", "GAMMA", "ALPHA", "METHODS",
    "rollout", "td_error", "critic_objective", "task_loss_after_inner_step", "meta_critic_loss",
    "closed_form", "closed_form_critic_params", "default_thetas", "fixed_points", "paper_meta_critic_theta",
    "run_supervised", "run_ours", "run_meta_critic", "curves", "stationary_points",
    "init_sweep", "run_toy", "add_arguments", "run_from_args",
]

T = 2
"""Horizon: states ``s_0, s_1, s_2``; actions at ``t = 0, 1``; reward only at ``t = T``."""
GAMMA = 1.0
"""Discount factor used in the TD error."""
ALPHA = 0.5
"""Inner (policy) learning rate of our method and of the Meta-Critic policy update."""
METHODS = ("supervised", "ours", "meta_critic")
NEWTON_DAMPING = 0.8
"""Fraction of the Newton step taken by the default (curvature-normalised) supervised policy step."""

_DT = torch.float64


# ---------------------------------------------------------------------------------------------------
# The problem (torch, elementwise over a batch of independent thetas)
# ---------------------------------------------------------------------------------------------------
def _t(x) -> torch.Tensor:
    return torch.as_tensor(np.asarray(x, dtype=np.float64), dtype=_DT)


def rollout(s0: torch.Tensor, theta: torch.Tensor) -> list[torch.Tensor]:
    """States ``[s_0, s_1, s_2]`` of ``pi_theta`` (``a_t = theta``) under the model ``s_{t+1} = s_t + a_t``."""
    states = [s0 + 0.0 * theta]
    for _ in range(T):
        states.append(states[-1] + theta)
    return states


def _reward(s: torch.Tensor, t: int, g: float) -> torch.Tensor:
    """Sparse cost: 0 for ``t < T``, ``(s_T - g)^2`` at ``t = T``."""
    return (s - g) ** 2 if t == T else torch.zeros_like(s)


def _critic(phi: torch.Tensor, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
    """``Q_phi(s, a) = phi (s + a)^2`` (also the form of ``L_critic``)."""
    return phi * (s + a) ** 2


def critic_objective(phi: torch.Tensor, states: list[torch.Tensor], theta: torch.Tensor) -> torch.Tensor:
    """``sum_{t=0}^{T-1} Q_phi(s_t, pi_theta(s_t))`` with the given (data) states."""
    return sum(_critic(phi, states[t], theta) for t in range(T))


def td_error(phi: torch.Tensor, states: list[torch.Tensor], theta: torch.Tensor, g: float,
             gamma: float = GAMMA) -> torch.Tensor:
    """Supervised TD loss ``delta`` of eq. (2) on one rollout (states, actions and rewards are data).

    ``delta = sum_{t=0}^{T-1} (Q(s_t, a_t) - (r_t + gamma * V_{t+1}))^2`` with ``V_{t+1} = Q(s_{t+1}, a_{t+1})``
    for ``t + 1 < T`` and the terminal cost ``V_T = r_T``.
    """
    delta = 0.0
    for t in range(T):
        nxt = _reward(states[T], T, g) if t + 1 == T else _critic(phi, states[t + 1], theta)
        target = _reward(states[t], t, g) + gamma * nxt
        delta = delta + (_critic(phi, states[t], theta) - target) ** 2
    return delta


def _inner_step(theta: torch.Tensor, states: list[torch.Tensor], coef: torch.Tensor,
                alpha: float) -> torch.Tensor:
    """``theta - alpha * grad_theta sum_t coef (s_t + theta)^2`` (states as data), differentiable in ``coef``."""
    th = theta.detach().clone().requires_grad_(True)
    obj = critic_objective(coef, states, th)
    (grad,) = torch.autograd.grad(obj.sum(), th, create_graph=True)
    return th.detach() - alpha * grad


def task_loss_after_inner_step(phi: torch.Tensor, theta: torch.Tensor, states: list[torch.Tensor],
                               s0: torch.Tensor, g: float, alpha: float = ALPHA) -> torch.Tensor:
    """Our outer objective: ``L_task = (s_2^new - g)^2`` for ``theta_new(phi)`` rolled out through the model."""
    theta_new = _inner_step(theta, states, phi, alpha)
    new_states = rollout(s0, theta_new)
    return sum(_reward(new_states[t], t, g) for t in range(T + 1))


def meta_critic_loss(beta: torch.Tensor, phi: torch.Tensor, theta: torch.Tensor,
                     states: list[torch.Tensor], alpha: float = ALPHA) -> torch.Tensor:
    """Meta-Critic objective ``l(beta) = sum_t Q_phi(s_t, pi_{theta_new(beta)}(s_t))`` (states, phi as data)."""
    theta_new = _inner_step(theta, states, phi.detach() + beta, alpha)
    return critic_objective(phi.detach(), states, theta_new)


def _fit(loss_fn: Callable[[torch.Tensor], torch.Tensor], p0: torch.Tensor, max_steps: int = 5,
         rtol: float = 1e-12) -> torch.Tensor:
    """Minimise ``loss_fn`` elementwise over ``p`` (a batch of independent scalar problems) by autograd Newton steps.

    All objectives used here are quadratic in ``p``, so one step is exact up to rounding; steps are repeated
    until the step is below ``rtol * (1 + |p|)`` (this also repairs the rounding of a first step taken from a
    far-away ``p0``). Elements whose curvature is not positive (the loss is flat in ``p``) keep their value.
    """
    p = p0.detach().clone()
    for _ in range(max_steps):
        p.requires_grad_(True)
        (grad,) = torch.autograd.grad(loss_fn(p).sum(), p, create_graph=True)
        if grad.grad_fn is None:  # the loss does not depend on p at all
            return p.detach()
        (curv,) = torch.autograd.grad(grad.sum(), p, allow_unused=True)
        if curv is None:
            return p.detach()
        ok = curv > 0
        step = torch.where(ok, grad.detach() / torch.where(ok, curv, torch.ones_like(curv)),
                           torch.zeros_like(curv))
        p = p.detach() - step
        if bool((step.abs() <= rtol * (1.0 + p.abs())).all()):
            break
    return p.detach()


# ---------------------------------------------------------------------------------------------------
# Closed forms
# ---------------------------------------------------------------------------------------------------
def closed_form(s0: float, g: float) -> dict[str, float]:
    """Fixed points (policy parameters) of the three learning loops, and the optimum, in closed form.

    Returns ``{'supervised': -2 s0/3, 'ours': (g - s0)/2, 'meta_critic': -2 s0/3, 'optimal': (g - s0)/2}``
    (see the module docstring for the derivations; the Meta-Critic value differs from the paper's
    printed formula, :func:`paper_meta_critic_theta`).
    """
    s0, g = float(s0), float(g)
    return {
        "supervised": -2.0 * s0 / 3.0,
        "ours": (g - s0) / 2.0,
        "meta_critic": -2.0 * s0 / 3.0,
        "optimal": (g - s0) / 2.0,
    }


def closed_form_critic_params(s0: float, g: float, thetas, alpha: float = ALPHA) -> dict[str, np.ndarray]:
    """Converged critic parameters on the rollout of ``pi_theta``, in closed form, for each ``theta``.

    ``supervised``: ``phi* = s_2^2 r_2 / ((s_1^2 - s_2^2)^2 + s_2^4)``; ``ours``:
    ``phi* = (s_0 + 2 theta - g) / (4 alpha c)``; ``meta_critic_beta``: ``1/(4 alpha) - phi*_sup``.
    Degenerate rollouts (flat objective) give ``nan``.
    """
    th = np.asarray(thetas, dtype=np.float64)
    s1, s2 = s0 + th, s0 + 2 * th
    r2 = (s2 - g) ** 2
    c = s0 + s1 + 2 * th
    with np.errstate(divide="ignore", invalid="ignore"):
        den = (s1 ** 2 - s2 ** 2) ** 2 + s2 ** 4
        phi_sup = np.where(den > 0, s2 ** 2 * r2 / np.where(den > 0, den, 1.0), np.nan)
        phi_ours = np.where(c != 0, (s2 - g) / (4 * alpha * np.where(c != 0, c, 1.0)), np.nan)
        beta = np.where((phi_sup != 0) & (c != 0), 1.0 / (4 * alpha) - phi_sup, np.nan)
    return {"supervised": phi_sup, "ours": phi_ours, "meta_critic_phi": phi_sup, "meta_critic_beta": beta}


def fixed_points(s0: float, g: float) -> dict[str, list[dict]]:
    """All fixed points of the three loops: ``{method: [{'theta', 'kind', 'why'}, ...]}``.

    ``kind`` is ``'attracting'`` (reached from generic initialisations by the default solvers) or
    ``'degenerate'`` (the update vanishes because the fitted critic gives no gradient; reached only
    from that exact point, or -- supervised with a plain learning rate -- crept towards from one side).
    Coinciding points are listed once.
    """
    cf = closed_form(s0, g)
    a, opt, z = cf["supervised"], cf["optimal"], -float(s0) / 2.0

    def dedup(items):
        out = []
        for it in items:
            if not any(abs(it["theta"] - o["theta"]) < 1e-12 for o in out):
                out.append(it)
        return out

    return {
        "supervised": dedup([
            {"theta": a, "kind": "attracting", "why": "c = s0 + s1 + 2 theta = 0 (minimiser of the fitted Q)"},
            {"theta": opt, "kind": "degenerate", "why": "r2 = 0 => phi* = 0 (optimal)"},
            {"theta": z, "kind": "degenerate", "why": "s2 = 0 => phi* = 0"},
        ]),
        "ours": dedup([
            {"theta": opt, "kind": "attracting", "why": "L_task = 0 after one inner step (optimal)"},
            {"theta": a, "kind": "degenerate", "why": "c = 0: inner gradient is 0 for every phi"},
        ]),
        "meta_critic": dedup([
            {"theta": a, "kind": "attracting", "why": "c = 0 (updated policy minimises the TD critic)"},
            {"theta": opt, "kind": "degenerate", "why": "phi* = 0 (r2 = 0): l flat in beta; fixed only with beta = 0"},
            {"theta": z, "kind": "degenerate", "why": "phi* = 0 (s2 = 0): l flat in beta; fixed only with beta = 0"},
        ]),
    }


def paper_meta_critic_theta(s0: float) -> float:
    """The paper's printed Meta-Critic "fixed point" (Appendix A.3), solved for ``theta``.

    ``theta = -(s0 + s1) / (2 [(s0 + a)^2 + (s1 + a)^2])`` with ``s1 = s0 + theta``, ``a = theta``, i.e. the
    cubic ``2 theta [(s0 + theta)^2 + (s0 + 2 theta)^2] + 2 s0 + theta = 0``. Returns the real root closest
    to zero. It is *not* a fixed point of the Meta-Critic loop (see the module docstring).
    """
    P = np.polynomial.Polynomial
    th = P([0.0, 1.0])
    poly = 2 * th * ((s0 + th) ** 2 + (s0 + 2 * th) ** 2) + (2 * s0 + th)
    roots = poly.roots()
    real = roots[np.abs(roots.imag) < 1e-9].real
    return float(real[np.argmin(np.abs(real))])


# ---------------------------------------------------------------------------------------------------
# Learning loops (batched over theta0 internally)
# ---------------------------------------------------------------------------------------------------
def _fit_td(s0: torch.Tensor, theta: torch.Tensor, g: float, phi0: torch.Tensor):
    states = [s.detach() for s in rollout(s0, theta.detach())]
    phi = _fit(lambda p: td_error(p, states, theta.detach(), g), phi0)
    return phi, states


def _policy_step(theta: torch.Tensor, coef: torch.Tensor, states: list[torch.Tensor],
                 policy_lr: float | None) -> torch.Tensor:
    """One policy-gradient step on ``sum_t Q_coef(s_t, pi_theta(s_t))`` (states and coef as data)."""
    th = theta.detach().clone().requires_grad_(True)
    (grad,) = torch.autograd.grad(critic_objective(coef.detach(), states, th).sum(), th, create_graph=True)
    if policy_lr is not None:
        return th.detach() - policy_lr * grad.detach()
    (curv,) = torch.autograd.grad(grad.sum(), th)
    ok = curv > 0
    step = torch.where(ok, grad.detach() / torch.where(ok, curv, torch.ones_like(curv)), torch.zeros_like(curv))
    return th.detach() - NEWTON_DAMPING * step


def _converged(new: torch.Tensor, old: torch.Tensor, tol: float) -> bool:
    return bool(((new - old).abs() <= tol * (1.0 + old.abs())).all())


def _loop_supervised(s0, g, theta0, iters, policy_lr=None, phi0=0.0, tol=1e-13):
    theta = _t(theta0).reshape(-1)
    s0_t = _t(s0)
    phi = torch.full_like(theta, float(phi0))
    tr = {"theta": [theta.clone()], "phi": [], "cost": []}
    for _ in range(int(iters)):
        phi, states = _fit_td(s0_t, theta, g, phi)
        tr["phi"].append(phi.clone())
        tr["cost"].append(_reward(states[T], T, g))
        new = _policy_step(theta, phi, states, policy_lr)
        done = _converged(new, theta, tol)
        theta = new
        tr["theta"].append(theta.clone())
        if done or not bool(torch.isfinite(theta).all()):
            break
    phi, states = _fit_td(s0_t, theta, g, phi)  # the critic at the final policy
    tr["phi"].append(phi.clone())
    tr["cost"].append(_reward(states[T], T, g))
    return theta, phi, {k: torch.stack(v).numpy() for k, v in tr.items()}


def _loop_ours(s0, g, theta0, iters, alpha=ALPHA, phi0=0.0, tol=1e-13):
    theta = _t(theta0).reshape(-1)
    s0_t = _t(s0)
    phi = torch.full_like(theta, float(phi0))
    tr = {"theta": [theta.clone()], "phi": [], "cost": []}

    def fit(theta, phi):
        states = [s.detach() for s in rollout(s0_t, theta)]
        phi = _fit(lambda p: task_loss_after_inner_step(p, theta, states, s0_t, g, alpha), phi)
        return phi, states

    for _ in range(int(iters)):
        phi, states = fit(theta, phi)
        tr["phi"].append(phi.clone())
        tr["cost"].append(_reward(states[T], T, g))
        new = _inner_step(theta, states, phi, alpha).detach()  # theta <- theta_new(phi*)
        done = _converged(new, theta, tol)
        theta = new
        tr["theta"].append(theta.clone())
        if done or not bool(torch.isfinite(theta).all()):
            break
    phi, states = fit(theta, phi)
    tr["phi"].append(phi.clone())
    tr["cost"].append(_reward(states[T], T, g))
    return theta, phi, {k: torch.stack(v).numpy() for k, v in tr.items()}


def _loop_meta_critic(s0, g, theta0, iters, alpha=ALPHA, phi0=0.0, beta0=0.0, tol=1e-13):
    theta = _t(theta0).reshape(-1)
    s0_t = _t(s0)
    phi = torch.full_like(theta, float(phi0))
    beta = torch.full_like(theta, float(beta0))
    tr = {"theta": [theta.clone()], "phi": [], "beta": [], "cost": []}

    def fit(theta, phi, beta):
        phi, states = _fit_td(s0_t, theta, g, phi)
        beta = _fit(lambda b: meta_critic_loss(b, phi, theta, states, alpha), beta)
        return phi, beta, states

    for _ in range(int(iters)):
        phi, beta, states = fit(theta, phi, beta)
        tr["phi"].append(phi.clone())
        tr["beta"].append(beta.clone())
        tr["cost"].append(_reward(states[T], T, g))
        new = _inner_step(theta, states, phi + beta, alpha).detach()
        done = _converged(new, theta, tol)
        theta = new
        tr["theta"].append(theta.clone())
        if done or not bool(torch.isfinite(theta).all()):
            break
    phi, beta, states = fit(theta, phi, beta)
    tr["phi"].append(phi.clone())
    tr["beta"].append(beta.clone())
    tr["cost"].append(_reward(states[T], T, g))
    return theta, (phi, beta), {k: torch.stack(v).numpy() for k, v in tr.items()}


def _scalar_trace(trace: dict) -> dict[str, np.ndarray]:
    return {k: v[:, 0].copy() for k, v in trace.items()}


def run_supervised(s0: float, g: float, theta0: float = 0.1, iters: int = 500,
                   policy_lr: float | None = None, phi0: float = 0.0, tol: float = 1e-13):
    """Run supervised Q learning (Algorithm 1) until ``theta`` stops moving or ``iters`` iterations.

    Each iteration: roll out ``pi_theta``; fit ``phi`` to the TD error to convergence; one policy-gradient
    step on ``sum_t Q_phi(s_t, pi_theta(s_t))`` (states as data). ``policy_lr=None`` uses the
    curvature-normalised step (learning rate ``0.5 / (4 phi)``); a float uses that fixed learning rate.

    Returns ``(theta, phi, trace)``: final policy parameter, the TD critic fitted at it, and a dict of
    arrays: ``theta`` (iterates, starting with ``theta0``), ``phi`` and ``cost`` (``r_2``) at each iterate.
    """
    theta, phi, tr = _loop_supervised(s0, g, theta0, iters, policy_lr, phi0, tol)
    return float(theta[0]), float(phi[0]), _scalar_trace(tr)


def run_ours(s0: float, g: float, theta0: float = 0.1, iters: int = 500, alpha: float = ALPHA,
             phi0: float = 0.0, tol: float = 1e-13):
    """Run our model-based meta-learning of the critic (Algorithm 2) with ``theta <- theta_new`` each iteration.

    Each iteration: roll out ``pi_theta``; fit ``phi`` to convergence on ``L_task(theta_new(phi))`` (autograd
    through the inner step ``theta_new = theta - alpha grad_theta sum_t L_critic``); set ``theta = theta_new``.

    Returns ``(theta, phi, trace)`` like :func:`run_supervised` (``phi`` re-fitted at the final ``theta``;
    it is 0 at the optimum).
    """
    theta, phi, tr = _loop_ours(s0, g, theta0, iters, alpha, phi0, tol)
    return float(theta[0]), float(phi[0]), _scalar_trace(tr)


def run_meta_critic(s0: float, g: float, theta0: float = 0.1, iters: int = 500, alpha: float = ALPHA,
                    phi0: float = 0.0, beta0: float = 0.0, tol: float = 1e-13):
    """Run the Meta-Critic loop of Appendix A.3 (TD critic ``phi`` plus meta critic ``beta``).

    Each iteration: roll out; fit ``phi`` by TD; fit ``beta`` so that ``theta_new(beta) = theta - alpha
    grad_theta sum_t (Q_phi + Q_beta)`` minimises ``sum_t Q_phi(s_t, theta_new)``; set ``theta = theta_new``.

    Returns ``(theta, phi, trace)`` where ``phi`` is the TD critic's parameter; the meta critic's ``beta``
    is in ``trace['beta']`` (its last entry is the value at the final policy, which there is flat in
    ``beta`` and keeps the previous iteration's value).
    """
    theta, (phi, _beta), tr = _loop_meta_critic(s0, g, theta0, iters, alpha, phi0, beta0, tol)
    return float(theta[0]), float(phi[0]), _scalar_trace(tr)


# ---------------------------------------------------------------------------------------------------
# Curves over theta (the appendix figures)
# ---------------------------------------------------------------------------------------------------
def default_thetas(s0: float, g: float, n: int = 400) -> np.ndarray:
    """The plotting grid: ``n`` points from 5 below to 4 above the fixed points (``[-2, 8]`` for ``s0=-6, g=0``).

    Grid points that fall on a special point (``theta*``, ``-2 s0/3``, ``-s0/2``) are moved by a quarter step:
    there a critic fit is degenerate (flat objective: ``c = 0`` for ours, ``phi* = 0`` for the Meta-Critic's
    ``beta``) and the "converged critic" is not defined; those points are the degenerate fixed points
    listed by :func:`fixed_points`.
    """
    pts = np.array([(g - s0) / 2.0, -2.0 * s0 / 3.0, -s0 / 2.0])
    th = np.linspace(pts.min() - 5.0, pts.max() + 4.0, int(n))
    step = th[1] - th[0] if th.size > 1 else 1.0
    for p in pts:  # keep grid points off the special points, where a critic fit is degenerate
        near = np.abs(th - p) < 1e-6 * step
        th[near] += 0.25 * step
    return th


def curves(s0: float = -6.0, g: float = 0.0, thetas=None, alpha: float = ALPHA,
           converged: dict | None = None) -> dict[str, np.ndarray]:
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
      ``None`` runs the loops from ``theta0 = 0.1``), see the module docstring.

    Where a fit is degenerate (flat objective) the parameter stays at 0; ``ours_L`` has a pole where
    ``c = 0`` (``ours_phi ~ 1/c``) while ``ours_dL`` stays finite there.
    """
    if thetas is None:
        thetas = default_thetas(s0, g)
    th = _t(thetas).reshape(-1)
    s0_t = _t(s0)
    zeros = torch.zeros_like(th)
    states = [s.detach() for s in rollout(s0_t, th)]
    r2 = _reward(states[T], T, g)
    c = states[0] + states[1] + 2 * th

    phi_sup = _fit(lambda p: td_error(p, states, th, g), zeros)
    phi_ours = _fit(lambda p: task_loss_after_inner_step(p, th, states, s0_t, g, alpha), zeros)
    beta = _fit(lambda b: meta_critic_loss(b, phi_sup, th, states, alpha), zeros)

    def value(coef):
        return critic_objective(coef, states, th) + r2

    def grad(coef):
        x = th.detach().clone().requires_grad_(True)
        (gr,) = torch.autograd.grad(critic_objective(coef, states, x).sum(), x)
        return gr

    if converged is None:
        converged = {
            "supervised": (run_supervised(s0, g)[1], 0.0),
            "ours": (run_ours(s0, g, alpha=alpha)[1], 0.0),
        }
        _, (p_m, b_m), _ = _loop_meta_critic(s0, g, 0.1, 500, alpha)
        converged["meta_critic"] = (float(p_m[0]), float(b_m[0]))
    fixed = {m: torch.full_like(th, float(sum(converged[m]))) for m in METHODS}

    out = {
        "theta": th, "Q_true": r2, "dQ_true": 4 * (states[T] - g), "c": c,
        "supervised_phi": phi_sup, "supervised_Q": value(phi_sup), "supervised_dQ": grad(phi_sup),
        "ours_phi": phi_ours, "ours_L": value(phi_ours), "ours_dL": grad(phi_ours),
        "meta_critic_phi": phi_sup, "meta_critic_beta": beta,
        "meta_critic_Q": value(phi_sup + beta), "meta_critic_dQ": grad(phi_sup + beta),
        "supervised_Q_fixed": value(fixed["supervised"]), "supervised_dQ_fixed": grad(fixed["supervised"]),
        "ours_L_fixed": value(fixed["ours"]), "ours_dL_fixed": grad(fixed["ours"]),
        "meta_critic_Q_fixed": value(fixed["meta_critic"]), "meta_critic_dQ_fixed": grad(fixed["meta_critic"]),
    }
    return {k: v.detach().numpy().copy() for k, v in out.items()}


_CURVE_KEYS = {  # method -> (value key, gradient key)
    "supervised": ("supervised_Q", "supervised_dQ"),
    "ours": ("ours_L", "ours_dL"),
    "meta_critic": ("meta_critic_Q", "meta_critic_dQ"),
}


def stationary_points(thetas, grad, rtol: float = 1e-6, vertex_rtol: float = 0.1) -> list[tuple[float, str]]:
    """Zeros of a gradient sampled on a grid: ``[(theta, kind), ...]`` sorted by ``theta``.

    * ``'sign change'``: neighbouring samples with opposite signs; the root is located by linear
      interpolation (so it is only as accurate as the grid resolves the curve).
    * ``'touch'``: the gradient reaches zero without changing sign (a double/quartic zero, e.g. where the
      fitted critic vanishes). Detected either as samples with ``|grad| <= rtol * max|grad|`` (a run of them
      counts once; it is a sign change if the samples around the run have opposite signs), or as a local
      minimum of ``|grad|`` whose interpolating parabola through the three samples reaches zero or comes
      within ``vertex_rtol`` of the neighbouring values (a non-zero minimum that the grid resolves has its
      vertex near the neighbouring values, ratio ~1). The location is the parabola's vertex.

    Non-finite samples are skipped.
    """
    th = np.asarray(thetas, dtype=np.float64)
    gr = np.asarray(grad, dtype=np.float64)
    keep = np.isfinite(gr)
    th, gr = th[keep], gr[keep]
    n = gr.size
    if n == 0 or float(np.max(np.abs(gr))) == 0.0:
        return []
    tol = rtol * float(np.max(np.abs(gr)))
    sgn = np.sign(np.where(np.abs(gr) <= tol, 0.0, gr))
    out: list[tuple[float, str]] = []
    i = 0
    while i < n:
        if sgn[i] == 0:  # a run of (near-)zero samples: one stationary point
            j = i
            while j + 1 < n and sgn[j + 1] == 0:
                j += 1
            k = i + int(np.argmin(np.abs(gr[i:j + 1])))
            left = sgn[i - 1] if i > 0 else 0
            right = sgn[j + 1] if j + 1 < n else 0
            if i > 0 and j + 1 < n:
                kind = "sign change" if left * right < 0 else "touch"
                x_k = float(th[k])
                if kind == "touch" and 0 < k < n - 1:  # refine by the vertex of the parabola around the minimum
                    xs = th[k - 1:k + 2] - th[k]
                    a, b, _ = np.polyfit(xs, gr[k - 1:k + 2], 2)
                    if a != 0.0 and xs[0] <= -b / (2 * a) <= xs[2]:
                        x_k = float(th[k] - b / (2 * a))
                out.append((x_k, kind))
            i = j + 1
            continue
        if i + 1 < n and sgn[i] * sgn[i + 1] < 0:
            out.append((float(th[i] - gr[i] * (th[i + 1] - th[i]) / (gr[i + 1] - gr[i])), "sign change"))
        i += 1
    absg = np.abs(gr)
    last = -10
    for k in range(1, n - 1):
        if not (sgn[k - 1] == sgn[k] == sgn[k + 1] != 0):
            continue
        if absg[k] > absg[k - 1] or absg[k] > absg[k + 1] or k - last <= 2:
            continue
        x = th[k - 1:k + 2] - th[k]
        a, b, c = np.polyfit(x, gr[k - 1:k + 2], 2)
        if a == 0.0:
            continue
        xv = -b / (2 * a)
        v = c - b * b / (4 * a)
        if not (x[0] <= xv <= x[2]):
            continue
        if v * gr[k] <= 0 or abs(v) <= vertex_rtol * max(absg[k - 1], absg[k + 1]):
            out.append((float(th[k] + xv), "touch"))
            last = k
    return sorted(out)


# ---------------------------------------------------------------------------------------------------
# Which fixed point from which initialisation
# ---------------------------------------------------------------------------------------------------
def _nearest_fixed_point(theta: float, fps: list[dict]) -> tuple[dict, float]:
    best = min(fps, key=lambda f: abs(f["theta"] - theta))
    return best, abs(best["theta"] - theta)


def init_sweep(s0: float, g: float, thetas0=None, iters: int = 200, alpha: float = ALPHA,
               plain_lr: float = 0.05) -> list[dict]:
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
        thetas0 = np.unique(np.r_[0.0, base, cf["optimal"] - 3, cf["optimal"] - 0.1,
                                  (cf["optimal"] + cf["supervised"]) / 2, cf["supervised"] + 2])
    th0 = np.asarray(thetas0, dtype=np.float64)
    runs = {
        "supervised": (_loop_supervised(s0, g, th0, iters)[0], "supervised"),
        f"supervised/lr={plain_lr:g}": (_loop_supervised(s0, g, th0, iters, policy_lr=plain_lr)[0], "supervised"),
        "ours": (_loop_ours(s0, g, th0, iters, alpha)[0], "ours"),
        "meta_critic": (_loop_meta_critic(s0, g, th0, iters, alpha)[0], "meta_critic"),
    }
    rows = []
    for variant, (theta, method) in runs.items():
        for t0, t in zip(th0, theta.numpy()):
            if np.isfinite(t):
                fp, d = _nearest_fixed_point(float(t), fps[method])
                rows.append({"variant": variant, "theta0": float(t0), "theta": float(t),
                             "nearest": fp["theta"], "kind": fp["kind"], "distance": d})
            else:
                rows.append({"variant": variant, "theta0": float(t0), "theta": float(t),
                             "nearest": float("nan"), "kind": "diverged", "distance": float("inf")})
    return rows


# ---------------------------------------------------------------------------------------------------
# Figures, recording, report
# ---------------------------------------------------------------------------------------------------
_TITLES = {
    "supervised": "Supervised Q learning (Alg. 1)",
    "ours": r"Ours: model-based meta-learned $\mathcal{L}_{critic}$ (Alg. 2)",
    "meta_critic": r"Meta-Critic: $Q_\phi + Q_{meta,\beta}$ (App. A.3)",
}


def _robust_ylim(*arrays, q: float = 0.95, pad: float = 0.1):
    vals = np.concatenate([np.asarray(a)[np.isfinite(a)] for a in arrays])
    lo, hi = np.quantile(vals, 1 - q), np.quantile(vals, q)
    lo, hi = min(lo, 0.0), max(hi, 0.0)
    span = hi - lo if hi > lo else 1.0
    return lo - pad * span, hi + pad * span


def _plot_method(path: Path, method: str, cv: dict, result: dict, s0: float, g: float) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    vkey, gkey = _CURVE_KEYS[method]
    th = cv["theta"]
    fig = Figure(figsize=(7.0, 6.5), dpi=110)
    FigureCanvasAgg(fig)
    ax_v, ax_g = fig.subplots(2, 1, sharex=True)
    crit = r"$\sum_{t=0}^{1} \mathcal{L}_{critic}(s_t,\theta) + r_2$" if method == "ours" \
        else r"$\sum_{t=0}^{1} Q(s_t,\theta) + r_2$"
    ax_v.plot(th, cv["Q_true"], color="k", lw=2, label=r"$Q_{true} = r_2 = (s_0+2\theta-g)^2$")
    # break the line at the pole of our critic (phi* ~ 1/c where c = s0 + s1 + 2 theta changes sign)
    cut = np.flatnonzero(np.sign(cv["c"][:-1]) * np.sign(cv["c"][1:]) < 0) + 1
    ax_v.plot(np.insert(th, cut, np.nan), np.insert(cv[vkey], cut, np.nan), color="C0", lw=2,
              label=crit + r", critic fitted at each $\theta$")
    ax_v.plot(th, cv[vkey + "_fixed"], color="C0", ls="--", lw=1,
              label="critic frozen at the loop's converged value")
    ax_v.set_ylim(*_robust_ylim(cv["Q_true"], cv[vkey]))
    ax_v.set_ylabel("value (cost)")
    ax_v.legend(fontsize=7, loc="upper center")
    ax_v.set_title(f"{_TITLES[method]}   ($s_0={s0:g}$, $g={g:g}$)", fontsize=10)

    ax_g.plot(th, cv["dQ_true"], color="k", lw=2, label=r"$dQ_{true}/d\theta$")
    coef = r"(\phi+\beta)" if method == "meta_critic" else r"\phi"
    ax_g.plot(th, cv[gkey], color="C1", lw=2,
              label=r"policy gradient $2\," + coef + r"\,(s_0+s_1+2\theta)$, critic fitted at each $\theta$")
    ax_g.plot(th, cv[gkey + "_fixed"], color="C1", ls="--", lw=1, label="with the converged critic frozen")
    ax_g.axhline(0.0, color="0.5", lw=0.8)
    for j, (x, kind) in enumerate(result["stationary_points"][method]):
        ax_g.plot([x], [0.0], marker="o" if kind == "sign change" else "D", ms=8, mfc="none", mec="C3", mew=2)
        ax_g.annotate(f"{x:.3g} ({kind})", (x, 0.0), textcoords="offset points",
                      xytext=(6, 10 if j % 2 == 0 else -16), fontsize=8, color="C3")
    opt = result["optimal"]
    for ax in (ax_v, ax_g):
        ax.axvline(opt, color="g", ls=":", lw=1.2, label=r"optimal $\theta^*$")
        ax.axvline(result["numerical"][method], color="C3", ls="-.", lw=1.0, label="loop converged to")
    ax_g.set_ylim(*_robust_ylim(cv["dQ_true"], cv[gkey]))
    ax_g.set_xlabel(r"policy parameter $\theta$")
    ax_g.set_ylabel(r"$d/d\theta$")
    ax_g.legend(fontsize=7, loc="upper left")
    fig.subplots_adjust(left=0.1, right=0.97, top=0.94, bottom=0.08, hspace=0.08)
    fig.savefig(path)


def _blueprint():
    from warp_critic.recording import rrb

    cols = []
    for m in METHODS:
        cols.append(rrb.Vertical(
            rrb.TimeSeriesView(origin=f"/toy/{m}/value", name=f"{m}: value vs theta_index"),
            rrb.TimeSeriesView(origin=f"/toy/{m}/gradient", name=f"{m}: d/dtheta vs theta_index"),
            rrb.TimeSeriesView(origin=f"/toy/{m}/trace", name=f"{m}: learning trace (timeline 'iteration')"),
        ))
    return rrb.Blueprint(rrb.Horizontal(*cols), rrb.TimePanel(timeline="theta_index"))


def _default_recorder(path: Path, blueprint):
    from warp_critic.recording import Recorder

    return Recorder(path, application_id="warp-critic-toy", blueprint=blueprint)


def _record(rec, cv: dict, traces: dict, result: dict) -> None:
    colors = {"true": (20, 20, 20), "critic": (31, 119, 180), "fixed": (140, 180, 230)}
    for m in METHODS:
        vkey, gkey = _CURVE_KEYS[m]
        for grp, true_name in (("value", "Q_true"), ("gradient", "dQ_true")):
            rec.series_style(f"toy/{m}/{grp}/{true_name}", true_name, colors["true"])
            rec.series_style(f"toy/{m}/{grp}/critic", "critic (fitted at each theta)", colors["critic"])
            rec.series_style(f"toy/{m}/{grp}/critic_fixed", "critic (frozen at convergence)", colors["fixed"])
    rec.series_style("toy/grid/theta", "theta at theta_index")
    for i, th in enumerate(cv["theta"]):
        rec.set_time("theta_index", i)
        rec.scalar("toy/grid/theta", th)
        for m in METHODS:
            vkey, gkey = _CURVE_KEYS[m]
            vals = {
                f"toy/{m}/value/Q_true": cv["Q_true"][i], f"toy/{m}/value/critic": cv[vkey][i],
                f"toy/{m}/value/critic_fixed": cv[vkey + "_fixed"][i],
                f"toy/{m}/gradient/dQ_true": cv["dQ_true"][i], f"toy/{m}/gradient/critic": cv[gkey][i],
                f"toy/{m}/gradient/critic_fixed": cv[gkey + "_fixed"][i],
            }
            for ent, v in vals.items():
                if np.isfinite(v):
                    rec.scalar(ent, v)
    rec.reset_time()
    for m in METHODS:
        tr = traces[m]
        for k in range(len(tr["theta"])):
            rec.set_time("iteration", k)
            for name, arr in tr.items():
                if k < len(arr) and np.isfinite(arr[k]):
                    rec.scalar(f"toy/{m}/trace/{name}", arr[k])
    rec.reset_time()
    rec.text("toy/summary", result["table_markdown"])


def _format_table(result: dict) -> tuple[str, str]:
    rows = [("method", "closed-form theta", "numerical theta", "optimal theta")]
    for m in METHODS:
        rows.append((m, f"{result['closed_form'][m]:.6g}", f"{result['numerical'][m]:.6g}",
                     f"{result['optimal']:.6g}"))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    text = "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in rows)
    md = "| " + " | ".join(rows[0]) + " |\n|" + "---|" * 4 + "\n" + \
        "\n".join("| " + " | ".join(r) + " |" for r in rows[1:])
    return text, md


def run_toy(out_dir: Path, s0: float = -6.0, g: float = 0.0, recorder_factory=None, *,
            iters: int = 500, theta0: float = 0.1, alpha: float = ALPHA, plain_lr: float = 0.05,
            thetas=None, verbose: bool = True) -> dict:
    """Run the whole analysis: loops, closed forms, curves, init sweep; write figures and a recording.

    Writes ``out_dir/toy.rrd`` and ``out_dir/toy_{supervised,ours,meta_critic}.png``; prints a table
    (method, closed-form theta, numerical theta, optimal theta) and the init sweep when ``verbose``.
    ``recorder_factory(path, blueprint)`` makes the recorder (default: :class:`warp_critic.recording.Recorder`).
    ``iters`` caps every learning loop (the init sweep uses at most 200); ``theta0`` starts the reported
    runs; ``thetas`` is the curve grid (default :func:`default_thetas`).

    Returns a dict with ``closed_form``, ``numerical`` (theta per method), ``critic_params`` (converged
    ``phi`` per method; ``beta`` for the Meta-Critic), ``optimal``, ``stationary_points`` (per method, on the
    fitted-at-each-theta gradient curves), ``init_sweep`` rows, ``paper_meta_critic_theta``, ``files``.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cf = closed_form(s0, g)

    th_s, phi_s, tr_s = run_supervised(s0, g, theta0, iters)
    th_o, phi_o, tr_o = run_ours(s0, g, theta0, iters, alpha)
    th_m, phi_m, tr_m = run_meta_critic(s0, g, theta0, iters, alpha)
    beta_m = float(tr_m["beta"][-1])
    traces = {"supervised": tr_s, "ours": tr_o, "meta_critic": tr_m}
    converged = {"supervised": (phi_s, 0.0), "ours": (phi_o, 0.0), "meta_critic": (phi_m, beta_m)}
    cv = curves(s0, g, thetas, alpha, converged=converged)

    result: dict = {
        "s0": float(s0), "g": float(g),
        "closed_form": cf,
        "numerical": {"supervised": th_s, "ours": th_o, "meta_critic": th_m},
        "critic_params": {"supervised": {"phi": phi_s}, "ours": {"phi": phi_o},
                          "meta_critic": {"phi": phi_m, "beta": beta_m}},
        "iterations": {m: len(tr["theta"]) - 1 for m, tr in traces.items()},
        "optimal": cf["optimal"],
        "stationary_points": {m: stationary_points(cv["theta"], cv[_CURVE_KEYS[m][1]]) for m in METHODS},
        "paper_meta_critic_theta": paper_meta_critic_theta(s0),
        "init_sweep": init_sweep(s0, g, iters=min(iters, 200), alpha=alpha, plain_lr=plain_lr),
    }
    text, md = _format_table(result)
    result["table"], result["table_markdown"] = text, md

    files = {m: out_dir / f"toy_{m}.png" for m in METHODS}
    for m in METHODS:
        _plot_method(files[m], m, cv, result, s0, g)
    rrd = out_dir / "toy.rrd"
    factory = recorder_factory or _default_recorder
    rec = factory(rrd, _blueprint())
    try:
        _record(rec, cv, traces, result)
    finally:
        rec.close()
    files["rrd"] = rrd
    result["files"] = files

    if verbose:
        print(f"1-D toy example (s0={s0:g}, g={g:g}, T={T}, gamma={GAMMA:g}, alpha={alpha:g})")
        print(text)
        print("stationary points of the policy gradient (critic fitted at each theta): " + "; ".join(
            f"{m}: " + ", ".join(f"{x:.4g} ({k})" for x, k in result["stationary_points"][m])
            for m in METHODS))
        print(f"paper's printed Meta-Critic formula gives theta = {result['paper_meta_critic_theta']:.4g} "
              f"(not a fixed point; the loop converges to {th_m:.4g})")
        n_sweep = min(iters, 200)
        print(f"init sweep, at most {n_sweep} iterations (theta0 -> theta; '(~fixed point, kind)' when "
              "not within 1e-6 of a listed fixed point):")
        for variant in dict.fromkeys(r["variant"] for r in result["init_sweep"]):
            cells = [f"{r['theta0']:.3g}->{r['theta']:.4g}" + ("" if r["distance"] < 1e-6 else
                                                             f"(~{r['nearest']:.3g},{r['kind']})")
                     for r in result["init_sweep"] if r["variant"] == variant]
            print(f"  {variant:<20} " + "  ".join(cells))
        print(f"wrote {rrd} and {', '.join(str(files[m]) for m in METHODS)}")
    return result


# ---------------------------------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the flags of the ``analysis toy`` command to ``parser``."""
    parser.add_argument("--s0", type=float, default=-6.0, metavar="S0",
                        help="initial state s_0 (finite, non-zero; default -6)")
    parser.add_argument("--goal", type=float, default=0.0, metavar="G",
                        help="goal g; the terminal cost is (s_2 - g)^2 (finite; default 0)")
    parser.add_argument("--out", type=Path, default=Path("runs/analysis-toy"), metavar="DIR",
                        help="output folder for toy.rrd and the PNG figures (default runs/analysis-toy)")
    parser.add_argument("--iters", type=int, default=500, metavar="N",
                        help="maximum iterations of each learning loop (>= 1; default 500)")
    parser.add_argument("--theta0", type=float, default=0.1, metavar="THETA",
                        help="initial policy parameter of the reported runs (finite; default 0.1, see the module docs)")
    parser.add_argument("--alpha", type=float, default=ALPHA, metavar="LR",
                        help="inner policy learning rate of ours and of the Meta-Critic (> 0; default 0.5)")
    parser.add_argument("--grid", type=int, default=400, metavar="N",
                        help="number of theta grid points of the curves (>= 3; default 400)")
    parser.add_argument("--plain-lr", type=float, default=0.05, metavar="LR",
                        help="fixed policy learning rate of the plain supervised variant in the init sweep "
                             "(> 0; default 0.05)")


def _check_finite(name: str, value: float) -> float:
    if value is None or not math.isfinite(value):
        raise UserError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def run_from_args(args: argparse.Namespace) -> int:
    """Validate the parsed flags, run :func:`run_toy` and return the exit code (0)."""
    s0 = _check_finite("--s0", args.s0)
    if s0 == 0.0:
        raise UserError("--s0 must be non-zero: at s0 = 0 the supervised fixed point theta = 0 has all "
                        "critic features (s_t + a_t)^2 = 0 and the TD fit is undefined there")
    g = _check_finite("--goal", args.goal)
    theta0 = _check_finite("--theta0", args.theta0)
    alpha = _check_finite("--alpha", args.alpha)
    if alpha <= 0:
        raise UserError(f"--alpha must be > 0, got {alpha!r}")
    plain_lr = _check_finite("--plain-lr", args.plain_lr)
    if plain_lr <= 0:
        raise UserError(f"--plain-lr must be > 0, got {plain_lr!r}")
    if args.iters is None or int(args.iters) < 1:
        raise UserError(f"--iters must be a positive integer, got {args.iters!r}")
    if args.grid is None or int(args.grid) < 3:
        raise UserError(f"--grid must be an integer >= 3, got {args.grid!r}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out} exists and is not a folder")
    run_toy(out, s0, g, iters=int(args.iters), theta0=theta0, alpha=alpha, plain_lr=plain_lr,
            thetas=default_thetas(s0, g, int(args.grid)))
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m warp_critic.analysis.toy [flags]``: the same as the CLI's toy-analysis command."""
    parser = argparse.ArgumentParser(prog="python -m warp_critic.analysis.toy",
                                     description="1-D analytic example of section 4.1 / Appendix A.")
    add_arguments(parser)
    try:
        return run_from_args(parser.parse_args(argv))
    except UserError as err:
        print(f"warp-critic: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
