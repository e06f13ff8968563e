"""Featherstone's mass matrix on a CPU in registers instead of Warp tiles (bitwise the same numbers).

``SolverFeatherstone`` launches, every physics step, one kernel per articulation size that forms
``H = J^T M J`` and its Cholesky factor (``solver._tile_kernels_by_size``). On a CPU that tile
kernel is half of the step; :func:`use_register_kernels` swaps in
:func:`~warp_critic.kernels.mass_matrix.mass_matrix_cholesky_kernel`, which has the same signature,
the same results bit for bit, forward and reverse, and is 4x faster forward and 3x in reverse on
the KUKA (``kernels/mass_matrix.py``). On CUDA the tile kernel stays: it is what tiles are for.
``tests/test_newton_internals.py`` pins the solver attributes this relies on.
"""

from __future__ import annotations

from typing import Any

from warp_critic.kernels.mass_matrix import MAX_SIZE, mass_matrix_cholesky_kernel


def use_register_kernels(solver: Any) -> list[tuple[int, int]]:
    """Give a CPU ``SolverFeatherstone`` the register kernels for each articulation size
    ``(joints, dofs)`` of at most :data:`~warp_critic.kernels.mass_matrix.MAX_SIZE` each; returns
    the sizes swapped. Nothing is swapped on CUDA, without tile GEMM, without the fused Cholesky
    or with mimic joints (the solver then launches other kernels)."""
    if (
        solver.model.device.is_cuda
        or not solver.use_tile_gemm
        or not solver.fuse_cholesky
        or solver._has_joint_mimics
    ):
        return []
    kernels = solver._tile_kernels_by_size
    swapped = [size for size in kernels if max(size) <= MAX_SIZE]
    for size in swapped:
        kernels[size] = mass_matrix_cholesky_kernel(*size)
    return swapped
