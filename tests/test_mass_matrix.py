"""The CPU's register kernel for Featherstone's mass matrix gives the tile kernel's numbers, bit for
bit, forward and reverse (``kernels/mass_matrix.py``): on the matrices of a real step, and through a
differentiable rollout of the whole simulator."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch
import warp as wp
from conftest import ROOT
from newton._src.solvers.featherstone.kernels import create_inertia_matrix_cholesky_kernel

from warp_critic.kernels.mass_matrix import MAX_SIZE, mass_matrix_cholesky_kernel
from warp_critic.physics.load import load_scene
from warp_critic.physics.mass_matrix import use_register_kernels
from warp_critic.physics.scene import Variant
from warp_critic.physics.simulator import Simulator


def _sim(worlds: int, differentiable: bool, name: str = "kuka") -> Simulator:
    scene = load_scene(ROOT / "scenes" / f"{name}.usda")
    return Simulator(
        scene,
        [Variant()] * worlds,
        dt=0.0025,
        substeps=2,
        device="cpu",
        differentiable=differentiable,
    )


def _both_kernels(size, J0, M0, group, dof_start, armature, adj_H, adj_L) -> dict:
    """``{"tile"|"register": [H, L, adj J, adj M]}`` of Newton's kernel and ours for articulations
    of ``size = (joints, dofs)``: ``J0 (n, 6 joints, dofs)``, ``M0 (n, 6 joints, 6 joints)``, the
    adjoints given to ``H`` and ``L`` ``(n, dofs, dofs)`` (numpy); ``group``, ``dof_start`` and
    ``armature`` Warp arrays as the solver passes them."""
    out = {}
    for name, kernel in (
        ("tile", create_inertia_matrix_cholesky_kernel(*size)),
        ("register", mass_matrix_cholesky_kernel(*size)),
    ):
        J = wp.array(J0, requires_grad=True)
        M = wp.array(M0, requires_grad=True)
        H = wp.zeros(adj_H.shape, requires_grad=True)
        L = wp.zeros(adj_H.shape, requires_grad=True)
        tape = wp.Tape()
        with tape:
            wp.launch_tiled(
                kernel,
                dim=J0.shape[0],
                inputs=[J, M, group, dof_start, armature],
                outputs=[H, L],
                device="cpu",
                block_dim=64,
            )
        tape.backward(grads={H: wp.array(adj_H), L: wp.array(adj_L)})
        out[name] = [a.numpy().copy() for a in (H, L, J.grad, M.grad)]
    return out


def _assert_bitwise(out: dict) -> None:
    for what, tile, reg in zip(("H", "L", "adj J", "adj M"), out["tile"], out["register"]):
        assert np.array_equal(tile, reg), f"{what} differs from the tile kernel's"
    assert np.abs(out["register"][2]).max() > 0, "no gradient reached J"


def test_the_cpu_bridge_uses_the_register_kernel():
    sim = _sim(2, differentiable=False)
    solver = sim.bridge.solver
    assert sim.bridge.register_kernels == list(solver._group_to_art) == [(7, 7)]
    assert solver._tile_kernels_by_size[(7, 7)] is mass_matrix_cholesky_kernel(7, 7)


@pytest.mark.parametrize("name", ["kuka", "reacher"])
def test_same_h_l_and_gradients_as_the_tile_kernel_on_a_real_step(name):
    """J and M of a robot after a step from a random state; H and L, then the adjoints of J and M
    for random adjoints of H and L: equal to the last bit."""
    sim = _sim(5, differentiable=False, name=name)
    gen = torch.Generator().manual_seed(0)
    dof = sim.dof
    q = (torch.rand(5, dof, generator=gen) - 0.5) * 2.0
    sim.step(q, torch.randn(5, dof, generator=gen), torch.randn(5, dof, generator=gen) * 10)
    solver, (size,) = sim.bridge.solver, list(sim.bridge.register_kernels)
    J0, M0 = solver._J_by_size[size].numpy(), solver._M_by_size[size].numpy()
    assert np.abs(J0).max() > 0.1 and np.abs(M0).max() > 0.1, "the step left J or M empty"
    rng = np.random.default_rng(1)
    shape = (5, size[1], size[1])
    adj_H = rng.standard_normal(shape).astype(np.float32)
    adj_L = rng.standard_normal(shape).astype(np.float32)
    group = solver._group_to_art[size]
    out = _both_kernels(
        size,
        J0,
        M0,
        group,
        solver.articulation_dof_start,
        solver.joint_armature_effective,
        adj_H,
        adj_L,
    )
    _assert_bitwise(out)


def test_same_as_the_tile_kernel_with_more_dofs_than_joints():
    """A size no shipped robot has (3 joints, 8 dofs: a free base and two hinges), random
    Jacobians and block-diagonal inertias, per-dof armature: the same numbers to the last bit."""
    rng = np.random.default_rng(3)
    n, (joints, dofs) = 4, (3, 8)
    J0 = rng.standard_normal((n, 6 * joints, dofs)).astype(np.float32)
    M0 = np.zeros((n, 6 * joints, 6 * joints), np.float32)
    for b in range(joints):
        A = rng.standard_normal((n, 6, 6))
        M0[:, 6 * b : 6 * b + 6, 6 * b : 6 * b + 6] = A @ A.transpose(0, 2, 1) + np.eye(6)
    adj = rng.standard_normal((2, n, dofs, dofs)).astype(np.float32)
    out = _both_kernels(
        (joints, dofs),
        J0,
        M0,
        wp.array(np.arange(n, dtype=np.int32)),
        wp.array(np.arange(n, dtype=np.int32) * dofs),
        wp.array(rng.uniform(0.01, 0.5, n * dofs).astype(np.float32)),
        adj[0],
        adj[1],
    )
    _assert_bitwise(out)


def test_a_differentiable_rollout_is_bitwise_the_tile_kernels():
    """States and the gradients of a loss w.r.t. torques and the start state, through 8 control
    steps: the simulator with the register kernel and one with Newton's tile kernel put back."""
    results = []
    for tile in (True, False):
        sim = _sim(3, differentiable=True)
        if tile:
            for size in sim.bridge.register_kernels:
                sim.bridge.solver._tile_kernels_by_size[size] = (
                    create_inertia_matrix_cholesky_kernel(*size)
                )
        gen = torch.Generator().manual_seed(2)
        q0 = ((torch.rand(3, 7, generator=gen) - 0.5) * 0.6).requires_grad_()
        qd0 = torch.randn(3, 7, generator=gen).requires_grad_()
        taus = (torch.randn(8, 3, 7, generator=gen) * 20).requires_grad_()
        q, qd, loss = q0, qd0, 0.0
        with sim.begin_rollout() as ro:
            for t in range(8):
                q, qd = ro.step(q, qd, taus[t])
                loss = loss + (q**2).sum() + 0.1 * (qd**2).sum()
        grads = torch.autograd.grad(loss, [taus, q0, qd0])
        results.append([q.detach(), qd.detach(), *grads])
    for tile, reg in zip(*results):
        assert torch.equal(tile, reg)
    assert results[1][2].abs().max() > 0


def test_only_cpu_tile_solvers_of_small_articulations_are_swapped():
    def solver(cuda=False, tile=True, fused=True, mimics=False, sizes=((7, 7), (17, 16))):
        return SimpleNamespace(
            model=SimpleNamespace(device=SimpleNamespace(is_cuda=cuda)),
            use_tile_gemm=tile,
            fuse_cholesky=fused,
            _has_joint_mimics=mimics,
            _tile_kernels_by_size={s: "newton's" for s in sizes},
        )

    s = solver()
    assert use_register_kernels(s) == [(7, 7)]
    assert s._tile_kernels_by_size[(17, 16)] == "newton's", f"more than {MAX_SIZE} joints swapped"
    for kept in (solver(cuda=True), solver(tile=False), solver(fused=False), solver(mimics=True)):
        assert use_register_kernels(kept) == []
        assert set(kept._tile_kernels_by_size.values()) == {"newton's"}
    with pytest.raises(ValueError, match="at most 16"):
        mass_matrix_cholesky_kernel(17, 7)
