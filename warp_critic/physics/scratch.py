"""Featherstone's mass-matrix scratch, one private set per taped physics step.

``SolverFeatherstone`` keeps its mass-matrix/Jacobian scratch (``M, J, P, H, L``; with
``use_tile_gemm`` also batched views of ``J, M, H, L`` grouped by articulation size) on the solver
object and rewrites it every step, so a single ``wp.Tape`` over many steps replays the backward pass
of every step with the *last* step's matrices (on a 60-step iiwa rollout that gradient was ~100%
wrong). :class:`SolverScratch` makes private copies of the set and swaps one in before each taped
step (:mod:`warp_critic.physics.bridge`), so every step's matrices stay alive for its backward
pass; the solver's own set is swapped back for untaped steps. ``tests/test_newton_internals.py``
pins the solver attributes this relies on.
"""

from __future__ import annotations

from typing import Any

import warp as wp

SCRATCH = ("M", "J", "P", "H", "L")
# With use_tile_gemm the solver reads batched views of J, M, H, L grouped by articulation size.
TILE_VIEWS = {
    "_J_by_size": ("J", "articulation_J_start"),
    "_M_by_size": ("M", "articulation_M_start"),
    "_H_by_size": ("H", "articulation_H_start"),
    "_L_by_size": ("L", "articulation_H_start"),
}


class SolverScratch:
    """The scratch of one ``SolverFeatherstone``: its own set, private copies, and swapping them in."""

    def __init__(self, solver: Any):
        self.solver = solver
        names = SCRATCH + (tuple(TILE_VIEWS) if solver.use_tile_gemm else ())
        self.own: dict[str, Any] = {n: getattr(solver, n) for n in names}

    def new(self) -> dict[str, Any]:
        """A private copy of the solver's scratch (and, for tile GEMM, its grouped views)."""
        solver = self.solver
        scratch: dict[str, Any] = {
            n: wp.zeros_like(self.own[n], requires_grad=True) for n in SCRATCH
        }
        if solver.use_tile_gemm:
            for view_name, (array_name, start_name) in TILE_VIEWS.items():
                starts = getattr(solver, start_name).numpy()
                views = {}
                for size, arts in solver._group_to_art.items():
                    shape = self.own[view_name][size].shape
                    first = int(arts.numpy()[0])
                    n = int(shape[0] * shape[1] * shape[2])
                    views[size] = scratch[array_name][
                        int(starts[first]) : int(starts[first]) + n
                    ].reshape(shape)
                scratch[view_name] = views
        return scratch

    def use(self, scratch: dict[str, Any]) -> None:
        """Let the solver's next steps write ``scratch`` (from :meth:`new`)."""
        for n, arr in scratch.items():
            setattr(self.solver, n, arr)

    def restore(self) -> None:
        """Give the solver its own scratch back."""
        self.use(self.own)
