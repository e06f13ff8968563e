"""The 2-D problem of section 4.2 on the Newton point mass: constant-force policies and their analytic
optimum. Background: ``docs/landscape.md``."""

from __future__ import annotations

import numpy as np
import torch

from warp_critic.analysis import scene_path

SCENE = "point_mass.usda"
AXIS_MASS = (1.001, 1.0)  # effective masses of the x (mass + carriage) and y joints [kg]


def default_scene():
    """The point-mass scene of the installed package (not of the current directory)."""
    return scene_path(SCENE)


def constant_force(
    params: dict[str, torch.Tensor], q: torch.Tensor, qd: torch.Tensor
) -> torch.Tensor:
    """The policy family ``a_t = theta``: ``params['theta'] (W, 2)``; ``q, qd`` ``(W, 2)`` or ``(T, W, 2)``."""
    return params["theta"].expand(q.shape)


class GoalRelative(torch.nn.Module):
    """A critic ``net`` seen as ``C(q, qd, a, g) = net(q - g, qd, a, 0)``: the goal absorbed into the state
    (how ``Q_sup`` is conditioned, and ``L_critic`` with ``--ours-goal-input relative``)."""

    def __init__(self, net: torch.nn.Module):
        super().__init__()
        self.net = net

    def forward(self, q, qd, tau, goal):
        return self.net(q - goal, qd, tau, torch.zeros_like(goal))


def analytic_gain(dt: float, horizon: int, substeps: int = 1, mass=AXIS_MASS) -> np.ndarray:
    """Displacement per newton of constant force from rest after ``horizon`` control steps, per axis:
    ``dt^2 N (N+1) / (2 m)`` with ``N = horizon * substeps`` (semi-implicit Euler)."""
    n = horizon * substeps
    return dt * dt * n * (n + 1) / 2.0 / np.asarray(mass, dtype=np.float64)


def analytic_optimum(goal, q0, dt: float, horizon: int, substeps: int = 1) -> np.ndarray:
    """``theta* = (g - q_0) / gain``: the constant force that ends exactly at the goal."""
    return (np.asarray(goal, float) - np.asarray(q0, float)) / analytic_gain(dt, horizon, substeps)
