"""The ray engine and the scene folder as the core reads it: what every renderer and the scene builder share.

``RayEngine`` is the Python face of the C++ Embree ray engine, with batched closest-hit and
occlusion queries:

    engine = RayEngine()
    engine.add_mesh(vertices, faces, mesh_id=0)   # (N, 3) float, (M, 3) int, metres
    engine.commit()
    hits = engine.intersect(origins, directions)  # (K, 3) arrays
    hits.t, hits.prim_id, hits.mesh_id, hits.normal, hits.hit

Both queries release the GIL and run on ``threads`` threads (0 = every core). Results do not
depend on the thread count. Normals are unit geometric normals from the triangle winding
(right-hand rule), so they point outwards on outward-wound closed meshes.

``load_core_scene`` reads the folder that the scene stage writes (``ptpb_scene.json`` and the
meshes it names) as the core's scene dict, which the renderer and the denoiser's guides trace.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from geometry.meshio import MESH_SUFFIXES, read_mesh
from render import _core

INVALID_ID = int(_core.INVALID_ID)


@dataclass(frozen=True)
class Hits:
    """Closest hits of a ray batch; misses have ``t = inf`` and ids equal to ``INVALID_ID``."""

    t: np.ndarray  # (K,) float32, distance in units of |direction|
    prim_id: np.ndarray  # (K,) uint32, triangle index within its mesh
    mesh_id: np.ndarray  # (K,) uint32, caller's mesh id
    normal: np.ndarray  # (K, 3) float32, unit geometric normal

    @property
    def hit(self) -> np.ndarray:
        return self.mesh_id != INVALID_ID


def _as_rays(name: str, array: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(array, dtype=np.float32)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return a


class RayEngine:
    """A set of triangle meshes traced by Embree 3."""

    def __init__(self) -> None:
        self._scene = _core.RayScene()

    def add_mesh(self, vertices: np.ndarray, faces: np.ndarray, mesh_id: int, offsets=None) -> None:
        """A mesh; with ``offsets``, the (K, 3) translations [m] of its instanced copies (add_instanced_mesh)."""
        if offsets is not None:
            self.add_instanced_mesh(vertices, faces, offsets, mesh_id)
            return
        v = np.ascontiguousarray(vertices, dtype=np.float32)
        f = np.asarray(faces)
        if f.size and (f.min() < 0):
            raise ValueError(f"mesh {mesh_id}: faces contain negative vertex indices")
        self._scene.add_mesh(v, np.ascontiguousarray(f, dtype=np.uint32), int(mesh_id))

    def add_instanced_mesh(self, vertices: np.ndarray, faces: np.ndarray, offsets, mesh_id: int) -> None:
        """The mesh placed at each of the (K, 3) translations ``offsets`` [m], traced as Embree instances of
        one copy (render/core/DESIGN.md §13); every copy answers with ``mesh_id``."""
        v = np.ascontiguousarray(vertices, dtype=np.float32)
        f = np.asarray(faces)
        if f.size and (f.min() < 0):
            raise ValueError(f"mesh {mesh_id}: faces contain negative vertex indices")
        t = np.ascontiguousarray(offsets, dtype=np.float64).reshape(-1, 3)
        self._scene.add_instanced_mesh(v, np.ascontiguousarray(f, dtype=np.uint32), t, int(mesh_id))

    def commit(self) -> RayEngine:
        self._scene.commit()
        return self

    @property
    def triangle_count(self) -> int:
        """Triangles stored: an instanced mesh counts once."""
        return int(self._scene.triangle_count)

    @property
    def placed_triangle_count(self) -> int:
        """Triangles in the scene: an instanced mesh counts once per copy."""
        return int(self._scene.placed_triangle_count)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lower, upper = self._scene.bounds
        return np.array(lower), np.array(upper)

    def intersect(self, origins, directions, tnear: float = 0.0, tfar=None, threads: int = 0) -> Hits:
        o = _as_rays("origins", origins)
        d = _as_rays("directions", directions)
        far = None if tfar is None else np.ascontiguousarray(np.broadcast_to(tfar, o.shape[:1]), dtype=np.float32)
        t, prim, mesh, normal = self._scene.intersect(o, d, float(tnear), far, int(threads))
        return Hits(t=t, prim_id=prim, mesh_id=mesh, normal=normal)

    def occluded(self, origins, directions, tnear: float = 0.0, tfar=None, threads: int = 0) -> np.ndarray:
        o = _as_rays("origins", origins)
        d = _as_rays("directions", directions)
        far = None if tfar is None else np.ascontiguousarray(np.broadcast_to(tfar, o.shape[:1]), dtype=np.float32)
        return self._scene.occluded(o, d, float(tnear), far, int(threads))


def _load_mesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    if path.suffix == ".npz":
        with np.load(path) as z:
            return np.asarray(z["vertices"], np.float32), np.asarray(z["faces"], np.uint32)
    if path.suffix.lower() in MESH_SUFFIXES:
        return read_mesh(path)
    raise ValueError(f"{path}: meshes must be .npz (vertices, faces) or one of {', '.join(MESH_SUFFIXES)}")


def load_core_scene(scene_dir: str | Path) -> dict:
    """Read the scene folder that the scene stage wrote (``scene_dir/ptpb_scene.json`` and the meshes
    it names) as the core's scene dict, ready for ``render``; exported as ``render.ptpb.load_scene``."""
    scene_dir = Path(scene_dir)
    path = scene_dir / "ptpb_scene.json"
    if not path.exists():
        raise FileNotFoundError(f"{path} not found: the scene stage must write the PTPB scene description there")
    scene = json.loads(path.read_text())
    for i, shape in enumerate(scene.get("shapes", [])):
        if "mesh" in shape:
            v, f = _load_mesh(scene_dir / shape.pop("mesh"))
            shape["vertices"], shape["faces"] = v, f
        elif "vertices" not in shape:
            raise ValueError(f"{path}: shapes[{i}] needs 'mesh' or 'vertices'/'faces'")
    return scene
