"""Settings of the scene stage (camera, lights, media, objects, film) and of the Mitsuba reference stage.

Conventions (render/core/DESIGN.md §1): metres, z up, x east, y north; time is optical path length (OPL) in metres;
light units are Mitsuba's (irradiance W m-2, radiance W m-2 sr-1, intensity W sr-1). Key paths are
scene.<field> and reference.<field>.
"""

from __future__ import annotations

import difflib
from typing import Annotated, Literal

from pydantic import BeforeValidator, Field, NonNegativeFloat, field_validator, model_validator

from common.paths import optics_preset_names
from pipeline.schema.base import StrictModel


def _broadcast_rgb(value):
    # One number means a grey triple.
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return (value, value, value)
    return value


RGB = Annotated[tuple[NonNegativeFloat, NonNegativeFloat, NonNegativeFloat], BeforeValidator(_broadcast_rgb)]
Vec3 = tuple[float, float, float]


class CameraConfig(StrictModel):
    """Pinhole perspective camera with Mitsuba's conventions (key path scene.camera.<field>)."""

    placement: Literal["look_at", "frame_objects"] = Field(
        "frame_objects",
        description="look_at: use origin/target as given; frame_objects: aim at the penitente mesh (or all objects) "
        "from view_azimuth_deg/view_elevation_deg at the distance that fits it in the frame [-].",
    )
    origin: Vec3 = Field((0.0, -5.0, 2.0), description="Pinhole position for placement look_at [m].")
    target: Vec3 = Field(
        (0.0, 0.0, 0.0), description="Point the optical axis passes through, for placement look_at [m]."
    )
    up: Vec3 = Field((0.0, 0.0, 1.0), description="World direction that appears up in the image [-].")
    view_azimuth_deg: float = Field(
        200.0,
        ge=-360,
        le=360,
        description="frame_objects: direction from the target to the camera, clockwise from north [deg].",
    )
    view_elevation_deg: float = Field(
        35.0, gt=-89, lt=89, description="frame_objects: elevation of the camera above the target [deg]."
    )
    frame_margin: float = Field(
        1.0, gt=0.2, le=5, description="frame_objects: distance factor; 1 fits the framed bounding sphere exactly [-]."
    )
    fov: float = Field(40.0, gt=0, lt=180, description="Field of view along fov_axis [deg].")
    fov_axis: Literal["x", "y", "diagonal", "smaller", "larger"] = Field(
        "x", description="Image axis the fov spans, as Mitsuba's perspective sensor [-]."
    )
    width: int = Field(96, ge=1, le=16384, description="Image width [px].")
    height: int = Field(64, ge=1, le=16384, description="Image height [px].")
    medium: str | None = Field(
        None, description="Medium id the pinhole sits in (a key of scene.media); null = air [-]."
    )


class SunConfig(StrictModel):
    """The sun (key path scene.sun.<field>)."""

    enabled: bool = Field(True, description="Include the sun [-].")
    kind: Literal["directional", "disk"] = Field(
        "disk",
        description="directional: a delta light (plane wave); disk: a uniform disk of angular_diameter_deg, which "
        "Mitsuba can also reach through smooth dielectrics [-].",
    )
    elevation_deg: float = Field(45.0, gt=0, le=90, description="Sun elevation above the horizon [deg].")
    azimuth_deg: float = Field(45.0, ge=-360, le=360, description="Sun azimuth clockwise from north (90 = east) [deg].")
    direction: Vec3 | None = Field(
        None, description="Explicit vector towards the sun (normalised); overrides elevation_deg/azimuth_deg [-]."
    )
    solar_time_h: float | None = Field(
        None,
        ge=0,
        le=24,
        description="Local solar time on the last grown day at the geometry's latitude (12 = noon); overrides "
        "elevation_deg/azimuth_deg with the site's sun path [h].",
    )
    angular_diameter_deg: float = Field(0.53, gt=0, le=20, description="Apparent diameter of the disk sun [deg].")
    irradiance: RGB = Field(
        (1000.0, 1000.0, 1000.0), description="Irradiance on a plane facing the sun, per channel [W m-2]."
    )
    reference_point: Vec3 | None = Field(
        None,
        description="Pins the sun's tau = 0 plane to this point; null = nearest point of the scene bounding "
        "sphere (render/core/DESIGN.md §1) [m].",
    )
    disk_distance_radii: float = Field(
        1000.0,
        ge=10,
        le=1e5,
        description="Mitsuba export only: distance of the emitting disk in scene bounding radii; its wavefront "
        "curvature error is ~R_s / (2 x this) of OPL [-].",
    )


