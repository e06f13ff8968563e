"""Scenes: robots stored as USD files, loaded through newton's USD importer.

A scene file (see ``tools/make_scenes.py``, which writes ``scenes/*.usda``) holds ONE fixed-base
articulation:

* a prim with ``UsdPhysics.ArticulationRootAPI`` carrying ``warp_critic:endEffectorBody`` (string,
  the end-effector link's prim name or path) and ``warp_critic:tipOffset`` (float3, metres, in
  that link's frame);
* rigid bodies (``RigidBodyAPI`` + ``MassAPI`` with ``physics:mass`` > 0 and
  ``physics:diagonalInertia`` >= 0, plus ``centerOfMass``/``principalAxes``), one per moving link;
* only ``UsdPhysics.RevoluteJoint``/``PrismaticJoint`` joints (the first one with no ``body0``:
  welded to the world), each with ``warp_critic:effortLimit`` (float, N*m or N).

Training defaults travel with the scene's CONTENT (not its file name): optional custom attributes of
the articulation root, read into :attr:`Scene.defaults` (only the keys the file authors) and
:attr:`Scene.home`. Real numbers may be ``double`` or ``float`` (the generated scenes use double so
that 0.0025 reads back as exactly 0.0025):

============================  =========  ==================  ====================================================
attribute                     type       ``defaults`` key    rule
============================  =========  ==================  ====================================================
``warp_critic:goals``         double[]   ``goals``           G x dof goals flattened row-major (rad or m), G >= 1,
                                                             each inside the joint limits; read as G lists
``warp_critic:horizon``       int        ``horizon``         control steps per rollout, > 0
``warp_critic:dt``            double     ``dt``              physics time step (s), > 0
``warp_critic:substeps``      int        ``substeps``        physics steps per control step, > 0
``warp_critic:maxTorque``     double[]   ``max_torque``      policy torque bound (N*m or N), dof values or 1,
                                                             each > 0; read as a list
``warp_critic:qdScale``       double     ``qd_scale``        velocity normalisation (rad/s), > 0
``warp_critic:alpha``         double     ``alpha``           inner learning rate, > 0
``warp_critic:lr``            double     ``lr``              outer learning rate, > 0
``warp_critic:gravity``       double     ``gravity``         gravity along -z (m/s^2), finite
``warp_critic:homePose``      double[]   (``Scene.home``)    dof joint positions inside the limits; zeros
                                                             when not authored
``warp_critic:iterations``    int        ``iterations``      outer iterations of meta-training, > 0
``warp_critic:innerSteps``    int        ``inner_steps``     inner critic-gradient steps, > 0
``warp_critic:criticInput``   string     ``critic_input``    ``full`` or ``relative``
``warp_critic:startStd``      double     ``start_std``       std of random training start states (rad), >= 0
``warp_critic:homeStarts``    int        ``home_starts``     worlds per goal kept at home, >= 0
============================  =========  ==================  ====================================================

The last five are the training schedule this project reports for the robot: with them, a method's
defaults on a scene are the reported configuration.

Every value must be finite; a bad one raises :class:`~warp_critic.core.errors.SceneError` naming the file
and the attribute. :attr:`Scene.content_hash` identifies the content (see :func:`content_hash`).

Units are SI throughout: metres, kilograms, seconds, radians (USD authors revolute limits in
degrees; newton converts them). Passive damping and limit gains come from ``newton:damping``,
``newton:limitStiffness``, ``newton:limitDamping``, which newton reads per DEGREE for revolute
joints; the model values are per radian.

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
import hashlib
import importlib.util
import math
import re
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from warp_critic.core.errors import SceneError, UserError
from warp_critic.physics.variants import Variant, apply_variant, is_finite, length_map

if TYPE_CHECKING:
    import newton

__all__ = ["Variant", "Scene", "load_scene", "scenes_dir"]


def scenes_dir() -> Path:
    """The scenes shipped with warp-critic (``reacher.usda``, ``kuka.usda``, ``point_mass.usda``):
    the package data ``warp_critic/scenes`` of an installed wheel, else the checkout's ``scenes/``."""
    checkout = Path(__file__).resolve().parents[2] / "scenes"
    if checkout.is_dir():
        return checkout
    from importlib.resources import files

    return Path(str(files("warp_critic.scenes")))


