"""Morphology and radiative metrics of a grown field (penitentes.md 7, V3 and V4).

Angles are reported in degrees; azimuths clockwise from north. Heights [m], wavelengths [m].
"""
from __future__ import annotations

import numpy as np

from geometry import irradiance


def radial_power_spectrum(h: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Radially averaged power spectrum: (|k| bin centres [rad m-1], mean power [m2 x m2]).

    Bins are one fundamental wavenumber 2 pi / L wide, so bin i holds |k| in ((i - 1/2), (i + 1/2)) k_1.
    """
    n = h.shape[0]
    power = np.abs(np.fft.fft2(h - h.mean())) ** 2 / n**4
    k1 = 2.0 * np.pi / (n * spacing)
    f = np.fft.fftfreq(n, d=1.0 / n)
    fy, fx = np.meshgrid(f, f, indexing="ij")
    index = np.rint(np.hypot(fx, fy)).astype(int)
    nbins = n // 2 + 1
    sums = np.bincount(index.ravel(), weights=power.ravel(), minlength=nbins)[:nbins]
    counts = np.bincount(index.ravel(), minlength=nbins)[:nbins]
    mean = np.divide(sums, counts, out=np.zeros(nbins), where=counts > 0)
    return np.arange(nbins) * k1, mean


def dominant_wavelength(h: np.ndarray, spacing: float) -> float:
    """Wavelength [m] at the peak of the radially averaged spectrum, refined by a parabola in log power."""
    k, power = radial_power_spectrum(h, spacing)
    i = int(np.argmax(power[1:]) + 1)
    peak = float(i)
    if 1 < i < len(power) - 1 and np.all(power[i - 1:i + 2] > 0):
        a, b, c = np.log(power[i - 1:i + 2])
        denom = a - 2.0 * b + c
        if denom < 0:
            peak = i + 0.5 * (a - c) / denom
    return float(2.0 * np.pi / (peak * k[1]))


def ridge_orientation(h: np.ndarray, spacing: float) -> dict:
    """Structure-tensor orientation: ridges run perpendicular to the dominant gradient direction.

    Returns ridge azimuth in [0, 180) deg, its deviation from east-west [deg, 0..90] and the
    coherence C in [0, 1] (0 isotropic, 1 perfectly parallel rows).
    """
    p, q = irradiance.gradient(h, spacing)
    jxx, jyy, jxy = float(np.mean(p * p)), float(np.mean(q * q)), float(np.mean(p * q))
    trace = jxx + jyy
    coherence = float(np.sqrt((jxx - jyy) ** 2 + 4 * jxy**2) / trace) if trace > 0 else 0.0
    # Major eigenvector angle from the x (east) axis; ridges are perpendicular to it.
    gradient_angle = 0.5 * np.arctan2(2 * jxy, jxx - jyy)
    gradient_azimuth = np.degrees(0.5 * np.pi - gradient_angle)
    ridge_azimuth = float(np.mod(gradient_azimuth + 90.0, 180.0))
    deviation = float(min(abs(ridge_azimuth - 90.0), 180.0 - abs(ridge_azimuth - 90.0)))
    return {"ridge_azimuth_deg": ridge_azimuth, "ridge_deviation_from_east_west_deg": deviation,
            "coherence": coherence}


def lean(h: np.ndarray, spacing: float, steep_deg: float = 30.0, sector_deg: float = 45.0) -> dict:
    """Blade lean from wall asymmetry (V3): tau = (beta_N - beta_S) / 2 with beta the median slope of
    steep (> steep_deg) north- and south-facing facets. Positive = leaning north [deg]."""
    p, q = irradiance.gradient(h, spacing)
    slope = np.degrees(np.arctan(np.hypot(p, q)))
    aspect = np.degrees(np.mod(np.arctan2(-p, -q), 2.0 * np.pi))  # downslope azimuth
    steep = slope > steep_deg
    north = steep & ((aspect < sector_deg) | (aspect > 360.0 - sector_deg))
    south = steep & (np.abs(aspect - 180.0) < sector_deg)
    if north.sum() < 10 or south.sum() < 10:
        return {"lean_north_deg": float("nan"), "north_wall_slope_deg": float("nan"),
                "south_wall_slope_deg": float("nan"), "steep_fraction": float(steep.mean())}
    beta_n, beta_s = float(np.median(slope[north])), float(np.median(slope[south]))
    return {"lean_north_deg": 0.5 * (beta_n - beta_s), "north_wall_slope_deg": beta_n,
            "south_wall_slope_deg": beta_s, "steep_fraction": float(steep.mean())}


def relief(h: np.ndarray) -> dict:
    """RMS height, crest-to-trough relief (2 sqrt 2 RMS, penitentes.md V3) and the 1-99 % range [m]."""
    rms = float(np.std(h))
    lo, hi = np.percentile(h, [1, 99])
    return {"rms_height_m": rms, "relief_m": 2.0 * np.sqrt(2.0) * rms, "range_1_99_m": float(hi - lo)}


def aspect_histogram(h: np.ndarray, spacing: float, bins: int = 36, steep_deg: float = 30.0) -> tuple[np.ndarray, np.ndarray]:
    """Histogram of downslope azimuth [deg] over steep facets: (bin edges, fraction per bin)."""
    p, q = irradiance.gradient(h, spacing)
    slope = np.degrees(np.arctan(np.hypot(p, q)))
    aspect = np.degrees(np.mod(np.arctan2(-p, -q), 2.0 * np.pi))
    counts, edges = np.histogram(aspect[slope > steep_deg], bins=bins, range=(0.0, 360.0))
    return edges, counts / max(counts.sum(), 1)


def morphology(h: np.ndarray, spacing: float) -> dict:
    """All shape metrics of one field in a flat dict."""
    out = relief(h)
    out["dominant_wavelength_m"] = dominant_wavelength(h, spacing)
    out.update(ridge_orientation(h, spacing))
    out.update(lean(h, spacing))
    out["spacing_to_height"] = out["dominant_wavelength_m"] / out["relief_m"] if out["relief_m"] > 0 else float("inf")
    return out
