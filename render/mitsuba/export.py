"""The neutral scene (render/scene/model.py) as a Mitsuba 3 / mitransient scene dict, and the limits of the reference.

Conventions, on top of render/scene/model.py and render/core/DESIGN.md §1-§2:

- Steady images are ``volpath``; transient ones ``transient_prbvolpath`` with ``camera_unwarp: False``,
  so τ includes the camera leg. Frames are bins (``transient_hdr_film``): W m-2 sr-1 per bin, returned
  as (T, H, W, 3) float32 C-contiguous (mitransient's own array is (H, W, T, C), render/core/DESIGN.md §2).
- Inside null boundaries mitransient moves at c (OPL = geometric length); only a dielectric BSDF
  changes its η.
- Media: Mitsuba's ``rgb`` spectra must lie in [0, 1], so sigma_t is passed as sigma_t / max(sigma_t)
  with ``scale`` = max(sigma_t); albedo = sigma_s / sigma_t (0 where sigma_t = 0).
- The disk sun is a one-sided ``disk`` area emitter at ``disk_distance_radii`` bounding radii from the
  bounding-sphere centre C towards the sun, of angular radius α = angular_diameter / 2 seen from C and
  radiance E / (π sin²α), so a plane at C facing the sun receives E. Its light leaves the disk at
  τ = 0, so in transient renders the film window is moved later by the OPL from the ptpb τ = 0
  plane to the disk plus the disk's mean excess path (``disk_sun_opl_shift``; when it is the only timed
  emitter), and frames stay on the ptpb time axis.
- Rendering goes in passes of ``spp_per_pass``, and optionally in tiles (``Tile``); each pass of each tile
  renders with its own seed, drawn from (seed, tile, pass) by ``pass_seed``, so that runs of different seeds
  share no samples.
- Mitsuba starts every ray that leaves a surface (1 + max|p|) · 9·10⁻⁵ scene units off it, single precision.
  A camera path that enters index-matched snow therefore starts below the face and sees the brighter radiance
  there: +1.3 % on the default sweep's firn point (render/core/DESIGN.md §12). A ``Tile`` renders a crop of the
  film with the scene in millimetres and moved so that the middle of what the tile sees lies at the origin,
  which shrinks that skip to the tile's own extent.
"""

from __future__ import annotations

import importlib
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from geometry.meshio import read_mesh
from render.scene.model import Scene, bounding_sphere_of_points, camera_ray_direction

log = logging.getLogger(__name__)

DEFAULT_DISK_DISTANCE_RADII = 1000.0
TRANSIENT_SEED_OFFSET = 1 << 16  # keeps the transient reference's noise independent of the steady one
TILE_UNITS = 1000.0  # scene units per metre in a tile: millimetres, so the offset's constant term is 1 µm


@dataclass(frozen=True)
class Tile:
    """A crop of the film [pixels] rendered with the scene point ``origin`` [m] moved to Mitsuba's origin."""

    x: int
    y: int
    width: int
    height: int
    origin: tuple[float, float, float]


def pass_seed(seed: int, tile: int, index: int) -> int:
    """Mitsuba's 32-bit seed of pass ``index`` of tile ``tile`` in a run of ``seed``: a hash, so that seeds
    s and s + 1 share no pass (seed + pass did) and cropped tiles, whose pixels Mitsuba numbers from 0, do
    not repeat each other's streams."""
    return int(np.random.SeedSequence([seed, tile, index]).generate_state(1)[0])


class ReferenceRefused(ValueError):
    """The scene is one that Mitsuba renders wrongly (not just noisily); the message says what to change."""


# ---------------------------------------------------------------- variants


def use_variant(preferred: str = "llvm_ad_rgb", *, transient: bool) -> str:
    """Set a Mitsuba variant and return its name; transient renders also import mitransient.

    Steady: ``preferred``, falling back to scalar_rgb with a warning. Transient: llvm_ad_rgb or an error,
    because mitransient registers its plugins only under llvm/cuda variants."""
    import mitsuba as mi

    wanted = "llvm_ad_rgb" if transient else preferred
    try:
        mi.set_variant(wanted)
    except Exception as err:  # noqa: BLE001 - Mitsuba raises several types when a JIT backend is missing
        if transient:
            raise RuntimeError(
                f"the transient reference needs Mitsuba's llvm_ad_rgb variant (mitransient registers its plugins "
                f"only under llvm/cuda variants), but it cannot be set: {err}. Install libllvm19 or point "
                "DRJIT_LIBLLVM_PATH at a recent libLLVM, or set reference.transient: false"
            ) from err
        if wanted == "scalar_rgb":
            raise
        log.warning(
            "Mitsuba variant %s is unavailable (%s); rendering the steady reference with scalar_rgb", wanted, err
        )
        mi.set_variant("scalar_rgb")
    if transient:
        importlib.import_module("mitransient")
    return str(mi.variant())


