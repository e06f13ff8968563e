"""Experience for the off-policy baselines: replay buffer, exploration noise and rewards."""

from __future__ import annotations

import torch

from warp_critic.learning.rollout import Trajectory

NOISE_KINDS = ("ou", "gaussian")
REWARD_KINDS = ("dense", "sparse")

_FIELDS = ("q", "qd", "tau", "goal", "reward", "q2", "qd2", "done")


class ReplayBuffer:
    """Ring buffer of transitions ``(q, qd, tau, g, r, q', qd', done)`` as one ``(N, D)`` tensor."""

    def __init__(self, capacity: int, dof: int, device):
        self.capacity, self.dof, self.device = int(capacity), dof, device
        widths = {
            "q": dof,
            "qd": dof,
            "tau": dof,
            "goal": dof,
            "reward": 1,
            "q2": dof,
            "qd2": dof,
            "done": 1,
        }
        self.slices, start = {}, 0
        for name in _FIELDS:
            self.slices[name] = slice(start, start + widths[name])
            start += widths[name]
        self.data = torch.zeros(self.capacity, start, device=device)
        self.ptr = 0
        self.size = 0

    def add_trajectory(
        self, traj: Trajectory, goal: torch.Tensor, reward: torch.Tensor, done: torch.Tensor
    ) -> None:
        """All ``T * W`` transitions of a rollout; ``reward, done``: ``(T, W)``."""
        T, W, _ = traj.tau.shape
        g = goal.unsqueeze(0).expand(T, W, -1)
        rows = torch.cat(
            [
                traj.q[:-1],
                traj.qd[:-1],
                traj.tau,
                g,
                reward.unsqueeze(-1),
                traj.q[1:],
                traj.qd[1:],
                done.unsqueeze(-1),
            ],
            dim=-1,
        ).reshape(T * W, -1)
        self._add_rows(rows.detach().to(self.device))

    def _add_rows(self, rows: torch.Tensor) -> None:
        n = rows.shape[0]
        if n >= self.capacity:
            rows, n = rows[-self.capacity :], self.capacity
        end = self.ptr + n
        if end <= self.capacity:
            self.data[self.ptr : end] = rows
        else:
            k = self.capacity - self.ptr
            self.data[self.ptr :] = rows[:k]
            self.data[: n - k] = rows[k:]
        self.ptr = end % self.capacity
        self.size = min(self.size + n, self.capacity)

    def sample(self, batch_size: int, gen: torch.Generator) -> dict[str, torch.Tensor]:
        idx = torch.randint(0, self.size, (batch_size,), generator=gen).to(self.device)
        rows = self.data[idx]
        out = {name: rows[:, s] for name, s in self.slices.items()}
        out["reward"], out["done"] = out["reward"].squeeze(-1), out["done"].squeeze(-1)
        return out

    def state_dict(self) -> dict:
        """The stored transitions oldest first (so a resume may change the capacity)."""
        if self.size < self.capacity:
            rows = self.data[: self.size]
        else:
            rows = torch.cat([self.data[self.ptr :], self.data[: self.ptr]])
        return {"rows": rows.cpu().clone()}

    def load_state_dict(self, state: dict) -> None:
        self.ptr, self.size = 0, 0
        self._add_rows(state["rows"].to(self.device))


class ExplorationNoise:
    """Per-world action noise in units of ``max_torque``: Ornstein-Uhlenbeck (reset every episode)
    ``x <- x - theta x + sigma N(0, 1)`` or i.i.d. Gaussian ``sigma N(0, 1)``."""

    def __init__(self, kind: str, sigma: float, theta: float, shape, gen: torch.Generator, device):
        self.kind, self.sigma, self.theta, self.shape = kind, sigma, theta, tuple(shape)
        self.gen, self.device = gen, device
        self.reset()

    def reset(self) -> None:
        self.x = torch.zeros(self.shape)

    def sample(self) -> torch.Tensor:
        eps = torch.randn(self.shape, generator=self.gen)
        if self.kind == "ou":
            self.x = self.x - self.theta * self.x + self.sigma * eps
        else:
            self.x = self.sigma * eps
        return self.x.to(self.device)


def rewards(
    traj: Trajectory, goal: torch.Tensor, kind: str, scale: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(reward, done)``, both ``(T, W)``; see the module docstring."""
    err = ((traj.q[1:] - goal.unsqueeze(0)) ** 2).sum(-1)  # (T, W): ||q_{t+1} - g||^2
    done = torch.zeros_like(err)
    if kind == "dense":
        r = -err
    else:
        r = torch.zeros_like(err)
        r[-1] = -err[-1]
        done[-1] = 1.0
    return scale * r, done
