"""Pins of the Newton / Warp internals that ``warp_critic/physics/bridge.py`` depends on.

The bridge's exact reverse mode swaps a private copy of ``SolverFeatherstone``'s mass-matrix scratch
(``M, J, P, H, L`` and, with tile GEMM, the grouped views ``_J_by_size``, ``_M_by_size``,
``_H_by_size``, ``_L_by_size`` built from ``_group_to_art`` and ``articulation_*_start``) into the
solver before every taped step, and on a CPU it swaps the solver's tile kernel for the mass matrix
(``_tile_kernels_by_size``) for a register kernel (``physics/mass_matrix.py``, compared bit for bit
with Newton's in ``tests/test_mass_matrix.py``). None of that is public API. These fast checks fail, with one message,
as soon as a Newton or Warp upgrade changes any of it; ``tests/test_bridge.py``'s exactness tests are
the real proof and must be re-run before the pins here and in ``pyproject.toml`` are moved.
"""

from __future__ import annotations

import inspect

import numpy as np
import pytest
from conftest import ROOT

TESTED = {"newton": "1.8.0", "warp-lang": "1.19.0"}
ADVICE = (
    "bridge.py depends on Newton internals; re-run tests/test_bridge.py's exactness tests and update "
    "the pins (tests/test_newton_internals.py, pyproject.toml)"
)
SCRATCH = ("M", "J", "P", "H", "L")
TILE_VIEWS = {
    "_J_by_size": ("J", "articulation_J_start"),
    "_M_by_size": ("M", "articulation_M_start"),
    "_H_by_size": ("H", "articulation_H_start"),
    "_L_by_size": ("L", "articulation_H_start"),
}


def pin(ok: bool, what: str) -> None:
    if not ok:
        pytest.fail(f"{what}: {ADVICE}", pytrace=False)


@pytest.fixture(scope="module")
def sim():
    from warp_critic.core import runtime
    from warp_critic.physics.load import load_scene
    from warp_critic.physics.scene import Variant
    from warp_critic.physics.simulator import Simulator

    runtime.init_warp()
    scene = load_scene(ROOT / "scenes" / "reacher.usda")
    return Simulator(scene, [Variant()] * 3, dt=0.01, substeps=1, device="cpu", differentiable=True)


def test_versions_are_the_tested_ones():
    import newton
    import warp as wp

    pin(
        newton.__version__ == TESTED["newton"],
        f"newton {newton.__version__} is installed, tested: {TESTED['newton']}",
    )
    pin(
        wp.config.version == TESTED["warp-lang"],
        f"warp-lang {wp.config.version} is installed, tested: {TESTED['warp-lang']}",
    )
    pyproject = (ROOT / "pyproject.toml").read_text()
    for name, version in TESTED.items():
        pin(f'"{name}=={version}"' in pyproject, f"pyproject.toml does not pin {name}=={version}")


def test_solver_signatures():
    import newton

    cls = newton.solvers.SolverFeatherstone
    init = inspect.signature(cls.__init__).parameters
    pin("use_tile_gemm" in init, "SolverFeatherstone(model, use_tile_gemm=...) is gone")
    pin(
        init.get("update_mass_matrix_interval") is not None
        and init["update_mass_matrix_interval"].default == 1,
        "SolverFeatherstone's update_mass_matrix_interval no longer defaults to 1 (every step must rebuild M, J, H, L)",
    )
    step = list(inspect.signature(cls.step).parameters)
    pin(
        step[:6] == ["self", "state_in", "state_out", "control", "contacts", "dt"],
        f"SolverFeatherstone.step's signature changed: {step}",
    )


def test_step_reads_the_scratch_from_the_solver_attributes():
    """The bridge swaps arrays by ``setattr``: ``step`` must read them from ``self`` every call, and keep
    its other per-step intermediates on the output state when differentiating."""
    import newton

    src = inspect.getsource(newton.solvers.SolverFeatherstone.step)
    for name in SCRATCH:
        pin(f"self.{name}" in src, f"SolverFeatherstone.step no longer reads self.{name}")
    for name in (*TILE_VIEWS, "_group_to_art"):
        pin(
            f"self.{name}[size]" in src,
            f"SolverFeatherstone.step no longer reads self.{name}[size]",
        )
    pin(
        "state_aug = state_out" in src,
        "SolverFeatherstone.step no longer keeps its differentiable intermediates on state_out",
    )