# ---------------------------------------------------------------- scene export


def _bounding_sphere(scene: Scene, scene_dir: Path) -> tuple[np.ndarray, float]:
    if scene.bounding_sphere is not None:
        return np.asarray(scene.bounding_sphere["center"], np.float64), float(scene.bounding_sphere["radius"])
    points = [
        (v[None] + np.asarray(s.offsets or [[0.0, 0.0, 0.0]])[:, None]).reshape(-1, 3)
        for s in scene.shapes
        for v in [read_mesh(scene.mesh_path(s, scene_dir))[0]]
    ]
    if not points:
        return np.zeros(3), 1.0
    return bounding_sphere_of_points(np.concatenate(points))


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _any_up(direction: np.ndarray) -> list[float]:
    return [0.0, 0.0, 1.0] if abs(direction[2]) < 0.9 else [0.0, 1.0, 0.0]


def disk_sun(light: dict[str, Any], centre: np.ndarray, radius: float) -> dict[str, Any]:
    """Geometry of the disk sun: centre, unit normal (towards the scene), disk radius, distance, radiance."""
    s = _unit(light["to_sun"])
    distance = float(light.get("disk_distance_radii") or DEFAULT_DISK_DISTANCE_RADII) * radius
    alpha = math.radians(float(light["angular_diameter_deg"])) / 2
    # Projected solid angle π sin²α (not 2π(1 - cos α)): a plane at C facing the sun then gets exactly E.
    radiance = np.asarray(light["irradiance"], np.float64) / (math.pi * math.sin(alpha) ** 2)
    return {
        "center": centre + distance * s,
        "normal": -s,
        "radius": distance * math.tan(alpha),
        "distance": distance,
        "radiance": radiance,
    }


def _timed_emitters(scene: Scene) -> list[str]:
    names = [light["type"] for light in scene.lights if light["type"] in ("point", "spot")]
    return names + [s.name for s in scene.shapes if s.emission is not None and max(s.emission) > 0]


def disk_sun_opl_shift(scene: Scene, scene_dir: Path) -> float:
    """OPL [m] by which mitransient's film window is moved for a disk sun (0 when not applied): from the
    ptpb τ = 0 plane (through tau_origin_point, normal to_sun) to the emitting disk, plus the disk's mean
    excess path.

    Light from a disk point q reaches a point p after |q - p| ≈ (D - p·s) + |q⊥ - p⊥|² / 2D (D the disk's
    distance, ⊥ across s). The cross term -q⊥·p⊥ / D is the real sun's spread of directions and averages to
    zero; |q⊥|² / 2D is an artefact of the disk's finite distance, a delay of ρ²/4D = D tan²α / 4 on average
    over the disk's area (radius ρ = D tan α): 4.6 cm on the demo's field (R = 8.7 m), which had put 35 % more
    energy in our first frame of the dense benchmark's demo row than in the reference's. The window is moved
    by that mean too, so that the reference's frames are centred on the plane-wave time axis of ptpb
    (render/core/DESIGN.md §1). The remaining curvature term |p⊥|² / 2D is at most R / 2000 at the default
    distance of 1000 R."""
    suns = _suns(scene, "disk")
    if not suns or _timed_emitters(scene):
        return 0.0
    light = suns[0]
    centre, radius = _bounding_sphere(scene, scene_dir)
    s = _unit(light["to_sun"])
    origin = np.asarray(light.get("tau_origin_point") or centre + radius * s, np.float64)
    disk = disk_sun(light, centre, radius)
    mean_excess = disk["radius"] ** 2 / (4.0 * disk["distance"])
    return float((disk["center"] - origin) @ s) + mean_excess


