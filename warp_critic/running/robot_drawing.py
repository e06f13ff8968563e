"""The robot in a recording's 3-D view, drawn from the Newton model's own geometry.

:class:`RobotDrawing` reads one world's shapes from the Newton model (capsules, spheres, boxes,
cylinders and triangle meshes attached to the bodies, and the static base shapes); a robot whose
bodies carry no such shape is drawn as line strips along its links (parent body to child body, and
the end-effector body to the tip). A mesh's geometry is logged once, statically, per entity; each
later pose logs only the mesh's transform, so a recording stays small. :func:`camera_for` frames a
set of points.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

_GOAL_COLORS = [
    (230, 25, 75),
    (60, 180, 75),
    (0, 130, 200),
    (245, 130, 48),
    (145, 30, 180),
    (70, 240, 240),
    (240, 50, 230),
    (210, 245, 60),
    (128, 128, 0),
    (0, 0, 128),
]
BEFORE_COLOR = (150, 150, 150)  # the arm before the inner update (a baseline's exploration)
BASE_COLOR = (90, 90, 90)
MAX_GOALS_DRAWN = 6  # goals drawn in the 3-D view (every goal is plotted)
GHOST_ALPHA = 70  # a mesh drawn as the goal's ghost: see-through


def goal_color(i: int) -> tuple[int, int, int]:
    return _GOAL_COLORS[i % len(_GOAL_COLORS)]


# newton.GeoType values (newton/_src/geometry/types.py); kept here so that reading a model's shapes
# needs no import of newton
SPHERE, CAPSULE, CYLINDER, BOX, MESH, CONVEX_MESH = 3, 4, 6, 7, 8, 10
DRAWN = (SPHERE, CAPSULE, CYLINDER, BOX)
MESHES = (MESH, CONVEX_MESH)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions in ``(x, y, z, w)`` order, broadcast over leading axes."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        -1,
    )


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` rotated by the unit quaternion ``q`` ``(x, y, z, w)``, broadcast over leading axes."""
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


