"""The warp <-> torch boundary: Newton's Featherstone step as a torch autograd function.

This is the only module that moves data between torch tensors and Newton/Warp arrays.

State convention (per world ``w``, ``dof`` joints, ``W`` worlds): joint positions ``q`` (rad or m)
and velocities ``qd`` (rad/s or m/s) as torch tensors of shape ``(W, dof)``, joint torques/forces
``tau`` (N·m or N) of shape ``(W, dof)``, float32, on the simulator's device.

Two paths:

* **forward only** (:meth:`NewtonBridge.step`, or a rollout's step under ``torch.no_grad`` or with no
  input requiring a gradient): two preallocated Newton states ping-pong, no tape, no per-step
  allocation.
* **differentiable** (:meth:`DiffRollout.step`, :class:`_SimStep`): every physics sub-step ``k`` of a rollout gets its own
  Newton state, its own ``wp.Tape`` and its **own copy of the solver's mass-matrix scratch**
  (``M, J, P, H, L``; :mod:`warp_critic.physics.scratch` says why). Swapping in a per-step scratch
  set before each taped step keeps every step's matrices alive for its backward pass -- the same
  exactness as re-running each step's forward inside its backward (checkpointing), without paying
  for the second forward.

  One tape per sub-step (rather than one per control step) matters too: each step overwrites
  ``state_in.body_q`` with forward kinematics that the previous step had already written, and Warp's
  adjoint does not clear the gradient of an overwritten array, so the ``body_q`` gradient would be
  counted twice. Between sub-steps we therefore read the joint-space gradient, zero the tape and
  re-seed only ``joint_q``/``joint_qd``, which fully determine the next step.

On CUDA, Warp launches go to torch's current stream when that is a stream of its own
(``wp.stream_from_torch``), else to Warp's blocking device stream, which CUDA orders with torch's
default (NULL) stream: either way torch copies into the zero-copy views and Warp kernels are ordered
without host synchronisation, and the step can be captured into a CUDA graph (see ``_stream``).

**Graph replay** (:mod:`warp_critic.physics.replay`). Every step of both paths always touches the
same arrays (the forward path's ping-pong pair; the differentiable path's per-sub-step buffers,
reused across rollouts), so after running it once directly the bridge captures it and replays it
with ``wp.capture_launch``: one graph per control step forward (its ``substeps`` solver steps), and
in a differentiable rollout one graph per control step for the taped forward and one for the
backward (each sub-step's ``tape.backward()``, the gradient hand-over between sub-steps and
``tape.zero()``). Replay runs the same kernels on the same memory in the same order, so results
are bitwise those of the direct calls (``tests/test_bridge.py`` checks it).

**Rollouts are objects.** :meth:`NewtonBridge.begin_rollout` returns a :class:`DiffRollout` that
counts its own steps. Buffers are reused across rollouts: starting a newer one invalidates the
older one's, and calling ``backward`` through an older graph raises instead of silently returning
wrong gradients.

**The mass matrix on a CPU** (:mod:`warp_critic.physics.mass_matrix`): the solver's tile kernel
for ``H = J^T M J`` and its Cholesky factor is swapped for a register kernel with bitwise the same
results, forward and reverse, 4x faster forward and 3x in reverse on the KUKA.
"""

from __future__ import annotations

import contextlib

import newton
import torch
import warp as wp

from warp_critic.physics.mass_matrix import use_register_kernels
from warp_critic.physics.replay import (
    ControlBuffers,
    Replay,
    StepBuffers,
    keep_input_grads,
    seed_output_grads,
)
from warp_critic.physics.scratch import SolverScratch


