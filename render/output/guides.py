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


def arrival_bins(scene: Scene, core: dict) -> np.ndarray | None:
    """For every light with a time origin (render.scene.build.direct_arrivals: the sun, point and spot lights,
    then the emitting shapes), the first and last film bin that its direct light (light -> visible surface ->
    pinhole) reaches within each pixel, from the OPL at the pixel's lit corners: (lights, 2, H, W) int32, -1 where
    no corner of the pixel sees a surface that the light reaches directly (shadowed, or facing away). None for a
    steady film or a scene whose lights have no time origin (a sky alone).

    A shadowed pixel's first light is the snow's diffuse glow, not a spike: counted in the band it left a hole in
    each frame's denoising and took the prompt image's gain from its lit neighbours (86 % of the demo's band
    pixels with a gain above 2 were shadowed; render/output/LOOK.md, *The arrival band*)."""
    from render.scene.build import direct_arrivals

    film, camera = scene.film, scene.camera
    if film.mode != "transient" or film.temporal_bins < 1:
        return None
    # As the scene stage times its window: emitters are lights (timed from their centres), the rest surfaces.
    emits = [shape.emission is not None and any(shape.emission) for shape in scene.shapes]
    surfaces = [c for c, e in zip(core["shapes"], emits, strict=True) if not e]
    centres = [np.asarray(c["vertices"], np.float64).mean(axis=0) for c, e in zip(core["shapes"], emits) if e]
    width, height = camera.width, camera.height
    # (W + 1) x (H + 1) rays: direct_arrivals then samples the pixel corners exactly.
    opl = direct_arrivals(
        camera,
        scene.lights,
        [(c["vertices"], c["faces"]) for c in surfaces],
        centres,
        max_rays=(width + 1) * (height + 1),
        offsets=[c.get("offsets") for c in surfaces],
        shadows=True,
    )
    if opl.shape[0] == 0:
        return None
    bins = np.floor((opl - film.start_opl) / film.bin_width_opl)
    corners = np.stack([bins[:, i : i + height, j : j + width] for i in (0, 1) for j in (0, 1)])
    seen = np.isfinite(corners)
    first = np.where(seen, corners, np.inf).min(axis=0)
    last = np.where(seen, corners, -np.inf).max(axis=0)
    out = np.full((opl.shape[0], 2, height, width), -1, np.int32)
    # A range that ends before the film's first frame is none; one that starts before it starts at frame 0; a
    # bin past the film's end stands for "after it".
    lit = np.isfinite(first) & (last >= 0)
    limit = film.temporal_bins
    out[:, 0][lit] = np.clip(first[lit], 0, limit).astype(np.int32)
    out[:, 1][lit] = np.clip(last[lit], 0, limit).astype(np.int32)
    return out


def guide_buffers(scene_dir: str | Path, samples: int = GUIDE_SAMPLES) -> Guides:
    """Albedo and normal of the first camera hit in the scene folder the scene stage wrote (``scene.json``,
    its meshes and ``optics.json``), averaged over ``samples`` x ``samples`` stratified rays per pixel."""
    from render.engine import RayEngine, load_core_scene

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
    return Guides(
        albedo=np.ascontiguousarray(albedo, np.float32),
        normal=np.ascontiguousarray(normal, np.float32),
        arrival_bins=arrival_bins(scene, core),
    )