def test_solver_scratch_layout(sim):
    import warp as wp

    solver, model = sim.bridge.solver, sim.model
    pin(solver.use_tile_gemm is True, "the bridge's solver does not use tile GEMM")
    pin(solver.update_mass_matrix_interval == 1, "the mass matrix is not rebuilt every step")
    sizes = {
        "M": solver.M_size,
        "J": solver.J_size,
        "P": solver.J_size,
        "H": solver.H_size,
        "L": solver.H_size,
    }
    for name in SCRATCH:
        arr = getattr(solver, name, None)
        pin(isinstance(arr, wp.array), f"SolverFeatherstone.{name} is not a wp.array")
        pin(
            arr.ndim == 1 and arr.dtype == wp.float32 and arr.shape == (sizes[name],),
            f"SolverFeatherstone.{name}: {arr.dtype} {arr.shape}, expected flat float32 ({sizes[name]},)",
        )
        pin(
            arr.requires_grad, f"SolverFeatherstone.{name} has no gradient on a requires_grad model"
        )
    arts = model.articulation_count
    for name in ("articulation_J_start", "articulation_M_start", "articulation_H_start"):
        arr = getattr(solver, name, None)
        pin(
            isinstance(arr, wp.array) and arr.dtype == wp.int32 and arr.shape == (arts,),
            f"SolverFeatherstone.{name} is not an int32 array with one start per articulation",
        )

    groups = getattr(solver, "_group_to_art", None)
    pin(
        isinstance(groups, dict) and groups,
        "SolverFeatherstone._group_to_art is not a non-empty dict",
    )
    seen = []
    for size, group in groups.items():
        pin(
            isinstance(size, tuple) and len(size) == 2 and all(isinstance(x, int) for x in size),
            f"_group_to_art key {size!r} is not (joint_count, dof_count)",
        )
        pin(
            isinstance(group, wp.array) and group.dtype == wp.int32,
            "_group_to_art values are not int32 arrays",
        )
        seen += group.numpy().tolist()
    pin(sorted(seen) == list(range(arts)), "_group_to_art does not cover every articulation once")
    pin(
        sim.dof == 2 and set(groups) == {(2, 2)},
        f"reacher worlds are not one (2 joints, 2 dofs) group: {set(groups)}",
    )

    for view_name, (array_name, start_name) in TILE_VIEWS.items():
        views = getattr(solver, view_name, None)
        pin(
            isinstance(views, dict) and set(views) == set(groups),
            f"SolverFeatherstone.{view_name} is not keyed like _group_to_art",
        )
        base, starts = getattr(solver, array_name), getattr(solver, start_name).numpy()
        for (joints, dofs), view in views.items():
            group = groups[joints, dofs]
            rows = {
                "J": (6 * joints, dofs),
                "M": (6 * joints, 6 * joints),
                "H": (dofs, dofs),
                "L": (dofs, dofs),
            }[array_name]
            pin(
                isinstance(view, wp.array) and view.shape == (group.shape[0], *rows),
                f"{view_name}[{(joints, dofs)}] has shape {getattr(view, 'shape', None)}, expected {(group.shape[0], *rows)}",
            )
            first = int(group.numpy()[0])
            pin(
                view.ptr == base.ptr + int(starts[first]) * 4,
                f"{view_name}[{(joints, dofs)}] is not a view into {array_name} at articulation {first}'s start",
            )


def test_model_and_warp_api_the_bridge_uses(sim):
    import warp as wp

    model = sim.model
    pin(
        model.requires_grad is True and model.joint_dof_count == model.joint_coord_count == 3 * 2,
        "Model.requires_grad / joint_dof_count / joint_coord_count changed",
    )
    state = model.state(requires_grad=True)
    control = model.control(clone_variables=True, requires_grad=True)
    for arr, name in (
        (state.joint_q, "State.joint_q"),
        (state.joint_qd, "State.joint_qd"),
        (control.joint_f, "Control.joint_f"),
    ):
        pin(
            isinstance(arr, wp.array) and arr.shape == (6,) and arr.grad is not None,
            f"{name} is not a per-dof array with a gradient",
        )
    for name in (
        "Tape",
        "ScopedStream",
        "stream_from_torch",
        "to_torch",
        "device_to_torch",
        "zeros_like",
    ):
        pin(callable(getattr(wp, name, None)), f"wp.{name} is gone")