def plan_tiles(scene: Scene, scene_dir: Path, tiles: int) -> list[Tile]:
    """The film cut into square tiles, ``tiles`` of them along its longer side. Each tile's origin is the
    centre of the box around the points that its pixel centres see (the point that makes max|p| smallest
    there); a tile that sees nothing within the bounding sphere keeps the sphere's centre."""
    from render.engine import RayEngine

    if tiles < 1:
        raise ValueError(f"tiles must be at least 1, got {tiles}")
    scene_dir = Path(scene_dir)
    cam = scene.camera
    centre, radius = _bounding_sphere(scene, scene_dir)
    engine = RayEngine()
    for i, shape in enumerate(scene.shapes):
        vertices, faces = read_mesh(scene.mesh_path(shape, scene_dir))
        engine.add_mesh(np.asarray(vertices, np.float32), np.asarray(faces, np.uint32), i, shape.offsets)
    engine.commit()
    px, py = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    directions = camera_ray_direction(cam, px.ravel(), py.ravel()).reshape(-1, 3)
    origins = np.broadcast_to(np.asarray(cam.origin, np.float64), directions.shape)
    hits = engine.intersect(origins, directions)
    points = origins + np.where(hits.hit, hits.t, 0.0)[:, None] * directions
    seen = hits.hit & (np.linalg.norm(points - centre, axis=1) <= 1.001 * radius)
    points, seen = points.reshape(cam.height, cam.width, 3), seen.reshape(cam.height, cam.width)
    size = math.ceil(max(cam.width, cam.height) / tiles)
    plan = []
    for y in range(0, cam.height, size):
        for x in range(0, cam.width, size):
            w, h = min(size, cam.width - x), min(size, cam.height - y)
            inside = points[y : y + h, x : x + w][seen[y : y + h, x : x + w]]
            origin = 0.5 * (inside.min(axis=0) + inside.max(axis=0)) if len(inside) else centre
            plan.append(Tile(x, y, w, h, (float(origin[0]), float(origin[1]), float(origin[2]))))
    return plan


def _rgb(value) -> dict[str, Any]:
    return {"type": "rgb", "value": [float(v) for v in value]}


def _medium_dict(medium, units: float = 1.0) -> dict[str, Any]:
    """``units`` scene units per metre: the coefficients are per scene unit."""
    sigma_s = np.asarray(medium.sigma_s, np.float64)
    sigma_t = sigma_s + np.asarray(medium.sigma_a, np.float64)
    albedo = np.divide(sigma_s, sigma_t, out=np.zeros(3), where=sigma_t > 0)
    scale = float(sigma_t.max()) if sigma_t.max() > 0 else 1.0
    return {
        "type": "homogeneous",
        "sigma_t": _rgb(sigma_t / scale),
        "scale": scale / units,
        "albedo": _rgb(np.clip(albedo, 0.0, 1.0)),
        "phase": {"type": "hg", "g": float(medium.g)},
    }


# Mitsuba starts camera rays near_clip / cos(theta) in front of the pinhole (default 1 cm), and
# mitransient's OPL counts from there: frames would arrive ~1 cm early. 0.1 mm keeps that below 1e-4 m.
NEAR_CLIP = 1e-4


