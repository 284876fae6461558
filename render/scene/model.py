"""The neutral scene description: one ``scene.json`` that both our renderer and Mitsuba read.

Everything is explicit and resolved: metres, z up, x east, y north; media hold per-RGB sigma_s,
sigma_a (m-1), HG g and the region index n; lights hold Mitsuba-unit quantities; meshes are PLY
files referenced relative to the folder of scene.json (or absolute). Nothing here depends on a
renderer. Schema (``version`` 1)::

    camera:   origin, target, up [m]; fov [deg] along fov_axis (x|y|diagonal|smaller|larger);
              width, height [px]; medium (id or null). Pixel (i, j), i right, j down, row 0 at the
              top, is the square [i, i+1) x [j, j+1); see ``camera_ray_direction`` for the exact map.
    film:     mode steady|transient, temporal_bins, start_opl [m], bin_width_opl [m], frame_mode bins|gate.
    integrator: max_depth (Mitsuba's meaning, -1 unbounded), rr_depth.
    media:    {id: {sigma_s[3], sigma_a[3] [m-1], g (scalar used by renderers), g_rgb[3],
               ior (region index: refraction and OPL; 1 for null boundaries), material_ior_rgb[3],
               boundary null|dielectric, form, name, source}}
    shapes:   [{name, mesh (PLY path), kind null|dielectric|diffuse, interior (medium id or null),
               albedo[3] (diffuse), emission[3] (one-sided radiance along the outward normal, W m-2 sr-1,
               or null), offsets (K x 3 translations in m: the mesh stands at each, as instances; or null)}].
               Closed meshes, counter-clockwise seen from outside (instanced copies close with the other
               shapes of their medium); all sit in air (n = 1).
    lights:   [{type: sun, model directional|disk, to_sun[3], irradiance[3] W m-2 (on a plane facing
               the sun), angular_diameter_deg, tau_origin_point[3] (tau = 0 plane through it, normal
               to_sun), reference_point (config pin or null)},
               {type: sky, radiance[3] W m-2 sr-1 (steady only)},
               {type: point, position, intensity[3] W sr-1, medium},
               {type: spot, position, direction, intensity[3], cutoff_angle_deg, beam_width_deg, medium}]
    bounding_sphere: {center, radius} of the axis-aligned box of all shape vertices (Mitsuba's rule).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from common.atomic import write_json_atomic

SCENE_FORMAT = "penitentes-scene"
SCENE_VERSION = 1

Vec3 = tuple[float, float, float]


def as_vec3(x) -> Vec3:
    """Three numbers (a list, tuple or array of 3) as a triple of Python floats."""
    px, py, pz = np.asarray(x, dtype=np.float64).reshape(3)
    return float(px), float(py), float(pz)


@dataclass
class Camera:
    origin: Vec3
    target: Vec3
    up: Vec3
    fov: float  # degrees along fov_axis
    width: int
    height: int
    fov_axis: str = "x"
    medium: str | None = None


@dataclass
class Film:
    mode: Literal["steady", "transient"] = "steady"
    temporal_bins: int = 1
    start_opl: float = 0.0  # m
    bin_width_opl: float = 0.003  # m
    frame_mode: Literal["bins", "gate"] = "bins"


@dataclass
class Medium:
    sigma_s: Vec3  # m-1
    sigma_a: Vec3  # m-1
    g: float  # HG mean cosine a renderer uses
    ior: float  # region index (refraction and OPL); 1 inside null boundaries
    boundary: Literal["null", "dielectric"]
    g_rgb: Vec3 = (0.0, 0.0, 0.0)
    material_ior_rgb: Vec3 = (1.0, 1.0, 1.0)
    form: str = "full"
    name: str = ""
    source: str = ""

    @property
    def sigma_t(self) -> np.ndarray:
        return np.asarray(self.sigma_s) + np.asarray(self.sigma_a)


@dataclass
class Shape:
    name: str
    mesh: str  # PLY path, relative to the scene folder or absolute
    kind: Literal["null", "dielectric", "diffuse"]
    interior: str | None = None
    albedo: Vec3 | None = None
    emission: Vec3 | None = None
    # Translations [m] at which the mesh stands, each a copy traced as an instance of one (render/core/DESIGN.md
    # §13); None: once, where its vertices are.
    offsets: list[list[float]] | None = None


@dataclass
class Scene:
    camera: Camera
    film: Film
    media: dict[str, Medium] = field(default_factory=dict)
    shapes: list[Shape] = field(default_factory=list)
    lights: list[dict[str, Any]] = field(default_factory=list)
    max_depth: int = -1
    rr_depth: int = 5
    bounding_sphere: dict[str, Any] | None = None
    notes: list[str] = field(default_factory=list)

    # ---- serialisation

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": SCENE_FORMAT,
            "version": SCENE_VERSION,
            "units": "metres, z up, x east, y north; sigma in 1/m; radiance W m-2 sr-1; irradiance W m-2; "
            "intensity W sr-1; time = optical path length in metres",
            "camera": asdict(self.camera),
            "film": asdict(self.film),
            "integrator": {"max_depth": self.max_depth, "rr_depth": self.rr_depth},
            "media": {k: asdict(m) for k, m in self.media.items()},
            "shapes": [asdict(s) for s in self.shapes],
            "lights": self.lights,
            "bounding_sphere": self.bounding_sphere,
            "notes": self.notes,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Scene:
        if data.get("format") != SCENE_FORMAT or data.get("version") != SCENE_VERSION:
            raise ValueError(
                f"not a {SCENE_FORMAT} v{SCENE_VERSION} document "
                f"(format={data.get('format')!r}, version={data.get('version')!r})"
            )
        camera = Camera(**{**data["camera"], **{k: as_vec3(data["camera"][k]) for k in ("origin", "target", "up")}})
        media = {
            k: Medium(**{**m, **{q: as_vec3(m[q]) for q in ("sigma_s", "sigma_a", "g_rgb", "material_ior_rgb")}})
            for k, m in data["media"].items()
        }
        shapes = [
            Shape(
                **{
                    **s,
                    "albedo": as_vec3(s["albedo"]) if s.get("albedo") is not None else None,
                    "emission": as_vec3(s["emission"]) if s.get("emission") is not None else None,
                }
            )
            for s in data["shapes"]
        ]
        return cls(
            camera=camera,
            film=Film(**data["film"]),
            media=media,
            shapes=shapes,
            lights=list(data["lights"]),
            max_depth=int(data["integrator"]["max_depth"]),
            rr_depth=int(data["integrator"]["rr_depth"]),
            bounding_sphere=data.get("bounding_sphere"),
            notes=list(data.get("notes", [])),
        )

    def save(self, path: str | os.PathLike[str]) -> Path:
        return write_json_atomic(path, self.to_dict())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Scene:
        return cls.from_dict(json.loads(Path(path).read_text(encoding="utf-8")))

    # ---- queries

    def mesh_path(self, shape: Shape, scene_dir: str | os.PathLike[str]) -> Path:
        p = Path(shape.mesh)
        return p if p.is_absolute() else Path(scene_dir) / p

    def lights_of(self, kind: str) -> list[dict[str, Any]]:
        return [light for light in self.lights if light["type"] == kind]


# ---------------------------------------------------------------- geometry helpers


def sun_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """Unit vector towards the sun; azimuth clockwise from north (y), so 90 deg is east (x)."""
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.cos(e) * math.sin(a), math.cos(e) * math.cos(a), math.sin(e)])


def bounding_sphere_of_points(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius of the sphere around the axis-aligned box of ``points`` (Mitsuba's bsphere)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lo, hi = pts.min(0), pts.max(0)
    centre = 0.5 * (lo + hi)
    return centre, float(np.linalg.norm(hi - centre))


def sun_tau_origin(to_sun: np.ndarray, centre: np.ndarray, radius: float, reference_point=None) -> np.ndarray:
    """A point of the tau = 0 plane: P0 = C + R_s s, or the pinned reference point (render/core/DESIGN.md §1)."""
    if reference_point is not None:
        return np.asarray(reference_point, dtype=np.float64)
    return np.asarray(centre, dtype=np.float64) + radius * np.asarray(to_sun, dtype=np.float64)


def _camera_frame(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    origin, target, up = (np.asarray(v, dtype=np.float64) for v in (camera.origin, camera.target, camera.up))
    forward = target - origin
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    norm = np.linalg.norm(right)
    if norm < 1e-9:
        raise ValueError("camera.up is parallel to the viewing direction; choose another up vector")
    right /= norm
    true_up = np.cross(right, forward)
    return forward, right, true_up


def tan_half_fov(camera: Camera) -> tuple[float, float]:
    """tan of the half field of view along x and y, with Mitsuba's fov_axis rule."""
    w, h = camera.width, camera.height
    t = math.tan(math.radians(camera.fov) / 2)
    axis = camera.fov_axis
    if axis == "smaller":
        axis = "x" if w <= h else "y"
    elif axis == "larger":
        axis = "x" if w >= h else "y"
    aspect = w / h
    if axis == "x":
        tx = t
    elif axis == "y":
        tx = t * aspect
    elif axis == "diagonal":
        tx = t * aspect / math.sqrt(1 + aspect * aspect)
    else:
        raise ValueError(f"camera.fov_axis must be x, y, diagonal, smaller or larger, got {camera.fov_axis!r}")
    return tx, tx / aspect


