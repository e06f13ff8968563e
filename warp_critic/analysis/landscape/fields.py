"""The landscapes of section 4.2 over a ``grid x grid`` lattice of constant forces, and the descent check.

Each critic's value ``sum_t C(s_t, theta, g)`` and its policy gradient (states as data) come from
:func:`warp_critic.learning.losses.critic_loss`; ``Q_true``'s gradient is taken through the differentiable Newton
model. The descent check follows the gradient field from every grid point. Details: ``docs/landscape.md``.
"""

from __future__ import annotations

import numpy as np
import torch

from warp_critic.analysis.landscape.problem import constant_force
from warp_critic.learning.inner import policy_fn
from warp_critic.learning.losses import critic_loss
from warp_critic.learning.rollout import rollout

METHODS = ("Q_true", "Q_sup", "L_critic")


def memory_bytes(grid: int, horizon: int, substeps: int) -> float:
    """Rough peak memory of :func:`compute_landscapes`: per world and control step ~12 KiB for a critic's
    activations and gradients (``(T * grid^2)`` rows through 2 x 400 units) and ~4 KiB per physics
    step of the differentiable simulator's tape (measured ~13 KB per world-step in total at the defaults)."""
    return float(grid) ** 2 * horizon * (12 + 4 * substeps) * 1024.0


def compute_landscapes(
    cfg, eval_sim, grad_sim, critic, qsup, goals: np.ndarray, q0_eval: np.ndarray
):
    """Axis ``(n,)``, values ``(G, 3, n, n)`` and gradients ``(G, 3, n, n, 2)`` indexed ``[goal, method, i1, i2]``
    (methods as :data:`METHODS`); ``critic`` and ``qsup`` are loss modules ``C(q, qd, a, g)``."""
    n = cfg.grid
    dev = eval_sim.torch_device
    axis = np.linspace(-cfg.range, cfg.range, n)
    t1, t2 = np.meshgrid(axis, axis, indexing="ij")
    theta = torch.tensor(np.stack([t1.ravel(), t2.ravel()], 1), dtype=torch.float32, device=dev)
    P = n * n
    q0 = torch.tensor(q0_eval, dtype=torch.float32, device=dev).expand(P, -1).contiguous()
    qd0 = torch.zeros_like(q0)
    data = rollout(
        eval_sim,
        policy_fn(constant_force, {"theta": theta}),
        q0,
        qd0,
        cfg.horizon,
        differentiable=False,
    )
    # Q_true gradient through the differentiable model (the goal enters only through the cost)
    th = theta.clone().requires_grad_(True)
    diff = rollout(
        grad_sim,
        policy_fn(constant_force, {"theta": th}),
        q0,
        qd0,
        cfg.horizon,
        differentiable=True,
    )
    qT = diff.q[-1]
    rows = []
    for j in range(2):  # dq_T/dtheta rows: q_T(theta) per axis
        (gj,) = torch.autograd.grad(qT[:, j].sum(), th, retain_graph=(j == 0))
        rows.append(gj)
    jac = torch.stack(rows, 1)  # (P, 2 [q axis], 2 [theta])
    qT_data = data.q[-1]
    values = np.zeros((len(goals), 3, n, n))
    grads = np.zeros((len(goals), 3, n, n, 2))
    for gi, g in enumerate(goals):
        gt = torch.tensor(g, dtype=torch.float32, device=dev).expand(P, -1)
        err = qT_data - gt
        values[gi, 0] = (err**2).sum(-1).reshape(n, n).cpu().numpy()
        grads[gi, 0] = (
            (2 * torch.einsum("pj,pjk->pk", qT.detach() - gt, jac)).reshape(n, n, 2).cpu().numpy()
        )
        for mi, net in ((1, qsup), (2, critic)):
            params = {"theta": theta.clone().requires_grad_(True)}
            v = critic_loss(
                net, constant_force, params, data, gt
            )  # sum_t C(s_t, theta, g), states as data
            (gr,) = torch.autograd.grad(v.sum(), params["theta"])
            values[gi, mi] = v.detach().reshape(n, n).cpu().numpy()
            grads[gi, mi] = gr.reshape(n, n, 2).cpu().numpy()
    return axis, values, grads


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
    return (
        (1 - f0) * (1 - f1) * field[i0, i1]
        + f0 * (1 - f1) * field[i0 + 1, i1]
        + (1 - f0) * f1 * field[i0, i1 + 1]
        + f0 * f1 * field[i0 + 1, i1 + 1]
    )


def descend(
    field: np.ndarray, axis: np.ndarray, starts: np.ndarray, steps: int = 300, decay: float = 0.98
) -> np.ndarray:
    """Normalised-gradient descent on the interpolated ``field`` from ``starts (P, 2)``; final points."""
    h = axis[1] - axis[0]
    lo, hi = axis[0], axis[-1]
    x = starts.astype(np.float64).copy()
    for k in range(steps):
        g = _bilinear(field, axis, x)
        norm = np.linalg.norm(g, axis=1, keepdims=True)
        d = np.where(norm > 1e-12, g / np.maximum(norm, 1e-12), 0.0)
        x = np.clip(x - h * decay**k * d, lo, hi)
    return x


def descent_fraction(field: np.ndarray, axis: np.ndarray, optimum, tolerance: float) -> float:
    """Fraction of grid points from which :func:`descend` ends within ``tolerance`` of ``optimum``."""
    t1, t2 = np.meshgrid(axis, axis, indexing="ij")
    starts = np.stack([t1.ravel(), t2.ravel()], axis=1)
    final = descend(field, axis, starts)
    return float(np.mean(np.linalg.norm(final - np.asarray(optimum)[None], axis=1) <= tolerance))
