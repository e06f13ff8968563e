"""Graph replay of Warp work, and the per-step buffers the differentiable bridge replays over.

A Featherstone step is ~25 small Warp operations whose Python-side argument packing costs more
than their arithmetic. Work that always touches the same arrays is run once directly (allocating,
loading kernels, recording tapes), then captured with ``wp.capture_begin``/``wp.capture_end`` -- a
CUDA graph on a GPU, Warp's APIC operation stream on a CPU -- and replayed with
``wp.capture_launch``: the same kernels on the same memory in the same order, so bitwise the same
results as the direct calls.
"""

from __future__ import annotations

import contextlib
import warnings
from dataclasses import dataclass

import newton
import torch
import warp as wp


class Replay:
    """Run ``direct()`` the first time, capture ``captured()`` into a graph the second, replay after.

    ``direct`` does the first call's one-time work (allocations, kernel loads, tape recording);
    ``captured`` issues the same Warp operations without it. Capture records without executing, so
    the freshly captured graph is launched right away. With ``enabled=False`` every call is direct;
    so is every call after a capture that fails (with a warning): on CUDA, a stream that cannot be
    captured or an operation a capture does not allow.
    """

    __slots__ = ("device", "direct", "captured", "enabled", "graph", "ran")

    def __init__(self, device, direct, captured=None, enabled: bool = True):
        self.device, self.direct, self.captured = device, direct, captured or direct
        self.enabled, self.graph, self.ran = enabled, None, False

    def __call__(self) -> None:
        if self.graph is None:
            if not (self.enabled and self.ran):
                self.ran = True
                self.direct()
                return
            # the direct call loaded every kernel this graph launches
            try:
                wp.capture_begin(device=self.device, force_module_load=False)
            except RuntimeError as e:
                return self._without_graphs(e)
            try:
                self.captured()
            except RuntimeError as e:  # e.g. an operation CUDA does not allow in a capture
                with contextlib.suppress(RuntimeError):
                    wp.capture_end(device=self.device)  # discarded
                return self._without_graphs(e)
            except BaseException:
                wp.capture_end(device=self.device)
                raise
            self.graph = wp.capture_end(device=self.device)
        wp.capture_launch(self.graph)

    def _without_graphs(self, error: Exception) -> None:
        """A capture that failed recorded work without running it: every call is direct from now."""
        self.enabled = False
        warnings.warn(
            f"graph capture failed on {self.device} ({error}); running Warp's launches directly "
            "(the same results, slower)",
            RuntimeWarning,
            stacklevel=3,
        )
        self.direct()


@wp.kernel
def keep_input_grads(
    q_grad: wp.array[float],
    qd_grad: wp.array[float],
    tau_grad: wp.array[float],
    q_keep: wp.array[float],
    qd_keep: wp.array[float],
    g_tau: wp.array[float],
):
    """After one sub-step's backward: keep its input-state gradient, accumulate the torque's."""
    i = wp.tid()
    q_keep[i] = q_grad[i]
    qd_keep[i] = qd_grad[i]
    g_tau[i] = g_tau[i] + tau_grad[i]


@wp.kernel
def seed_output_grads(
    q_keep: wp.array[float],
    qd_keep: wp.array[float],
    q_grad: wp.array[float],
    qd_grad: wp.array[float],
):
    """Seed the previous sub-step's output gradient with the kept one (its tape zeroed it)."""
    i = wp.tid()
    q_grad[i] = q_keep[i]
    qd_grad[i] = qd_keep[i]


@dataclass
class StepBuffers:
    """Everything physics sub-step ``k`` of a differentiable rollout needs for its backward pass."""

    state_out: newton.State
    scratch: dict  # name -> wp.array, the solver's mass-matrix scratch for this step
    tape: wp.Tape
    q_out: torch.Tensor  # torch views (W, dof) of state_out.joint_q / joint_qd and their grads
    qd_out: torch.Tensor
    q_out_grad: torch.Tensor
    qd_out_grad: torch.Tensor


@dataclass
class ControlBuffers:
    """Control step ``c``: its ``substeps`` sub-steps share one control and replay as one graph each way.

    ``forward`` runs the taped sub-steps (recording their tapes the first time); ``backward`` runs,
    for each sub-step from the last: ``tape.backward()``, :func:`keep_input_grads`, ``tape.zero()``
    and :func:`seed_output_grads` into the sub-step before -- the gradient hand-over that used to be
    torch copies between per-sub-step replays, now inside the captured work.
    """

    control: newton.Control
    q_in: torch.Tensor  # (W, dof) views of the input state of the first sub-step
    qd_in: torch.Tensor
    tau: torch.Tensor  # view of control.joint_f
    g_tau: wp.array  # d loss / d tau of this control step, summed over its sub-steps
    q_keep: wp.array  # d loss / d (q, qd) of the input state, kept across a tape.zero()
    qd_keep: wp.array
    g_tau_t: torch.Tensor  # torch views of the three above
    q_keep_t: torch.Tensor
    qd_keep_t: torch.Tensor
    forward: Replay | None = None
    backward: Replay | None = None