@dataclass
class RobotDrawing:
    """One world's drawable shapes, in the frames of its bodies.

    ``kind[s]``, ``body[s]`` (index within the world), ``local[s]`` (7: position, quaternion xyzw of
    the shape in its body), ``scale[s]`` (newton's shape scale: radius, half height, ...);
    ``static``: the same for shapes fixed to the world (the base); ``links``: ``(parent, child)``
    body pairs for the line-strip fallback; ``ee_body``/``tip``: the end effector and its tip offset;
    ``mesh_body``/``mesh_local``/``mesh_vertices`` (scaled, in the shape's frame)/``mesh_indices``:
    the bodies' triangle meshes (``newton.GeoType.MESH``/``CONVEX_MESH``, from the model's
    ``shape_source``).
    """

    kind: np.ndarray
    body: np.ndarray
    local: np.ndarray
    scale: np.ndarray
    static_kind: np.ndarray
    static_local: np.ndarray
    static_scale: np.ndarray
    links: list[tuple[int, int]]
    ee_body: int
    tip: np.ndarray
    mesh_body: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    mesh_local: np.ndarray = field(default_factory=lambda: np.zeros((0, 7)))
    mesh_vertices: list[np.ndarray] = field(default_factory=list)
    mesh_indices: list[np.ndarray] = field(default_factory=list)
    # entities whose mesh geometry is logged (statically, once); later poses log transforms only
    _meshes_logged: set[str] = field(default_factory=set, init=False, repr=False)

    @classmethod
    def from_model(
        cls, model, worlds: int, ee_body: int, tip: np.ndarray, meshes=()
    ) -> RobotDrawing:
        """One world's shapes of ``model``; ``meshes``: more, ``(body, local, vertices,
        triangles)`` each (a URDF's links: :func:`warp_critic.physics.robot_meshes.link_meshes`)."""
        B = model.body_count // worlds
        body = model.shape_body.numpy()
        kind = model.shape_type.numpy()
        local = model.shape_transform.numpy().astype(np.float64)
        scale = model.shape_scale.numpy().astype(np.float64)
        mine = (body >= 0) & (body < B) & np.isin(kind, DRAWN)
        # static shapes repeat once per world at the same place: keep one of each
        static = np.nonzero((body < 0) & np.isin(kind, DRAWN))[0]
        seen, keep = set(), []
        for s in static:
            key = (int(kind[s]), *np.round(local[s], 5), *np.round(scale[s], 5))
            if key not in seen:
                seen.add(key)
                keep.append(s)
        parent, child = model.joint_parent.numpy(), model.joint_child.numpy()
        links = [(int(p), int(c)) for p, c in zip(parent, child) if 0 <= p < B and 0 <= c < B]
        sources = getattr(model, "shape_source", None) or [None] * len(kind)
        found = [
            s
            for s in np.nonzero((body >= 0) & (body < B) & np.isin(kind, MESHES))[0]
            if getattr(sources[s], "vertices", None) is not None
            and getattr(sources[s], "indices", None) is not None
        ]
        all_meshes = [
            (
                int(body[s]),
                local[s],
                np.asarray(sources[s].vertices, np.float32) * scale[s].astype(np.float32),
                np.asarray(sources[s].indices, np.uint32).reshape(-1, 3),
            )
            for s in found
        ] + [m for m in meshes if m[0] < B]  # -1: a link welded to the world (drawn with the base)
        return cls(
            kind[mine],
            body[mine],
            local[mine],
            scale[mine],
            kind[keep],
            local[keep],
            scale[keep],
            links,
            int(ee_body),
            np.asarray(tip, np.float64),
            np.array([m[0] for m in all_meshes], int),
            np.array([m[1] for m in all_meshes], np.float64).reshape(-1, 7),
            [m[2] for m in all_meshes],
            [m[3] for m in all_meshes],
        )

    @property
    def has_shapes(self) -> bool:
        return len(self.kind) > 0 or bool((self.mesh_body >= 0).any())

    def tip_of(self, poses: np.ndarray) -> np.ndarray:
        """The tip position for body poses ``(B, 7)``."""
        p = poses[self.ee_body]
        return p[:3] + quat_rotate(p[3:], self.tip)

    def points(self, poses: np.ndarray) -> np.ndarray:
        """Body origins, the tip and the corners of the meshes' bounding boxes: what the camera
        frames."""
        pts = [poses[:, :3], self.tip_of(poses)[None]]
        frames = self._mesh_frames(poses)
        for frame, local, v in zip(frames, self.mesh_local, self.mesh_vertices):
            lo, hi = v.min(0), v.max(0)
            corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
            at = local[:3] + quat_rotate(local[3:], corners)
            pts.append(frame[:3] + quat_rotate(frame[3:], at))
        return np.concatenate(pts)

    def log_static(self, stream: rr.RecordingStream, entity: str, color) -> None:
        """The shapes fixed to the world (the base), once."""
        if len(self.static_kind):
            ident = np.tile([0.0, 0, 0, 0, 0, 0, 1], (len(self.static_kind), 1))
            self._log_shapes(
                stream,
                entity,
                self.static_kind,
                ident,
                self.static_local,
                self.static_scale,
                color,
                True,
                True,
            )
        if (self.mesh_body < 0).any():
            self._log_meshes(stream, entity, None, color, True, True, fixed=True)

    def _mesh_frames(self, poses: np.ndarray | None) -> np.ndarray:
        """Each mesh's body pose ``(M, 7)``; the world's (identity) for a mesh fixed to it."""
        ident = np.array([0.0, 0, 0, 0, 0, 0, 1])
        return np.array(
            [poses[b] if b >= 0 and poses is not None else ident for b in self.mesh_body]
        ).reshape(-1, 7)

    def log_arm(
        self,
        stream: rr.RecordingStream,
        entity: str,
        poses: np.ndarray,
        color,
        *,
        solid: bool = True,
        static: bool = False,
    ) -> None:
        """The robot at body poses ``(B, 7)`` under ``entity`` (solid, or as a wireframe ghost)."""
        if (self.mesh_body >= 0).any():
            self._log_meshes(stream, entity, poses, color, solid, static)
        if len(self.kind):
            self._log_shapes(
                stream,
                entity,
                self.kind,
                poses[self.body],
                self.local,
                self.scale,
                color,
                solid,
                static,
            )
        if self.has_shapes:
            return
        tip = self.tip_of(poses)
        strips = [np.stack([poses[p, :3], poses[c, :3]]) for p, c in self.links]
        strips.append(np.stack([poses[self.ee_body, :3], tip]))
        stream.log(
            f"{entity}/links",
            rr.LineStrips3D(strips, colors=[color], radii=0.02 if solid else 0.006),
            static=static,
        )

    def _log_meshes(self, stream, entity, poses, color, solid, static, fixed=False) -> None:
        """Each mesh on a body (``fixed``: on the world) under ``entity/meshes/<i>``: its geometry
        once (static, coloured per body: alternate bodies a shade darker), then its transform at
        these poses."""
        frames = self._mesh_frames(poses)
        pos = frames[:, :3] + quat_rotate(frames[:, 3:], self.mesh_local[:, :3])
        rot = quat_mul(frames[:, 3:], self.mesh_local[:, 3:]).astype(np.float32)
        first = entity not in self._meshes_logged
        self._meshes_logged.add(entity)
        for i, b in enumerate(self.mesh_body):
            if (b < 0) != fixed:
                continue
            path = f"{entity}/meshes/{i}"
            if first:
                shade = 1.0 if int(b) % 2 == 0 else 0.8
                rgba = [int(c * shade) for c in color] + [255 if solid else GHOST_ALPHA]
                stream.log(
                    path,
                    rr.Mesh3D(
                        vertex_positions=self.mesh_vertices[i],
                        triangle_indices=self.mesh_indices[i],
                        albedo_factor=rgba,
                    ),
                    static=True,
                )
            stream.log(
                path,
                rr.Transform3D(
                    translation=pos[i].astype(np.float32), quaternion=rr.Quaternion(xyzw=rot[i])
                ),
                static=static,
            )

    @staticmethod
    def _log_shapes(stream, entity, kind, frames, local, scale, color, solid, static) -> None:
        pos = frames[:, :3] + quat_rotate(frames[:, 3:], local[:, :3])
        rot = quat_mul(frames[:, 3:], local[:, 3:])
        FillMode = rr.components.FillMode
        fill = FillMode.Solid if solid else FillMode.TransparentFillMajorWireframe
        quats = lambda m: rot[m].astype(np.float32)  # noqa: E731 (x, y, z, w)
        m = kind == CAPSULE
        if m.any():
            half = scale[m, 1:2]
            axis = quat_rotate(rot[m], np.tile([0.0, 0.0, 1.0], (int(m.sum()), 1)))
            stream.log(
                f"{entity}/capsules",
                rr.Capsules3D(
                    lengths=2 * half[:, 0],
                    radii=scale[m, 0],
                    translations=pos[m] - axis * half,
                    quaternions=quats(m),
                    colors=[color],
                    fill_mode=fill,
                ),
                static=static,
            )
        m = kind == CYLINDER
        if m.any():
            stream.log(
                f"{entity}/cylinders",
                rr.Cylinders3D(
                    lengths=2 * scale[m, 1],
                    radii=scale[m, 0],
                    centers=pos[m],
                    quaternions=quats(m),
                    colors=[color],
                    fill_mode=fill,
                ),
                static=static,
            )
        for k, name, half in (
            (SPHERE, "spheres", lambda s: np.repeat(s[:, :1], 3, 1)),
            (BOX, "boxes", lambda s: s),
        ):
            m = kind == k
            if m.any():
                cls = rr.Ellipsoids3D if k == SPHERE else rr.Boxes3D
                stream.log(
                    f"{entity}/{name}",
                    cls(
                        centers=pos[m],
                        half_sizes=half(scale[m]),
                        quaternions=quats(m),
                        colors=[color],
                        fill_mode=fill,
                    ),
                    static=static,
                )


