"""The scene builder: turn the config's scene section and the geometry stage's mesh into the
neutral scene description (``scene.json``), the PTPB core's dict (``ptpb_scene.json``), the
meshes (``meshes/*.ply``) and the media's derived optical quantities (``optics.json``).

Placement rules:
- ``penitentes`` is the geometry stage's watertight PLY as it is (metres, mean surface at z = 0); with
  ``tiles`` > 1 it is instead the grown field's periodic surface placed tiles x tiles times around the grown
  tile as instances of one copy, closed by walls and a base around the outside (render/core/DESIGN.md §13).
- ``snowpack`` next to a penitente mesh is a closed ring of snow around its footprint, ``gap``
  away from it, ``margin`` wide, with its top at ``top_z`` (default 0, the field's mean surface);
  alone it is a slab under the origin.
- ``frame_objects`` cameras aim at the centre of the penitente field (or of all objects) and stand
  back until its bounding sphere fits the narrower field of view.
- The sun comes from the site's sun path when ``scene.sun.solar_time_h`` is set.
- An ``auto`` film window starts at the earliest single-scattering arrival seen by the camera and
  ends ``window_tail_opl`` after the latest one.
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from geometry.meshio import read_mesh, write_ply
from pipeline.schema.scene import CameraConfig, FilmConfig, MediumConfig, ObjectConfig, SceneConfig
from render.scene import optics as optics_mod
from render.scene import shapes
from render.scene.model import (
    Camera,
    Film,
    Medium,
    Scene,
    Shape,
    as_vec3,
    bounding_sphere_of_points,
    camera_ray_direction,
    sun_direction,
    sun_tau_origin,
    tan_half_fov,
)

log = logging.getLogger(__name__)

PENITENTE_MESH = "penitentes.ply"
HEIGHTFIELD = "heightfield.npz"
Mesh = tuple[np.ndarray, np.ndarray]


# ---------------------------------------------------------------- media


def medium_optics(cfg: MediumConfig, medium_id: str) -> optics_mod.MediumOptics:
    """Resolve one ``scene.media.<id>`` entry into a medium in its render form."""
    where = f"scene.media.{medium_id}"
    try:
        if cfg.preset is not None:
            if cfg.metres_per_unit is not None and not cfg.preset.startswith("thesis_set_"):
                raise ValueError("metres_per_unit applies to thesis_set_* presets only")
            if cfg.preset in optics_mod.THESIS_SET_NAMES:
                base = optics_mod.thesis_set(int(cfg.preset[-1]), metres_per_unit=cfg.metres_per_unit)
            else:
                base = optics_mod.load_preset(cfg.preset)
        elif cfg.physical is not None:
            p = cfg.physical
            extra = {"black_carbon_ng_per_g": p.black_carbon_ng_per_g, "dust_ug_per_g": p.dust_ug_per_g}
            if p.kind == "snow":
                base = optics_mod.derive_snow(
                    p.density,
                    ssa=p.ssa,
                    optical_radius=p.optical_radius,
                    absorption_enhancement=p.absorption_enhancement,
                    g0_natural=p.g0_natural,
                    name=medium_id,
                    **extra,
                )
            elif p.kind == "bubbly_ice":
                if p.bubble_radius is None:
                    raise ValueError("bubbly_ice needs bubble_radius [m]")
                base = optics_mod.derive_bubbly_ice(p.density, p.bubble_radius, g=p.g, name=medium_id, **extra)
            else:
                base = optics_mod.derive_clear_ice(haze_sigma_s=p.haze_sigma_s, g=p.g, name=medium_id)
        elif cfg.coefficients is not None:
            c = cfg.coefficients
            base = optics_mod.MediumOptics(
                c.sigma_s,
                c.sigma_a,
                (c.g,) * 3,
                (c.ior,) * 3,
                cfg.boundary or "null",
                "full",
                medium_id,
                "explicit coefficients",
            )
        else:
            raise ValueError("give exactly one of preset, physical or coefficients")
        # Grain and bubble media render in the diffraction-removed form by default (OPTICS.md §4);
        # literal sets, explicit coefficients and clear ice stay as given.
        granular = base.inputs.get("ssa_m2_kg") is not None or base.inputs.get("bubble_radius_m") is not None
        medium = optics_mod.reduce(base, cfg.form or ("diffraction_removed" if granular else "full"))
        updates: dict[str, Any] = {}
        if cfg.boundary is not None:
            updates["boundary"] = cfg.boundary
        if cfg.ior is not None:
            updates["ior"] = (cfg.ior,) * 3
        medium = replace(medium, **updates)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    return medium


def scene_medium(medium: optics_mod.MediumOptics) -> Medium:
    return Medium(
        sigma_s=medium.sigma_s,
        sigma_a=medium.sigma_a,
        g=medium.render_g,
        ior=medium.region_ior,
        boundary=medium.boundary,
        g_rgb=medium.g,
        material_ior_rgb=medium.ior,
        form=medium.form,
        name=medium.name,
        source=medium.source,
    )


# ---------------------------------------------------------------- objects


def _object_mesh(obj: ObjectConfig, penitentes: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray]:
    where = f"scene.objects '{obj.name}'"
    if obj.shape == "penitentes":
        if penitentes is None:
            raise ValueError(f"{where} has shape penitentes, but the geometry stage's {PENITENTE_MESH} is missing")
        return penitentes
    if obj.shape == "box":
        c, s = np.asarray(obj.center), np.asarray(obj.size)
        return shapes.box_mesh(c - s / 2, c + s / 2)
    if obj.shape == "sphere":
        return shapes.sphere_mesh(obj.center, obj.radius, obj.subdivisions)
    if obj.shape == "slab":
        top = 0.0 if obj.top_z is None else obj.top_z
        c, s = np.asarray(obj.center), np.asarray(obj.size)
        return shapes.box_mesh(
            (c[0] - s[0] / 2, c[1] - s[1] / 2, top - obj.thickness), (c[0] + s[0] / 2, c[1] + s[1] / 2, top)
        )
    if obj.shape == "snowpack":
        top = 0.0 if obj.top_z is None else obj.top_z
        if penitentes is None:
            half = obj.margin
            return shapes.box_mesh((-half, -half, top - obj.thickness), (half, half, top))
        lo, hi = penitentes[0].min(0), penitentes[0].max(0)
        return shapes.frame_mesh(lo[:2] - obj.gap, hi[:2] + obj.gap, obj.margin, top, obj.thickness)
    path = Path(obj.path or "")
    if not path.is_file():
        raise ValueError(f"{where}: mesh file {path} does not exist (scene.objects[].path)")
    try:
        return read_mesh(path)
    except (ValueError, KeyError, IndexError) as exc:  # a truncated or foreign PLY
        reason = str(exc).removeprefix(f"{path}: ")
        raise ValueError(f"{where}: cannot read mesh file {path}: {reason}") from None


def _tiled_field(obj: ObjectConfig, geometry_dir: Path, z_base: float) -> tuple[Mesh, np.ndarray, Mesh]:
    """The grown field as a landscape (render/core/DESIGN.md §13): its periodic surface at full resolution,
    the (tiles^2, 3) offsets of its copies centred on the grown tile, and the walls and base that close them
    into one solid at the base of the geometry stage's mesh. The copies and walls are checked to close on 3 x 3
    (the same construction at any count)."""
    from geometry import mesh as field_mesh

    path = Path(geometry_dir) / HEIGHTFIELD
    if not path.is_file():
        raise FileNotFoundError(
            f"{path}: scene.objects '{obj.name}' has tiles {obj.tiles}, which needs the geometry stage's height "
            "field; run the geometry stage first"
        )
    with np.load(path) as z:
        h, spacing = np.asarray(z["height"], float), float(z["spacing"])
    sheet = field_mesh.periodic_surface(h, spacing)
    closure = field_mesh.tiled_closure(h, spacing, z_base, obj.tiles)
    tile = h.shape[0] * spacing
    trial = field_mesh.tiled_closure(h, spacing, z_base, 3)
    pieces = [sheet.vertices + o for o in field_mesh.tile_offsets(tile, 3)] + [trial.vertices]
    counts = np.cumsum([0] + [len(v) for v in pieces])
    faces = np.concatenate([sheet.faces + counts[k] for k in range(9)] + [trial.faces + counts[9]])
    welded, inverse = np.unique(np.round(np.concatenate(pieces), 7), axis=0, return_inverse=True)
    _check_mesh(f"{obj.name} (3 x 3 tiles)", welded, inverse.reshape(-1)[faces])
    return _as_arrays(sheet), field_mesh.tile_offsets(tile, obj.tiles), _as_arrays(closure)


def _as_arrays(mesh) -> Mesh:
    """A geometry.mesh.TriangleMesh as the (float32 vertices, uint32 faces) pair the scene stage writes."""
    return mesh.vertices.astype(np.float32), mesh.faces.astype(np.uint32)


def _check_mesh(name: str, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Refuse meshes a renderer cannot treat as a closed boundary: empty, NaN, indices out of range,
    not watertight (non-manifold), or inside out. Zero-area triangles that repeat a vertex leave the
    surface closed and are kept: no ray can hit them."""
    if len(vertices) == 0 or len(faces) == 0:
        raise ValueError(f"object '{name}': the mesh is empty")
    if not np.all(np.isfinite(vertices)):
        raise ValueError(f"object '{name}': the mesh has NaN or infinite vertices")
    if int(np.max(faces)) >= len(vertices):
        raise ValueError(
            f"object '{name}': face {int(np.argmax(np.max(faces, axis=1)))} refers to vertex "
            f"{int(np.max(faces))}, but the mesh has {len(vertices)} vertices"
        )
    import manifold3d

    solid = manifold3d.Manifold(
        manifold3d.Mesh(vert_properties=np.asarray(vertices, np.float32), tri_verts=np.asarray(faces, np.uint32))
    )
    if solid.status() != manifold3d.Error.NoError:
        raise ValueError(
            f"object '{name}': the mesh is not a closed manifold ({solid.status().name}); "
            "media need watertight boundaries; repair it (e.g. pymeshlab) or use another shape"
        )
    if solid.volume() <= 0:
        raise ValueError(f"object '{name}': the mesh encloses no volume (inverted or flat); flip its faces")


