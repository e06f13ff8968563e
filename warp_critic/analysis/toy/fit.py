"""The one Newton step of the toy analysis, and "train to convergence" built on it.

Every critic objective of the toy is quadratic in its parameter, and so is the critic objective of the
policy, so a Newton step (gradient and curvature from torch autograd) is exact up to rounding. Used
for the critic fits (:func:`fit`) and for the curvature-normalised supervised policy step.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

Objective = Callable[[torch.Tensor], torch.Tensor]


def gradient(loss_fn: Objective, p: torch.Tensor) -> torch.Tensor:
    """``d loss_fn(p) / dp`` elementwise (a batch of independent scalar problems), detached."""
    x = p.detach().clone().requires_grad_(True)
    (grad,) = torch.autograd.grad(loss_fn(x).sum(), x)
    return grad


def newton_step(loss_fn: Objective, p: torch.Tensor) -> torch.Tensor | None:
    """The Newton step ``grad / curv`` of ``loss_fn`` at ``p``, elementwise.

    Elements whose curvature is not positive (the loss is flat in ``p`` there) get a zero step.
    Returns ``None`` when the loss does not depend on ``p`` at all.
    """
    x = p.detach().clone().requires_grad_(True)
    (grad,) = torch.autograd.grad(loss_fn(x).sum(), x, create_graph=True)
    if grad.grad_fn is None:
        return None
    (curv,) = torch.autograd.grad(grad.sum(), x, allow_unused=True)
    if curv is None:
        return None
    ok = curv > 0
    return torch.where(
        ok, grad.detach() / torch.where(ok, curv, torch.ones_like(curv)), torch.zeros_like(curv)
    )


def fit(
    loss_fn: Objective, p0: torch.Tensor, max_steps: int = 5, rtol: float = 1e-12
) -> torch.Tensor:
    """Minimise ``loss_fn`` elementwise over ``p`` by Newton steps, until the step is below
    ``rtol * (1 + |p|)`` (this also repairs the rounding of a first step taken from a far-away ``p0``).
    Elements where the loss is flat keep their value."""
    p = p0.detach().clone()
    for _ in range(max_steps):
        step = newton_step(loss_fn, p)
        if step is None:
            return p
        p = p - step
        if bool((step.abs() <= rtol * (1.0 + p.abs())).all()):
            break
    return p.detach()
