"""Simple closed triangle meshes for tests and set-ups: boxes, spheres, quads and disks.

Every function returns ``(vertices, faces)``: float32 ``(N, 3)`` positions in metres and uint32
``(M, 3)`` vertex indices. Closed shapes wind counter-clockwise seen from outside, so the
right-hand normal ``(v1 - v0) x (v2 - v0)`` points outwards.
"""

from __future__ import annotations

import numpy as np

Mesh = tuple[np.ndarray, np.ndarray]


def box_mesh(lower=(-0.5, -0.5, -0.5), upper=(0.5, 0.5, 0.5)) -> Mesh:
    """Axis-aligned box with corners ``lower`` and ``upper`` (m): 8 vertices, 12 triangles."""
    lo = np.asarray(lower, dtype=np.float64)
    hi = np.asarray(upper, dtype=np.float64)
    if lo.shape != (3,) or hi.shape != (3,) or not np.all(hi > lo):
        raise ValueError(f"box needs lower < upper in every axis, got lower={lower}, upper={upper}")
    corners = np.array([[(hi if (i >> a) & 1 else lo)[a] for a in range(3)] for i in range(8)])
    # Each face lists its 4 corners counter-clockwise seen from outside (corner bit a = axis a at hi).
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = []
    for a, b, c, d in quads:
        faces += [(a, b, c), (a, c, d)]
    return corners.astype(np.float32), np.asarray(faces, dtype=np.uint32)


def sphere_mesh(center=(0.0, 0.0, 0.0), radius: float = 1.0, subdivisions: int = 4) -> Mesh:
    """Geodesic sphere: an icosahedron subdivided ``subdivisions`` times, vertices on the sphere."""
    if radius <= 0:
        raise ValueError(f"sphere radius must be positive, got {radius}")
    t = (1.0 + 5.0**0.5) / 2.0
    verts = [
        (-1, t, 0),
        (1, t, 0),
        (-1, -t, 0),
        (1, -t, 0),
        (0, -1, t),
        (0, 1, t),
        (0, -1, -t),
        (0, 1, -t),
        (t, 0, -1),
        (t, 0, 1),
        (-t, 0, -1),
        (-t, 0, 1),
    ]
    faces = [
        (0, 11, 5),
        (0, 5, 1),
        (0, 1, 7),
        (0, 7, 10),
        (0, 10, 11),
        (1, 5, 9),
        (5, 11, 4),
        (11, 10, 2),
        (10, 7, 6),
        (7, 1, 8),
        (3, 9, 4),
        (3, 4, 2),
        (3, 2, 6),
        (3, 6, 8),
        (3, 8, 9),
        (4, 9, 5),
        (2, 4, 11),
        (6, 2, 10),
        (8, 6, 7),
        (9, 8, 1),
    ]
    v = [np.asarray(p, dtype=np.float64) / np.linalg.norm(p) for p in verts]
    for _ in range(subdivisions):
        midpoint_cache: dict[tuple[int, int], int] = {}

        def midpoint(i: int, j: int, midpoint_cache: dict[tuple[int, int], int] = midpoint_cache) -> int:
            key = (min(i, j), max(i, j))
            if key not in midpoint_cache:
                m = v[i] + v[j]
                v.append(m / np.linalg.norm(m))
                midpoint_cache[key] = len(v) - 1
            return midpoint_cache[key]

        new_faces = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            new_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new_faces
    vertices = np.asarray(center, dtype=np.float64) + radius * np.asarray(v)
    return vertices.astype(np.float32), np.asarray(faces, dtype=np.uint32)


def quad_mesh(center=(0.0, 0.0, 0.0), u=(0.5, 0.0, 0.0), v=(0.0, 0.5, 0.0)) -> Mesh:
    """Parallelogram ``center ± u ± v`` (two triangles); its normal is ``u x v``."""
    c, a, b = (np.asarray(x, dtype=np.float64) for x in (center, u, v))
    vertices = np.array([c - a - b, c + a - b, c + a + b, c - a + b])
    return vertices.astype(np.float32), np.array([(0, 1, 2), (0, 2, 3)], dtype=np.uint32)


def disk_mesh(center=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), radius: float = 1.0, segments: int = 64) -> Mesh:
    """Flat disk as a triangle fan facing ``normal``."""
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(n, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    angles = 2 * np.pi * np.arange(segments) / segments
    rim = np.asarray(center) + radius * (np.cos(angles)[:, None] * e1 + np.sin(angles)[:, None] * e2)
    vertices = np.vstack([np.asarray(center, dtype=np.float64)[None], rim])
    faces = [(0, 1 + i, 1 + (i + 1) % segments) for i in range(segments)]
    return vertices.astype(np.float32), np.asarray(faces, dtype=np.uint32)


def frame_mesh(inner_lower, inner_upper, margin: float, top_z: float, thickness: float) -> Mesh:
    """A closed rectangular ring: the box of footprint ``inner`` grown by ``margin`` on every side,
    minus the ``inner`` footprint, between ``top_z - thickness`` and ``top_z`` (m).

    It is one manifold (genus 1), so a medium inside it has no internal faces.
    """
    (x0, y0), (x1, y1) = (tuple(float(c) for c in inner_lower[:2]), tuple(float(c) for c in inner_upper[:2]))
    if not (x1 > x0 and y1 > y0 and margin > 0 and thickness > 0):
        raise ValueError("frame_mesh needs a non-empty inner footprint and positive margin and thickness")
    X0, Y0, X1, Y1 = x0 - margin, y0 - margin, x1 + margin, y1 + margin
    ring = [(X0, Y0), (X1, Y0), (X1, Y1), (X0, Y1)]  # outer, counter-clockwise from above
    hole = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]  # inner, same order
    z_bottom = top_z - thickness
    vertices = [(x, y, z) for z in (z_bottom, top_z) for x, y in ring + hole]
    # Indices: bottom outer 0-3, bottom inner 4-7, top outer 8-11, top inner 12-15.
    faces = []
    for i in range(4):
        j = (i + 1) % 4
        faces += [(8 + i, 8 + j, 12 + j), (8 + i, 12 + j, 12 + i)]  # top annulus, normal +z
        faces += [(i, 4 + j, j), (i, 4 + i, 4 + j)]  # bottom annulus, normal -z
        faces += [(i, j, 8 + j), (i, 8 + j, 8 + i)]  # outer walls, outwards
        faces += [(4 + i, 12 + j, 4 + j), (4 + i, 12 + i, 12 + j)]  # inner walls, towards the hole
    return np.asarray(vertices, dtype=np.float32), np.asarray(faces, dtype=np.uint32)