EFFORT_ATTR = "warp_critic:effortLimit"
EE_ATTR = "warp_critic:endEffectorBody"
TIP_ATTR = "warp_critic:tipOffset"
HOME_ATTR = "warp_critic:homePose"
# training-default attributes of the articulation root: attribute -> (Scene.defaults key, kind)
DEFAULT_ATTRS: dict[str, tuple[str, str]] = {
    "warp_critic:goals": ("goals", "goals"),
    "warp_critic:horizon": ("horizon", "count"),
    "warp_critic:dt": ("dt", "positive"),
    "warp_critic:substeps": ("substeps", "count"),
    "warp_critic:maxTorque": ("max_torque", "torques"),
    "warp_critic:qdScale": ("qd_scale", "positive"),
    "warp_critic:alpha": ("alpha", "positive"),
    "warp_critic:lr": ("lr", "positive"),
    "warp_critic:gravity": ("gravity", "finite"),
    "warp_critic:iterations": ("iterations", "count"),
    "warp_critic:innerSteps": ("inner_steps", "count"),
    "warp_critic:criticInput": ("critic_input", "critic_input"),
    "warp_critic:startStd": ("start_std", "nonnegative"),
    "warp_critic:homeStarts": ("home_starts", "natural"),
}
CRITIC_INPUT_CHOICES = ("full", "relative")


# ------------------------------------------------------------------------------------------------
# Scene
# ------------------------------------------------------------------------------------------------


class Scene:
    """A robot loaded from a USD file; builds newton models with per-world :class:`Variant`\\ s.

    Attributes:
        path: the USD file (resolved).
        name: the file's stem, e.g. ``"reacher"``.
        dof: number of actuated degrees of freedom (= joints = coordinates).
        joint_names: ``(dof,)`` joint prim names in DoF order.
        body_names: link prim names in body order within one world.
        q_lower, q_upper: ``(dof,)`` joint limits [rad or m].
        effort_limit: ``(dof,)`` actuator effort limits [N*m or N].
        damping: ``(dof,)`` passive joint damping [N*m*s/rad or N*s/m].
        limit_ke, limit_kd: ``(dof,)`` joint-limit penalty stiffness [N*m/rad or N/m] and damping.
        ee_body: index of the end-effector body within ONE world.
        tip_offset: ``(3,)`` end-effector tip [m] in the ee body frame, as authored.
        defaults: the training defaults the file authors (module docstring): a subset of the keys
            ``goals`` (G lists of dof floats), ``horizon``, ``dt``, ``substeps``, ``max_torque``
            (list of dof or 1 floats), ``qd_scale``, ``alpha``, ``lr``, ``gravity``; ``{}`` if none.
        home: ``(dof,)`` home joint positions [rad or m] (``warp_critic:homePose``; zeros if absent).
        content_hash: sha256 hex digest of the scene's content; equal for a renamed or moved copy,
            different when any authored value changes (see :func:`content_hash`).
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

    def __repr__(self) -> str:
        return f"Scene({self.name!r}, dof={self.dof}, ee={self.body_names[self.ee_body]!r})"

    # -- variants ---------------------------------------------------------------------------------
    def tip_offset_of(self, variant: Variant = Variant()) -> np.ndarray:
        """``(3,)`` end-effector tip [m] in the ee body frame with ``variant``'s link length."""
        return self._length_map(variant)[1] @ self.tip_offset

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
        return main.finalize(device=device, requires_grad=requires_grad)


def _array(values) -> np.ndarray:
    return np.array(values, dtype=np.float64)


# ------------------------------------------------------------------------------------------------
# Loading
# ------------------------------------------------------------------------------------------------

_CACHE: dict[tuple[str, int, int], Scene] = {}
_CACHE_LOCK = threading.Lock()


def load_scene(path: str | Path) -> Scene:
    """Parse and validate a scene USD file (once per file version; later calls hit a cache).

    Raises:
        SceneError: one line naming the file and the problem (missing file, not USD, no
            articulation root, unsupported joint, bad mass properties, ...).
    """
    path = Path(path).expanduser()
    if not path.exists():
        raise SceneError(f"{path}: no such scene file")
    if path.is_dir():
        raise SceneError(f"{path}: is a directory, not a USD scene file")
    path = path.resolve()
    stat = path.stat()
    key = (str(path), stat.st_mtime_ns, stat.st_size)
    with _CACHE_LOCK:
        scene = _CACHE.get(key)
        if scene is None:
            scene = _load(path)
            _CACHE[key] = scene
    return scene


def _fail(path: Path, problem: str) -> SceneError:
    return SceneError(f"{path}: {' '.join(str(problem).split())}")


