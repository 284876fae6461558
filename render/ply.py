"""Binary little-endian PLY meshes: ``vertex x y z float`` and ``face vertex_indices list uchar int``.

The geometry stage writes the same layout, so either side reads the other's files. The reader also
accepts extra vertex properties (normals, colours) and other scalar types, as long as the file is
binary little-endian and every face is a triangle.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from pipeline.atomic import atomic_path

_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "<i2",
    "int16": "<i2",
    "ushort": "<u2",
    "uint16": "<u2",
    "int": "<i4",
    "int32": "<i4",
    "uint": "<u4",
    "uint32": "<u4",
    "float": "<f4",
    "float32": "<f4",
    "double": "<f8",
    "float64": "<f8",
}


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


def read_ply(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """Read ``(vertices float32 (N, 3), faces uint32 (M, 3))`` from a binary little-endian triangle PLY."""
    data = Path(path).read_bytes()
    marker = b"end_header"
    at = data.find(marker)
    if not data.startswith(b"ply") or at < 0:
        raise ValueError(f"{path}: not a PLY file (no 'ply' magic or no end_header)")
    body = data.index(b"\n", at) + 1
    lines = data[:body].decode("ascii", errors="replace").splitlines()
    if "format binary_little_endian 1.0" not in [line.strip() for line in lines]:
        raise ValueError(f"{path}: only binary_little_endian PLY is supported; convert the mesh first")
    elements: list[dict] = []
    for line in lines:
        parts = line.split()
        if parts[:1] == ["element"]:
            elements.append({"name": parts[1], "count": int(parts[2]), "props": []})
        elif parts[:1] == ["property"]:
            elements[-1]["props"].append(parts[1:])
    offset = body
    vertices = faces = None
    for element in elements:
        if element["name"] == "face":
            props = element["props"]
            if len(props) != 1 or props[0][0] != "list":
                raise ValueError(f"{path}: faces must have exactly one list property (vertex_indices)")
            _, count_type, index_type, _ = props[0]
            dtype = np.dtype([("count", _PLY_TYPES[count_type]), ("index", _PLY_TYPES[index_type], (3,))])
            records = np.frombuffer(data, dtype, count=element["count"], offset=offset)
            if element["count"] and np.any(records["count"] != 3):
                raise ValueError(f"{path}: only triangle faces are supported")
            faces = records["index"].astype(np.uint32)
            offset += dtype.itemsize * element["count"]
        else:
            if any(p[0] == "list" for p in element["props"]):
                raise ValueError(f"{path}: list properties are only supported on faces")
            dtype = np.dtype([(p[1], _PLY_TYPES[p[0]]) for p in element["props"]])
            records = np.frombuffer(data, dtype, count=element["count"], offset=offset)
            offset += dtype.itemsize * element["count"]
            if element["name"] == "vertex":
                vertices = np.stack([records[a] for a in ("x", "y", "z")], axis=1).astype(np.float32)
    if vertices is None or faces is None:
        raise ValueError(f"{path}: needs a vertex and a face element")
    return vertices, faces


__all__ = ["write_ply", "read_ply"]
