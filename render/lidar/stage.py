"""The lidar stage: one laser shot over the target, rendered backwards (render/lidar/scene.py), its
waveform with the pulse applied, the range each estimator gives and its bias against the surface's
reference heights (render/lidar/LIDAR.md).

The renderer's three channels carry three lasers at once, the same snow seen through different ice
absorption (``CHANNELS``): 532 nm with Warren & Brandt 2008, 532 nm with Picard et al. 2016 and 1064 nm with
Warren & Brandt 2008. Scattering is the same at both lines (grains far larger than either wavelength);
only absorption differs, and so one set of paths serves all three. They share one clock too, the snow's
group index at 532 nm (``group_index_of``): 1064 nm's is 0.4–0.6 % smaller at 300–550 kg m⁻³, and light
there barely enters the snow.
"""

from __future__ import annotations

import csv
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np

from common.atomic import atomic_path, write_json_atomic
from common.memory import PeakMemory
from render.lidar.optics import SnowOptics, snow_group_index, snow_optics
from render.lidar.scene import Receiver, bins_for, medium, receiver_weights, shot_scene
from render.lidar.waveform import (
    REFERENCES,
    ReferenceHeights,
    bias_table,
    convolve_pulse,
    estimate_ranges,
    pulse_sigma_opl,
)

log = logging.getLogger(__name__)

CHANNELS = (
    ("532 nm, Warren & Brandt 2008", 532.0, "warren_brandt_2008"),
    ("532 nm, Picard et al. 2016", 532.0, "picard_2016"),
    ("1064 nm, Warren & Brandt 2008", 1064.0, "warren_brandt_2008"),
)
REFERENCE_MARGIN = 0.1  # the reference plane stands at least this far above the highest surface point [m]
PULSE_MARGIN_SIGMAS = 5.0  # and the film reaches this many of the pulse's standard deviations beyond the surfaces


def channel_optics(cfg) -> list[SnowOptics]:
    """The snow of each channel (``CHANNELS``) from ``lidar.density`` and ``lidar.optical_diameter``."""
    return [snow_optics(cfg.density, cfg.optical_diameter, wl, ice_data_set=data) for _, wl, data in CHANNELS]


def group_index_of(cfg, optics: list[SnowOptics]) -> float:
    """The snow's clock (``lidar.group_index``): set, or (1 − φ) + B φ n_g of the 532 nm channel's snow."""
    if cfg.group_index is not None:
        return float(cfg.group_index)
    snow = optics[0]
    return snow_group_index(snow.density, snow.absorption_enhancement, snow.wavelength_nm)


def snow_medium(optics: list[SnowOptics], form: str, group_index: float = 1.0) -> dict[str, Any]:
    """The core's medium: per channel, isotropic with sigma_s' (``isotropic_reduced``) or Henyey-Greenstein
    with sigma_s and the 532 nm channel's g (``full``; g is one number per medium in the core), its clock
    running at ``group_index``."""
    absorption = tuple(o.absorption for o in optics)
    if form == "isotropic_reduced":
        return medium(tuple(o.reduced_scattering for o in optics), absorption, 0.0, group_index)
    return medium(tuple(o.scattering for o in optics), absorption, optics[0].asymmetry, group_index)


def diffusion_depth(optics: SnowOptics) -> float:
    """Six diffusion lengths 1/mu_eff, mu_eff = sqrt(3 sigma_a sigma_s'), and at least 1 m: the snow a shot
    needs below its surface for light not to reach the bottom (e^-6 of the flux)."""
    mu_eff = math.sqrt(3.0 * optics.absorption * optics.reduced_scattering)
    return max(1.0, 6.0 / mu_eff)


def _field(geometry_dir: Path) -> tuple[np.ndarray, float]:
    path = geometry_dir / "heightfield.npz"
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing; run the geometry stage again (--stage geometry --force)")
    with np.load(path) as data:
        return np.asarray(data["height"], np.float64), float(data["spacing"])


