"""New dynamics variants for the worlds of a live :class:`~warp_critic.physics.simulator.Simulator`.

Dynamics-randomised training changes every world's variant every iteration. Building a new
simulator each time would cost seconds (Newton's finalize, the solver's allocations, new captured
graphs); instead :func:`set_variants` rewrites, in place, the model arrays a variant changes:

* the bodies' mass properties ``body_mass, body_com, body_inertia``, and their inverses computed by
  the kernel Newton's ``finalize`` uses (``compute_body_inverses_kernel``, a Newton internal:
  ``tests/test_newton_internals.py`` catches a move); then
  ``SolverFeatherstone.notify_model_changed(BODY_INERTIAL_PROPERTIES)`` re-derives the spatial
  inertias the solver keeps, in place;
* the joints' parent frames ``joint_X_p`` (a length change moves the child joint).

The values come from :meth:`Scene.world_builder` with the new variant, the same code path a model
built with that variant takes, so an edited simulator steps bitwise like one built with the new
variants (``tests/test_train_variants.py``). The arrays keep their memory, so captured graphs and the
bridge's buffers stay valid. Visual shapes are not moved (they have no effect on the dynamics).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from warp_critic.physics.variants import Variant

#: the model arrays a variant sets (per body, then per joint); the inverses follow from them
BODY_FIELDS = ("body_mass", "body_com", "body_inertia")
JOINT_FIELDS = ("joint_X_p",)
DERIVED_FIELDS = ("body_inv_mass", "body_inv_inertia")


def set_variants(sim, variants: Sequence[Variant]) -> None:
    """Give world ``i`` of ``sim`` the dynamics of ``variants[i]`` (in place; see the module doc).

    Raises:
        ValueError: when ``len(variants)`` is not the number of worlds.
        FieldError: for a variant that does not apply to the scene (one line, from the variant).
    """
    import newton
    import warp as wp
    from newton._src.geometry.inertia import compute_body_inverses_kernel

    variants = list(variants)
    if len(variants) != sim.worlds:
        raise ValueError(f"{len(variants)} variants for {sim.worlds} worlds")
    changed = [w for w, v in enumerate(variants) if v != sim.variants[w]]
    if not changed:
        return
    model = sim.model
    per_body, per_joint = model.body_count // sim.worlds, model.joint_count // sim.worlds
    # copies (on the CPU numpy() is a view): a variant that fails half-way leaves the model as it was
    arrays = {f: getattr(model, f).numpy().copy() for f in BODY_FIELDS + JOINT_FIELDS}
    builders: dict[Variant, object] = {}
    for w in changed:
        v = variants[w]
        v.validate()
        if v not in builders:
            builders[v] = sim.scene.world_builder(v)
        b = builders[v]
        for f in BODY_FIELDS:
            values = np.asarray(getattr(b, f), dtype=arrays[f].dtype)
            arrays[f][w * per_body : (w + 1) * per_body] = values.reshape(
                per_body, *arrays[f].shape[1:]
            )
        for f in JOINT_FIELDS:
            values = np.asarray(getattr(b, f), dtype=arrays[f].dtype)
            arrays[f][w * per_joint : (w + 1) * per_joint] = values.reshape(
                per_joint, *arrays[f].shape[1:]
            )
    for f, values in arrays.items():
        getattr(model, f).assign(values)
    wp.launch(
        compute_body_inverses_kernel,
        dim=model.body_count,
        inputs=[model.body_mass, model.body_inertia],
        outputs=[model.body_inv_mass, model.body_inv_inertia],
        device=model.device,
    )
    sim.bridge.solver.notify_model_changed(newton.ModelFlags.BODY_INERTIAL_PROPERTIES)
    sim.variants = variants


__all__ = ["set_variants", "BODY_FIELDS", "JOINT_FIELDS", "DERIVED_FIELDS"]