class NewtonBridge:
    """Batched Featherstone stepping of ``W`` identical-topology worlds, driven from torch.

    Args:
        model: a finalized ``newton.Model`` with ``W`` worlds of ``dof`` joints each, built with
            ``requires_grad=True`` if differentiable rollouts are wanted.
        worlds: number of worlds ``W``.
        dof: joints per world.
        dt: physics time step (s).
        substeps: physics steps per call of :meth:`step` (the control is held constant over them).
        use_tile_gemm: let Featherstone form ``H = J^T M J`` and its Cholesky factor with Warp tile
            kernels (3x faster than the dense batched GEMM at 64 iiwa worlds on a CPU); on a CPU
            the tile kernel is then swapped for a register kernel of the same results
            (:func:`~warp_critic.physics.mass_matrix.use_register_kernels`).
        graphs: replay captured graphs instead of re-issuing each step's Warp launches (see the
            module docstring); ``False`` issues every launch from Python (bitwise the same results).
    """

    def __init__(
        self,
        model: newton.Model,
        worlds: int,
        dof: int,
        dt: float,
        substeps: int = 1,
        use_tile_gemm: bool = True,
        graphs: bool = True,
    ):
        if model.joint_dof_count != worlds * dof or model.joint_coord_count != worlds * dof:
            raise ValueError(
                f"model has {model.joint_dof_count} dofs / {model.joint_coord_count} coords, "
                f"expected {worlds} worlds x {dof}"
            )
        self.model = model
        self.worlds, self.dof = worlds, dof
        self.dt, self.substeps = float(dt), int(substeps)
        self.device = model.device
        self.torch_device = torch.device(wp.device_to_torch(model.device))
        self.requires_grad = bool(model.requires_grad)
        self.solver = newton.solvers.SolverFeatherstone(model, use_tile_gemm=use_tile_gemm)
        self.register_kernels = use_register_kernels(self.solver)  # the sizes swapped (CPU)
        self._is_cuda = self.torch_device.type == "cuda"
        self._wp_streams: dict[int, wp.Stream] = {}  # torch stream handle -> its Warp stream
        self.scratch = SolverScratch(self.solver)  # the solver's own, and a copy per taped step
        # A replayed step skips the solver's Python, including its every-N-steps mass-matrix
        # schedule: replay only what is the same on every step.
        self.graphs = bool(graphs) and self.solver.update_mass_matrix_interval == 1

        # forward-only path: two states without gradients, one control
        self._fw_states = [model.state(requires_grad=False), model.state(requires_grad=False)]
        self._fw_control = model.control(clone_variables=True, requires_grad=False)
        self._fw_q = [self._view(s.joint_q) for s in self._fw_states]
        self._fw_qd = [self._view(s.joint_qd) for s in self._fw_states]
        self._fw_tau = self._view(self._fw_control.joint_f)
        self._fw_run = Replay(model.device, self._fw_substeps, enabled=self.graphs)
        self._fw_last = self.substeps % 2  # the ping-pong state holding the result

        # differentiable path: grown on demand, reused across rollouts
        self._steps: list[StepBuffers] = []  # one per physics sub-step
        self._controls: list[ControlBuffers] = []  # one per control step
        self._state0: newton.State | None = None
        self.generation = 0  # of the newest DiffRollout: older ones' buffers are overwritten

    # -- torch views on warp memory ------------------------------------------------------------
    def _view(self, arr: wp.array) -> torch.Tensor:
        """Zero-copy ``(W, dof)`` torch view of a per-dof Warp array."""
        return wp.to_torch(arr).view(self.worlds, self.dof)

    def _stream(self):
        """The CUDA stream Warp runs on for one call (no-op on CPU).

        Under a ``torch.cuda.stream(s)`` context: ``s`` itself, so torch's copies into the views and
        Warp's kernels are ordered without host synchronisation. On torch's default stream -- the
        legacy NULL stream, which CUDA cannot capture into a graph and Warp does not register
        ("Warp error: unknown stream" at ``capture_begin``) -- Warp's own stream of the device: a
        blocking stream, which CUDA orders with every NULL-stream operation both ways.
        """
        if not self._is_cuda:
            return contextlib.nullcontext()
        ts = torch.cuda.current_stream(self.torch_device)
        if ts.cuda_stream == 0:
            return wp.ScopedStream(self.device.stream)
        ws = self._wp_streams.get(ts.cuda_stream)
        if ws is None:  # one registered Warp stream per torch stream, kept (graphs replay on it)
            ws = self._wp_streams[ts.cuda_stream] = wp.stream_from_torch(ts)
        return wp.ScopedStream(ws)

    # -- forward only --------------------------------------------------------------------------
    @torch.no_grad()
    def step_forward(self, q: torch.Tensor, qd: torch.Tensor, tau: torch.Tensor):
        """One control step (``substeps`` physics steps) without gradients. Returns new tensors."""
        with self._stream():
            return self._step_forward(q, qd, tau)

    def _step_forward(self, q, qd, tau):
        self._fw_q[0].copy_(q)
        self._fw_qd[0].copy_(qd)
        self._fw_tau.copy_(tau)
        self._fw_run()
        return self._fw_q[self._fw_last].clone(), self._fw_qd[self._fw_last].clone()

    def _fw_substeps(self) -> None:
        self.scratch.restore()
        a, b = 0, 1
        for _ in range(self.substeps):
            self.solver.step(
                self._fw_states[a], self._fw_states[b], self._fw_control, None, self.dt
            )
            a, b = b, a

    # -- differentiable ------------------------------------------------------------------------
    def begin_rollout(self) -> DiffRollout:
        """Start a differentiable rollout: returns its :class:`DiffRollout`.

        The rollout object carries its own position; starting a newer one reuses the buffers, and a
        ``backward()`` through an older one then raises instead of returning wrong gradients.
        """
        if not self.requires_grad:
            raise RuntimeError(
                "differentiable rollout needs a model finalized with requires_grad=True"
            )
        self.generation += 1
        if self._state0 is None:
            self._state0 = self.model.state(requires_grad=True)
        return DiffRollout(self, self.generation)

    def _state_in(self, k: int) -> newton.State:
        return self._state0 if k == 0 else self._steps[k - 1].state_out

    def _grow(self, c: int) -> None:
        """Buffers for control steps ``0 .. c`` (and their sub-steps)."""
        S = self.substeps
        while len(self._steps) < (c + 1) * S:
            s = self.model.state(requires_grad=True)
            self._steps.append(
                StepBuffers(
                    state_out=s,
                    scratch=self.scratch.new(),
                    tape=wp.Tape(),
                    q_out=self._view(s.joint_q),
                    qd_out=self._view(s.joint_qd),
                    q_out_grad=self._view(s.joint_q.grad),
                    qd_out_grad=self._view(s.joint_qd.grad),
                )
            )
        while len(self._controls) <= c:
            i = len(self._controls)
            control = self.model.control(clone_variables=True, requires_grad=True)
            state_in = self._state_in(i * S)
            n = self.worlds * self.dof
            keep = [wp.zeros(n, dtype=float, device=self.device) for _ in range(3)]
            buf = ControlBuffers(
                control=control,
                q_in=self._view(state_in.joint_q),
                qd_in=self._view(state_in.joint_qd),
                tau=self._view(control.joint_f),
                g_tau=keep[0],
                q_keep=keep[1],
                qd_keep=keep[2],
                g_tau_t=self._view(keep[0]),
                q_keep_t=self._view(keep[1]),
                qd_keep_t=self._view(keep[2]),
            )
            buf.forward = Replay(
                self.device,
                lambda i=i: self._taped_substeps(i, record=True),
                lambda i=i: self._taped_substeps(i, record=False),
                enabled=self.graphs,
            )
            buf.backward = Replay(
                self.device, lambda i=i: self._backward_substeps(i), enabled=self.graphs
            )
            self._controls.append(buf)

    def _taped_substeps(self, c: int, record: bool) -> None:
        """The sub-steps of control step ``c``; each records its own tape once (``record``)."""
        control = self._controls[c].control
        for k in range(c * self.substeps, (c + 1) * self.substeps):
            buf = self._steps[k]
            self.scratch.use(buf.scratch)
            if record:  # later rollouts reuse the same arrays, so the tape stays valid
                buf.tape.reset()
                with buf.tape:
                    self.solver.step(self._state_in(k), buf.state_out, control, None, self.dt)
            else:
                self.solver.step(self._state_in(k), buf.state_out, control, None, self.dt)
        self.scratch.restore()

    def _backward_substeps(self, c: int) -> None:
        """Reverse sub-steps of control step ``c``: the output gradient is seeded in the last one."""
        cb = self._controls[c]
        tau_grad = cb.control.joint_f.grad
        tau_grad.zero_()
        cb.g_tau.zero_()
        n = self.worlds * self.dof
        for k in reversed(range(c * self.substeps, (c + 1) * self.substeps)):
            state_in = self._state_in(k)
            self._steps[k].tape.backward()
            wp.launch(
                keep_input_grads,
                dim=n,
                inputs=[state_in.joint_q.grad, state_in.joint_qd.grad, tau_grad],
                outputs=[cb.q_keep, cb.qd_keep, cb.g_tau],
                device=self.device,
            )
            self._steps[k].tape.zero()  # every gradient this step touched (incl. its inputs')
            tau_grad.zero_()
            if k > c * self.substeps:
                wp.launch(
                    seed_output_grads,
                    dim=n,
                    inputs=[cb.q_keep, cb.qd_keep],
                    outputs=[state_in.joint_q.grad, state_in.joint_qd.grad],
                    device=self.device,
                )

    def step(self, q: torch.Tensor, qd: torch.Tensor, tau: torch.Tensor):
        """One control step without gradients (a differentiable one: :meth:`begin_rollout`)."""
        if torch.is_grad_enabled() and (q.requires_grad or qd.requires_grad or tau.requires_grad):
            raise RuntimeError(
                "a differentiable step belongs to a rollout: "
                "rollout = sim.begin_rollout(); q, qd = rollout.step(q, qd, tau)"
            )
        return self.step_forward(q, qd, tau)

    # called by _SimStep ----------------------------------------------------------------------
    def _forward_taped(self, c: int, q, qd, tau):
        with self._stream():
            self._grow(c)
            cb = self._controls[c]
            cb.q_in.copy_(q)
            cb.qd_in.copy_(qd)
            cb.tau.copy_(tau)
            assert cb.forward is not None  # captured by _grow
            cb.forward()
            last = self._steps[(c + 1) * self.substeps - 1]
            return last.q_out.clone(), last.qd_out.clone()

    def _backward_taped(self, c: int, gq, gqd):
        with self._stream():
            last = self._steps[(c + 1) * self.substeps - 1]
            last.q_out_grad.copy_(gq)
            last.qd_out_grad.copy_(gqd)
            cb = self._controls[c]
            assert cb.backward is not None  # captured by _grow
            cb.backward()
            return cb.q_keep_t.clone(), cb.qd_keep_t.clone(), cb.g_tau_t.clone()