# ---------------------------------------------------------------- camera, lights, film


def frame_camera(cfg: CameraConfig, centre: np.ndarray, radius: float) -> Camera:
    """A camera looking at ``centre`` from the configured azimuth and elevation, far enough back
    that the sphere (centre, radius) fits the narrower field of view (times frame_margin)."""
    probe = Camera((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), cfg.up, cfg.fov, cfg.width, cfg.height, cfg.fov_axis)
    half = math.atan(min(tan_half_fov(probe)))
    distance = cfg.frame_margin * radius / math.sin(half)
    direction = sun_direction(cfg.view_elevation_deg, cfg.view_azimuth_deg)
    origin = np.asarray(centre) + distance * direction
    return Camera(
        as_vec3(origin),
        as_vec3(centre),
        cfg.up,
        cfg.fov,
        cfg.width,
        cfg.height,
        cfg.fov_axis,
        cfg.medium,
    )


def site_sun_direction(latitude: float, day_of_year: float, solar_time_h: float) -> np.ndarray:
    """Unit vector towards the sun (x east, y north, z up) at a local solar time."""
    from geometry import sunpath

    hour_angle = math.radians(15.0 * (solar_time_h - 12.0))
    sun = sunpath.sun_vector(latitude, float(sunpath.declination(day_of_year)), hour_angle)
    if sun[2] <= 0.01:
        raise ValueError(
            f"scene.sun.solar_time_h={solar_time_h}: the sun is below the horizon at latitude "
            f"{latitude} deg on day {(round(day_of_year) - 1) % 365 + 1} of the year; choose a daytime hour"
        )
    return np.asarray(sun, dtype=np.float64)