def scene_to_mitsuba(
    scene: Scene, scene_dir: Path, *, transient: bool, spp: int, seed: int = 0, tile: Tile | None = None
) -> dict:
    """The ``mi.load_dict`` dictionary of ``scene`` (meshes resolved against ``scene_dir``); with ``tile``,
    of that crop of the film, in millimetres, with ``tile.origin`` at Mitsuba's origin (the same images).

    A variant must be set (``use_variant``); transient dicts need mitransient imported to load."""
    import mitsuba as mi

    if mi.variant() is None:
        use_variant(transient=transient)
    T = mi.ScalarTransform4f
    scene_dir = Path(scene_dir)
    cam, film = scene.camera, scene.film
    centre, radius = _bounding_sphere(scene, scene_dir)
    units = TILE_UNITS if tile is not None else 1.0
    frame = T().scale(units) @ T().translate([-float(v) for v in tile.origin]) if tile is not None else T()

    def place(point) -> list[float]:
        return [float(v) for v in frame @ mi.ScalarPoint3f([float(v) for v in point])]

    out: dict[str, Any] = {"type": "scene"}

    if transient:
        out["integrator"] = {
            "type": "transient_prbvolpath",
            "camera_unwarp": False,
            "max_depth": scene.max_depth,
            "rr_depth": scene.rr_depth,
        }
        film_dict = {
            "type": "transient_hdr_film",
            "width": cam.width,
            "height": cam.height,
            "temporal_bins": film.temporal_bins,
            "bin_width_opl": film.bin_width_opl * units,
            "start_opl": (film.start_opl + disk_sun_opl_shift(scene, scene_dir)) * units,
            "rfilter": {"type": "box"},
        }
    else:
        out["integrator"] = {"type": "volpath", "max_depth": scene.max_depth, "rr_depth": scene.rr_depth}
        film_dict = {
            "type": "hdrfilm",
            "width": cam.width,
            "height": cam.height,
            "rfilter": {"type": "box"},
            "pixel_format": "rgb",
        }

    if tile is not None:
        film_dict.update(crop_offset_x=tile.x, crop_offset_y=tile.y, crop_width=tile.width, crop_height=tile.height)
    for key, medium in scene.media.items():  # declared first so that shapes and the camera can refer to them
        out[f"medium_{key}"] = _medium_dict(medium, units)

    def ref(key: str) -> dict[str, str]:
        if key not in scene.media:
            raise ValueError(f"medium '{key}' is not defined in scene.media ({', '.join(scene.media) or 'none'})")
        return {"type": "ref", "id": f"medium_{key}"}

    far = 1e4  # Mitsuba's default far clip, widened so that the camera can see a far disk sun
    for light in scene.lights:
        if light["type"] == "sun" and light["model"] == "disk":
            reach = np.linalg.norm(np.asarray(cam.origin) - centre) + disk_sun(light, centre, radius)["distance"]
            far = max(far, 2.0 * reach)
    sensor = {
        "type": "perspective",
        "fov": float(cam.fov),
        "fov_axis": cam.fov_axis,
        "far_clip": float(far) * units,
        "near_clip": NEAR_CLIP * units,
        "to_world": T().look_at(origin=place(cam.origin), target=place(cam.target), up=list(cam.up)),
        "film": film_dict,
        "sampler": {"type": "independent", "sample_count": int(spp), "seed": int(seed)},
    }
    if cam.medium:
        sensor["medium"] = ref(cam.medium)
    out["sensor"] = sensor

    for i, shape in enumerate(scene.shapes):
        d: dict[str, Any] = {
            "type": "ply",
            "filename": str(Path(scene.mesh_path(shape, scene_dir)).resolve()),
            "face_normals": True,
        }
        if tile is not None:
            d["to_world"] = frame
        if shape.kind == "null":
            d["bsdf"] = {"type": "null"}
        elif shape.kind == "dielectric":
            if not shape.interior:
                raise ValueError(f"shape '{shape.name}' is dielectric but has no interior medium to give its ior")
            d["bsdf"] = {"type": "dielectric", "int_ior": float(scene.media[shape.interior].ior), "ext_ior": 1.0}
        elif shape.kind == "diffuse":
            if shape.albedo is None:
                raise ValueError(f"shape '{shape.name}' is diffuse but has no albedo")
            d["bsdf"] = {"type": "diffuse", "reflectance": _rgb(shape.albedo)}
        else:
            raise ValueError(f"shape '{shape.name}': unknown kind {shape.kind!r} (null, dielectric or diffuse)")
        if shape.interior:
            d["interior"] = ref(shape.interior)
        if shape.emission is not None and max(shape.emission) > 0:
            d["emitter"] = {"type": "area", "radiance": _rgb(shape.emission)}
        if not shape.offsets:
            out[f"shape_{i}_{shape.name}"] = d
            continue
        # Copies of one mesh: a shapegroup placed by instances, so Mitsuba holds the mesh once too (media inside
        # instanced shapes render as inside the same shape placed by hand; render/core/DESIGN.md §13).
        group = {k: v for k, v in d.items() if k != "to_world"}
        out[f"group_{i}_{shape.name}"] = {"type": "shapegroup", "shape": group}
        for k, offset in enumerate(shape.offsets):
            move = T().translate([float(c) for c in offset])
            out[f"shape_{i}_{shape.name}_{k}"] = {
                "type": "instance",
                "shapegroup": {"type": "ref", "id": f"group_{i}_{shape.name}"},
                "to_world": frame @ move,
            }

    for i, light in enumerate(scene.lights):
        kind, key = light["type"], f"light_{i}_{light['type']}"
        if kind == "sun" and light["model"] == "directional":
            out[key] = {
                "type": "directional",
                "direction": [float(v) for v in -_unit(light["to_sun"])],
                "irradiance": _rgb(light["irradiance"]),
            }
        elif kind == "sun" and light["model"] == "disk":
            disk = disk_sun(light, centre, radius)
            disk_frame = T().look_at(
                origin=list(disk["center"]), target=list(disk["center"] + disk["normal"]), up=_any_up(disk["normal"])
            )  # the disk's local +z (its emitting side) faces the scene
            out[key] = {
                "type": "disk",
                "to_world": frame @ disk_frame @ T().scale([disk["radius"], disk["radius"], 1.0]),
                "bsdf": {"type": "diffuse", "reflectance": _rgb((0, 0, 0))},
                "emitter": {"type": "area", "radiance": _rgb(disk["radiance"])},
            }
        elif kind == "sun":
            raise ValueError(f"sun model {light['model']!r} is neither directional nor disk")
        elif kind == "sky":
            out[key] = {"type": "constant", "radiance": _rgb(light["radiance"])}
        elif kind == "point":
            out[key] = {
                "type": "point",
                "position": place(light["position"]),
                "intensity": _rgb(np.asarray(light["intensity"]) * units**2),  # W/sr: irradiance falls as 1/r²
            }
        elif kind == "spot":
            p, direction = np.asarray(light["position"], np.float64), _unit(light["direction"])
            out[key] = {
                "type": "spot",
                "intensity": _rgb(np.asarray(light["intensity"]) * units**2),
                "cutoff_angle": float(light["cutoff_angle_deg"]),
                "beam_width": float(light["beam_width_deg"]),
                "to_world": T().look_at(origin=place(p), target=place(p + direction), up=_any_up(direction)),
            }
        else:
            raise ValueError(f"unknown light type {kind!r}")
    return out