class SkyConfig(StrictModel):
    """Uniform sky, steady images only (key path scene.sky.<field>)."""

    radiance: RGB = Field((12.0, 16.0, 22.0), description="Constant sky radiance; 0 = black sky [W m-2 sr-1].")


class AreaLightConfig(StrictModel):
    """A one-sided emitting quad or disk that flashes at tau = 0 (key path scene.area_lights[i].<field>)."""

    shape: Literal["quad", "disk"] = Field("quad", description="Emitter shape [-].")
    center: Vec3 = Field((0.0, 0.0, 2.0), description="Centre of the emitter [m].")
    normal: Vec3 = Field((0.0, 0.0, -1.0), description="Emission side; the emitter is perpendicular to it [-].")
    size: tuple[float, float] = Field((0.5, 0.5), description="quad: side lengths along its local u, v axes [m].")
    radius: float = Field(0.25, gt=0, description="disk: radius [m].")
    radiance: RGB = Field((20.0, 20.0, 20.0), description="Emitted radiance on the normal's side [W m-2 sr-1].")

    @model_validator(mode="after")
    def _positive_size(self) -> AreaLightConfig:
        if min(self.size) <= 0:
            raise ValueError(f"size must be two positive lengths in m, got {self.size}")
        if sum(c * c for c in self.normal) == 0:
            raise ValueError("normal must be a non-zero vector")
        return self


class PulseLightConfig(StrictModel):
    """A point or spot light that pulses at tau = 0 (key path scene.pulse_lights[i].<field>)."""

    kind: Literal["point", "spot"] = Field("point", description="Isotropic point or spot [-].")
    position: Vec3 = Field((0.0, 0.0, 2.0), description="Light position [m].")
    direction: Vec3 = Field((0.0, 0.0, -1.0), description="spot: axis of the cone [-].")
    intensity: RGB = Field((10.0, 10.0, 10.0), description="Radiant intensity [W sr-1].")
    cutoff_angle_deg: float = Field(20.0, gt=0, le=90, description="spot: half-angle where emission stops [deg].")
    beam_width_deg: float = Field(15.0, gt=0, le=90, description="spot: half-angle of full intensity [deg].")
    medium: str | None = Field(None, description="Medium id the light sits in; null = air [-].")


