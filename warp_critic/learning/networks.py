"""Networks: batched per-world policies (pure functions of their parameters) and the critic.

Policy (paper, section 5): MLP ``s -> a`` with two hidden layers of 64 units and tanh. Every world
has its own parameters; they are stored stacked with a leading world dimension ``W`` so that one
batched matmul evaluates all policies, and an inner update is ``theta - alpha * grad`` on plain
tensors (no module, no in-place mutation).

Critic ``L_critic(s, a, g)``: MLP with two hidden layers of 400 units and ELU, one scalar output.
Eight input layouts (``CRITIC_INPUTS``, normalised as below):

* ``full``: ``[q, qd, a, g, q - g]`` -- everything; the goal-relative position ``q - g`` is a fixed
  feature of ``(s, g)`` that adds no information but makes goal generalisation easier to learn;
* ``relative``: ``[q - g, qd, a]`` -- the state seen from the goal. The critic is then equivariant
  to shifting the goal and the state together, so it cannot memorise the few training goals and
  has to describe how to move towards *a* goal. It suits robots whose dynamics change little with
  ``q`` over the goal region, e.g. a gravity-compensated arm. On its own it generalises on the KUKA
  about as well as ``full``; with random start states (``--start-std``), which it reads as goal
  offsets, it reaches the paper's Table 1 (RESULTS.md has the measurements).
* ``history``: ``[q - g, qd, a, qd_t - qd_{t-1}, a_{t-1}]`` -- ``relative`` plus the last control
  step's response: the torque applied there and the velocity change it produced (zeros at the first
  step), observed data like the states. Under ``qd_t - qd_{t-1} ~ dt M^-1 (a_{t-1} - bias)`` the
  pair tells the critic about the inertia it acts on, so one critic can tell models apart (for
  dynamics-randomised training, ``--train-variants``); :func:`history_features` builds it from a
  trajectory.
* ``pose``: ``[q - g, qd, a, q]`` -- ``relative`` plus the arm's own configuration. The goal still
  enters through ``q - g`` only, but the critic sees the joint angles the dynamics depend on: an
  arm's inertia ``M(q)`` changes with every joint but the first (the reacher's elbow), which a
  ``relative`` critic cannot see, so it applies near far goals the field it learned near the
  training goals (RESULTS.md, "Why the far goals miss").
* ``pose-trig``: ``[q - g, qd, a, sin q, cos q]`` -- ``pose`` with the joint angles encoded by their
  sine and cosine. A rigid arm's inertia and gravity terms are sums of products of ``sin q_i`` and
  ``cos q_i``, so the critic sees the pose in the coordinates its dynamics are simple in (the
  reacher's ``M(q)`` is affine in ``cos q2``). ``q - g`` stays an angle difference: the joint
  limits let it exceed ``pi``, where its sine and cosine would alias.

* ``inertial``: ``[q - g, qd, M(q_h) M(q)^-1 a]`` -- ``relative`` with the torque seen as the torque
  that gives the same joint acceleration at the home pose ``q_h`` (``M``: the nominal model's
  inertia, :class:`~warp_critic.physics.inertia.NominalInertia`, evaluated as data). Its inner update
  steps the torques in the metric ``P(q) = M(q) M(q_h)^-2 M(q)`` (:meth:`Critic.torque_metric`), so
  that one critic gradient changes the joint acceleration by the same amount in every pose:
  ``M(q)^-1 P(q) d/dtau = M(q_h)^-1 d/dx`` with ``x`` the home-equivalent torque. Where the dynamics
  depend on the pose only through ``M(q)`` (the reacher: its joint axes are parallel to gravity),
  the inner loop is then the same at every goal and a field learned near the training goals holds
  at all of them. At the home pose it is the ``relative`` critic with the paper's update.
* ``pose-dynamics``: ``[q - g, qd, a, q, d]`` -- ``pose`` plus the world's dynamics ``d (K,)``
  relative to the scene's nominal model (:class:`~warp_critic.physics.descriptor.DynamicsDescriptor`:
  masses, centres of mass, inertias, joint offsets). Privileged: the critic is told the model
  instead of identifying it, at training and at meta-test alike (the trajectory carries ``d``,
  :attr:`~warp_critic.learning.rollout.Trajectory.dynamics`). It measures how far identifying the
  model alone takes one critic across dynamics-randomised training's range.
* ``relative-dynamics``: ``[q - g, qd, a, d]`` -- the same for the ``relative`` layout (the KUKA's).

Input normalisation (documented, fixed from the scene, not learned):
  * joint positions and goals: ``(q - centre) / half_range`` of the joint limits; a continuous joint
    (no limits: a half range of at least ``CONTINUOUS_HALF_RANGE``) is an angle, seen wrapped:
    ``wrap(q) / pi`` with ``wrap`` to ``[-pi, pi)``, and so are its differences ``q - g``,
  * joint velocities: ``qd / qd_scale`` (``qd_scale`` a flag, rad/s),
  * actions: ``tau / max_torque``.
Policy output shaping: ``tau = max_torque * tanh(out)``, so torque limits always hold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import torch
from torch import nn

from warp_critic.physics.schema import CRITIC_INPUTS  # a scene may name its critic's layout

PolicyParams = dict[str, torch.Tensor]

POLICY_INIT_SCHEMES = ("fresh", "fixed", "persistent")


CONTINUOUS_HALF_RANGE = 1e6  # rad: a joint whose limits are this far apart has none

#: the critic inputs told each world's model (privileged: ``warp-critic identify`` estimates it instead)
TOLD_INPUTS = ("pose-dynamics", "relative-dynamics")


class Inertia(Protocol):
    """A model's joint-space inertia as data: ``q (..., dof)`` -> ``M(q) (..., dof, dof)``, and
    ``home()`` -> ``M(q_h) (dof, dof)`` (e.g. :class:`~warp_critic.physics.inertia.NominalInertia`)."""

    def __call__(self, q: torch.Tensor, /) -> torch.Tensor: ...

    def home(self) -> torch.Tensor: ...


def wrap_angles(x: torch.Tensor, wrap: torch.Tensor | None) -> torch.Tensor:
    """``x (..., dof)`` with the joints where ``wrap (dof,)`` is true wrapped to ``[-pi, pi)``."""
    if wrap is None:
        return x
    return torch.where(wrap, torch.remainder(x + math.pi, 2 * math.pi) - math.pi, x)


@dataclass(frozen=True)
class Normalizer:
    """Fixed affine input scales (all ``(dof,)`` tensors); ``wrap``: the continuous joints (bool)."""

    q_centre: torch.Tensor
    q_half_range: torch.Tensor
    qd_scale: float
    max_torque: torch.Tensor
    wrap: torch.Tensor | None = None
    # the nominal model's M(q) (:class:`~warp_critic.physics.inertia.NominalInertia`), for the
    # ``inertial`` critic; evaluated lazily, so carrying it costs nothing
    inertia: Inertia | None = None
    # K, the numbers of a world's dynamics descriptor (Simulator.dynamics_size), for the
    # ``pose-dynamics`` and ``relative-dynamics`` critics; 0 where the caller has none
    dynamics_size: int = 0

    @staticmethod
    def from_limits(
        q_lower: torch.Tensor,
        q_upper: torch.Tensor,
        max_torque: torch.Tensor,
        qd_scale: float,
        inertia: Inertia | None = None,
        dynamics_size: int = 0,
    ) -> Normalizer:
        centre, half = (q_upper + q_lower) / 2, (q_upper - q_lower) / 2
        wrap = half >= CONTINUOUS_HALF_RANGE
        if not bool(wrap.any()):
            return Normalizer(
                centre, half, float(qd_scale), max_torque, None, inertia, dynamics_size
            )
        centre = torch.where(wrap, torch.zeros_like(centre), centre)
        half = torch.where(wrap, torch.full_like(half, math.pi), half)
        return Normalizer(centre, half, float(qd_scale), max_torque, wrap, inertia, dynamics_size)

    def q(self, q: torch.Tensor) -> torch.Tensor:
        return wrap_angles(q - self.q_centre, self.wrap) / self.q_half_range

    def dq(self, q: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """``(q - goal) / half_range``, continuous joints wrapped."""
        return wrap_angles(q - goal, self.wrap) / self.q_half_range

    def state(self, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        return torch.cat([self.q(q), qd / self.qd_scale], dim=-1)

    def action(self, tau: torch.Tensor) -> torch.Tensor:
        return tau / self.max_torque


# ------------------------------------------------------------------------------------------------
# policy: W independent MLPs evaluated in one batched call
# ------------------------------------------------------------------------------------------------


def init_policy(
    worlds: int,
    obs_dim: int,
    act_dim: int,
    *,
    hidden: int = 64,
    generator=None,
    device="cpu",
    out_scale: float = 0.1,
) -> PolicyParams:
    """PyTorch-default (Kaiming-uniform) initialisation for ``W`` policies.

    The last layer is scaled by ``out_scale`` so fresh policies start with small torques.
    Returns tensors ``w1 (W,h,obs) b1 (W,h) w2 (W,h,h) b2 (W,h) w3 (W,act,h) b3 (W,act)``.
    """

    def layer(n_out, n_in, scale=1.0):
        bound = 1.0 / math.sqrt(n_in)
        w = (torch.rand(worlds, n_out, n_in, generator=generator) * 2 - 1) * bound * scale
        b = (torch.rand(worlds, n_out, generator=generator) * 2 - 1) * bound * scale
        return w.to(device), b.to(device)

    w1, b1 = layer(hidden, obs_dim)
    w2, b2 = layer(hidden, hidden)
    w3, b3 = layer(act_dim, hidden, out_scale)
    return {"w1": w1, "b1": b1, "w2": w2, "b2": b2, "w3": w3, "b3": b3}


def policy_forward(params: PolicyParams, obs: torch.Tensor) -> torch.Tensor:
    """``obs (W, obs_dim)`` or ``(T, W, obs_dim)`` -> pre-shaping output ``(..., W, act_dim)``."""
    h = torch.tanh(torch.einsum("wij,...wj->...wi", params["w1"], obs) + params["b1"])
    h = torch.tanh(torch.einsum("wij,...wj->...wi", params["w2"], h) + params["b2"])
    return torch.einsum("wij,...wj->...wi", params["w3"], h) + params["b3"]


def policy_action(
    params: PolicyParams, norm: Normalizer, q: torch.Tensor, qd: torch.Tensor
) -> torch.Tensor:
    """Joint torques ``(..., W, dof)`` within ``+-max_torque``."""
    return norm.max_torque * torch.tanh(policy_forward(params, norm.state(q, qd)))


class MLPPolicy:
    """The paper's policy family as a function ``(params, q, qd) -> tau``: per-world MLPs over the
    normalised state, ``max_torque * tanh`` output. :mod:`warp_critic.learning.inner` takes any such function
    (the point-mass landscape uses a constant-force policy ``(params, q, qd) -> theta``)."""

    def __init__(self, norm: Normalizer, hidden: int = 64):
        self.norm, self.hidden = norm, hidden

    def __call__(self, params: PolicyParams, q: torch.Tensor, qd: torch.Tensor) -> torch.Tensor:
        return policy_action(params, self.norm, q, qd)

    def init(self, worlds: int, *, generator=None, device="cpu") -> PolicyParams:
        """Fresh parameters for ``worlds`` policies (see :func:`init_policy`)."""
        dof = self.norm.max_torque.shape[0]
        return init_policy(
            worlds, 2 * dof, dof, hidden=self.hidden, generator=generator, device=device
        )


def detach_params(params: PolicyParams, requires_grad: bool = True) -> PolicyParams:
    return {k: v.detach().clone().requires_grad_(requires_grad) for k, v in params.items()}


def flat_params(params: PolicyParams) -> torch.Tensor:
    """``(W, n_params)``: all parameters of each world's policy in one row (for traces)."""
    return torch.cat([v.reshape(v.shape[0], -1) for v in params.values()], dim=1)


