"""Shortwave irradiance on a periodic height field: direct sun with horizon shadows, isotropic sky
weighted by the sky view factor, and light reflected by the surrounding snow (1-n bounces).

Height fields are arrays ``h[iy, ix]`` [m] on a square periodic grid of spacing ``spacing`` [m];
rows run north (y), columns east (x). Visibility marches along sheared grid lines (DESIGN.md 6.3):
one cell per step along the direction's major axis, a linear blend along the minor one. The
marches run cell by cell in numba kernels (rows in parallel), each cell stopping as soon as its
answer is settled, so flat-lying and deep cells cost a few steps and only the highest crests
march the whole period.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage

# OpenMP first: Debian 12's TBB is older than numba wants, and trying it first only prints a warning.
numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]  # type: ignore[attr-defined]  # set at run time


def check_height_field(h: np.ndarray, name: str = "height field") -> np.ndarray:
    """Return ``h`` as a float array, or raise ValueError if it is not a finite square 2-D grid."""
    h = np.asarray(h, dtype=float)
    if h.ndim != 2 or h.shape[0] != h.shape[1] or h.shape[0] < 4:
        raise ValueError(f"{name} must be a square 2-D grid of at least 4x4 cells, got shape {h.shape}")
    if not np.all(np.isfinite(h)):
        bad = int(np.size(h) - np.count_nonzero(np.isfinite(h)))
        raise ValueError(
            f"{name} contains {bad} NaN/inf values; check the growth parameters (time step, geometry.diffusivity)"
        )
    return h


def gradient(h: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Central-difference slopes (dh/dx east, dh/dy north) [-] on the periodic grid."""
    p = (np.roll(h, -1, axis=1) - np.roll(h, 1, axis=1)) / (2.0 * spacing)
    q = (np.roll(h, -1, axis=0) - np.roll(h, 1, axis=0)) / (2.0 * spacing)
    return p, q


def unit_normals(h: np.ndarray, spacing: float) -> np.ndarray:
    """Outward unit normals (east, north, up), shape (N, N, 3)."""
    p, q = gradient(h, spacing)
    norm = np.sqrt(1.0 + p * p + q * q)
    return np.stack((-p / norm, -q / norm, 1.0 / norm), axis=-1)


@numba.njit(inline="always")
def _sample_along(h, ix, iy, j, step_east, step_north):
    """h at the point j steps from cell (ix, iy) along a sheared line (steps in cells, one of them
    +-1): one cell per step along the major axis, linear along the minor one, periodic."""
    n = h.shape[0]
    ox, oy = j * step_east, j * step_north
    fx, fy = math.floor(ox), math.floor(oy)
    wx, wy = ox - fx, oy - fy  # one of them is zero
    x0 = (ix + int(fx)) % n
    y0 = (iy + int(fy)) % n
    sample = h[y0, x0]
    if wx > 1e-12:
        sample = (1.0 - wx) * sample + wx * h[y0, (x0 + 1) % n]
    elif wy > 1e-12:
        sample = (1.0 - wy) * sample + wy * h[(y0 + 1) % n, x0]
    return sample


@numba.njit(parallel=True, cache=True)
def _shadowed(h, step_east, step_north, rise_per_step, max_steps):
    """True where terrain toward the sun stands above the ray from the cell (rows in parallel)."""
    n = h.shape[0]
    top = h.max()
    out = np.zeros((n, n), dtype=np.bool_)
    for iy in numba.prange(n):
        for ix in range(n):
            height = h[iy, ix]
            for j in range(1, max_steps + 1):
                ray = height + j * rise_per_step
                if ray >= top:
                    break
                if _sample_along(h, ix, iy, j, step_east, step_north) > ray:
                    out[iy, ix] = True
                    break
    return out


def sun_visibility(h: np.ndarray, spacing: float, sun: np.ndarray, max_periods: float = 2.0) -> np.ndarray:
    """1 where the sun is visible (facing it and not shadowed by the terrain), else 0.

    sun: unit vector (east, north, up). Each cell marches toward the sun along a sheared grid line
    for up to ``max_periods`` domain lengths, stopping at the first occluder or once the ray has
    risen above the highest point (DESIGN.md 6.3).
    """
    sun = np.asarray(sun, float)
    normals = unit_normals(h, spacing)
    facing = (normals @ sun) > 0.0
    horizontal = float(np.hypot(sun[0], sun[1]))
    if sun[2] <= 0.0:
        return np.zeros_like(h)
    if horizontal < 1e-9:
        return facing.astype(float)
    east, north = sun[0] / horizontal, sun[1] / horizontal
    major = max(abs(east), abs(north))
    rise_per_step = spacing / major * sun[2] / horizontal
    shadowed = _shadowed(h, east / major, north / major, rise_per_step, int(max_periods * h.shape[0]))
    return (facing & ~shadowed).astype(float)