def grid_offsets(n: int, spacing: float) -> np.ndarray:
    """``(n, 3)`` offsets that lay ``n`` copies of the robot out side by side in a near-square grid
    (rows along -y, columns along x)."""
    cols = int(np.ceil(np.sqrt(n)))
    return np.array([[(i % cols) * spacing, -(i // cols) * spacing, 0.0] for i in range(n)])


def camera_for(points: np.ndarray, planar: bool) -> rrb.EyeControls3D:
    """An orbit camera looking at the centre of ``points (N, 3)``, from above for a ``planar`` robot
    and from the front, above and to the side otherwise, just far enough back to see them all."""
    lo, hi = points.min(0), points.max(0)
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 0.25)
    direction = np.array([0.0, -0.45, 1.0]) if planar else np.array([0.6, -1.0, 0.55])
    direction /= np.linalg.norm(direction)
    return rrb.EyeControls3D(
        position=(centre + direction * radius * 2.2).tolist(),
        look_target=centre.tolist(),
        eye_up=[0.0, 0.0, 1.0],
    )


__all__ = [
    "BASE_COLOR",
    "BEFORE_COLOR",
    "MAX_GOALS_DRAWN",
    "RobotDrawing",
    "camera_for",
    "goal_color",
    "grid_offsets",
    "quat_mul",
    "quat_rotate",
]
