"""Simulator: a scene's articulation replicated into many Newton worlds, stepped from torch.

One world per (goal, policy initialisation, variant). All worlds share one Newton model and every
solver launch covers all of them. The torch/warp plumbing lives in :mod:`warp_critic.physics.bridge`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
import warp as wp

from warp_critic.core import runtime
from warp_critic.core.errors import FieldError
from warp_critic.physics.bridge import DiffRollout, NewtonBridge
from warp_critic.physics.scene import Scene, Variant
from warp_critic.physics.schema import STANDARD_GRAVITY  # a scene's gravity when it authors none

#: whether ``auto`` may pick CUDA. Off until ``tools/gpu_check.py`` has measured the CUDA path
#: (graph replay) faster than the CPU's: the one GPU run so far measured direct CUDA launches slower
#: than the CPU (0.93 against 0.36 s per KUKA iteration, an H200), and the graph-capture fix for CUDA
#: has not yet run on a GPU. ``cuda`` stays available by name.
AUTO_PICKS_CUDA = False


def resolve_device(device: str) -> str:
    """``auto`` -> ``cpu`` (see :data:`AUTO_PICKS_CUDA`); ``cuda``/``cuda:N`` only where Warp and
    torch both see a GPU."""
    runtime.check_device(device)
    if device == "auto":
        try:
            has_cuda = AUTO_PICKS_CUDA and wp.is_cuda_available() and torch.cuda.is_available()
        except Exception:  # pragma: no cover - broken driver installs
            has_cuda = False
        return "cuda" if has_cuda else "cpu"
    if device.startswith("cuda") and not (wp.is_cuda_available() and torch.cuda.is_available()):
        raise FieldError("device", f"{device}: no CUDA device is available to both Warp and torch")
    return device


class Simulator:
    """``W`` worlds of one scene, each with its own dynamics variant.

    Args:
        scene: the loaded scene.
        variants: one :class:`Variant` per world (``len(variants) == W``).
        dt: physics time step (s).
        substeps: physics steps per control step; the control period is ``dt * substeps``.
        device: ``cpu``/``cuda``/``auto``.
        differentiable: build the model with gradients (needed for model-based meta-training).
        gravity: magnitude of gravity along -z (m/s^2). ``0`` is exactly a perfectly gravity-compensated
            robot (``tau_applied = tau + g(q)``), as the iiwa's torque interface provides.
        graphs: replay captured Warp graphs after each step's first run (bitwise the same results,
            a fraction of the Python overhead; see :mod:`warp_critic.physics.bridge`); ``None`` reads
            ``$WARP_CRITIC_GRAPHS`` (default on).
    """

    def __init__(
        self,
        scene: Scene,
        variants: Sequence[Variant],
        *,
        dt: float,
        substeps: int = 1,
        device: str = "cpu",
        differentiable: bool = True,
        gravity: float = STANDARD_GRAVITY,
        graphs: bool | None = None,
    ):
        if dt <= 0:
            raise FieldError("dt", f"must be > 0 (got {dt})")
        if substeps < 1:
            raise FieldError("substeps", f"must be >= 1 (got {substeps})")
        for v in variants:
            v.validate()
        self.scene = scene
        self._describe = None  # DynamicsDescriptor, built on first use
        self.variants = list(variants)
        self.worlds = len(self.variants)
        self.dof = scene.dof
        self.dt, self.substeps = float(dt), int(substeps)
        self.control_dt = self.dt * self.substeps
        runtime.init_warp()  # once per process, quietly (a no-op after runtime.init)
        self.device = resolve_device(device)
        self.model = scene.build_model(
            self.variants, device=self.device, requires_grad=differentiable
        )
        if gravity < 0:
            raise FieldError("gravity", f"must be >= 0 (got {gravity})")
        self.gravity = float(gravity)
        self.model.set_gravity((0.0, 0.0, -self.gravity))
        self.bridge = NewtonBridge(
            self.model,
            self.worlds,
            self.dof,
            self.dt,
            self.substeps,
            graphs=runtime.graphs_from_env() if graphs is None else graphs,
        )
        self.torch_device = self.bridge.torch_device
        tdev = self.torch_device
        self.q_lower = torch.as_tensor(np.asarray(scene.q_lower), dtype=torch.float32, device=tdev)
        self.q_upper = torch.as_tensor(np.asarray(scene.q_upper), dtype=torch.float32, device=tdev)
        self.effort_limit = torch.as_tensor(
            np.asarray(scene.effort_limit), dtype=torch.float32, device=tdev
        )

    # -- the worlds' dynamics as data ---------------------------------------------------------------
    @property
    def variants(self) -> list[Variant]:
        """Each world's dynamics variant; setting them (:func:`~warp_critic.physics.redraw.set_variants`,
        after it has rewritten the model arrays) drops the cached :meth:`dynamics`."""
        return self._variants

    @variants.setter
    def variants(self, variants: list[Variant]) -> None:
        self._variants = variants
        self._dynamics: torch.Tensor | None = None

    @property
    def dynamics_size(self) -> int:
        """``K``: the numbers per world of :meth:`dynamics`."""
        return self._descriptor().size

    @property
    def dynamics_names(self) -> list[str]:
        """The ``K`` names of :meth:`dynamics`' numbers (``LINK.mass``, ``JOINT.offset.x``, ...)."""
        return self._descriptor().names

    def dynamics(self) -> torch.Tensor:
        """``(W, K)``: each world's dynamics relative to the scene's nominal model
        (:class:`~warp_critic.physics.descriptor.DynamicsDescriptor`), read from the model arrays
        once per set of variants (every rollout asks for it)."""
        if self._dynamics is None:
            values = self._descriptor().of(self.model, self.worlds)
            self._dynamics = torch.as_tensor(values, device=self.torch_device)
        return self._dynamics

    def _descriptor(self):
        if self._describe is None:
            from warp_critic.physics.descriptor import DynamicsDescriptor

            self._describe = DynamicsDescriptor(self.scene)
        return self._describe

    # -- stepping --------------------------------------------------------------------------------
    def begin_rollout(self) -> DiffRollout:
        """A differentiable rollout (its ``step`` is differentiable; reuses the gradient buffers)."""
        return self.bridge.begin_rollout()

    def step(self, q: torch.Tensor, qd: torch.Tensor, tau: torch.Tensor):
        """One control step without gradients. ``q, qd, tau``: ``(W, dof)``."""
        return self.bridge.step(q, qd, tau)

    def zeros(self) -> torch.Tensor:
        return torch.zeros(self.worlds, self.dof, device=self.torch_device)

    # -- kinematics for recordings ------------------------------------------------------------------
    @torch.no_grad()
    def body_poses(self, q: torch.Tensor) -> np.ndarray:
        """World poses of all bodies for joint positions ``q`` ``(W, dof)``.

        Returns ``(W, bodies_per_world, 7)``: position (m) and quaternion ``(x, y, z, w)``.
        """
        import newton

        state = self.model.state(requires_grad=False)
        wp.to_torch(state.joint_q).view(self.worlds, self.dof).copy_(q)
        newton.eval_fk(self.model, state.joint_q, state.joint_qd, state)
        poses = state.body_q.numpy().reshape(self.worlds, -1, 7)
        return poses

    @torch.no_grad()
    def tip_positions(self, q: torch.Tensor) -> np.ndarray:
        """End-effector tip of every world for joint positions ``q`` ``(W, dof)`` -> ``(W, 3)`` (m)."""
        import newton

        from warp_critic.kernels.kinematics import tip_positions_kernel

        state = self.model.state(requires_grad=False)
        wp.to_torch(state.joint_q).view(self.worlds, self.dof).copy_(q)
        newton.eval_fk(self.model, state.joint_q, state.joint_qd, state)
        offsets = np.stack([self.scene.tip_offset_of(v) for v in self.variants]).astype(np.float32)
        tip_offset = wp.array(offsets, dtype=wp.vec3, device=self.model.device)
        tips = wp.zeros(self.worlds, dtype=wp.vec3, device=self.model.device)
        wp.launch(
            tip_positions_kernel,
            dim=self.worlds,
            inputs=[
                state.body_q,
                self.model.body_count // self.worlds,
                self.scene.ee_body,
                tip_offset,
            ],
            outputs=[tips],
            device=self.model.device,
        )
        return tips.numpy()