def _open_stage(path: Path):
    from pxr import Sdf, Usd

    if Sdf.FileFormat.FindByExtension(path.suffix.lstrip(".")) is None:
        raise _fail(
            path,
            f"not a USD file (unknown extension {path.suffix or '(none)'!r}; "
            "expected .usd, .usda, .usdc or .usdz)",
        )
    try:
        stage = Usd.Stage.Open(str(path))
    except Exception as exc:  # pxr.Tf.ErrorException and friends
        raise _fail(path, f"not a readable USD file ({_first_line(exc)})") from None
    if stage is None:
        raise _fail(path, "not a readable USD file")
    return stage


def _first_line(exc: BaseException) -> str:
    """A short one-line reason; pxr errors read "Error in '<function>' at line N in file F : '<reason>'"."""
    text = " ".join(str(exc).split())
    reason = re.search(r" : '([^']+)'", text)
    if reason:
        text = reason.group(1)
    return text[:300] if text else type(exc).__name__


def _check_stage(path: Path, stage) -> tuple[object, dict[str, float]]:
    """Validate what newton's importer would silently repair; return (root prim, effort by joint)."""
    from pxr import UsdPhysics

    roots, joints, bodies = [], [], []
    for prim in stage.Traverse():
        if prim.HasAPI(UsdPhysics.ArticulationRootAPI):
            roots.append(prim)
        if prim.IsA(UsdPhysics.Joint):
            joints.append(prim)
        if prim.HasAPI(UsdPhysics.RigidBodyAPI):
            bodies.append(prim)
    if not roots:
        raise _fail(path, "no prim with UsdPhysics.ArticulationRootAPI (not a robot scene)")
    if len(roots) > 1:
        raise _fail(path, f"{len(roots)} articulation roots; a scene holds exactly one robot")
    if not joints:
        raise _fail(path, "the articulation has no joints")
    if not bodies:
        raise _fail(path, "no rigid bodies (UsdPhysics.RigidBodyAPI)")

    effort: dict[str, float] = {}
    for prim in joints:
        if not (prim.IsA(UsdPhysics.RevoluteJoint) or prim.IsA(UsdPhysics.PrismaticJoint)):
            raise _fail(
                path,
                f"joint {prim.GetPath()} is a {prim.GetTypeName()}; only "
                "PhysicsRevoluteJoint and PhysicsPrismaticJoint are supported",
            )
        value = prim.GetAttribute(EFFORT_ATTR).Get() if prim.HasAttribute(EFFORT_ATTR) else None
        if value is None or not is_finite(value) or value <= 0.0:
            raise _fail(
                path, f"joint {prim.GetPath()} needs a positive {EFFORT_ATTR} (got {value})"
            )
        effort[str(prim.GetPath())] = float(value)

    for prim in bodies:
        mass_api = UsdPhysics.MassAPI(prim)
        mass = mass_api.GetMassAttr().Get() if prim.HasAPI(UsdPhysics.MassAPI) else None
        if mass is None or not prim.GetAttribute("physics:mass").HasAuthoredValue():
            raise _fail(path, f"link {prim.GetPath()} has no physics:mass (MassAPI)")
        if not is_finite(mass) or mass <= 0.0:
            raise _fail(path, f"link {prim.GetPath()} has non-positive mass {mass} kg")
        inertia = mass_api.GetDiagonalInertiaAttr().Get()
        if inertia is None or not mass_api.GetDiagonalInertiaAttr().HasAuthoredValue():
            raise _fail(path, f"link {prim.GetPath()} has no physics:diagonalInertia")
        if not all(is_finite(v) for v in inertia) or any(v < 0.0 for v in inertia):
            raise _fail(
                path, f"link {prim.GetPath()} has negative or non-finite inertia {tuple(inertia)}"
            )
        if sum(inertia) <= 0.0:
            raise _fail(path, f"link {prim.GetPath()} has zero inertia")
    return roots[0], effort


def _read_root(path: Path, root) -> tuple[str, np.ndarray]:
    """The end-effector name and tip offset authored on the articulation root."""
    ee_name = root.GetAttribute(EE_ATTR).Get() if root.HasAttribute(EE_ATTR) else None
    if not ee_name or not isinstance(ee_name, str):
        raise _fail(
            path, f"articulation root {root.GetPath()} lacks the string attribute {EE_ATTR}"
        )
    tip = root.GetAttribute(TIP_ATTR).Get() if root.HasAttribute(TIP_ATTR) else None
    try:
        tip = np.array([float(v) for v in tip], dtype=np.float64)
    except (TypeError, ValueError):
        tip = None
    if tip is None or tip.shape != (3,) or not np.isfinite(tip).all():
        raise _fail(path, f"articulation root {root.GetPath()} lacks a finite float3 {TIP_ATTR}")
    return ee_name, tip