def _lights(
    cfg: SceneConfig, site: dict | None, centre: np.ndarray, radius: float
) -> tuple[list[dict], list[Shape], list]:
    lights: list[dict[str, Any]] = []
    emitters: list[Shape] = []
    meshes = []
    sun = cfg.sun
    if sun.enabled:
        if sun.direction is not None:
            to_sun = np.asarray(sun.direction, dtype=np.float64)
            to_sun /= np.linalg.norm(to_sun)
        elif sun.solar_time_h is not None:
            if site is None:
                raise ValueError("scene.sun.solar_time_h needs the geometry section's latitude and days")
            to_sun = site_sun_direction(site["latitude"], site["day_of_year"], sun.solar_time_h)
        else:
            to_sun = sun_direction(sun.elevation_deg, sun.azimuth_deg)
        lights.append(
            {
                "type": "sun",
                "model": sun.kind,
                "to_sun": [float(v) for v in to_sun],
                "irradiance": list(sun.irradiance),
                "angular_diameter_deg": sun.angular_diameter_deg,
                "tau_origin_point": [float(v) for v in sun_tau_origin(to_sun, centre, radius, sun.reference_point)],
                "reference_point": list(sun.reference_point) if sun.reference_point is not None else None,
                "disk_distance_radii": sun.disk_distance_radii,
            }
        )
    if max(cfg.sky.radiance) > 0:
        lights.append({"type": "sky", "radiance": list(cfg.sky.radiance)})
    for i, area in enumerate(cfg.area_lights):
        normal = np.asarray(area.normal, dtype=np.float64)
        normal /= np.linalg.norm(normal)
        if area.shape == "quad":
            helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
            u = np.cross(helper, normal)
            u /= np.linalg.norm(u)
            v = np.cross(normal, u)
            mesh = shapes.quad_mesh(area.center, u * area.size[0] / 2, v * area.size[1] / 2)
        else:
            mesh = shapes.disk_mesh(area.center, normal, area.radius)
        name = f"area_light_{i}"
        meshes.append((name, mesh))
        emitters.append(
            Shape(
                name=name,
                mesh=f"meshes/{name}.ply",
                kind="diffuse",
                albedo=(0.0, 0.0, 0.0),
                emission=area.radiance,
            )
        )
    for p in cfg.pulse_lights:
        light: dict[str, Any] = {
            "type": p.kind,
            "position": list(p.position),
            "intensity": list(p.intensity),
            "medium": p.medium,
        }
        if p.kind == "spot":
            light.update(
                direction=list(p.direction), cutoff_angle_deg=p.cutoff_angle_deg, beam_width_deg=p.beam_width_deg
            )
        lights.append(light)
    return lights, emitters, meshes