def test_a_step_writes_the_swapped_in_scratch_and_leaves_the_solver_own(sim):
    """What the bridge does before every taped step, on Newton directly."""
    import warp as wp

    bridge, solver, model = sim.bridge, sim.bridge.solver, sim.model
    own = {n: getattr(solver, n) for n in (*SCRATCH, *TILE_VIEWS)}
    before = {n: own[n].numpy().copy() for n in SCRATCH}
    scratch = bridge.scratch.new()
    s_in, s_out = model.state(requires_grad=True), model.state(requires_grad=True)
    control = model.control(clone_variables=True, requires_grad=True)
    s_in.joint_q.assign(np.linspace(-0.8, 0.9, 6).astype(np.float32))
    for name, arr in scratch.items():
        setattr(solver, name, arr)
    try:
        tape = wp.Tape()
        with tape:
            solver.step(s_in, s_out, control, None, 0.01)
    finally:
        for name, arr in own.items():
            setattr(solver, name, arr)
    for name in ("M", "J", "H", "L"):
        pin(np.abs(scratch[name].numpy()).sum() > 0, f"a step did not write the swapped-in {name}")
    for name in SCRATCH:
        # bitwise: scratch Newton allocates uninitialised may hold NaNs, which never compare equal
        pin(
            own[name].numpy().tobytes() == before[name].tobytes(),
            f"a step wrote the solver's own {name} while it was swapped out",
        )


def test_the_mass_matrix_kernel_swap_internals_present(sim):
    """``physics/mass_matrix.py`` swaps the CPU solver's tile kernels: ``step`` must still launch
    ``self._tile_kernels_by_size[size]`` with (J, M, group, dof start, armature) -> (H, L), the flags
    it reads must exist, and Newton's tile kernel (the reference of tests/test_mass_matrix.py) too."""
    import newton
    from newton._src.solvers.featherstone import kernels

    solver = sim.bridge.solver
    src = inspect.getsource(newton.solvers.SolverFeatherstone.step)
    for text in (
        "self._tile_kernels_by_size.items()",
        "self.articulation_dof_start",
        "self.joint_armature_effective",
        "outputs=[self._H_by_size[size], self._L_by_size[size]]",
        "self.fuse_cholesky and not self._has_joint_mimics",
    ):
        pin(text in src, f"SolverFeatherstone.step no longer has {text!r}")
    for name in ("fuse_cholesky", "_has_joint_mimics", "joint_armature_effective", "model"):
        pin(hasattr(solver, name), f"SolverFeatherstone.{name} is gone")
    pin(
        callable(getattr(kernels, "create_inertia_matrix_cholesky_kernel", None)),
        "newton's create_inertia_matrix_cholesky_kernel is gone",
    )
    pin(sim.bridge.register_kernels == [(2, 2)], "the reacher's solver got no register kernel")


def test_redraw_internals_present(sim):
    """``physics/redraw.py`` (``--train-variants``): the inverse-inertia kernel finalize uses, and
    Featherstone's re-derivation of its spatial inertias on BODY_INERTIAL_PROPERTIES."""
    import newton

    try:
        from newton._src.geometry.inertia import compute_body_inverses_kernel
    except ImportError:
        compute_body_inverses_kernel = None
    pin(
        compute_body_inverses_kernel is not None,
        "newton._src.geometry.inertia.compute_body_inverses_kernel",
    )
    solver = sim.bridge.solver
    pin(
        hasattr(newton.ModelFlags, "BODY_INERTIAL_PROPERTIES"),
        "newton.ModelFlags.BODY_INERTIAL_PROPERTIES",
    )
    pin(
        hasattr(solver, "body_I_m") and hasattr(solver, "_update_body_inertial_buffers"),
        "SolverFeatherstone.body_I_m / _update_body_inertial_buffers",
    )
    solver.notify_model_changed(newton.ModelFlags.BODY_INERTIAL_PROPERTIES)  # in sync first
    before = solver.body_I_m.numpy().copy()
    mass = sim.model.body_mass.numpy().copy()  # on the CPU numpy() is a view of the array
    sim.model.body_mass.assign(mass * 2)
    solver.notify_model_changed(newton.ModelFlags.BODY_INERTIAL_PROPERTIES)
    pin(
        not np.array_equal(solver.body_I_m.numpy(), before),
        "notify_model_changed re-derives body_I_m",
    )
    sim.model.body_mass.assign(mass)
    solver.notify_model_changed(newton.ModelFlags.BODY_INERTIAL_PROPERTIES)
    pin(np.array_equal(solver.body_I_m.numpy(), before), "body_I_m follows body_mass back")