def _number(value) -> float | None:
    """A real number (not bool/str/vector) as float, else None."""
    if isinstance(value, (bool, str, bytes)) or value is None:
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def _numbers(value) -> list[float] | None:
    """A 1-D array of real numbers as a list of floats, else None."""
    if isinstance(value, (str, bytes)) or value is None:
        return None
    try:
        out = [_number(v) for v in value]
    except TypeError:
        return None
    return None if any(v is None for v in out) else out


def _read_defaults(
    path: Path, root, q_lower: np.ndarray, q_upper: np.ndarray, joint_names: list[str]
) -> tuple[dict[str, Any], np.ndarray]:
    """Read and validate the training-default attributes of the articulation root (module docstring)."""
    dof = len(joint_names)
    tol = 1e-6 * np.maximum(1.0, np.maximum(np.abs(q_lower), np.abs(q_upper)))

    def fail(attr: str, problem: str) -> SceneError:
        return _fail(path, f"articulation root {root.GetPath()}: {attr} {problem}")

    def authored(attr: str):
        prop = root.GetAttribute(attr) if root.HasAttribute(attr) else None
        return prop.Get() if prop is not None and prop.HasAuthoredValue() else None

    def inside_limits(attr: str, q: list[float], what: str) -> None:
        for j, v in enumerate(q):
            if not q_lower[j] - tol[j] <= v <= q_upper[j] + tol[j]:
                raise fail(
                    attr,
                    f"{what} has {joint_names[j]} = {v}, outside the joint limits "
                    f"[{q_lower[j]:.6g}, {q_upper[j]:.6g}]",
                )

    defaults: dict[str, Any] = {}
    for attr, (key, kind) in DEFAULT_ATTRS.items():
        raw = authored(attr)
        if raw is None:
            continue
        if kind in ("goals", "torques"):
            values = _numbers(raw)
            if values is None:
                raise fail(attr, f"must be an array of numbers (got {raw!r})")
            if not all(math.isfinite(v) for v in values):
                raise fail(attr, f"must be finite (got {values})")
            if kind == "goals":
                if not values or len(values) % dof:
                    raise fail(
                        attr,
                        f"needs G x {dof} values (G >= 1 goals of {dof} joint positions, "
                        f"flattened), got {len(values)}",
                    )
                goals = [values[i : i + dof] for i in range(0, len(values), dof)]
                for g, goal in enumerate(goals):
                    inside_limits(attr, goal, f"goal {g}")
                defaults[key] = goals
            else:
                if len(values) not in (1, dof):
                    raise fail(attr, f"needs 1 or {dof} values (got {len(values)})")
                if any(v <= 0.0 for v in values):
                    raise fail(attr, f"must be > 0 (got {values})")
                defaults[key] = values
            continue
        if kind == "critic_input":
            if raw not in CRITIC_INPUT_CHOICES:
                raise fail(attr, f"must be one of {', '.join(CRITIC_INPUT_CHOICES)} (got {raw!r})")
            defaults[key] = str(raw)
            continue
        value = _number(raw)
        if value is None:
            raise fail(attr, f"must be a number (got {raw!r})")
        if not math.isfinite(value):
            raise fail(attr, f"must be finite (got {value})")
        if kind in ("count", "natural"):
            if value < (1 if kind == "count" else 0) or not value.is_integer():
                raise fail(
                    attr,
                    f"must be a {'positive' if kind == 'count' else 'non-negative'} integer (got {raw!r})",
                )
            defaults[key] = int(value)
        else:
            if kind == "positive" and value <= 0.0:
                raise fail(attr, f"must be > 0 (got {value})")
            if kind == "nonnegative" and value < 0.0:
                raise fail(attr, f"must be >= 0 (got {value})")
            defaults[key] = value

    home = np.zeros(dof)
    raw = authored(HOME_ATTR)
    if raw is not None:
        values = _numbers(raw)
        if values is None:
            raise fail(HOME_ATTR, f"must be an array of numbers (got {raw!r})")
        if len(values) != dof:
            raise fail(HOME_ATTR, f"needs {dof} values (got {len(values)})")
        if not all(math.isfinite(v) for v in values):
            raise fail(HOME_ATTR, f"must be finite (got {values})")
        inside_limits(HOME_ATTR, values, "the home pose")
        home = np.array(values, dtype=np.float64)
    return defaults, home


