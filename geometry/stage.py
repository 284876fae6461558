"""The geometry stage: grow a penitente field, mesh it watertight, measure it and draw it.

Outputs in ``out_dir`` (all metres, x = east, y = north, z = up): heightfield.npz,
penitentes.ply, metrics.json, metrics.png, preview.png, hillshade.png, timelapse.mp4.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from common.atomic import atomic_path, write_json_atomic
from geometry import ablation, irradiance, mesh, metrics, morphology, preview, sunpath
from pipeline.schema.geometry import GeometryConfig

log = logging.getLogger(__name__)


def noon_radiation_metrics(h: np.ndarray, spacing: float, cfg: GeometryConfig, day_of_year: float) -> dict:
    """Field albedo at local noon against flat snow/ice of the same local albedo (V4)."""
    delta = float(sunpath.declination(day_of_year))
    sun = sunpath.sun_vector(cfg.latitude, delta, 0.0)
    elevation = float(np.arcsin(sun[2]))
    sky = ablation.Sky(cfg.direct_normal_irradiance, cfg.optical_depth, cfg.diffuse_fraction)
    s_b, s_d = sky.direct_normal(elevation), sky.diffuse_horizontal(elevation)
    horizons = irradiance.compute_horizons(h, spacing, max(cfg.azimuths, 24))
    budget = irradiance.radiation_budget(h, spacing, sun, s_b, s_d, cfg.albedo, horizons, max(cfg.bounces, 3))
    albedo, closure = irradiance.field_albedo(budget, horizons, s_b * np.sin(elevation) + s_d)
    return {
        "field_albedo": albedo,
        "flat_albedo": cfg.albedo,
        "albedo_difference": albedo - cfg.albedo,
        "albedo_energy_closure": closure,
        "noon_sun_elevation_deg": float(np.degrees(elevation)),
        "mean_sky_view": float(horizons.sky_view.mean()),
    }


def field_metrics(grown: ablation.GrowthResult, cfg: GeometryConfig) -> dict:
    """The grown field's shape (crests counted once within metrics.crest_radius) and stage, its lean toward the
    equator against the noon zenith angles, and its noon radiation (V3, V4; DESIGN.md 7)."""
    h, spacing = grown.height, grown.spacing
    last_day = cfg.start_day_of_year + cfg.days - 1
    out = metrics.morphology(h, spacing, metrics.crest_radius(cfg.optical_efolding_depth))
    out.update(morphology.stage_metrics(h, spacing))
    delta = float(sunpath.declination(last_day))
    out["noon_zenith_angle_deg"] = float(np.degrees(sunpath.noon_zenith_angle(cfg.latitude, delta)))
    out["noon_zenith_growth_weighted_deg"] = float(
        np.degrees(sunpath.growth_weighted_noon_zenith(cfg.latitude, cfg.start_day_of_year, grown.relief_history))
    )
    toward_equator = 1.0 if cfg.latitude < 0 else -1.0
    out["lean_toward_equator_deg"] = toward_equator * out["lean_north_deg"]
    out["axis_lean_toward_equator_deg"] = toward_equator * out["axis_lean_north_deg"]
    out.update(noon_radiation_metrics(h, spacing, cfg, last_day))
    out["onset_wavelength_m"] = ablation.onset_wavelength(cfg.optical_efolding_depth)
    return out


def run_geometry_stage(cfg: GeometryConfig, out_dir: Path, *, seed: int, quiet: bool = False) -> dict:
    """Grow, mesh, measure and draw one field; returns a small JSON-able summary."""
    from tqdm import tqdm

    out_dir = Path(out_dir)
    for warning in ablation.config_warnings(cfg):
        log.warning("%s", warning)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    spacing = cfg.spacing
    h0 = ablation.initial_height_field_from_config(cfg, rng)
    settings = ablation.settings_from_config(cfg)
    log.info(
        "growing a %d^2 field of %.3g m for %d days at %.1f deg latitude",
        cfg.grid_cells,
        cfg.domain_size,
        cfg.days,
        cfg.latitude,
    )
    with tqdm(total=cfg.days, desc="geometry: growing", unit="day", disable=quiet, leave=False) as bar:
        grown = ablation.grow_field(h0, spacing, settings, rng, progress=bar.update)
    h = grown.height
    timings["growth_s"] = time.perf_counter() - t0
    timings.update({f"growth_{k}": v for k, v in grown.timings.items()})

    t = time.perf_counter()
    with atomic_path(out_dir / "heightfield.npz") as tmp:
        np.savez_compressed(
            tmp,
            height=h,
            spacing=spacing,
            snapshots=grown.snapshots.astype(np.float32),
            snapshot_days=grown.snapshot_days,
            relief_history=grown.relief_history,
            sky_view=grown.sky_view,
            melt_fraction=grown.melt,
            initial_height=h0,
        )
    solid = mesh.heightfield_solid(h, spacing, cfg.base_thickness, cfg.mesh_tiles)
    full_triangles = len(solid.faces)
    solid = mesh.decimate(solid, cfg.max_triangles)
    volume = mesh.manifold_volume(solid)
    expected = mesh.height_integral_volume(h, spacing, cfg.base_thickness, cfg.mesh_tiles)
    if abs(volume - expected) > 0.01 * expected:
        raise ValueError(
            f"mesh volume {volume:.4g} m3 differs from the height integral {expected:.4g} m3 by more "
            "than 1 %; raise geometry.max_triangles"
        )
    mesh.write_ply(
        out_dir / "penitentes.ply",
        solid,
        comment="penitente field: metres, x east, y north, z up; mean surface at z = 0",
    )
    timings["mesh_s"] = time.perf_counter() - t

    t = time.perf_counter()
    summary_metrics = field_metrics(grown, cfg)
    radius = metrics.crest_radius(cfg.optical_efolding_depth)
    history = {
        "day": grown.snapshot_days.tolist(),
        **metrics.season_history(grown.snapshots, spacing, radius),
        **morphology.stage_history(grown.snapshots, spacing),
    }
    aspects = metrics.aspect_table(h, spacing)
    summary_metrics.update(
        {
            "initial_relief_m": float(2 * np.sqrt(2) * h0.std()),
            "mean_lowering_m": float(-(h.mean() - h0.mean())),
            "melt_fraction_mean": float(grown.melt.mean()),
            "slope_clamp_fraction": grown.clamp_fraction,
            "max_change_per_frozen_period_m": grown.max_daily_change,
            "grid_spacing_m": spacing,
            "triangles": int(len(solid.faces)),
            "triangles_before_decimation": full_triangles,
            "mesh_volume_m3": volume,
            "height_integral_volume_m3": expected,
        }
    )
    timings["metrics_s"] = time.perf_counter() - t

    t = time.perf_counter()
    preview.save_metrics_plot(out_dir / "metrics.png", h, spacing, grown.relief_history, summary_metrics, history)
    preview.save_hillshade(
        out_dir / "hillshade.png",
        h,
        spacing,
        cfg.preview_size,
        f"grown field, {cfg.latitude:.1f}° lat, {cfg.days} days (north up)",
    )
    noon_sun = sunpath.sun_vector(cfg.latitude, float(sunpath.declination(cfg.start_day_of_year + cfg.days - 1)), 0.0)
    preview.render_preview(
        out_dir / "preview.png",
        solid,
        noon_sun,
        cfg.preview_size,
        f"penitentes, {cfg.latitude:.1f}° lat, day {cfg.days}; arrow: noon sun",
    )
    preview.save_timelapse(
        out_dir / "timelapse.mp4",
        grown.snapshots,
        grown.snapshot_days,
        spacing,
        cfg.timelapse_fps,
        stages=history["stage"],
    )
    timings["pictures_s"] = time.perf_counter() - t
    timings["total_s"] = time.perf_counter() - t0
    write_json_atomic(
        out_dir / "metrics.json",
        {
            "metrics": summary_metrics,
            "timings_s": timings,
            "relief_history_m": (2 * np.sqrt(2) * grown.relief_history).tolist(),
            "season_history": history,
            "aspect_histogram": aspects,
        },
    )
    log.info(
        "geometry: crest-to-trough %.2f m, crest spacing %.2f m (ratio %.2f), %d triangles in %.1f s",
        summary_metrics["crest_to_trough_m"],
        summary_metrics["crest_spacing_m"],
        summary_metrics["spacing_to_height"],
        len(solid.faces),
        timings["total_s"],
    )
    return {
        "relief_m": summary_metrics["relief_m"],
        "crest_to_trough_m": summary_metrics["crest_to_trough_m"],
        "row_spacing_m": summary_metrics["row_spacing_m"],
        "spacing_to_height": summary_metrics["spacing_to_height"],
        "dominant_wavelength_m": summary_metrics["dominant_wavelength_m"],
        "crest_spacing_m": summary_metrics["crest_spacing_m"],
        "crest_density_per_m2": summary_metrics["crest_density_per_m2"],
        "ridge_deviation_from_east_west_deg": summary_metrics["ridge_deviation_from_east_west_deg"],
        "lean_north_deg": summary_metrics["lean_north_deg"],
        "field_albedo": summary_metrics["field_albedo"],
        "triangles": int(len(solid.faces)),
        "timings_s": {k: round(v, 3) for k, v in timings.items()},
    }