def camera_ray_direction(camera: Camera, px, py) -> np.ndarray:
    """Unit world direction through film position (px, py) in pixels: px in [0, W) to the right,
    py in [0, H) downwards; pixel centres are at (i + 0.5, j + 0.5). Matches Mitsuba's perspective."""
    forward, right, up = _camera_frame(camera)
    tx, ty = tan_half_fov(camera)
    sx = (2.0 * np.asarray(px, dtype=np.float64) / camera.width - 1.0) * tx
    sy = (1.0 - 2.0 * np.asarray(py, dtype=np.float64) / camera.height) * ty
    d = forward + sx[..., None] * right + sy[..., None] * up
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def project_to_pixel(camera: Camera, point) -> np.ndarray:
    """Film position (px, py) of a world point in front of the camera (inverse of camera_ray_direction)."""
    forward, right, up = _camera_frame(camera)
    tx, ty = tan_half_fov(camera)
    d = np.asarray(point, dtype=np.float64) - np.asarray(camera.origin, dtype=np.float64)
    depth = d @ forward
    if np.any(depth <= 0):
        raise ValueError("point lies behind the camera")
    sx, sy = (d @ right) / depth / tx, (d @ up) / depth / ty
    return np.stack([(sx + 1.0) * 0.5 * camera.width, (1.0 - sy) * 0.5 * camera.height], axis=-1)


