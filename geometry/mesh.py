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


def _checked_field(h: np.ndarray) -> np.ndarray:
    h = np.asarray(h, float)
    if not np.all(np.isfinite(h)):
        raise ValueError("height field has NaN/inf values; cannot mesh it (check geometry.* growth settings)")
    return h


def _surface(field: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grid of a periodic field as triangles: vertices ((n+1)^2, 3), with the periodic edge repeated,
    their (n+1, n+1) index, and faces counter-clockwise from above. Quads split along the diagonal with the
    smaller height difference, which keeps crests from turning into saw-teeth (DESIGN.md 6.4)."""
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
    return top, index, np.where(keep[:, None], faces_ad, faces_bc)


def _skirt_and_base(loop_points: np.ndarray, z_base: float, first_id: int) -> tuple[np.ndarray, np.ndarray]:
    """Walls from a closed boundary loop (counter-clockwise from above, its vertices numbered from
    ``first_id``) down to z_base, and a base fan facing down: the vertices they add and their faces."""
    nb = len(loop_points)
    loop = first_id + np.arange(nb)
    bottom = loop_points.copy()
    bottom[:, 2] = z_base
    bottom_ids = first_id + nb + np.arange(nb)
    nxt = np.roll(np.arange(nb), -1)
    # Skirt quads (top i, top i+1, bottom i+1, bottom i), outward for a counter-clockwise loop.
    skirt = np.concatenate(
        (
            np.column_stack((loop, bottom_ids, bottom_ids[nxt])),
            np.column_stack((loop, bottom_ids[nxt], loop[nxt])),
        )
    )
    centre_id = first_id + 2 * nb
    lo, hi = loop_points[:, :2].min(0), loop_points[:, :2].max(0)
    centre = np.array([[(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, z_base]])
    base = np.column_stack((np.full(nb, centre_id), bottom_ids[nxt], bottom_ids))  # faces down
    return np.concatenate((bottom, centre)), np.concatenate((skirt, base))


def _boundary_loop(m: int) -> tuple[np.ndarray, np.ndarray]:
    """(row, col) of the boundary of an m x m vertex grid, counter-clockwise seen from above."""
    last = m - 1
    rows = np.concatenate((np.zeros(last, int), np.arange(last), np.full(last, last), np.arange(last, 0, -1)))
    cols = np.concatenate((np.arange(last), np.full(last, last), np.arange(last, 0, -1), np.zeros(last, int)))
    return rows, cols


def heightfield_solid(h: np.ndarray, spacing: float, base_thickness: float, tiles: int = 1) -> TriangleMesh:
    """Close a periodic height field [m] into a solid: surface, four side skirts and a base slab.

    The grid is tiled ``tiles`` times per side and wrapped so the tile edges repeat the first
    row/column (tiles of the mesh then fit together).
    """
    h = _checked_field(h)
    if base_thickness <= 0:
        raise ValueError(f"geometry.base_thickness must be positive, got {base_thickness}")
    field = np.tile(h - h.mean(), (tiles, tiles))
    top, index, surface = _surface(field, spacing)
    rows, cols = _boundary_loop(index.shape[0])
    z_base = float(field.min()) - base_thickness
    ring = top[index[rows, cols]]
    walls, faces = _skirt_and_base(ring, z_base, len(top))
    # The walls' top edge reuses the surface's boundary vertices instead of the copies in `ring`.
    faces = np.where(
        faces < len(top) + len(ring), index[rows, cols][np.clip(faces - len(top), 0, len(ring) - 1)], faces
    )
    faces = np.where(faces >= len(top) + len(ring), faces - len(ring), faces)
    vertices = np.concatenate((top, walls))
    return TriangleMesh(vertices, np.concatenate((surface, faces)).astype(np.int64))


def periodic_surface(h: np.ndarray, spacing: float) -> TriangleMesh:
    """The open surface of one tile of a periodic field [m] over [0, L]^2, mean height at z = 0, normals up:
    its edges repeat each other, so copies translated by multiples of L join without a seam (the tiled
    landscape, render/core/DESIGN.md §13)."""
    top, _, surface = _surface(_checked_field(h) - np.mean(h), spacing)
    return TriangleMesh(top, surface.astype(np.int64))


def tiled_closure(h: np.ndarray, spacing: float, z_base: float, tiles: int) -> TriangleMesh:
    """Walls and base that close ``tiles`` x ``tiles`` copies of ``periodic_surface(h)`` into one solid: the
    copies centred on the original tile (offsets ``tile_offsets``), the walls following the field's profile
    around the outside, the base at ``z_base`` [m].

    No triangle is longer than a tile, so that a ray's traversal meets few of them (a fan from the middle of
    a 41-tile base made a ray 35x slower): the walls drop in cell-wide strips from the profile to a level
    line between the deepest trough and the base, then in one fan per tile to the tile corners on the base,
    and the base is a grid of tile-sized squares."""
    h = _checked_field(h)
    if tiles < 1 or tiles % 2 == 0:
        raise ValueError(f"tiles must be odd and >= 1 (the grown tile in the middle), got {tiles}")
    field = h - h.mean()
    n = field.shape[0]
    if not z_base < field.min():
        raise ValueError(f"the base z = {z_base} m must lie below the field's deepest point {field.min():.4g} m")
    shift = (tiles - 1) // 2 * n * spacing
    rows, cols = _boundary_loop(tiles * n + 1)
    nb = len(rows)
    profile = np.column_stack((cols * spacing - shift, rows * spacing - shift, field[rows % n, cols % n]))
    level = profile.copy()
    level[:, 2] = 0.5 * (field.min() + z_base)
    # The base: (tiles + 1)^2 tile corners, its boundary the loop of every n-th profile vertex.
    corners = (np.arange(tiles + 1) * n * spacing) - shift
    cy, cx = np.meshgrid(corners, corners, indexing="ij")
    base = np.column_stack((cx.ravel(), cy.ravel(), np.full(cx.size, z_base)))
    top_id, level_id, base_id = np.arange(nb), nb + np.arange(nb), 2 * nb + np.arange(len(base)).reshape(tiles + 1, -1)
    nxt = np.roll(np.arange(nb), -1)
    b_rows, b_cols = _boundary_loop(tiles + 1)
    corner_loop = base_id[b_rows, b_cols]  # corner c sits below profile vertex c * n
    segment = np.arange(nb) // n
    # Outward for a counter-clockwise loop, as in heightfield_solid's skirt.
    upper = np.concatenate(
        (np.column_stack((top_id, level_id, level_id[nxt])), np.column_stack((top_id, level_id[nxt], top_id[nxt])))
    )
    fans = np.column_stack((level_id, corner_loop[segment], level_id[nxt]))
    ends = np.arange(len(corner_loop))
    closing = np.column_stack(
        (level_id[(ends + 1) * n % nb], corner_loop[ends], corner_loop[(ends + 1) % len(corner_loop)])
    )
    a, b = base_id[:-1, :-1].ravel(), base_id[:-1, 1:].ravel()
    c, d = base_id[1:, :-1].ravel(), base_id[1:, 1:].ravel()
    bottom = np.concatenate((np.column_stack((a, d, b)), np.column_stack((a, c, d))))  # facing down
    vertices = np.concatenate((profile, level, base))
    return TriangleMesh(vertices, np.concatenate((upper, fans, closing, bottom)).astype(np.int64))


def tile_offsets(tile_size: float, tiles: int) -> np.ndarray:
    """(tiles^2, 3) translations [m] of the copies of one tile, centred on the original: k L for k in
    -(tiles-1)/2 .. (tiles-1)/2 along x and y."""
    if tiles < 1 or tiles % 2 == 0:
        raise ValueError(f"tiles must be odd and >= 1 (the grown tile in the middle), got {tiles}")
    k = (np.arange(tiles) - (tiles - 1) // 2) * tile_size
    ky, kx = np.meshgrid(k, k, indexing="ij")
    return np.column_stack((kx.ravel(), ky.ravel(), np.zeros(tiles * tiles)))


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
