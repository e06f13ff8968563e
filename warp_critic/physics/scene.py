"""Scenes: robots loaded from files, and the newton models built from them.

:func:`warp_critic.physics.load.load_scene` is the one way in: it finds the reader of the
file's format, keeps each file version loaded once (:mod:`.scene_cache`) and returns a
:class:`Scene`. What a scene file holds is :mod:`.schema`; reading a USD file is :mod:`.usd_scene`;
:attr:`Scene.content_hash` is :mod:`.scene_hash`.

Layout: a :class:`newton.Model` built by :meth:`Scene.build_model` holds one newton *world* per
:class:`Variant`. Bodies, joints, coordinates and DoFs are world-major: world ``w`` owns bodies
``w*len(body_names) ... (w+1)*len(body_names) - 1`` and DoFs ``w*dof ... (w+1)*dof - 1``
(``joint_q``/``joint_qd``/``joint_f`` reshape to ``(worlds, dof)``), because every world of a
scene has the same topology and ``joint_coord_count == joint_dof_count == dof``.

Variants (:mod:`warp_critic.physics.variants`) change one link; see that module for the rules.

All user mistakes raise :class:`~warp_critic.core.errors.SceneError` (bad scene file) or
:class:`~warp_critic.core.errors.UserError` (bad variant value) with a one-line message.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from warp_critic.core.errors import UserError
from warp_critic.physics.variants import (
    Variant,
    apply_changes,
    apply_variant,
    changed_tip,
    length_map,
)

if TYPE_CHECKING:
    import newton

__all__ = ["Variant", "Scene", "scenes_dir"]


def scenes_dir() -> Path:
    """The scenes shipped with warp-critic (``reacher.usda``, ``kuka.usda``, ``point_mass.usda``):
    the package data ``warp_critic/scenes`` of an installed wheel, else the checkout's ``scenes/``."""
    checkout = Path(__file__).resolve().parents[2] / "scenes"
    if checkout.is_dir():
        return checkout
    from importlib.resources import files

    return Path(str(files("warp_critic.scenes")))


# ------------------------------------------------------------------------------------------------
# Scene
# ------------------------------------------------------------------------------------------------