def pixel_footprint(camera: Camera, distance: float) -> float:
    """Width of one pixel at ``distance`` along the axis [m]."""
    return 2.0 * distance * tan_half_fov(camera)[0] / camera.width


# ---------------------------------------------------------------- the PTPB core's dict (render/ptpb/api.py)


def to_ptpb_core(scene: Scene) -> tuple[dict[str, Any], list[str], list[str]]:
    """Translate to the core dict of render/ptpb/api.py, with meshes named by ``mesh`` (relative to the
    scene folder). Returns the dict, the things it had to leave out (lights the core does not support),
    and the ones it renders approximately by design (a disk sun as a directional one)."""
    ids = list(scene.media)
    index = {k: i for i, k in enumerate(ids)}
    omitted: list[str] = []
    approximated: list[str] = []
    shapes = []
    for s in scene.shapes:
        shapes.append(
            {
                "mesh": s.mesh,
                "kind": s.kind,
                "interior": index[s.interior] if s.interior else -1,
                "exterior": -1,
                "albedo": list(s.albedo) if s.albedo is not None else [0.0, 0.0, 0.0],
                "radiance": list(s.emission) if s.emission is not None else [0.0, 0.0, 0.0],
                **({"offsets": [list(map(float, o)) for o in s.offsets]} if s.offsets else {}),
            }
        )
    core: dict[str, Any] = {
        "media": [
            {"sigma_s": list(m.sigma_s), "sigma_a": list(m.sigma_a), "g": m.g, "ior": m.ior}
            for m in scene.media.values()
        ],
        "shapes": shapes,
        "point_lights": [],
        "directional_lights": [],
        "environment_radiance": [0.0, 0.0, 0.0],
        "ambient_ior": 1.0,
        "camera": {**asdict(scene.camera), "medium": index[scene.camera.medium] if scene.camera.medium else -1},
        "film": {
            "frame_mode": "steady" if scene.film.mode == "steady" else scene.film.frame_mode,
            "temporal_bins": scene.film.temporal_bins,
            "start_opl": scene.film.start_opl,
            "bin_width_opl": scene.film.bin_width_opl,
        },
    }
    for light in scene.lights:
        if light["type"] == "sun":
            if light["model"] == "disk":
                approximated.append(
                    f"sun angular size {light['angular_diameter_deg']} deg (PTPB uses a directional sun)"
                )
            core["directional_lights"].append(
                {
                    "to_sun": light["to_sun"],
                    "irradiance": light["irradiance"],
                    "reference_point": light.get("reference_point"),
                }
            )
        elif light["type"] == "sky":
            core["environment_radiance"] = list(light["radiance"])
            # z is up in the neutral scene: next-event estimation samples the sky above the horizon.
            core["environment_up"] = [0.0, 0.0, 1.0]
        elif light["type"] == "point":
            core["point_lights"].append(
                {
                    "position": light["position"],
                    "intensity": light["intensity"],
                    "medium": index[light["medium"]] if light.get("medium") else -1,
                }
            )
        else:
            omitted.append(f"{light['type']} light (not supported by the PTPB core)")
    return core, omitted, approximated


__all__ = [
    "Camera",
    "Film",
    "Medium",
    "Shape",
    "Scene",
    "as_vec3",
    "sun_direction",
    "bounding_sphere_of_points",
    "sun_tau_origin",
    "camera_ray_direction",
    "project_to_pixel",
    "tan_half_fov",
    "pixel_footprint",
    "to_ptpb_core",
    "SCENE_FORMAT",
    "SCENE_VERSION",
]