def direct_arrivals(
    camera: Camera,
    lights: list[dict],
    meshes: list[tuple[np.ndarray, np.ndarray]],
    emitter_centres: list[np.ndarray],
    max_rays: int = 16384,
    offsets: list[np.ndarray | None] | None = None,
    shadows: bool = False,
) -> np.ndarray:
    """OPL of single-scattered light at the surfaces the camera sees, light -> surface point -> pinhole,
    on a grid over the film (its edges included: jittered rays reach the pixel corners).

    Returns (lights with a time origin, rows, columns), NaN where the camera sees no surface; the sun,
    point and spot lights come first in scene order, then the emitting shapes. ``offsets[i]``, when given,
    places mesh i at each of its translations (instanced copies). With ``shadows``, also NaN where the light
    does not reach the point directly: the side the camera sees faces away from it, or a mesh lies between
    (a spot light's cone is not applied)."""
    from render.engine import RayEngine

    engine = RayEngine()
    for i, (v, f) in enumerate(meshes):
        engine.add_mesh(np.asarray(v, np.float32), np.asarray(f, np.uint32), i, offsets[i] if offsets else None)
    engine.commit()
    step = max(1.0, math.sqrt(camera.width * camera.height / max_rays))
    px, py = np.meshgrid(
        np.linspace(0, camera.width, int(camera.width / step) + 1),
        np.linspace(0, camera.height, int(camera.height / step) + 1),
    )
    directions = camera_ray_direction(camera, px.ravel(), py.ravel()).reshape(-1, 3)
    origins = np.broadcast_to(np.asarray(camera.origin), directions.shape)
    hits = engine.intersect(origins, directions)
    camera_leg = np.where(hits.hit, hits.t, np.nan).astype(np.float64)
    points = origins + np.nan_to_num(camera_leg)[:, None] * directions
    # The normal on the side the camera sees, and shadow rays leaving from just off that side (float32 rays: an
    # offset relative to the point's distance from the origin).
    normal = np.where((np.sum(hits.normal * directions, axis=1) > 0)[:, None], -hits.normal, hits.normal)
    starts = points + 1e-5 * (1.0 + np.linalg.norm(points, axis=1))[:, None] * normal

    def reached(towards: np.ndarray, whole_way: bool) -> np.ndarray:
        """Whether each point sees the light in direction ``towards`` (to it, when ``whole_way``: a position)."""
        if not shadows:
            return np.ones(len(points), bool)
        towards = np.broadcast_to(towards, points.shape)
        blocked = engine.occluded(starts, towards, tfar=1.0 - 1e-6 if whole_way else None)
        return (np.sum(normal * towards, axis=1) > 0) & ~blocked

    taus = []
    for light in lights:
        if light["type"] == "sun":
            s, p0 = np.asarray(light["to_sun"]), np.asarray(light["tau_origin_point"])
            taus.append(np.where(reached(s, False), (p0 - points) @ s + camera_leg, np.nan))
        elif light["type"] in ("point", "spot"):
            position = np.asarray(light["position"])
            distance = np.linalg.norm(points - position, axis=1) + camera_leg
            taus.append(np.where(reached(position - starts, True), distance, np.nan))
    for c in emitter_centres:
        distance = np.linalg.norm(points - c, axis=1) + camera_leg
        taus.append(np.where(reached(c - starts, True), distance, np.nan))
    return np.stack(taus).reshape(len(taus), *px.shape) if taus else np.zeros((0, *px.shape))