class PhysicalOpticsConfig(StrictModel):
    """Physical inputs of render/scene/OPTICS.md §3, §6, §7 (key path scene.media.<id>.physical.<field>)."""

    kind: Literal["snow", "bubbly_ice", "clear_ice"] = Field("snow", description="Material model [-].")
    density: float = Field(550.0, gt=0, le=917, description="Bulk density (snow, bubbly ice) [kg m-3].")
    ssa: float | None = Field(None, gt=0, le=200, description="snow: specific surface area [m2 kg-1].")
    optical_radius: float | None = Field(None, gt=0, le=0.05, description="snow: optical radius, instead of ssa [m].")
    bubble_radius: float | None = Field(None, gt=0, le=0.05, description="bubbly_ice: bubble radius r_b [m].")
    absorption_enhancement: float = Field(1.6, gt=0, le=5, description="snow: absorption enhancement B [-].")
    g0_natural: float = Field(
        0.86, gt=0, lt=1, description="snow: TARTES g0 at n = 1.3 (0.86 natural, 0.89 spheres) [-]."
    )
    g: float = Field(0.86, gt=-1, lt=1, description="bubbly/clear ice: HG mean cosine of the bubbles [-].")
    black_carbon_ng_per_g: float = Field(0.0, ge=0, le=1e5, description="Black-carbon mass mixing ratio [ng g-1].")
    dust_ug_per_g: float = Field(0.0, ge=0, le=1e5, description="Mineral-dust mass mixing ratio [ug g-1].")
    haze_sigma_s: float = Field(0.0, ge=0, le=10, description="clear_ice: faint grey scattering [m-1].")

    @model_validator(mode="after")
    def _inputs_for_kind(self) -> PhysicalOpticsConfig:
        if self.kind == "snow":
            if (self.ssa is None) == (self.optical_radius is None):
                raise ValueError("snow needs exactly one of ssa [m2/kg] or optical_radius [m]")
            if self.density >= 917:
                raise ValueError("snow density must be below 917 kg/m3 (pure ice); use kind bubbly_ice or clear_ice")
        if self.kind == "bubbly_ice" and self.bubble_radius is None:
            raise ValueError("bubbly_ice needs bubble_radius [m]")
        return self


class CoefficientsConfig(StrictModel):
    """Explicit RTE coefficients (key path scene.media.<id>.coefficients.<field>)."""

    sigma_s: RGB = Field(..., description="Scattering coefficient per channel [m-1].")
    sigma_a: RGB = Field(..., description="Absorption coefficient per channel [m-1].")
    g: float = Field(0.0, gt=-1, lt=1, description="Henyey-Greenstein mean cosine [-].")
    ior: float = Field(
        1.31, ge=1, le=4, description="Material refractive index, used when the boundary is dielectric [-]."
    )


class MediumConfig(StrictModel):
    """One homogeneous medium: exactly one of preset, physical or coefficients (key path scene.media.<id>)."""

    preset: str | None = Field(
        None,
        description="Optical preset in configs/presets/optics/ (fresh_snow, aged_snow, penitente_firn, dense_firn, "
        "bubbly_ice, clear_ice, thesis_set_1..6) [-].",
    )
    physical: PhysicalOpticsConfig | None = Field(None, description="Derive from physical inputs [-].")
    coefficients: CoefficientsConfig | None = Field(None, description="Explicit sigma_s, sigma_a, g [-].")
    form: Literal["full", "diffraction_removed", "isotropic_reduced"] | None = Field(
        None,
        description="Phase-function form (render/scene/OPTICS.md §4); null = diffraction_removed for snow and bubbly ice, "
        "full for clear ice, thesis sets and explicit coefficients [-].",
    )
    boundary: Literal["null", "dielectric"] | None = Field(
        None, description="null: index matched; dielectric: smooth Fresnel interface; null = the preset's own [-]."
    )
    ior: float | None = Field(None, ge=1, le=4, description="Overrides the material refractive index [-].")
    metres_per_unit: float | None = Field(
        None, gt=0, description="Thesis sets: metres per thesis scene unit; coefficients are divided by it [m]."
    )

    @field_validator("preset")
    @classmethod
    def _preset_exists(cls, name: str | None) -> str | None:
        if name is None:
            return name
        available = optics_preset_names()
        if name not in available:
            close = difflib.get_close_matches(name, available, n=1)
            hint = f"did you mean '{close[0]}'? " if close else ""
            raise ValueError(
                f"unknown optical preset {name!r}; {hint}available: {', '.join(available)} "
                "(files in configs/presets/optics/)"
            )
        return name

    @model_validator(mode="after")
    def _one_source(self) -> MediumConfig:
        given = [k for k in ("preset", "physical", "coefficients") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"give exactly one of preset, physical or coefficients (got {given or 'none'})")
        return self