@dataclass(frozen=True)
class Horizons:
    """Horizons of every cell in M azimuths, and what they imply for sky and terrain view.

    azimuths: (M,) [rad, clockwise from north]; seen_distance: (M, N, N) view-weighted mean
    horizontal distance of the snow seen in each azimuth [m] (0 where only sky is seen); sky_view: (N, N)
    sky view factor [-]; terrain_weight: (M, N, N) share of the hemisphere's cosine-weighted view
    that is snow in each azimuth sector [-], summing to 1 - sky_view; openness: (N, N) sky view of
    a level receiver at each point, mean of cos^2 of the (non-negative) horizon elevation [-];
    shelter: (N, N) mean over azimuths of the tangent of that non-negative horizon elevation, the
    terrain shelter index Sx of Winstral et al. (2002) averaged over wind directions [-]. Openness
    departs from 1 only at second order in the horizon angle, shelter at first order. true_area: (N, N)
    surface area per unit horizontal area of each facet, sqrt(1 + |grad h|^2) from central slopes [-].
    """

    azimuths: np.ndarray
    seen_distance: np.ndarray
    sky_view: np.ndarray
    terrain_weight: np.ndarray
    openness: np.ndarray
    shelter: np.ndarray
    true_area: np.ndarray


def _sector_sky(tan_horizon: np.ndarray, slope_along: np.ndarray, cos_slope: np.ndarray) -> np.ndarray:
    """Dozier & Frew (1990) sky integrand of one azimuth for a horizon elevation given by its tangent.

    cos S sin^2 H + sin S cos(psi - A)(H - sin H cos H), with H = pi/2 - atan(tan_horizon) and
    sin S cos(psi - A) = -cos S * slope_along (slope_along = dh/dr along psi).
    """
    t = tan_horizon
    inv = 1.0 / (1.0 + t * t)
    zenith = 0.5 * np.pi - np.arctan(t)
    return cos_slope * (inv - slope_along * (zenith - t * inv))


@numba.njit(cache=True, inline="always")
def _sector_sky_at(tan_horizon: float, slope_along: float, cos_slope: float) -> float:
    """_sector_sky for one cell."""
    inv = 1.0 / (1.0 + tan_horizon * tan_horizon)
    zenith = 0.5 * np.pi - math.atan(tan_horizon)
    return cos_slope * (inv - slope_along * (zenith - tan_horizon * inv))


# The horizon march takes one-cell steps up to NEAR_STEPS cells, then doubles its step every
# NEAR_STEPS / 2 steps, sampling a max-filtered copy of h as wide as the step (a max-pyramid, DESIGN.md
# 6.3): a conservative horizon whose angular error stays under one part in NEAR_STEPS.
NEAR_STEPS = 32


def max_pyramid(h: np.ndarray) -> np.ndarray:
    """Stack of h max-filtered (periodic, square windows) over 1, 2, 4, ... cells up to the grid size."""
    levels = [h]
    width = 2
    while width <= h.shape[0] // NEAR_STEPS * 2 and width < h.shape[0]:
        levels.append(ndimage.maximum_filter(h, size=width, mode="wrap"))
        width *= 2
    return np.stack(levels)


@numba.njit(parallel=True, cache=True)
def _sweep_azimuth(pyramid, step_east, step_north, step_length, slope_along, cos_slope, headroom, tolerance):
    """One azimuth's sweep, cell by cell (rows in parallel): the sector's sky integrand, the moment
    (view weight x distance) of the terrain it exposes, and the level receiver's horizon tangent.

    The march moves along the major axis and blends linearly along the minor one (step_east,
    step_north in cells, one of them +-1), for at most one domain period, on the max-pyramid (see
    NEAR_STEPS). A cell stops once no farther point could raise its horizon, or that of a level
    receiver, by more than ``tolerance`` (a tangent); trough cells close within their own depth.
    """
    h = pyramid[0]
    n = h.shape[0]
    sky_out = np.empty((n, n))
    moment_out = np.empty((n, n))
    level_out = np.empty((n, n))
    for iy in numba.prange(n):
        for ix in range(n):
            height = h[iy, ix]
            slope, cos_s, room = slope_along[iy, ix], cos_slope[iy, ix], headroom[iy, ix]
            tan_run = slope  # the facet's own tangent plane bounds what it can see (3.3)
            sky_run = _sector_sky_at(tan_run, slope, cos_s)
            moment = 0.0  # sum of (view weight x distance) of the terrain exposed so far
            level = 0.0  # horizon of a level receiver, never below the horizontal
            j, stride, level_index, count = 0, 1, 0, 0
            while j < n:
                j += stride
                count += 1
                r = j * step_length
                sample = _sample_along(pyramid[level_index], ix, iy, j, step_east, step_north)
                tan_here = (sample - height) / r
                if tan_here > level:
                    level = tan_here
                if tan_here > tan_run:
                    tan_run = tan_here
                    sky_here = _sector_sky_at(tan_run, slope, cos_s)
                    moment += (sky_run - sky_here) * r
                    sky_run = sky_here
                if count % 8 == 0 and room / r < min(tan_run, level) + tolerance:
                    break
                if j >= NEAR_STEPS * stride and level_index + 1 < pyramid.shape[0]:
                    stride *= 2
                    level_index += 1
            sky_out[iy, ix] = sky_run
            moment_out[iy, ix] = moment
            level_out[iy, ix] = level
    return sky_out, moment_out, level_out