def fit_window(film: FilmConfig, arrivals: np.ndarray) -> Film:
    """The scene's film; an auto window spans the direct arrivals plus the tail, 2 % early margin."""
    if film.window == "manual" or film.mode == "steady":
        start, width = film.start_opl, film.bin_width_opl
    else:
        if not np.any(np.isfinite(arrivals)):
            raise ValueError(
                "scene.film.window is auto, but the camera sees no lit surface; aim the camera "
                "(scene.camera) or set scene.film.window: manual with start_opl and bin_width_opl"
            )
        earliest, latest = float(np.nanmin(arrivals)), float(np.nanmax(arrivals)) + film.window_tail_opl
        start = earliest - 0.02 * (latest - earliest)
        width = (latest - start) / film.temporal_bins
    return Film(
        mode=film.mode,
        temporal_bins=film.temporal_bins if film.mode == "transient" else 1,
        start_opl=float(start),
        bin_width_opl=float(width),
    )


# ---------------------------------------------------------------- the stage


def build_scene(
    cfg: SceneConfig, out_dir: Path, *, geometry_dir: Path | None = None, site: dict | None = None
) -> tuple[Scene, dict[str, optics_mod.MediumOptics]]:
    """Write meshes under ``out_dir/meshes``; return the resolved scene (not yet saved) and its media.

    ``site`` = {"latitude": deg, "day_of_year": day} feeds ``scene.sun.solar_time_h``.
    """
    out_dir = Path(out_dir)
    penitentes = None
    if any(o.shape == "penitentes" for o in cfg.objects):
        path = Path(geometry_dir or "") / PENITENTE_MESH
        if geometry_dir is None or not path.is_file():
            raise FileNotFoundError(
                f"{path}: the scene has a penitentes object but the geometry stage's mesh is "
                "missing; run the geometry stage first"
            )
        penitentes = read_mesh(path)
    media = {key: medium_optics(m, key) for key, m in cfg.media.items()}
    meshes: list[tuple[str, tuple[np.ndarray, np.ndarray]]] = []
    offsets: list[np.ndarray | None] = []
    scene_shapes: list[Shape] = []
    extents: list[np.ndarray] = []  # points whose box bounds the scene, copies included
    for obj in cfg.objects:
        vertices, faces = _object_mesh(obj, penitentes)
        _check_mesh(obj.name, vertices, faces)
        pieces: list[tuple[str, Mesh, np.ndarray | None]] = [(obj.name, (vertices, faces), None)]
        if obj.tiles > 1:
            # The grown tile's surface placed tiles x tiles times as instances, closed by one set of walls.
            sheet, copies, closure = _tiled_field(obj, Path(geometry_dir or ""), float(np.min(vertices[:, 2])))
            pieces = [(obj.name, sheet, copies), (f"{obj.name}_walls", closure, None)]
        for name, piece, where in pieces:
            meshes.append((name, piece))
            offsets.append(where)
            placed = None if where is None else where.tolist()
            extents.append(piece[0])
            if obj.medium is not None:
                kind = media[obj.medium].boundary
                scene_shapes.append(Shape(name, f"meshes/{name}.ply", kind, interior=obj.medium, offsets=placed))
            else:
                scene_shapes.append(
                    Shape(name, f"meshes/{name}.ply", "diffuse", albedo=obj.reflectance, offsets=placed)
                )
    all_points = np.concatenate(extents)
    centre, radius = bounding_sphere_of_points(all_points)
    if cfg.camera.placement == "look_at":
        camera = Camera(
            cfg.camera.origin,
            cfg.camera.target,
            cfg.camera.up,
            cfg.camera.fov,
            cfg.camera.width,
            cfg.camera.height,
            cfg.camera.fov_axis,
            cfg.camera.medium,
        )
    else:
        framed = penitentes[0] if penitentes is not None else all_points
        lo, hi = framed.min(0), framed.max(0)
        if penitentes is not None:
            lo[2] = min(float(np.percentile(framed[:, 2], 5)), 0.0)  # frame the blades, not the base slab
        target = 0.5 * (lo + hi)
        camera = frame_camera(cfg.camera, target, float(np.linalg.norm(hi - target)))
    lights, emitters, light_meshes = _lights(cfg, site, centre, radius)
    # The bounding sphere (and so the sun's tau origin) is that of all geometry, light shapes included.
    if light_meshes:
        centre, radius = bounding_sphere_of_points(np.concatenate([all_points] + [m[1][0] for m in light_meshes]))
        for light in lights:
            if light["type"] == "sun":
                light["tau_origin_point"] = [
                    float(v)
                    for v in sun_tau_origin(np.asarray(light["to_sun"]), centre, radius, light["reference_point"])
                ]
    arrivals = direct_arrivals(
        camera,
        lights,
        [m[1] for m in meshes],
        [np.asarray(m[1][0], np.float64).mean(0) for m in light_meshes],
        offsets=offsets,
    )
    film = fit_window(cfg.film, arrivals)
    if arrivals.shape[0] and np.any(np.isfinite(arrivals)):
        from render.scene.figures import arrival_map

        first = np.nanmin(np.where(np.isfinite(arrivals), arrivals, np.inf), axis=0)
        arrival_map(
            np.where(np.isfinite(first), first, np.nan),
            out_dir / "first_arrival.png",
            "earliest direct light, light -> surface -> camera",
        )
    (out_dir / "meshes").mkdir(parents=True, exist_ok=True)
    for name, (v, f) in meshes + light_meshes:
        write_ply(out_dir / "meshes" / f"{name}.ply", v, f, comment=f"{name}: metres, x east, y north, z up")
    notes = [f"{key}: {m.source}; form {m.form}; boundary {m.boundary}" for key, m in media.items()]
    scene = Scene(
        camera=camera,
        film=film,
        media={k: scene_medium(m) for k, m in media.items()},
        shapes=scene_shapes + emitters,
        lights=lights,
        max_depth=cfg.max_depth,
        bounding_sphere={"center": [float(v) for v in centre], "radius": radius},
        notes=notes,
    )
    return scene, media


__all__ = [
    "medium_optics",
    "scene_medium",
    "frame_camera",
    "site_sun_direction",
    "direct_arrivals",
    "fit_window",
    "build_scene",
]