def plan_shot(cfg, optics: list[SnowOptics], geometry_dir: Path | None) -> tuple[dict, Receiver, dict]:
    """The core scene of the shot, its receiver and what the analysis needs to know of the surface: the
    heights in the scene's frame (the field's mean at z = 0), the footprint's centre in the field, tiles."""
    side = cfg.film_side_footprints * cfg.footprint_diameter
    depth = cfg.depth if cfg.depth is not None else diffusion_depth(optics[0])
    bin_width_opl = 2.0 * cfg.range_bin
    snow = snow_medium(optics, cfg.form, group_index_of(cfg, optics))
    if cfg.target == "penitentes":
        from geometry.mesh import heightfield_solid

        if geometry_dir is None:
            raise ValueError("lidar.target penitentes needs the geometry stage; enable scene.objects' penitentes")
        heights, spacing = _field(geometry_dir)
        period = heights.shape[0] * spacing
        # Tile the periodic field until it covers the film and a metre of snow around it for the light
        # that wanders sideways (render/lidar/LIDAR.md §7.3).
        tiles = max(1, math.ceil((side + 2.0) / period))
        relief = heights - heights.mean()
        solid = heightfield_solid(heights, spacing, depth, tiles=tiles)
        centre = (0.5 * tiles * period, 0.5 * tiles * period)
        top, bottom = float(relief.max()), float(relief.min())
        surface = {
            "relief": relief,
            "spacing": spacing,
            "tiles": tiles,
            "centre_in_field": (centre[0] % period, centre[1] % period),
        }
        mesh = (np.asarray(solid.vertices, np.float32), np.asarray(solid.faces, np.uint32))
    else:
        centre, top, bottom, mesh, surface = (0.0, 0.0), 0.0, 0.0, None, {"relief": None, "tiles": 0}
    # The pulse spreads the return by its sigma (in range, half its OPL): the film holds it whole on both sides.
    margin = max(REFERENCE_MARGIN, PULSE_MARGIN_SIGMAS * 0.5 * pulse_sigma_opl(cfg.pulse_fwhm_ns))
    z_ref = top + margin
    span = 2.0 * (z_ref - bottom + cfg.tail_range + margin)
    receiver = Receiver(centre, side, cfg.pixels, z_ref, bin_width_opl, bins_for(span, bin_width_opl))
    scene = shot_scene(cfg.target, receiver, snow=snow, mesh=mesh, bare_albedo=cfg.bare_albedo, depth=depth)
    surface["depth"] = depth
    return scene, receiver, surface


def reference_heights_of(cfg, surface: dict, receiver: Receiver) -> ReferenceHeights:
    """The surface's reference heights inside the footprint, in the scene's frame."""
    if surface["relief"] is None:  # flat: every reference is the plane z = 0
        return ReferenceHeights(0.0, 0.0, 0.0)
    from render.lidar.waveform import reference_heights

    return reference_heights(surface["relief"], surface["spacing"], cfg.footprint_diameter, surface["centre_in_field"])


def run_lidar_stage(cfg, out_dir: Path, *, geometry_dir: Path | None, seed: int, threads: int, quiet: bool) -> dict:
    """Render the shot, then write waveform.npz/.csv, biases.csv/.md, waveform.png and return the summary."""
    with PeakMemory() as memory:
        summary = _lidar(cfg, out_dir, geometry_dir, seed, threads, quiet)
    return {**summary, **memory.record()}


def _lidar(cfg, out_dir: Path, geometry_dir: Path | None, seed: int, threads: int, quiet: bool) -> dict:
    from render.ptpb.api import render

    optics = channel_optics(cfg)
    scene, receiver, surface = plan_shot(cfg, optics, geometry_dir)
    settings: dict[str, Any] = {
        "iterations": cfg.iterations,
        "frame_mode": "bins",
        "max_depth": -1,
        "seed": seed,
        "threads": threads,
        "medium_estimator": "paths",
        "path_max_survival": cfg.path_max_survival,
    }
    if cfg.time_budget_s is not None:
        settings.update(iterations=10**7, time_budget_s=cfg.time_budget_s)
    log.info(
        "lidar: %s, footprint %.3g m on a %d px film of %.3g m, %d bins of %.3g m range, snow %.3g m deep%s",
        cfg.target,
        cfg.footprint_diameter,
        receiver.pixels,
        receiver.side,
        receiver.temporal_bins,
        cfg.range_bin,
        surface["depth"],
        f", field tiled {surface['tiles']} x {surface['tiles']}" if surface["tiles"] else "",
    )
    result = render(scene, settings, progress=not quiet)
    weights = receiver_weights(receiver, cfg.footprint_diameter)
    impulse = np.einsum("thwc,hw->tc", result.frames.astype(np.float64), weights)
    late = np.einsum("hwc,hw->c", np.asarray(result.late, np.float64), weights)
    early = np.einsum("hwc,hw->c", np.asarray(result.early, np.float64), weights)
    pulsed = convolve_pulse(impulse, receiver.bin_width_opl, cfg.pulse_fwhm_ns, axis=0)
    references = reference_heights_of(cfg, surface, receiver)
    ranges = (np.arange(receiver.temporal_bins) + 0.5) * cfg.range_bin
    channels = []
    for c, (label, wavelength, data_set) in enumerate(CHANNELS):
        estimates = estimate_ranges(
            pulsed[:, c],
            0.0,
            receiver.bin_width_opl,
            threshold=cfg.first_return_threshold,
            pulse_fwhm_ns=cfg.pulse_fwhm_ns,
        )
        total = float(impulse[:, c].sum() + late[c] + early[c])
        channels.append(
            {
                "label": label,
                "wavelength_nm": wavelength,
                "ice_data_set": data_set,
                "optics": {
                    "sigma_s_per_m": optics[c].scattering,
                    "sigma_a_per_m": optics[c].absorption,
                    "g": optics[c].asymmetry,
                    "reduced_scattering_per_m": optics[c].reduced_scattering,
                    "transport_mean_free_path_m": optics[c].transport_mean_free_path,
                },
                "apparent_reflectance": math.pi * total,
                "late_fraction": float(late[c]) / total if total > 0 else 0.0,
                "estimates": estimates.to_dict(),
                "bias_m": bias_table(estimates, references, receiver.reference_height),
            }
        )
    _write_waveforms(out_dir, ranges, impulse, pulsed, receiver)
    _write_biases(out_dir, channels)
    _plot(out_dir / "waveform.png", ranges, pulsed, channels, references, receiver, cfg)
    summary = {
        "config": cfg.model_dump(),
        "target": cfg.target,
        "reference_height_m": receiver.reference_height,
        "reference_heights_m": references.to_dict(),
        "film": {
            "pixels": receiver.pixels,
            "side_m": receiver.side,
            "bins": receiver.temporal_bins,
            "range_bin_m": cfg.range_bin,
        },
        "tiles": surface["tiles"],
        "snow_depth_m": surface["depth"],
        "group_index": scene["media"][0]["ior"] if scene["media"] else 1.0,
        "channels": channels,
        "render": {k: result.stats[k] for k in ("iterations", "time_total_s") if k in result.stats},
    }
    write_json_atomic(out_dir / "summary.json", summary)
    return summary