class DiffRollout:
    """One differentiable rollout: control steps chained through the bridge's reused buffers.

    ``q, qd`` of step ``i+1`` must be the outputs of step ``i``. Use as a plain object or as a
    context manager (``with sim.begin_rollout() as ro: q, qd = ro.step(q, qd, tau)``); backward
    through its steps works until the bridge starts a newer rollout.
    """

    def __init__(self, bridge: NewtonBridge, generation: int):
        self.bridge, self.generation = bridge, generation
        self.steps = 0  # control steps taken

    def __enter__(self) -> DiffRollout:
        return self

    def __exit__(self, *exc) -> None:
        return None

    @property
    def current(self) -> bool:
        """Whether the bridge's buffers still hold this rollout."""
        return self.generation == self.bridge.generation

    def step(self, q: torch.Tensor, qd: torch.Tensor, tau: torch.Tensor):
        """One control step, differentiable w.r.t. ``q``, ``qd`` and ``tau`` when grad is enabled."""
        if torch.is_grad_enabled() and (q.requires_grad or qd.requires_grad or tau.requires_grad):
            if not self.current:
                raise RuntimeError("a newer rollout has started: this one can take no more steps")
            return _SimStep.apply(q, qd, tau, self)
        return self.bridge.step_forward(q, qd, tau)


class _SimStep(torch.autograd.Function):
    """``(q, qd, tau) -> (q', qd')`` through ``substeps`` Featherstone steps, exact reverse mode."""

    @staticmethod
    def forward(ctx, q, qd, tau, rollout: DiffRollout):
        c = rollout.steps
        q1, qd1 = rollout.bridge._forward_taped(c, q.detach(), qd.detach(), tau.detach())
        rollout.steps += 1
        ctx.rollout, ctx.c = rollout, c
        return q1, qd1

    @staticmethod
    def backward(ctx, gq, gqd):
        rollout, bridge = ctx.rollout, ctx.rollout.bridge
        if not rollout.current:
            raise RuntimeError(
                "this rollout's simulation buffers were reused by a newer rollout before backward(); "
                "call backward() before starting the next differentiable rollout"
            )
        if gq is None:
            gq = torch.zeros(bridge.worlds, bridge.dof, device=bridge.torch_device)
        if gqd is None:
            gqd = torch.zeros_like(gq)
        dq, dqd, dtau = bridge._backward_taped(ctx.c, gq.contiguous(), gqd.contiguous())
        return dq, dqd, dtau, None
