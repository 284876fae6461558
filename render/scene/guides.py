"""Guide buffers of the denoised delivery (render/output/LOOK.md, *Denoised delivery*): the albedo and normal of
the first camera hit, traced from the scene folder's own triangles with the core's Embree engine.

Every pixel's camera rays (a few stratified positions per pixel) meet the scene's triangles, so the guides
carry no Monte Carlo noise and are the same for every frame; the frames then share one set of edges, which
keeps the denoiser from inventing different ones frame to frame. Albedo is the diffuse reflectance of what the
ray hits: a diffuse surface's albedo, or the medium's diffuse albedo r_d behind a null or dielectric boundary
(render/scene/OPTICS.md). A ray that leaves the scene gets zero albedo and a zero normal, Open Image Denoise's
"no surface here".
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from render.output.denoise import Guides
from render.scene.model import Scene, Shape, camera_ray_direction

# Stratified camera rays per pixel side (4 x 4 = 16 rays): edges come out anti-aliased the way the rendered
# frames' are, which the denoiser expects of its guides.
GUIDE_SAMPLES = 4


def _shape_albedo(shape: Shape, optics: dict) -> np.ndarray:
    """What a guide ray sees of a shape: a diffuse surface's albedo, else r_d of the medium inside it (0 if none)."""
    if shape.kind == "diffuse":
        return np.clip(np.asarray(shape.albedo or (0.0, 0.0, 0.0), float), 0.0, 1.0)
    if shape.interior and shape.interior in optics:
        return np.clip(np.asarray(optics[shape.interior]["derived"]["diffuse_albedo"], float), 0.0, 1.0)
    return np.zeros(3)


def guide_buffers(scene_dir: str | Path, samples: int = GUIDE_SAMPLES) -> Guides:
    """Albedo and normal of the first camera hit in the scene folder the scene stage wrote (``scene.json``,
    its meshes and ``optics.json``), averaged over ``samples`` x ``samples`` stratified rays per pixel."""
    from render.ptpb.raytrace import RayEngine
    from render.ptpb.stage import load_core_scene

    scene_dir = Path(scene_dir)
    scene = Scene.load(scene_dir / "scene.json")
    optics_path = scene_dir / "optics.json"
    optics = json.loads(optics_path.read_text()) if optics_path.is_file() else {}
    core = load_core_scene(scene_dir)
    engine = RayEngine()
    albedos = []
    for index, (shape, core_shape) in enumerate(zip(scene.shapes, core["shapes"], strict=True)):
        engine.add_mesh(core_shape["vertices"], core_shape["faces"], index, core_shape.get("offsets"))
        albedos.append(_shape_albedo(shape, optics))
    engine.commit()
    camera = scene.camera
    width, height = camera.width, camera.height
    table = np.vstack([*albedos, np.zeros(3)]).astype(np.float32)
    albedo = np.zeros((height, width, 3), np.float32)
    normal = np.zeros((height, width, 3), np.float32)
    offsets = (np.arange(samples) + 0.5) / samples
    sub_y, sub_x = (a.ravel() for a in np.meshgrid(offsets, offsets, indexing="ij"))
    per_pixel = samples * samples
    rows = max(1, (1 << 20) // (width * per_pixel))  # about a million rays at a time
    for top in range(0, height, rows):
        pixel_y, pixel_x = np.meshgrid(np.arange(top, min(top + rows, height)), np.arange(width), indexing="ij")
        px = (pixel_x[..., None] + sub_x).ravel()
        py = (pixel_y[..., None] + sub_y).ravel()
        directions = camera_ray_direction(camera, px, py).astype(np.float32)
        hits = engine.intersect(np.broadcast_to(np.asarray(camera.origin, np.float32), directions.shape), directions)
        first = np.where(hits.hit, hits.mesh_id, len(albedos)).astype(np.int64)
        facing = np.where(hits.hit[:, None], hits.normal, 0.0).astype(np.float32)
        # Face the camera: which side of a face was hit is no edge the denoiser should see.
        facing[np.sum(facing * directions, axis=1) > 0] *= -1.0
        per_ray = (*pixel_y.shape, per_pixel, 3)
        albedo[top : top + rows] = table[first].reshape(per_ray).mean(axis=2)
        normal[top : top + rows] = facing.reshape(per_ray).mean(axis=2)
    return Guides(albedo=np.ascontiguousarray(albedo, np.float32), normal=np.ascontiguousarray(normal, np.float32))