def _write_waveforms(
    out_dir: Path, ranges: np.ndarray, impulse: np.ndarray, pulsed: np.ndarray, receiver: Receiver
) -> None:
    with atomic_path(out_dir / "waveform.npz") as tmp, open(tmp, "wb") as f:
        np.savez(
            f,
            range_m=ranges,
            impulse=impulse,
            pulsed=pulsed,
            bin_width_opl=receiver.bin_width_opl,
            reference_height=receiver.reference_height,
            channels=np.array([c[0] for c in CHANNELS]),
        )
    with atomic_path(out_dir / "waveform.csv") as tmp, open(tmp, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["range_m", *[f"impulse {c[0]}" for c in CHANNELS], *[f"pulsed {c[0]}" for c in CHANNELS]])
        for r, a, b in zip(ranges, impulse, pulsed):
            writer.writerow([f"{r:.6f}", *[f"{v:.6e}" for v in a], *[f"{v:.6e}" for v in b]])


def _write_biases(out_dir: Path, channels: list[dict]) -> None:
    rows = [
        (ch["label"], estimator, reference, value)
        for ch in channels
        for estimator, by_reference in ch["bias_m"].items()
        for reference, value in by_reference.items()
    ]
    with atomic_path(out_dir / "biases.csv") as tmp, open(tmp, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["channel", "estimator", "reference", "bias_m"])
        writer.writerows([(a, b, c, f"{d:.5f}") for a, b, c, d in rows])
    lines = ["| channel | estimator | " + " | ".join(REFERENCES) + " |", "|---|---|" + "---|" * len(REFERENCES)]
    for ch in channels:
        for estimator, by_reference in ch["bias_m"].items():
            cells = " | ".join(f"{100 * by_reference[r]:+.1f}" for r in REFERENCES)
            lines.append(f"| {ch['label']} | {estimator} | {cells} |")
    text = "Range bias in cm (estimated range minus the range to each reference height; positive: too low)\n\n"
    with atomic_path(out_dir / "biases.md") as tmp:
        Path(tmp).write_text(text + "\n".join(lines) + "\n", encoding="utf-8")


def _plot(path: Path, ranges, pulsed, channels, references: ReferenceHeights, receiver: Receiver, cfg) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4), dpi=150)
    depth = ranges - receiver.reference_height  # range below the reference plane -> height = -depth
    for c, ch in enumerate(channels):
        peak = pulsed[:, c].max()
        ax.plot(-depth, pulsed[:, c] / peak if peak > 0 else pulsed[:, c], label=ch["label"], lw=1.2)
    for name, h in references.to_dict().items():
        ax.axvline(h, ls=":", color="0.4", lw=0.8)
        ax.annotate(name.replace("_", " "), (h, 1.02), rotation=90, fontsize=6, ha="right", va="bottom", color="0.3")
    ax.set_xlabel("height of the return [m] (range below the reference plane, negated)")
    ax.set_ylabel("pulsed waveform / its peak")
    ax.set_title(f"{cfg.target}: {cfg.footprint_diameter:g} m footprint, {cfg.pulse_fwhm_ns:g} ns pulse", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