# ------------------------------------------------------------------------------------------------
# critic
# ------------------------------------------------------------------------------------------------


class Critic(nn.Module):
    """``L_critic(s, a, g)``: MLP ``[state, action, goal] -> scalar`` (2 x 400, ELU).

    Inputs are normalised with the scene's fixed :class:`Normalizer` (stored as buffers so that a
    checkpoint is self-contained).
    """

    q_centre: torch.Tensor  # buffers (dof,)
    q_half_range: torch.Tensor
    max_torque: torch.Tensor
    q_wrap: torch.Tensor  # (dof,) bool: the continuous joints

    def __init__(self, dof: int, norm: Normalizer, hidden: int = 400, inputs: str = "full"):
        super().__init__()
        if inputs not in CRITIC_INPUTS:
            raise ValueError(f"critic inputs must be one of {CRITIC_INPUTS} (got {inputs!r})")
        self.dof, self.inputs, self.hidden = dof, inputs, hidden
        widths = {
            "relative": 3,
            "inertial": 3,
            "relative-dynamics": 3,
            "pose": 4,
            "pose-trig": 5,
            "pose-dynamics": 4,
        }
        n_in = widths.get(inputs, 5) * dof
        self.inertia = norm.inertia if inputs == "inertial" else None
        if inputs == "inertial" and self.inertia is None:
            raise ValueError("an inertial critic needs the scene's nominal inertia (norm.inertia)")
        told = inputs in TOLD_INPUTS
        self.dynamics_size = norm.dynamics_size if told else 0
        if told and self.dynamics_size <= 0:
            raise ValueError(
                f"a {inputs} critic needs the worlds' descriptor size (norm.dynamics_size)"
            )
        n_in += self.dynamics_size
        self.net = nn.Sequential(
            nn.Linear(n_in, hidden),
            nn.ELU(),
            nn.Linear(hidden, hidden),
            nn.ELU(),
            nn.Linear(hidden, 1),
        )
        self.register_buffer("q_centre", norm.q_centre.clone())
        self.register_buffer("q_half_range", norm.q_half_range.clone())
        self.register_buffer("max_torque", norm.max_torque.clone())
        # the continuous joints: from the scene, not the checkpoint (persistent=False)
        wrap = (
            norm.wrap
            if norm.wrap is not None
            else torch.zeros_like(norm.q_centre, dtype=torch.bool)
        )
        self.register_buffer("q_wrap", wrap.clone(), persistent=False)
        self._wraps = bool(wrap.any())
        self.qd_scale = norm.qd_scale

    def _angles(self, x: torch.Tensor, wrap: torch.Tensor | None) -> torch.Tensor:
        """Joint positions ``(..., dof)`` normalised by the joint limits (continuous ones wrapped)."""
        return wrap_angles(x - self.q_centre, wrap) / self.q_half_range

    @property
    def uses_history(self) -> bool:
        """Whether :meth:`forward` takes ``history`` (:func:`history_features`)."""
        return self.inputs == "history"

    @property
    def uses_dynamics(self) -> bool:
        """Whether :meth:`forward` takes ``dynamics`` (the worlds' descriptor, ``(..., K)``)."""
        return self.dynamics_size > 0

    def torque_metric(self, q: torch.Tensor) -> torch.Tensor | None:
        """The metric ``P(q) (..., dof, dof)`` the inner update steps torques in at the states ``q
        (..., dof)`` (data): ``M(q) M(q_h)^-2 M(q)`` for the ``inertial`` layout, ``None`` (the
        identity: the paper's plain gradient) for the others."""
        if self.inertia is None:
            return None
        M = self.inertia(q)
        left = torch.linalg.solve(self.inertia.home(), M)  # M(q_h)^-1 M(q)
        return left.transpose(-1, -2) @ left

    def _home_equivalent(self, q: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
        """``M(q_h) M(q)^-1 tau`` ``(..., dof)``: the torque with the same acceleration at home."""
        assert self.inertia is not None
        acc = torch.linalg.solve(self.inertia(q), tau.unsqueeze(-1))
        return (self.inertia.home() @ acc).squeeze(-1)

    def features(
        self,
        q: torch.Tensor,
        qd: torch.Tensor,
        tau: torch.Tensor,
        goal: torch.Tensor,
        history: torch.Tensor | None = None,
        dynamics: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """The normalised input ``(..., n_in)`` of the input layout (``history``: ``(..., 2*dof)``,
        needed by the ``history`` layout only; ``dynamics``: ``(..., K)``, by the ``*-dynamics`` ones)."""
        wrap = self.q_wrap if self._wraps else None
        if self.inputs != "full":
            if self.inputs == "inertial":
                tau = self._home_equivalent(q, tau)
            parts = [
                wrap_angles(q - goal, wrap) / self.q_half_range,
                qd / self.qd_scale,
                tau / self.max_torque,
            ]
            if self.inputs in ("pose", "pose-dynamics"):
                parts.append(self._angles(q, wrap))
            elif self.inputs == "pose-trig":
                parts += [torch.sin(q), torch.cos(q)]
            if self.dynamics_size:
                if dynamics is None or dynamics.shape[-1] != self.dynamics_size:
                    raise ValueError(
                        f"a {self.inputs} critic needs the worlds' dynamics (..., {self.dynamics_size})"
                    )
                parts.append(dynamics.expand(*q.shape[:-1], -1))
            if self.inputs == "history":
                if history is None:
                    raise ValueError("a history critic needs history (history_features)")
                dqd, tau_prev = history.split(self.dof, dim=-1)
                parts += [dqd / self.qd_scale, tau_prev / self.max_torque]
            return torch.cat(parts, dim=-1)
        return torch.cat(
            [
                self._angles(q, wrap),
                qd / self.qd_scale,
                tau / self.max_torque,
                self._angles(goal, wrap),
                wrap_angles(q - goal, wrap) / self.q_half_range,
            ],
            dim=-1,
        )

    def forward(
        self,
        q: torch.Tensor,
        qd: torch.Tensor,
        tau: torch.Tensor,
        goal: torch.Tensor,
        history: torch.Tensor | None = None,
        dynamics: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """All ``(..., dof)`` (``history`` ``(..., 2*dof)``, ``dynamics`` ``(..., K)``) -> ``(...)``."""
        return self.net(self.features(q, qd, tau, goal, history, dynamics)).squeeze(-1)


def history_features(qd: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
    """``(T, W, 2*dof)``: at each step ``t`` of a trajectory, ``[qd_t - qd_{t-1}, tau_{t-1}]``
    (zeros at ``t = 0``), detached. ``qd``: ``(T+1, W, dof)`` or ``(T, W, dof)``; ``tau``:
    ``(T, W, dof)``, the applied torques."""
    qd, tau = qd[: tau.shape[0]].detach(), tau.detach()
    dqd = torch.cat([torch.zeros_like(qd[:1]), qd[1:] - qd[:-1]])
    prev = torch.cat([torch.zeros_like(tau[:1]), tau[:-1]])
    return torch.cat([dqd, prev], dim=-1)


def _linear(module: nn.Module) -> nn.Linear:
    if not isinstance(module, nn.Linear):
        raise TypeError(f"expected a Linear layer, got {type(module).__name__}")
    return module


class StackedCritic(nn.Module):
    """``S`` critics of one architecture (one per seed) evaluated as one module.

    The worlds axis (``-2`` of every input) is seed-major: worlds ``s*W .. (s+1)*W - 1`` belong to critic
    ``s``. Each layer is one batched matmul over the seeds, so ``S`` critics cost about one critic's
    overhead; their parameters are stacked ``(S, ...)`` tensors, and an optimiser over them that acts
    elementwise (Adam) is exactly ``S`` independent optimisers. :meth:`critic_state` /
    :meth:`from_critics` convert to and from ordinary :class:`Critic` state dicts.
    """

    _LAYERS = (0, 2, 4)  # indices of the Linear layers in Critic.net

    def __init__(self, critics: list[Critic]):
        super().__init__()
        first = critics[0]
        self.template: list[Critic] = [
            first
        ]  # a list: not a registered submodule (its parameters are not ours)
        self.seeds = len(critics)
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for i in self._LAYERS:
            layers = [_linear(c.net[i]) for c in critics]
            self.weights.append(nn.Parameter(torch.stack([x.weight.detach() for x in layers])))
            self.biases.append(nn.Parameter(torch.stack([x.bias.detach() for x in layers])))

    @property
    def uses_history(self) -> bool:
        return self.template[0].uses_history

    @property
    def uses_dynamics(self) -> bool:
        return self.template[0].uses_dynamics

    def torque_metric(self, q: torch.Tensor) -> torch.Tensor | None:
        """:meth:`Critic.torque_metric` (one scene for every seed)."""
        return self.template[0].torque_metric(q)

    def forward(
        self,
        q: torch.Tensor,
        qd: torch.Tensor,
        tau: torch.Tensor,
        goal: torch.Tensor,
        history: torch.Tensor | None = None,
        dynamics: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """All ``(..., S*W, dof)`` -> ``(..., S*W)``."""
        x = self.template[0].features(q, qd, tau, goal, history, dynamics)  # (..., S*W, n_in)
        lead, sw, n_in = x.shape[:-2], x.shape[-2], x.shape[-1]
        S = self.seeds
        x = x.reshape(-1, S, sw // S, n_in).permute(1, 0, 2, 3).reshape(S, -1, n_in)  # (S, M, n_in)
        for k, (w, b) in enumerate(zip(self.weights, self.biases)):
            x = torch.baddbmm(b.unsqueeze(1), x, w.transpose(1, 2))
            if k < len(self.weights) - 1:
                x = torch.nn.functional.elu(x)
        x = x.reshape(S, -1, sw // S).permute(1, 0, 2).reshape(*lead, sw)
        return x

    def critic_state(self, s: int) -> dict:
        """Critic ``s`` as an ordinary :class:`Critic` state dict."""
        state = {k: v.clone() for k, v in self.template[0].state_dict().items()}
        for i, w, b in zip(self._LAYERS, self.weights, self.biases):
            state[f"net.{i}.weight"] = w[s].detach().clone()
            state[f"net.{i}.bias"] = b[s].detach().clone()
        return state

    def load_critic_state(self, s: int, state: dict) -> None:
        with torch.no_grad():
            for i, w, b in zip(self._LAYERS, self.weights, self.biases):
                w[s].copy_(state[f"net.{i}.weight"])
                b[s].copy_(state[f"net.{i}.bias"])

    def critic(self, s: int) -> Critic:
        c = self.template[0]
        out = Critic(
            c.dof,
            Normalizer(
                c.q_centre,
                c.q_half_range,
                c.qd_scale,
                c.max_torque,
                c.q_wrap if c._wraps else None,
                c.inertia,
                c.dynamics_size,
            ),
            hidden=c.hidden,
            inputs=c.inputs,
        ).to(c.q_centre.device)
        out.load_state_dict(self.critic_state(s))
        return out

    def ordered(self) -> list[nn.Parameter]:
        """The stacked parameters in :meth:`Critic.parameters` order."""
        return [t for w, b in zip(self.weights, self.biases) for t in (w, b)]