class ObjectConfig(StrictModel):
    """One closed mesh: a medium inside a boundary, or a diffuse surface (key path scene.objects[i].<field>)."""

    name: str = Field(..., pattern=r"^[A-Za-z0-9_-]+$", description="Object id, also the PLY file name [-].")
    shape: Literal["penitentes", "snowpack", "box", "sphere", "slab", "ply"] = Field(
        ...,
        description="penitentes: the geometry stage's mesh; snowpack: a slab around (or, alone, under) it; "
        "box/sphere/slab: test shapes; ply: any closed PLY [-].",
    )
    medium: str | None = Field(None, description="Medium id inside (a key of scene.media) [-].")
    reflectance: RGB | None = Field(None, description="Diffuse reflectance, for an opaque surface instead [-].")
    center: Vec3 = Field((0.0, 0.0, 0.0), description="box/sphere centre; slab: x, y of its centre [m].")
    size: Vec3 = Field((1.0, 1.0, 1.0), description="box: edge lengths; slab: x and y extents (z ignored) [m].")
    radius: float = Field(0.5, gt=0, description="sphere radius [m].")
    subdivisions: int = Field(4, ge=0, le=7, description="sphere: icosahedron subdivisions [-].")
    top_z: float | None = Field(None, description="slab/snowpack: height of the top face; null = automatic [m].")
    thickness: float = Field(1.5, gt=0, description="slab/snowpack: thickness [m].")
    margin: float = Field(4.0, ge=0, description="snowpack: width of snow around the penitente footprint [m].")
    gap: float = Field(
        0.002, ge=0, le=0.1, description="snowpack: air gap to the penitente mesh, avoids coincident faces [m]."
    )
    path: str | None = Field(
        None,
        description="ply: mesh file, PLY (ASCII or binary), OBJ or STL; absolute, or relative to the config "
        "file's folder [path].",
    )
    tiles: int = Field(
        1,
        ge=1,
        le=401,
        description="penitentes: place the grown field's periodic surface tiles x tiles times around the grown "
        "tile, a landscape instead of a box: the copies are instances of one mesh (memory of one tile) closed by "
        "walls and a base around the outside, and the walls stand (tiles - 1) / 2 tiles away, so a low camera "
        "sees the field run to its horizon (render/core/DESIGN.md §13). Odd, so the grown tile is in the "
        "middle; 1 = the geometry stage's closed mesh as it is [-].",
    )

    @model_validator(mode="after")
    def _medium_or_surface(self) -> ObjectConfig:
        if (self.medium is None) == (self.reflectance is None):
            raise ValueError(f"object '{self.name}' needs exactly one of medium or reflectance")
        if self.shape == "ply" and not self.path:
            raise ValueError(f"object '{self.name}' has shape ply but no path")
        if self.reflectance is not None and max(self.reflectance) > 1:
            raise ValueError(f"object '{self.name}': reflectance must not exceed 1")
        if self.tiles > 1 and self.shape != "penitentes":
            raise ValueError(f"object '{self.name}': tiles applies to shape penitentes only (the periodic field)")
        if self.tiles % 2 == 0:
            raise ValueError(
                f"object '{self.name}': tiles must be odd ({self.tiles - 1} or {self.tiles + 1}), so that the "
                "grown tile stays in the middle"
            )
        return self


class FilmConfig(StrictModel):
    """Film and time axis (mitransient's names; key path scene.film.<field>)."""

    moved_keys = {
        "frame_mode": "scene.film.frame_mode has moved to render.frame_mode: only our renderer reads it (the "
        "references' frames are always bins), so it sits with the other keys of our estimator. Move the line to the "
        "render section (render: {frame_mode: gate}); for bins, the default, delete it",
    }

    mode: Literal["steady", "transient"] = Field("transient", description="Steady image only, or frames as well [-].")
    temporal_bins: int = Field(40, ge=1, le=100000, description="Number of frames F [-].")
    start_opl: float = Field(10.0, description="OPL where frame 0 begins [m].")
    bin_width_opl: float = Field(0.5, gt=0, description="Frame spacing Delta, in OPL [m].")
    window: Literal["manual", "auto"] = Field(
        "auto",
        description="manual: start_opl and bin_width_opl as given; auto: the scene stage fits the window to the "
        "arrivals of single-scattered light at the scene's surfaces plus window_tail_opl [-].",
    )
    window_tail_opl: float = Field(
        1.0,
        ge=0,
        description="auto window: OPL kept after the latest direct arrival, for light that lingers in the media [m].",
    )

    @property
    def end_opl(self) -> float:
        return self.start_opl + self.temporal_bins * self.bin_width_opl


