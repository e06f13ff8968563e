"""A URDF or MJCF robot's link meshes, for drawing only (the recordings' 3-D view), never for dynamics.

A URDF is imported without its meshes (:mod:`warp_critic.physics.importers`), and its links welded
by fixed joints are merged into the moving bodies. :func:`link_frames` keeps, at import, where each
of the file's links ended up (the model body it is part of and its frame there); :func:`link_meshes`
reads each link's meshes from the file (its ``<visual>`` meshes, else its ``<collision>`` ones; STL
files, binary or ASCII, as newton needs no other package for them; other formats are skipped) and
places them on those bodies (body -1: a link welded to the world, in the world's frame). An
MJCF's mesh geoms are those :mod:`warp_critic.physics.mjcf_file` removed before import (STL, or
OBJ read with trimesh).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from warp_critic.physics.file_format import file_format

IDENTITY = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def link_frames(labels: list[str], info: dict) -> dict[str, tuple[int, tuple[float, ...]]]:
    """Each body label (short name) of the file -> (its body in the model, -1 for the world; its
    frame in that body, 7: position, quaternion xyzw), from ``collapse_fixed_joints``' ``info``."""
    frames = {}
    for b, label in enumerate(labels):
        name = label.rsplit("/", 1)[-1]
        if b in info["body_merged_parent"]:
            parent = info["body_merged_parent"][b]
            body = info["body_remap"][parent] if parent >= 0 else -1
            frames[name] = (body, tuple(float(x) for x in info["body_merged_transform"][b]))
        elif b in info["body_remap"]:
            frames[name] = (info["body_remap"][b], IDENTITY)
    return frames


def mesh_path(urdf: Path, filename: str) -> Path | None:
    """The file a URDF mesh reference names (``package://`` searched up from the URDF), if any."""
    if filename.startswith("package://"):
        package, _, rest = filename[len("package://") :].partition("/")
        for parent in urdf.parents:
            if parent.name == package and (parent / rest).is_file():
                return parent / rest
            if (parent / package / rest).is_file():
                return parent / package / rest
        return None
    if filename.startswith("file://"):
        filename = filename[len("file://") :]
    target = Path(filename)
    target = target if target.is_absolute() else urdf.parent / target
    return target if target.is_file() else None


def read_stl(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(V, 3)`` float32 (shared corners merged) and triangles ``(F, 3)`` uint32."""
    data = path.read_bytes()
    n = int.from_bytes(data[80:84], "little") if len(data) >= 84 else -1
    if n >= 0 and len(data) == 84 + 50 * n:  # binary
        rows = np.frombuffer(
            data, np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]), n, 84
        )
        corners = rows["v"].reshape(-1, 3)
    else:  # ASCII: "vertex x y z" lines
        words = [line.split() for line in data.decode("ascii", "replace").splitlines()]
        corners = np.array([w[1:4] for w in words if w[:1] == ["vertex"]], np.float32).reshape(
            -1, 3
        )
    vertices, index = np.unique(corners, axis=0, return_inverse=True)
    return vertices.astype(np.float32), index.reshape(-1, 3).astype(np.uint32)


def link_meshes(scene) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """``(body, local (7,), vertices (V, 3), triangles (F, 3))`` for each mesh of a URDF robot
    scene's links (none for other scenes): ``local`` is the mesh's frame in the body (body -1: the
    world)."""
    import warp as wp

    frames = getattr(scene, "link_frames", None)
    path = Path(getattr(scene, "path", "") or "")
    if frames and getattr(scene, "drawn_meshes", None):
        return mjcf_meshes(scene.drawn_meshes, frames)
    if not frames or not path.is_file() or file_format(path) != "urdf":
        return []
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError):
        return []
    out = []
    for link in root.iter("link"):
        if link.get("name") not in frames:
            continue
        body, frame = frames[link.get("name")]
        for kind in ("visual", "collision"):
            found = []
            for element in link.findall(kind):
                mesh = element.find("geometry/mesh")
                file = mesh_path(path, mesh.get("filename", "")) if mesh is not None else None
                if mesh is None or file is None or file.suffix.lower() != ".stl":
                    continue
                origin = element.find("origin")
                at = (origin if origin is not None else ET.Element("origin")).attrib
                try:  # drawing only: a mesh that cannot be read is left out
                    xyz, rpy, scale = (
                        [float(v) for v in text.split()]
                        for text in (
                            at.get("xyz", "0 0 0"),
                            at.get("rpy", "0 0 0"),
                            mesh.get("scale", "1 1 1"),
                        )
                    )
                    vertices, triangles = read_stl(file)
                    pose = wp.transform(wp.vec3(*frame[:3]), wp.quat(*frame[3:])) * wp.transform(
                        wp.vec3(*xyz), wp.quat_rpy(*rpy)
                    )
                except (OSError, ValueError, TypeError):
                    continue
                scaled = vertices * np.asarray(scale, np.float32)
                found.append((body, np.array(pose, np.float64), scaled, triangles))
            if found:
                out += found
                break
    return out


def read_mesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(V, 3)`` float32 and triangles ``(F, 3)`` uint32 of an STL or OBJ file (OBJ read
    with trimesh, all its parts as one mesh). Raises OSError or ValueError where it cannot."""
    if path.suffix.lower() == ".stl":
        return read_stl(path)
    import trimesh

    mesh = trimesh.load(str(path), force="mesh", process=False)
    vertices = np.asarray(getattr(mesh, "vertices", ()), np.float32).reshape(-1, 3)
    faces = np.asarray(getattr(mesh, "faces", ()), np.uint32).reshape(-1, 3)
    if not len(faces):
        raise ValueError(f"{path}: no triangles")
    return vertices, faces


def mjcf_meshes(drawn, frames) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """``link_meshes``' tuples for an MJCF robot's mesh geoms (``mjcf_file.DrawnMesh``): each
    body's visual geoms, else its colliders; a mesh that cannot be read is left out."""
    import warp as wp

    out = []
    for name in dict.fromkeys(d.body for d in drawn):
        if name not in frames:
            continue
        mine = [d for d in drawn if d.body == name]
        mine = [d for d in mine if d.visual] or mine
        body, frame = frames[name]
        for d in mine:
            try:  # drawing only: a mesh that cannot be read is left out
                vertices, triangles = read_mesh(Path(d.file))
            except (OSError, ValueError, IndexError):
                continue
            pose = wp.transform(wp.vec3(*frame[:3]), wp.quat(*frame[3:])) * wp.transform(
                wp.vec3(*d.pose[:3]), wp.quat(*d.pose[3:])
            )
            scaled = vertices * np.asarray(d.scale, np.float32)
            out.append((body, np.array(pose, np.float64), scaled, triangles))
    return out


__all__ = ["link_frames", "link_meshes", "mesh_path", "mjcf_meshes", "read_mesh", "read_stl"]
