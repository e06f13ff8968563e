"""Featherstone's joint-space mass matrix ``H = J^T M J`` and its Cholesky factor, per articulation,
in registers: a CPU replacement for Newton's tile kernel of the same signature.

Newton's ``SolverFeatherstone`` (``use_tile_gemm``) forms ``H`` and ``L`` with Warp tile kernels
(``create_inertia_matrix_cholesky_kernel``). On a CPU a tile kernel runs as one thread per
articulation through Warp's generic tile loops, and it was half of a KUKA physics step (5.5 us of
9.4 us per world and sub-step at 1000 worlds). This kernel, 1.3 us forward and 6.4 us in reverse
per KUKA world against the tile kernel's 5.3 and 20 us (one 2-core CPU, side by side), computes
the same thing with every loop unrolled over fixed sizes and the matrices held in registers: each
6x6 diagonal block ``M_b`` of the spatial inertias times the 6 rows ``J_b`` of the Jacobian,
``H = sum_b J_b^T (M_b J_b)``, then ``L = chol(H + diag(armature))``.

Its ``H`` and ``L`` are bitwise those of the tile kernel on a CPU: the same products summed in the
same order (Warp's tile matmul accumulates body by body into ``H``) and the tile Cholesky's
operations (``1 / s`` in double, then multiplied). Its reverse mode is that of the tile kernel too:
the gradient reaches ``J`` and ``M`` from ``H``'s adjoint only; the factor's adjoint is not used,
because Newton differentiates the solve ``H x = b`` through ``H`` (``adj_dense_solve`` adds
``-adj_b x^T`` to ``H``'s adjoint) and the tile path, like this one, passes nothing back through the
factorisation. ``tests/test_mass_matrix.py`` compares both, forward and reverse, bit for bit.

No ``from __future__ import annotations`` here: Warp resolves the kernels' annotations, and the
matrix types are local to :func:`mass_matrix_cholesky_kernel`.
"""

import functools

import warp as wp

#: the largest joint or degree-of-freedom count of an articulation this kernel is built for: every
#: loop is unrolled (Warp's ``max_unroll``), so its code grows with the size. Compiled once per size
#: and machine, as Newton's tile kernel: 3.4 s at 7 x 7, 11.8 s at 16 x 16 (the tile kernel 4.7 s and
#: 10.9 s) on a 2-core CPU
MAX_SIZE = 16


@functools.cache
def mass_matrix_cholesky_kernel(num_joints: int, num_dofs: int) -> wp.Kernel:
    """The kernel for articulations of ``num_joints`` joints and ``num_dofs`` degrees of freedom,
    with the signature of Newton's ``create_inertia_matrix_cholesky_kernel(num_joints, num_dofs)``:
    ``J (n, 6 num_joints, num_dofs)``, ``M (n, 6 num_joints, 6 num_joints)`` (block diagonal),
    ``group_to_art (n,)``, ``articulation_dof_start``, ``armature`` (kg m^2 or kg, per dof) ->
    ``H, L (n, num_dofs, num_dofs)``. Launched by ``wp.launch_tiled`` (one lane per articulation
    works; the others return)."""
    if not (1 <= num_joints <= MAX_SIZE and 1 <= num_dofs <= MAX_SIZE):
        raise ValueError(
            f"articulations of {num_joints} joints and {num_dofs} dofs: at most {MAX_SIZE} each"
        )
    mat6n = wp.types.matrix(shape=(6, num_dofs), dtype=float)
    matnn = wp.types.matrix(shape=(num_dofs, num_dofs), dtype=float)

    @wp.func
    def cholesky_store(H: matnn, armature: wp.array[float], start: int, L: wp.array2d[float]):
        # Warp's scalar tile Cholesky (tile_cholesky.h), operation for operation
        for j in range(num_dofs):
            s = H[j, j] + armature[start + j]
            for k in range(j):
                s -= L[j, k] * L[j, k]
            s = wp.sqrt(s)
            inv_s = wp.float32(wp.float64(1.0) / wp.float64(s))  # C++'s 1.0 / s: in double
            L[j, j] = s
            for i in range(j + 1, num_dofs):
                t = H[i, j]
                for k in range(j):
                    t -= L[i, k] * L[j, k]
                L[i, j] = t * inv_s
                L[j, i] = 0.0

    @wp.func_grad(cholesky_store)
    def adj_cholesky_store(H: matnn, armature: wp.array[float], start: int, L: wp.array2d[float]):
        pass  # as the tile kernel: the solve is differentiated through H (module docstring)

    @wp.func
    def body_term(J: wp.array2d[float], M: wp.array2d[float], b: int):
        # J_b^T (M_b J_b) of body b: its 6x6 block of the spatial inertias, its 6 rows of J
        M_b = wp.spatial_matrix()
        J_b = mat6n()
        for r in range(6):
            for c in range(6):
                M_b[r, c] = M[6 * b + r, 6 * b + c]
            for i in range(num_dofs):
                J_b[r, i] = J[6 * b + r, i]
        return wp.transpose(J_b) @ (M_b @ J_b)

    @wp.kernel(module="unique", module_options={"max_unroll": MAX_SIZE})
    def mass_matrix_cholesky(
        J: wp.array3d[float],
        M: wp.array3d[float],
        group_to_art: wp.array[int],
        articulation_dof_start: wp.array[int],
        armature: wp.array[float],
        H: wp.array3d[float],
        L: wp.array3d[float],
    ):
        idx, lane = wp.tid()
        if lane != 0:
            return
        H_sum = matnn()
        for b in range(num_joints):
            H_sum += body_term(J[idx], M[idx], b)
        for i in range(num_dofs):
            for j in range(num_dofs):
                H[idx, i, j] = H_sum[i, j]
        cholesky_store(H_sum, armature, articulation_dof_start[group_to_art[idx]], L[idx])

    return mass_matrix_cholesky