def compute_horizons(
    h: np.ndarray,
    spacing: float,
    n_azimuths: int,
    rotation: float = 0.0,
    tolerance_deg: float = 0.25,
    wake_slope: float = 0.0,
) -> Horizons:
    """Horizon angles, sky view factor and terrain view weights by sheared sweeps in M azimuths.

    While sweeping, each rise of the running horizon exposes a band of sky-integrand weight that is
    snow at the current distance; its weighted mean distance says where the facet looks for terrain.

    rotation [rad] turns the whole azimuth set (a random turn per refresh keeps grid axes from
    imprinting). Each sweep runs at most one domain period; each cell leaves it once no farther point
    could raise its horizon by more than ``tolerance_deg``.
    """
    h = check_height_field(h)
    n = h.shape[0]
    azimuths = np.mod(rotation + 2.0 * np.pi * np.arange(n_azimuths) / n_azimuths, 2.0 * np.pi)
    p, q = gradient(h, spacing)
    cos_slope = 1.0 / np.sqrt(1.0 + p * p + q * q)
    headroom = float(h.max()) - h
    tolerance = np.tan(np.radians(tolerance_deg))
    distance = np.zeros((n_azimuths, n, n), dtype=np.float32)
    sky_sector = np.empty((n_azimuths, n, n))
    open_sector = np.empty((n_azimuths, n, n))
    openness = np.zeros_like(h)
    shelter = np.zeros_like(h)
    pyramid = max_pyramid(h)
    for m, psi in enumerate(azimuths):
        east, north = np.sin(psi), np.cos(psi)
        slope_along = p * east + q * north
        major = max(abs(east), abs(north))
        sky_run, seen_moment, tan_level = _sweep_azimuth(
            pyramid, east / major, north / major, spacing / major, slope_along, cos_slope, headroom, tolerance
        )
        open_sector_m = _sector_sky(slope_along, slope_along, cos_slope)
        exposed = open_sector_m - sky_run
        dist = np.divide(seen_moment, exposed, out=np.zeros_like(h), where=exposed > 1e-9)
        sky_sector[m] = sky_run
        open_sector[m] = open_sector_m
        distance[m] = dist
        openness += 1.0 / (1.0 + tan_level * tan_level) / n_azimuths
        shelter += np.maximum(tan_level - wake_slope, 0.0) / n_azimuths
    sky_view = np.clip(sky_sector.mean(axis=0), 0.0, 1.0)
    terrain = np.clip(open_sector - sky_sector, 0.0, None)
    total = terrain.sum(axis=0)
    # Everything in the hemisphere that is not sky is snow: scale sectors to sum to 1 - V_sky.
    scale = np.divide(1.0 - sky_view, total, out=np.zeros_like(total), where=total > 1e-12)
    terrain_weight = (terrain * scale).astype(np.float32)
    return Horizons(azimuths, distance, sky_view, terrain_weight, openness, shelter, 1.0 / cos_slope)


# Where the seen radiosity is sampled, as fractions of the view-weighted distance; two samples
# straddling the centroid reproduce the spherical-bowl identity to ~2 % (tests/geometry).
SAMPLE_FRACTIONS = (0.8, 1.2)


