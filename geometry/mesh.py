"""Height field -> closed, watertight triangle solid -> PLY.

Frame and units of every mesh here (the project's convention): metres, x = east, y = north,
z = up. The tile spans [0, L] x [0, L]; the surface's mean height sits at z = 0 and the flat base
lies ``base_thickness`` below the deepest trough. Normals point out of the solid.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from geometry import meshio


@dataclass(frozen=True)
class TriangleMesh:
    """vertices (V, 3) [m]; faces (F, 3) vertex indices, counter-clockwise seen from outside."""

    vertices: np.ndarray
    faces: np.ndarray


def heightfield_solid(h: np.ndarray, spacing: float, base_thickness: float, tiles: int = 1) -> TriangleMesh:
    """Close a periodic height field [m] into a solid: surface, four side skirts and a base slab.

    The grid is tiled ``tiles`` times per side and wrapped so the tile edges repeat the first
    row/column (tiles of the mesh then fit together). Quads split along the diagonal with the
    smaller height difference, which keeps crests from turning into saw-teeth (DESIGN.md 6.4).
    """
    h = np.asarray(h, float)
    if not np.all(np.isfinite(h)):
        raise ValueError("height field has NaN/inf values; cannot mesh it (check geometry.* growth settings)")
    if base_thickness <= 0:
        raise ValueError(f"geometry.base_thickness must be positive, got {base_thickness}")
    field = np.tile(h - h.mean(), (tiles, tiles))
    n = field.shape[0]
    z = np.pad(field, ((0, 1), (0, 1)), mode="wrap")  # (n+1, n+1) with the periodic edge repeated
    m = n + 1
    coords = np.arange(m) * spacing
    ys, xs = np.meshgrid(coords, coords, indexing="ij")
    top = np.column_stack((xs.ravel(), ys.ravel(), z.ravel()))
    index = np.arange(m * m).reshape(m, m)
    a, b = index[:-1, :-1].ravel(), index[:-1, 1:].ravel()  # (row, col) and (row, col+1)
    c, d = index[1:, :-1].ravel(), index[1:, 1:].ravel()  # (row+1, col) and (row+1, col+1)
    zf = z.ravel()
    split_ad = np.abs(zf[a] - zf[d]) <= np.abs(zf[b] - zf[c])
    # Counter-clockwise from above (+z): a(x0,y0) b(x1,y0) d(x1,y1) c(x0,y1).
    faces_ad = np.concatenate((np.column_stack((a, b, d)), np.column_stack((a, d, c))))
    faces_bc = np.concatenate((np.column_stack((a, b, c)), np.column_stack((b, d, c))))
    keep = np.concatenate((split_ad, split_ad))
    surface = np.where(keep[:, None], faces_ad, faces_bc)

    z_base = float(field.min()) - base_thickness
    # Boundary loop of the top grid, counter-clockwise seen from above.
    loop = np.concatenate((index[0, :-1], index[:-1, -1], index[-1, :0:-1], index[:0:-1, 0]))
    bottom = top[loop].copy()
    bottom[:, 2] = z_base
    nb = len(loop)
    bottom_ids = m * m + np.arange(nb)
    nxt = np.roll(np.arange(nb), -1)
    # Skirt quads (top i, top i+1, bottom i+1, bottom i), outward for a counter-clockwise loop.
    skirt = np.concatenate(
        (
            np.column_stack((loop, bottom_ids, bottom_ids[nxt])),
            np.column_stack((loop, bottom_ids[nxt], loop[nxt])),
        )
    )
    centre_id = m * m + nb
    centre = np.array([[n * spacing / 2, n * spacing / 2, z_base]])
    base = np.column_stack((np.full(nb, centre_id), bottom_ids[nxt], bottom_ids))  # faces down
    vertices = np.concatenate((top, bottom, centre))
    faces = np.concatenate((surface, skirt, base)).astype(np.int64)
    return TriangleMesh(vertices, faces)


def manifold_volume(mesh: TriangleMesh) -> float:
    """Volume [m3] of a mesh checked by manifold3d; ValueError if it is not a closed 2-manifold."""
    import manifold3d

    solid = manifold3d.Manifold(
        manifold3d.Mesh(
            vert_properties=np.asarray(mesh.vertices, np.float32), tri_verts=np.asarray(mesh.faces, np.uint32)
        )
    )
    status = solid.status()
    if status != manifold3d.Error.NoError:
        raise ValueError(
            f"the penitente mesh is not watertight/manifold (manifold3d: {status.name}); "
            "lower geometry.max_triangles decimation or check the height field"
        )
    return float(solid.volume())


def height_integral_volume(h: np.ndarray, spacing: float, base_thickness: float, tiles: int = 1) -> float:
    """Volume [m3] between the surface and the base from the height integral (mean height x area)."""
    field = np.tile(np.asarray(h, float) - np.mean(h), (tiles, tiles))
    depth = field - (field.min() - base_thickness)
    return float(depth.mean() * (field.shape[0] * spacing) ** 2)


def decimate(mesh: TriangleMesh, max_triangles: int) -> TriangleMesh:
    """Quadric edge-collapse decimation (pymeshlab) to at most ``max_triangles``, keeping topology,
    normals and sharp blade edges (planar quadrics, boundary-free closed solid)."""
    if len(mesh.faces) <= max_triangles:
        return mesh
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(
        pymeshlab.Mesh(vertex_matrix=np.asarray(mesh.vertices, float), face_matrix=np.asarray(mesh.faces, np.int32))
    )
    ms.meshing_decimation_quadric_edge_collapse(
        targetfacenum=int(max_triangles),
        qualitythr=0.3,
        preservetopology=True,
        preservenormal=True,
        optimalplacement=True,
        planarquadric=True,
        autoclean=True,
    )
    out = ms.current_mesh()
    return TriangleMesh(out.vertex_matrix().astype(float), out.face_matrix().astype(np.int64))


def write_ply(path: str | Path, mesh: TriangleMesh, comment: str = "") -> Path:
    """Write a binary little-endian PLY (float32 vertices, uint8 + int32 faces), atomically."""
    return meshio.write_ply(path, mesh.vertices, mesh.faces, comment)


def read_ply(path: str | Path) -> TriangleMesh:
    """Read a triangle mesh file (PLY, OBJ or STL; geometry/meshio.py)."""
    vertices, faces = meshio.read_mesh(path)
    return TriangleMesh(vertices.astype(float), faces.astype(np.int64))