def _default_media() -> dict[str, MediumConfig]:
    return {"snow": MediumConfig(preset="penitente_firn")}


def _default_objects() -> list[ObjectConfig]:
    return [
        ObjectConfig(name="penitentes", shape="penitentes", medium="snow"),
        ObjectConfig(name="snowpack", shape="snowpack", medium="snow"),
    ]


class SceneConfig(StrictModel):
    """The neutral scene: what both renderers see (key path scene.<field>)."""

    moved_keys = {
        "rr_depth": "scene.rr_depth has moved to render.rr_depth: only our renderer reads it (the references start "
        "their roulette at reference.rr_depth, auto by default). Move the line to the render section "
        "(render: {rr_depth: 5})",
    }

    camera: CameraConfig = Field(default_factory=CameraConfig, description="The camera [-].")
    sun: SunConfig = Field(default_factory=SunConfig, description="The sun [-].")
    sky: SkyConfig = Field(default_factory=SkyConfig, description="The constant sky [-].")
    area_lights: list[AreaLightConfig] = Field(default_factory=list, description="Quad and disk area lights [-].")
    pulse_lights: list[PulseLightConfig] = Field(default_factory=list, description="Point and spot pulse lights [-].")
    media: dict[str, MediumConfig] = Field(default_factory=_default_media, description="Media by id [-].")
    objects: list[ObjectConfig] = Field(default_factory=_default_objects, description="Closed meshes [-].")
    film: FilmConfig = Field(default_factory=FilmConfig, description="Film and time axis [-].")
    max_depth: int = Field(
        -1,
        ge=-1,
        le=100000,
        description="Mitsuba's meaning: non-null interactions on the path plus one; -1 = unbounded [-].",
    )

    @model_validator(mode="after")
    def _references_exist(self) -> SceneConfig:
        for i, obj in enumerate(self.objects):
            if obj.medium is not None and obj.medium not in self.media:
                close = difflib.get_close_matches(obj.medium, list(self.media), n=1)
                hint = f"did you mean '{close[0]}'? " if close else ""
                raise ValueError(
                    f"objects[{i}] ('{obj.name}') names medium {obj.medium!r}, which is not a key of "
                    f"scene.media; {hint}defined: {', '.join(self.media) or 'none'}"
                )
        for who, medium in [("camera", self.camera.medium)] + [
            (f"pulse_lights[{i}]", p.medium) for i, p in enumerate(self.pulse_lights)
        ]:
            if medium is not None and medium not in self.media:
                raise ValueError(f"{who}.medium {medium!r} is not a key of scene.media")
        names = [o.name for o in self.objects]
        if len(set(names)) != len(names):
            raise ValueError(f"object names must be unique, got {names}")
        if self.max_depth == 1 or self.max_depth == 0:
            raise ValueError("max_depth must be -1 (unbounded) or >= 2 (2 = direct light / single scattering)")
        if sum(o.shape == "penitentes" for o in self.objects) > 1:
            raise ValueError("at most one object may have shape penitentes")
        tiled = [o.name for o in self.objects if o.tiles > 1]
        ring = [o.name for o in self.objects if o.shape == "snowpack"]
        if tiled and ring:
            raise ValueError(
                f"objects {', '.join(ring)} (snowpack) would overlap the tiled field '{tiled[0]}': the copies "
                "already surround the grown tile; drop the snowpack object or set tiles: 1"
            )
        return self


