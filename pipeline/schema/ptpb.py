"""Settings of our Progressive Transient Photon Beams renderer (render/core/DESIGN.md §6 "Proposed keys").

A setting the core takes as it is has its default in the core (RenderSettings in
render/core/include/ptpb/settings.hpp, read here as CORE_DEFAULTS); this schema adds its description, range
and unit. The kernel radii are in the user's units here and resolved to metres in render/ptpb/settings.py
(tests/ptpb/test_settings_home.py keeps the two sides equal)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from pipeline.schema.base import StrictModel
from render import _core

CORE_DEFAULTS = _core.render_settings_defaults()


class BeamRadius(StrictModel):
    """Initial spatial kernel radius (R_0 of the beams, r_0 of the surface photons) with an explicit unit."""

    value: float = Field(..., gt=0, description="The radius in the unit below [m | scene radii | pixel footprints].")
    unit: Literal["m", "scene_radius", "pixel_footprint"] = Field(
        "pixel_footprint",
        description="m: absolute; scene_radius: fraction of the scene's bounding radius; pixel_footprint: "
        "multiples of 2 z tan(fov/2) / P at the distance z from the camera to the scene centre [-].",
    )


class TimeHalfWidth(StrictModel):
    """Initial temporal kernel half-width T_0 (gate mode) with an explicit unit."""

    value: float = Field(..., gt=0, description="T_0 in the unit below [m OPL | bins | n R_0].")
    unit: Literal["m_opl", "bin_width", "beam_radius"] = Field(
        "beam_radius",
        description="m_opl: metres of optical path; bin_width: multiples of bin_width_opl; beam_radius: value * n * R_0 "
        "with n the largest medium index (value * n * r_0 for the surface photons' own T_0). A floor of "
        "bin_width_opl / 2 applies [-].",
    )


class PTPBConfig(StrictModel):
    """Our PTPB renderer: light paths per iteration, bandwidth schedules, kernels and budgets."""

    iterations: int = Field(
        CORE_DEFAULTS["iterations"],
        ge=1,
        description="Number of progressive iterations (upper bound unless a time budget is set) [-].",
    )
    time_budget_s: float | None = Field(
        CORE_DEFAULTS["time_budget_s"],
        gt=0,
        description="Wall-clock budget; when set it overrides `iterations` (stops after the iteration in flight) [s].",
    )
    light_paths_per_iteration: int = Field(
        CORE_DEFAULTS["light_paths_per_iteration"],
        ge=1,
        lt=2**32,
        description="M: light paths launched per iteration; every sum is divided by M [-].",
    )
    alpha: float | None = Field(
        CORE_DEFAULTS["alpha"],
        gt=0,
        le=1,
        description="Kernel-volume schedule parameter; null picks 2/3 for gate and 4/5 for bins/steady [-].",
    )
    initial_beam_radius: BeamRadius = Field(
        default_factory=lambda: BeamRadius(value=2.0, unit="pixel_footprint"),
        description="R_0, the initial 1D spatial kernel radius [see unit].",
    )
    initial_time_half_width: TimeHalfWidth = Field(
        default_factory=lambda: TimeHalfWidth(value=1.0, unit="beam_radius"),
        description="T_0, the initial temporal kernel half-width of gate mode [see unit].",
    )
    initial_surface_radius: BeamRadius = Field(
        default_factory=lambda: BeamRadius(value=2.0, unit="pixel_footprint"),
        description="r_0, the initial 2D disk kernel radius of the surface photons on diffuse surfaces (render/core/DESIGN.md §7) [see unit].",
    )
    surface_alpha: float | None = Field(
        CORE_DEFAULTS["surface_alpha"],
        gt=0,
        le=1,
        description="Surface kernel-volume schedule parameter; null picks 4/7 for gate (r and T shrink as gamma^(1/3)) "
        "and 2/3 for bins/steady (r shrinks as gamma^(1/2)) [-].",
    )
    surface_normal_cos: float = Field(
        CORE_DEFAULTS["surface_normal_cos"],
        gt=0,
        le=1,
        description="A surface photon counts only where its normal and the shading normal have at least this cosine [-].",
    )
    spatial_kernel: Literal["box", "epanechnikov"] = Field(
        CORE_DEFAULTS["spatial_kernel"],
        description="Spatial kernel: 1D k_R of the beams and the matching 2D disk kernel of the surface photons [-].",
    )
    temporal_kernel: Literal["box", "epanechnikov", "quintic"] = Field(
        CORE_DEFAULTS["temporal_kernel"], description="Temporal kernel K_T of gate mode [-]."
    )
    photon_beam_kind: Literal["long", "short"] = Field(
        CORE_DEFAULTS["photon_beam_kind"],
        description="Photon beams run to the boundary (long) or to the next vertex (short) [-].",
    )
    query_beam_kind: Literal["long", "short"] = Field(
        CORE_DEFAULTS["query_beam_kind"], description="Camera query segments, long or short [-]."
    )
    parallel_guard_sin2: float = Field(
        CORE_DEFAULTS["parallel_guard_sin2"],
        ge=0,
        lt=1,
        description="Pairs with sin^2(theta) below this are skipped [-].",
    )
    medium_estimator: Literal["auto", "beams", "paths"] = Field(
        CORE_DEFAULTS["medium_estimator"],
        description="Estimator of light scattered in media (render/core/DESIGN.md §12): beams; camera paths with "
        "next-event estimation; or auto, which in each iteration path-traces a medium whose shortest mean free path "
        "is below R_i / beam_radius_mfp and keeps beams in the others [-].",
    )
    beam_radius_mfp: float = Field(
        CORE_DEFAULTS["beam_radius_mfp"],
        gt=0,
        description="With medium_estimator auto, a medium keeps beams while R_i is at most this many of its mean free "
        "paths; beams are biased low by about 0.2 R_i sigma_t near lit faces (render/core/DESIGN.md §12) [-].",
    )
    dense_optical_radius: float = Field(
        CORE_DEFAULTS["dense_optical_radius"],
        gt=0,
        description="With medium_estimator auto, a medium whose largest sigma_t times the scene's bounding radius "
        "exceeds this is path-traced at any radius: its light paths make hundreds of collisions and its beams are "
        "a few mean free paths long, too short to share between pixels (render/core/DESIGN.md §12) [-].",
    )
    path_max_survival: float = Field(
        CORE_DEFAULTS["path_max_survival"],
        gt=0,
        lt=1,
        description="Russian roulette of path-traced camera paths keeps a path with min(this, throughput); dense, "
        "high-albedo media need values near 1 so that paths of hundreds of collisions are not cut. 0.999 agrees with "
        "the auto-depth reference within 1 % in fresh snow, the highest albedo of any preset (DESIGN.md §12) [-].",
    )
    path_splits: int = Field(
        CORE_DEFAULTS["path_splits"],
        ge=0,
        le=8,  # kMaxPathSplits in render/core/include/ptpb/settings.hpp
        description="Splitting in time for path-traced camera paths in bins and gate films: a path doubles this many "
        "times, as its optical path past its first scattering passes W/2^n, ..., W/4, W/2 of the film's length W, "
        "so that late frames, lit by the few paths that stay long in dense snow, get more of them; a path that "
        "can light no frame is rouletted back to one. Pays where late frames are the noisy ones (snow's diffusion "
        "tail under the sun: the demo uses 3); costs where they are not (render/core/DESIGN.md §12) [-].",
    )
    path_hops: bool = Field(
        CORE_DEFAULTS["path_hops"],
        description="Shell transport for path-traced camera paths in isotropically scattering media: deep in the "
        "medium a walk crosses a surface-free ball in one step drawn from tabulated exit laws (path length, "
        "direction, collisions), with its time and absorption exact; one of the skipped events, weighted to stand "
        "for all of them, makes their next-event estimate. Off only to compare against the collision-by-collision "
        "walk "
        "(render/core/DESIGN.md §12, 'Hops') [-].",
    )
    # In a pipeline config max_depth, seed and threads come from scene.max_depth and the root's seed and threads
    # (pipeline/schema/__init__.py refuses them here); they are fields for direct use of the API.
    max_depth: int = Field(
        CORE_DEFAULTS["max_depth"],
        ge=-1,
        description="Mitsuba's max_depth: non-null interactions + 1; -1 unbounded (API use only) [-].",
    )
    rr_depth: int = Field(
        CORE_DEFAULTS["rr_depth"],
        ge=1,
        description="Depth from which the Russian roulette of our renderer's paths starts; path-traced camera paths "
        "then survive with min(path_max_survival, throughput). The references have their own, reference.rr_depth [-].",
    )
    seed: int = Field(CORE_DEFAULTS["seed"], ge=0, description="Key of every random stream (API use only) [-].")
    threads: int = Field(
        CORE_DEFAULTS["threads"], ge=0, description="Worker threads; 0 uses every core (API use only) [-]."
    )
    accel: Literal["grid", "embree"] = Field(
        CORE_DEFAULTS["accel"],
        description="Beam query structure: uniform grid of diced beams, or an Embree BVH over the same pieces [-].",
    )
    grid_resolution: int = Field(
        CORE_DEFAULTS["grid_resolution"], ge=1, le=1024, description="Grid cells along the longest axis [-]."
    )
    transmittance_cutoff: float = Field(
        CORE_DEFAULTS["transmittance_cutoff"],
        gt=0,
        lt=1,
        description="Long beams and queries end where the largest channel transmittance falls below this [-].",
    )
    camera_unwarp: bool = Field(
        CORE_DEFAULTS["camera_unwarp"],
        description="Remove camera-side OPL from tau (never compare such frames with mitransient) [-].",
    )
    snapshot_every: int = Field(
        CORE_DEFAULTS["snapshot_every"],
        ge=0,
        description="Keep the steady average every k iterations for error-against-time curves (0: never) [-].",
    )
    frame_mode: Literal["steady", "bins", "gate"] | None = Field(
        None,
        description="What our frames hold: bins, integrals over each bin (as mitransient's, whose frames are always "
        "bins); gate, densities per metre of OPL at the bin centres, with the temporal kernel; steady, the steady "
        "image only. null: bins for a transient film, steady for a steady one (scene.film.mode) [-].",
    )
    checkpoint_every_iterations: int = Field(
        CORE_DEFAULTS["checkpoint_every_iterations"],
        ge=0,
        description="Save the accumulated render (double sums, counters, snapshots) to runs/<name>/.render.checkpoint/ "
        "every k iterations, so that `pipeline run --resume` continues an interrupted render with the same bits "
        "(0: never) [-].",
    )
    checkpoint_every_s: float | None = Field(
        CORE_DEFAULTS["checkpoint_every_s"],
        gt=0,
        description="Also save a checkpoint when this much wall time has passed since the last one (null: never) [s].",
    )
    memory_budget_gib: float | None = Field(
        CORE_DEFAULTS["memory_budget_gib"],
        gt=0,
        description="Peak image buffers of one render pass. They take about 4 bytes per value of temporal_bins x "
        "height x width x 3 (float32 frame sums; 8 in a shard, which sums in float64) plus 36 per pixel value for "
        "steady, early and late and a double tile film per thread. A film over this renders in frame windows, one "
        "pass each (every pass re-traces the same random streams and keeps its window's frames, written straight to "
        "frames.npy), so the result does not depend on the split; the render stage logs the windows. 8 suits a 24 "
        "GiB machine; null: one pass whatever the size [GiB].",
    )

    @model_validator(mode="after")
    def _budget(self) -> PTPBConfig:
        if self.time_budget_s is None and self.iterations < 1:
            raise ValueError("render.iterations must be >= 1 when no time_budget_s is given")
        return self