def content_hash(path: Path, stage) -> str:
    """sha256 hex digest of the scene's composed content, independent of where the file lives.

    Hashes the text export of the FLATTENED stage (sublayers and references composed in), without
    the "Generated from Composed Stage of root layer <path>" note that :meth:`Usd.Stage.Flatten`
    would add, and with asset paths under the scene's own folder (which flattening makes absolute)
    written back relative to it (``@/abs/dir/x.png@`` -> ``@./x.png@``). So a renamed or moved
    copy (or the .usdc of the same stage) hashes the same, and any change of what the simulation
    reads -- a mass, a limit, the home pose -- changes the hash. The training-default attributes
    (:data:`DEFAULT_ATTRS`) are left out: a run resolves them into its own config, so a changed
    default does not change any run. The text format is the installed USD's: compare hashes made
    with the same USD version.
    """
    text = stage.Flatten(addSourceFileComment=False).ExportToString()
    text = text.replace(f"@{path.parent.as_posix()}/", "@./")
    names = tuple(f" {attr} " for attr in DEFAULT_ATTRS) + tuple(
        f" {attr}=" for attr in DEFAULT_ATTRS
    )
    text = "\n".join(line for line in text.splitlines() if not any(n in line for n in names))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _load(path: Path) -> Scene:
    import newton

    stage = _open_stage(path)
    try:
        root, effort = _check_stage(path, stage)
        ee_name, tip = _read_root(path, root)
        digest = content_hash(path, stage)
    except SceneError:
        raise
    except Exception as exc:  # unexpected pxr errors on odd files must not escape either
        raise _fail(path, f"invalid scene ({_first_line(exc)})") from None

    if importlib.util.find_spec("newton_usd_schemas") is None:
        # an installation problem, not a scene problem: let it surface as such
        raise ImportError(
            "newton's USD importer needs the 'newton-usd-schemas' package "
            "(pip install 'newton-usd-schemas>=0.6')"
        )

    builder = newton.ModelBuilder()
    try:
        builder.add_usd(stage, load_sites=False)
    except Exception as exc:  # newton/pxr errors must not escape
        raise _fail(path, f"newton's USD importer failed: {_first_line(exc)}") from None

    # The importer must have produced exactly one chain of 1-DoF joints.
    allowed = {int(newton.JointType.REVOLUTE), int(newton.JointType.PRISMATIC)}
    if any(int(t) not in allowed for t in builder.joint_type):
        raise _fail(
            path,
            "the imported articulation has joints other than revolute/prismatic "
            "(is a body missing a joint to the world or to its parent?)",
        )
    if not (
        builder.joint_coord_count == builder.joint_dof_count == builder.joint_count == len(effort)
    ):
        raise _fail(
            path,
            f"imported {builder.joint_count} joints / {builder.joint_dof_count} DoFs "
            f"but the file has {len(effort)} revolute/prismatic joints",
        )

    labels = list(builder.body_label)
    matches = [
        i
        for i, label in enumerate(labels)
        if label == ee_name or label.rsplit("/", 1)[-1] == ee_name
    ]
    if len(matches) != 1:
        raise _fail(
            path,
            f"{EE_ATTR} = {ee_name!r} names {len(matches)} of the bodies "
            f"{[label.rsplit('/', 1)[-1] for label in labels]}",
        )

    try:
        effort_limit = np.array([effort[label] for label in builder.joint_label])
    except KeyError as exc:
        raise _fail(path, f"imported joint {exc} not found in the file") from None
    builder.joint_effort_limit = [float(v) for v in effort_limit]

    joint_names = [label.rsplit("/", 1)[-1] for label in builder.joint_label]
    try:
        defaults, home = _read_defaults(
            path,
            root,
            _array(builder.joint_limit_lower),
            _array(builder.joint_limit_upper),
            joint_names,
        )
    except SceneError:
        raise
    except Exception as exc:  # unexpected pxr errors on odd attributes must not escape either
        raise _fail(path, f"invalid training defaults ({_first_line(exc)})") from None
    return Scene(
        path,
        builder,
        matches[0],
        tip,
        effort_limit,
        defaults=defaults,
        home=home,
        content_hash=digest,
    )
