"""The nominal model's joint-space inertia ``M(q)``, as data: what the ``inertial`` critic reads.

The ``inertial`` critic layout (:mod:`warp_critic.learning.networks`) sees a torque as the torque
that would give the same joint acceleration at the home pose, ``M(q_h) M(q)^-1 tau``, and the inner
update steps the torques in the metric that makes a critic gradient the same acceleration change in
every pose. Both need ``M(q)`` at the states a policy visited. Those states are data, so ``M(q)`` is
evaluated forward only: no model gradient, as everywhere in the inner loop. It is the *nominal*
model's inertia (the scene as authored, no variant), the one model a learner is assumed to know, so
a critic tested on a changed robot does not read the changed robot's inertia.
"""

from __future__ import annotations

import torch

CHUNK = 4096  # states per evaluation: the size of the evaluating model, in worlds


class NominalInertia:
    """``M(q)`` [kg m^2 or kg] of ``scene``'s nominal model: ``q (..., dof)`` -> ``(..., dof, dof)``.

    Built lazily on the first call (a Newton model of :data:`CHUNK` worlds), so a normaliser can
    carry one at no cost for critics that never read it. The last result is kept: the critic's
    features and the inner update's metric ask for the same states in turn.
    """

    def __init__(self, scene, device: str = "cpu"):
        self.scene, self.device = scene, str(device)
        self._model = None
        self._last: tuple[torch.Tensor, torch.Tensor] | None = None
        self._home: torch.Tensor | None = None

    def _build(self):
        import newton

        from warp_critic.physics.simulator import Simulator
        from warp_critic.physics.variants import Variant

        sim = Simulator(
            self.scene, [Variant()] * CHUNK, dt=1e-3, device=self.device, differentiable=False
        )
        self._model, self._dof, self._torch_device = sim.model, sim.dof, sim.torch_device
        self._state = sim.model.state(requires_grad=False)
        self._eval = (newton.eval_fk, newton.eval_mass_matrix)

    def _evaluate(self, q: torch.Tensor) -> torch.Tensor:
        import warp as wp

        if self._model is None:
            self._build()
        fk, mass = self._eval
        flat = q.detach().reshape(-1, self._dof).to(torch.float32)
        out = []
        joint_q = wp.to_torch(self._state.joint_q).view(CHUNK, self._dof)
        for start in range(0, flat.shape[0], CHUNK):
            part = flat[start : start + CHUNK]
            joint_q.zero_()
            joint_q[: part.shape[0]].copy_(part)
            fk(self._model, self._state.joint_q, self._state.joint_qd, self._state)
            H = wp.to_torch(mass(self._model, self._state))
            out.append(H[: part.shape[0], : self._dof, : self._dof].clone())
        return torch.cat(out).reshape(*q.shape, self._dof).to(self._torch_device)

    def __call__(self, q: torch.Tensor) -> torch.Tensor:
        last = self._last
        if last is not None and last[0].shape == q.shape and torch.equal(last[0], q.detach()):
            return last[1]
        M = self._evaluate(q)
        self._last = (q.detach().clone(), M)
        return M

    def home(self) -> torch.Tensor:
        """``M(q_h)`` ``(dof, dof)`` at the scene's home pose ``q_h``, computed once."""
        if self._home is None:
            q_home = torch.as_tensor(self.scene.home, dtype=torch.float32).reshape(1, -1)
            self._home = self._evaluate(q_home)[0].to(self._torch_device)
        return self._home