def terrain_irradiance(radiosity: np.ndarray, spacing: float, horizons: Horizons) -> np.ndarray:
    """Irradiance from the surrounding snow [W m-2, or J m-2 if radiosity is an energy]:
    sum over azimuths of the terrain weight times the radiosity seen along that azimuth, sampled
    (bilinear, periodic) around the view-weighted distance of the snow seen there."""
    n = radiosity.shape[0]
    rows, cols = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="ij")
    total = np.zeros_like(radiosity, dtype=float)
    for m, psi in enumerate(horizons.azimuths):
        weight = horizons.terrain_weight[m]
        if not np.any(weight > 0):
            continue
        reach = horizons.seen_distance[m] / spacing  # [cells]
        seen = np.zeros_like(total)
        for fraction in SAMPLE_FRACTIONS:
            coords = np.stack((rows + fraction * reach * np.cos(psi), cols + fraction * reach * np.sin(psi)))
            seen += ndimage.map_coordinates(radiosity, coords, order=1, mode="grid-wrap")
        total += weight * seen / len(SAMPLE_FRACTIONS)
    return total


def bounce_terrain_light(
    primary: np.ndarray, albedo: float, spacing: float, horizons: Horizons, bounces: int
) -> np.ndarray:
    """Terrain-reflected irradiance after ``bounces`` Jacobi gathers, given the primary (direct +
    sky) irradiance per unit true area. Lambertian snow: radiosity = albedo * total irradiance.

    Every gather is scaled so that the light the field receives from its terrain equals the light its facets
    send into it, the sum of B (1 - V_sky) over the true area (DESIGN.md 3.6): the two-sample gather alone
    received 7-18 % more than was sent on steep walls."""
    area = horizons.true_area
    terrain = np.zeros_like(primary)
    for _ in range(bounces):
        radiosity = albedo * (primary + terrain)
        terrain = terrain_irradiance(radiosity, spacing, horizons)
        received = float(np.sum(terrain * area))
        if received > 0.0:
            terrain *= float(np.sum(radiosity * (1.0 - horizons.sky_view) * area)) / received
    return terrain


@dataclass(frozen=True)
class RadiationBudget:
    """Irradiance components and absorbed flux per unit true surface area [W m-2]."""

    direct: np.ndarray
    sky: np.ndarray
    terrain: np.ndarray
    absorbed: np.ndarray
    radiosity: np.ndarray
    sun_visible: np.ndarray


def radiation_budget(
    h: np.ndarray,
    spacing: float,
    sun: np.ndarray,
    direct_normal: float,
    diffuse_horizontal: float,
    albedo: float,
    horizons: Horizons,
    bounces: int,
) -> RadiationBudget:
    """Irradiance and absorbed flux for one sun position (DESIGN.md 3.4-3.7).

    direct_normal: S_b [W m-2]; diffuse_horizontal: S_d [W m-2]; albedo: local broadband albedo a [-].
    """
    if not 0.0 <= albedo <= 1.0:
        raise ValueError(f"albedo must lie in [0, 1], got {albedo}")
    sun = np.asarray(sun, float)
    visible = sun_visibility(h, spacing, sun)
    cos_incidence = np.clip(unit_normals(h, spacing) @ sun, 0.0, None)
    direct = direct_normal * cos_incidence * visible
    sky = diffuse_horizontal * horizons.sky_view
    terrain = bounce_terrain_light(direct + sky, albedo, spacing, horizons, bounces)
    total = direct + sky + terrain
    return RadiationBudget(direct, sky, terrain, (1.0 - albedo) * total, albedo * total, visible)


def field_albedo(budget: RadiationBudget, horizons: Horizons, incident_horizontal: float) -> tuple[float, float]:
    """Broadband albedo of the field [-]: radiosity escaping to the sky through the top plane over
    the incident flux. Also returns the energy-closure error (absorbed + escaped - incident)/incident."""
    area = horizons.true_area
    escaped = float(np.mean(budget.radiosity * horizons.sky_view * area))
    absorbed = float(np.mean(budget.absorbed * area))
    return escaped / incident_horizontal, (absorbed + escaped - incident_horizontal) / incident_horizontal


def v_groove_albedo(albedo: float, spacing: float, depth: float) -> float:
    """Albedo of long V-grooves of the given spacing and depth [m] with Lambertian walls of ``albedo``, under
    uniform radiosity (DESIGN.md 7, V4): a wall sees the opening with view factor sin(theta) =
    (S/2) / sqrt(H^2 + S^2/4), so light entering the groove leaves after each bounce with that probability,
    A = a sin(theta) / (1 - a (1 - sin(theta))). Pits closed on all sides see less sky than a groove of their
    depth, so a pitted field is darker than this: it bounds the field albedo from above."""
    if spacing <= 0 or depth < 0:
        raise ValueError(f"a V-groove needs a positive spacing and a non-negative depth, got {spacing}, {depth}")
    opening = 0.5 * spacing / np.hypot(depth, 0.5 * spacing)
    return albedo * opening / (1.0 - albedo * (1.0 - opening))
