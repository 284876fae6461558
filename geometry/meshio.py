"""Mesh files: every reader goes through MeshLab (PLY in any encoding, OBJ, STL); the one writer is
binary little-endian PLY (``vertex x y z float``, ``face vertex_indices list uchar int``), written
atomically, which the geometry and scene stages produce."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from common.atomic import atomic_path

MESH_SUFFIXES = (".ply", ".obj", ".stl")


def write_ply(path: str | os.PathLike[str], vertices: np.ndarray, faces: np.ndarray, comment: str = "") -> Path:
    """Write triangles atomically: float32 (N, 3) vertices [m], (M, 3) vertex indices."""
    v = np.ascontiguousarray(vertices, dtype="<f4")
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"write_ply needs (N, 3) vertices and (M, 3) faces, got {v.shape} and {f.shape}")
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise ValueError(f"{path}: face indices must lie in [0, {len(v)})")
    records = np.empty(len(f), dtype=[("count", "u1"), ("index", "<i4", (3,))])
    records["count"] = 3
    records["index"] = f
    header = ["ply", "format binary_little_endian 1.0"]
    header += [f"comment {line}" for line in comment.splitlines() if line]
    header += [
        f"element vertex {len(v)}",
        "property float x",
        "property float y",
        "property float z",
        f"element face {len(f)}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as out:
            out.write(("\n".join(header) + "\n").encode("ascii"))
            out.write(v.tobytes())
            out.write(records.tobytes())
    return Path(path)


def read_mesh(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """Read ``(vertices float32 (N, 3), faces uint32 (M, 3))`` from a PLY (ASCII or binary), OBJ or STL.

    trimesh reads the file as it is (``process=False``): vertex and face order are kept, and NaN
    vertices or out-of-range faces reach the caller's checks instead of being dropped silently, as
    MeshLab's importer does. STL stores each triangle's corners separately, so its vertices are merged
    by position to give a connected surface."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise ValueError(f"{path}: unsupported mesh format '{path.suffix}'; use one of {', '.join(MESH_SUFFIXES)}")
    if not path.is_file():
        raise FileNotFoundError(f"{path}: mesh file not found")
    import trimesh

    try:
        mesh = trimesh.load(str(path), process=False, force="mesh")
    except Exception as exc:  # trimesh raises many types for malformed files
        raise ValueError(f"{path}: not a readable {suffix[1:].upper()} triangle mesh ({exc})") from None
    if not isinstance(mesh, trimesh.Trimesh):
        raise ValueError(f"{path}: not a single triangle mesh")
    if suffix == ".stl":
        mesh.merge_vertices()
    vertices = np.asarray(mesh.vertices, dtype=np.float32).reshape(-1, 3)
    faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        raise ValueError(f"{path}: the mesh is empty (no triangles in the file); is it a {suffix[1:].upper()} mesh?")
    return vertices, faces.astype(np.uint32)


__all__ = ["MESH_SUFFIXES", "read_mesh", "write_ply"]