class Scene:
    """A robot loaded from a scene file; builds newton models with per-world :class:`Variant`\\ s.

    Attributes:
        path: the USD file (resolved).
        name: the file's stem, e.g. ``"reacher"``.
        dof: number of actuated degrees of freedom (= joints = coordinates).
        joint_names: ``(dof,)`` joint prim names in DoF order.
        body_names: link prim names in body order within one world.
        q_lower, q_upper: ``(dof,)`` joint limits [rad or m].
        effort_limit: ``(dof,)`` actuator effort limits [N*m or N].
        damping: ``(dof,)`` passive joint damping [N*m*s/rad or N*s/m].
        armature: ``(dof,)`` joint armature (reflected rotor inertia) [kg*m^2 or kg].
        limit_ke, limit_kd: ``(dof,)`` joint-limit penalty stiffness [N*m/rad or N/m] and damping.
        ee_body: index of the end-effector body within ONE world.
        tip_offset: ``(3,)`` end-effector tip [m] in the ee body frame, as authored.
        defaults: the training defaults the file authors, keyed as in
            :data:`~warp_critic.physics.schema.ATTRIBUTES` (only the keys it authors; ``{}`` if none).
        home: ``(dof,)`` home joint positions [rad or m] (``warp_critic:homePose``; zeros if absent).
        content_hash: sha256 hex digest of the scene's content; equal for a renamed or moved copy,
            different when any value the simulation reads changes (:mod:`.scene_hash`).
    """

    def __init__(
        self,
        path: Path,
        base: newton.ModelBuilder,
        ee_body: int,
        tip_offset: np.ndarray,
        effort_limit: np.ndarray,
        *,
        defaults: dict[str, Any] | None = None,
        home: np.ndarray | None = None,
        content_hash: str = "",
    ):
        self.path = path
        self.name = path.stem
        self.content_hash = content_hash
        self._defaults = copy.deepcopy(defaults or {})
        self._base = base
        self.dof = base.joint_dof_count
        self.joint_names = [label.rsplit("/", 1)[-1] for label in base.joint_label]
        self.body_names = [label.rsplit("/", 1)[-1] for label in base.body_label]
        self._arrays = {
            "q_lower": _array(base.joint_limit_lower),
            "q_upper": _array(base.joint_limit_upper),
            "effort_limit": _array(effort_limit),
            "damping": _array(base.joint_damping),
            "armature": _array(base.joint_armature),
            "limit_ke": _array(base.joint_limit_ke),
            "limit_kd": _array(base.joint_limit_kd),
            "tip_offset": _array(tip_offset),
            "home": _array(np.zeros(self.dof) if home is None else home),
        }
        self.ee_body = ee_body

    # Arrays are handed out as copies: a Scene is cached and shared by every load_scene() caller.
    q_lower = property(
        lambda self: self._arrays["q_lower"].copy(), doc="(dof,) lower joint limits [rad or m]"
    )
    q_upper = property(
        lambda self: self._arrays["q_upper"].copy(), doc="(dof,) upper joint limits [rad or m]"
    )
    effort_limit = property(
        lambda self: self._arrays["effort_limit"].copy(), doc="(dof,) efforts [N*m or N]"
    )
    damping = property(
        lambda self: self._arrays["damping"].copy(), doc="(dof,) damping [N*m*s/rad or N*s/m]"
    )
    armature = property(
        lambda self: self._arrays["armature"].copy(), doc="(dof,) armature [kg*m^2 or kg]"
    )
    limit_ke = property(lambda self: self._arrays["limit_ke"].copy(), doc="(dof,) limit stiffness")
    limit_kd = property(lambda self: self._arrays["limit_kd"].copy(), doc="(dof,) limit damping")
    tip_offset = property(
        lambda self: self._arrays["tip_offset"].copy(), doc="(3,) tip [m] in the ee frame"
    )
    home = property(
        lambda self: self._arrays["home"].copy(), doc="(dof,) home joint positions [rad or m]"
    )

    @property
    def defaults(self) -> dict[str, Any]:
        """The training defaults authored in the file (a fresh deep copy; see the class docstring)."""
        return copy.deepcopy(self._defaults)

    def defaults_at(self, gravity: float) -> dict[str, Any]:
        """The defaults for a run under ``gravity`` [m/s^2]: an authored scene's are the file's,
        whatever the gravity (a robot file's derived ones depend on it: ``RobotScene``)."""
        return self.defaults

    def __repr__(self) -> str:
        return f"Scene({self.name!r}, dof={self.dof}, ee={self.body_names[self.ee_body]!r})"

    # -- variants ---------------------------------------------------------------------------------
    def tip_offset_of(self, variant: Variant = Variant()) -> np.ndarray:
        """``(3,)`` end-effector tip [m] in the ee body frame with ``variant``'s link length."""
        tip = self._length_map(variant)[1] @ self.tip_offset
        if not variant.changes:
            return tip
        return changed_tip(variant.changes, tip, self.body_names, self.ee_body)

    def _length_map(self, variant: Variant) -> tuple[float, np.ndarray]:
        """(s, S): the length ratio and the stretch matrix of ``variant`` (see :mod:`.variants`)."""
        return length_map(variant, self.tip_offset, self.name, self.body_names[self.ee_body])

    def world_builder(self, variant: Variant = Variant()) -> newton.ModelBuilder:
        """A fresh :class:`newton.ModelBuilder` with one copy of the robot, ``variant`` applied.

        Raises:
            UserError: for an invalid variant (names the flag).
        """
        import newton

        s, stretch = self._length_map(variant)
        builder = newton.ModelBuilder()
        builder.add_builder(self._base)
        apply_variant(builder, self.ee_body, self.tip_offset, variant, s, stretch)
        if variant.changes:
            apply_changes(
                builder, variant.changes, self.body_names, self.ee_body, stretch @ self.tip_offset
            )
        return builder

    def build_model(
        self, variants: Sequence[Variant], *, device: str = "cpu", requires_grad: bool = False
    ) -> newton.Model:
        """A finalized model with one world per entry of ``variants`` (world ``i`` = ``variants[i]``).

        Args:
            variants: one :class:`Variant` per world (at least one).
            device: warp device, e.g. ``"cpu"`` or ``"cuda:0"``.
            requires_grad: allocate gradients for the model's arrays.
        """
        import newton

        variants = list(variants)
        if not variants:
            raise UserError("build_model needs at least one variant (one per world)")
        for variant in variants:
            variant.validate()
        main = newton.ModelBuilder()
        cache: dict[Variant, newton.ModelBuilder] = {}
        for variant in variants:
            if variant not in cache:
                cache[variant] = self.world_builder(variant)
            main.add_world(cache[variant])
        import warnings

        with warnings.catch_warnings():
            # newton corrects a robot file's invalid inertias at every finalize, the same way each
            # time, and says so as a Python warning: library code prints nothing
            warnings.filterwarnings("ignore", message="Inertia validation corrected")
            return main.finalize(device=device, requires_grad=requires_grad)


def _array(values) -> np.ndarray:
    return np.array(values, dtype=np.float64)