class ReferenceConfig(StrictModel):
    """Mitsuba 3 / mitransient reference renders (key path reference.<field>)."""

    steady: bool = Field(True, description="Render the steady reference with volpath [-].")
    transient: bool = Field(
        True, description="Render the transient reference with mitransient (needs scene.film.mode transient) [-]."
    )
    spp: int = Field(
        64, ge=1, le=2**24, description="Samples per pixel of the steady reference (unless time_budget_s) [-]."
    )
    transient_spp: int | None = Field(
        None, ge=1, le=2**24, description="Samples per pixel of the transient reference; null = spp [-]."
    )
    spp_per_pass: int = Field(
        16, ge=1, le=2**20, description="Each pass renders this many spp with its own seed; passes are averaged [-]."
    )
    time_budget_s: float | None = Field(
        None,
        gt=0,
        description="Wall-clock budget per reference; overrides spp, stopping after the pass that "
        "would overrun it [s].",
    )
    rr_depth: Annotated[int, Field(ge=1, le=1_000_000)] | Literal["auto"] = Field(
        "auto",
        description="Depth (collisions) from which Mitsuba's and mitransient's roulette starts. Their roulette keeps "
        "a path with at most 0.95 a collision, so in dense, high-albedo snow a shallow start leaves the long paths "
        "almost never sampled and the references dark (1-3 % in fresh snow from 3000). auto: the depth at which "
        "each medium's channel is expected to leave out at most 0.25 % of its light, from exact half-space "
        "transport (render/scene/roulette.py; render/core/DESIGN.md §12, *Roulette depth from the medium*); an "
        "integer sets it (a warning when it is expected to leave out over 0.5 %) [-].",
    )
    tiles: int = Field(
        4,
        ge=0,
        le=256,
        description="Render the references in this many square tiles along the film's longer side, each in "
        "millimetres with the scene moved so that the middle of what it sees lies at the origin; 0 = the whole "
        "film in metres. Mitsuba starts every ray that leaves a surface (1 + max|p|) 9e-5 scene units off it, "
        "so a camera path enters dense snow below its face and reads bright: +1.3 % on the default sweep's "
        "firn point untiled, +0.4 % in 4 tiles (render/core/DESIGN.md §12) [-].",
    )
    downsample: int = Field(
        1,
        ge=1,
        le=64,
        description="Render the references on a film this many times coarser in each axis (the same camera and "
        "field of view; scene.camera.width and height must be multiples of it). Path tracing costs per pixel, so "
        "2 makes the references 4x cheaper at the same spp. The compare and composite stages then read our frames "
        "box-averaged over k x k pixels, which is what the same camera records on the coarser film [-].",
    )
    variant: Literal["llvm_ad_rgb", "scalar_rgb"] = Field(
        "llvm_ad_rgb",
        description="Preferred Mitsuba variant; falls back to scalar_rgb with a warning (steady only) [-].",
    )
    force: bool = Field(
        False,
        description="Render even when a delta light shines through a smooth dielectric (the medium renders "
        "black in Mitsuba) [-].",
    )

    @field_validator("rr_depth", mode="before")
    @classmethod
    def _null_depth_moved(cls, rr_depth: object) -> object:
        if rr_depth is None:
            raise ValueError(
                "null meant scene.rr_depth, which has moved to render.rr_depth (our renderer's); give the "
                "references' depth as an integer (the same as render.rr_depth to keep what null did) or auto"
            )
        return rr_depth


__all__ = [
    "SceneConfig",
    "ReferenceConfig",
    "CameraConfig",
    "SunConfig",
    "SkyConfig",
    "AreaLightConfig",
    "PulseLightConfig",
    "PhysicalOpticsConfig",
    "CoefficientsConfig",
    "MediumConfig",
    "ObjectConfig",
    "FilmConfig",
]