# ---------------------------------------------------------------- limits


def _suns(scene: Scene, model: str) -> list[dict[str, Any]]:
    return [light for light in scene.lights if light["type"] == "sun" and light["model"] == model]


def _delta_lights(scene: Scene) -> list[dict[str, Any]]:
    return [light for light in scene.lights if light["type"] in ("point", "spot")] + _suns(scene, "directional")


def check_reference_limits(scene: Scene, *, transient: bool, force: bool) -> list[str]:
    """Refuse scenes Mitsuba renders wrongly (unless ``force``); return warnings about what it leaves out."""
    warnings: list[str] = []
    sealed = [s for s in scene.shapes if s.kind == "dielectric" and s.interior]
    # A point or spot light inside the very medium a dielectric encloses is reached without crossing it.
    blocked = sorted(
        {
            light["type"] if light["type"] != "sun" else "directional sun"
            for light in _delta_lights(scene)
            for s in sealed
            if light.get("medium") != s.interior
        }
    )
    if blocked:
        ids = sorted({s.interior for s in sealed if s.interior is not None})
        message = (
            f"the {' and '.join(blocked)} light(s) reach the media {', '.join(ids)} only through a smooth "
            f"dielectric boundary (shapes {', '.join(s.name for s in sealed)}): Mitsuba's next-event estimation "
            "is blocked by the specular interface and BSDF sampling never hits a delta light, so the medium "
            "renders black. Use a finite sun "
            "(scene.sun.kind: disk), an index-matched boundary ("
            + ", ".join(f"scene.media.{k}.boundary: null" for k in ids)
            + "), or set reference.force: true to render it anyway"
        )
        if not force:
            raise ReferenceRefused(message)
        warnings.append("forced: " + message)
    if sealed and _suns(scene, "disk"):
        warnings.append(
            "the disk sun reaches media inside dielectric boundaries only through BSDF sampling "
            "(next-event estimation is blocked by the specular interface): expect heavy noise there"
        )
    if transient:
        sky = [light for light in scene.lights if light["type"] == "sky" and max(light["radiance"]) > 0]
        if sky:
            warnings.append(
                "the constant sky is missing from mitransient's transient frames (its paths have no "
                "finite OPL); it is in the steady images only, so frames sum to less than the steady image"
            )
        if _suns(scene, "directional"):
            warnings.append(
                "mitransient's directional sun is not a plane wavefront: next-event estimation puts the "
                "sun 2 R_s behind every shading point, so direct-sun τ is 2 R_s plus the camera leg "
                "everywhere; do not compare sun timing with it (render/core/DESIGN.md §11)"
            )
        if _suns(scene, "disk") and _timed_emitters(scene):
            warnings.append(
                "the disk sun's light reaches the scene disk_distance_radii bounding radii later than "
                "the ptpb τ origin, and other timed emitters share the film, so the window is not "
                "shifted: the sun's light lies outside the frames"
            )
        if scene.camera.medium:
            warnings.append(
                f"mitransient ignores camera.medium '{scene.camera.medium}' (camera paths start in "
                "vacuum), so its transient reference leaves that medium out along every camera ray "
                "until the ray crosses a boundary: do not compare it"
            )
        if scene.film.frame_mode == "gate":
            warnings.append(
                "mitransient frames are bins (integrals over each bin); divide by bin_width_opl to "
                "compare with gate frames"
            )
    return warnings
