"""Morphology and radiative metrics of a grown field (DESIGN.md 7, V3 and V4).

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


def _peak_wavelength(k: np.ndarray, power: np.ndarray, first: int) -> float:
    """Wavelength [m] at the largest of power[first:], refined by a parabola in log power."""
    i = int(np.argmax(power[first:]) + first)
    peak = float(i)
    if first <= i - 1 and i + 1 < len(power) and np.all(power[i - 1 : i + 2] > 0):
        a, b, c = np.log(power[i - 1 : i + 2])
        denom = a - 2.0 * b + c
        if denom < 0:
            peak = i + 0.5 * (a - c) / denom
    return float(2.0 * np.pi / (peak * k[1]))


def dominant_wavelength(h: np.ndarray, spacing: float) -> float:
    """Wavelength [m] at the peak of the radially averaged spectrum, refined by a parabola in log power
    (V1: the band selected by the penetration length). As in row_spacing the search starts at L/2: the
    one cycle of the fundamental is the domain, not a repeat, so the answer is never the domain size."""
    k, power = radial_power_spectrum(h, spacing)
    if power.size < 4:
        raise ValueError(f"a dominant wavelength needs a grid of at least 6 cells per side, got {h.shape}")
    return _peak_wavelength(k, power, 2)


def gain_spectrum(h: np.ndarray, h0: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Radially averaged log power gain of each Fourier mode since ``h0``: (|k| bin centres [rad m-1],
    mean over the bin of ln(|h_k|^2 / |h0_k|^2) [-]), bins as in radial_power_spectrum.

    Pre-whitening mode by mode: in a linear phase ln gain = 2 sigma(k) t exactly, whatever the random
    start gave each mode, so the bins' means follow the growth rate after any time, where the raw
    spectrum needs several e-folding times before the fastest band stands above the start's scatter
    (DESIGN.md 7, V1). Bins with no mode, and the mean (k = 0), read 0."""
    n = h.shape[0]
    gain = np.log(
        np.divide(
            np.abs(np.fft.fft2(h - h.mean())) ** 2,
            np.abs(np.fft.fft2(h0 - h0.mean())) ** 2,
            out=np.ones(h.shape),
            where=np.abs(np.fft.fft2(h0 - h0.mean())) > 0,
        ).clip(1e-300)
    )
    f = np.fft.fftfreq(n, d=1.0 / n)
    fy, fx = np.meshgrid(f, f, indexing="ij")
    index = np.rint(np.hypot(fx, fy)).astype(int)
    nbins = n // 2 + 1
    sums = np.bincount(index.ravel(), weights=gain.ravel(), minlength=nbins)[:nbins]
    counts = np.bincount(index.ravel(), minlength=nbins)[:nbins]
    mean = np.divide(sums, counts, out=np.zeros(nbins), where=counts > 0)
    mean[0] = 0.0
    return np.arange(nbins) * 2.0 * np.pi / (n * spacing), mean


def fastest_growing_wavelength(h: np.ndarray, h0: np.ndarray, spacing: float) -> float:
    """Wavelength [m] at the peak of gain_spectrum (search from L/2, as dominant_wavelength), refined by a
    parabola through the peak bin and its neighbours."""
    k, gain = gain_spectrum(h, h0, spacing)
    i = int(np.argmax(gain[2:]) + 2)
    peak = float(i)
    if 2 <= i - 1 and i + 1 < gain.size:
        a, b, c = gain[i - 1 : i + 2]
        denom = a - 2.0 * b + c
        if denom < 0:
            peak = i + 0.5 * (a - c) / denom
    return float(2.0 * np.pi / (peak * k[1]))


def _transects(h: np.ndarray, axis: int) -> np.ndarray:
    """The straight transects along ``axis`` (0: north-south columns, 1: east-west rows), one a row."""
    profiles = np.moveaxis(np.asarray(h, float), axis, 0)
    return profiles.reshape(profiles.shape[0], -1).T


def transect_power_spectrum(h: np.ndarray, spacing: float, axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Mean power spectrum of the grid's straight transects along ``axis`` (0: north-south columns,
    1: east-west rows), each less its own mean: (k [rad m-1] at 0, k_1, ..., (n/2) k_1; power per
    bin [m2], one-sided, so that it sums to the mean transect variance)."""
    profiles = _transects(h, axis)
    n = profiles.shape[1]
    spectrum = np.abs(np.fft.rfft(profiles - profiles.mean(axis=1, keepdims=True), axis=1)) ** 2 / n**2
    power = spectrum.mean(axis=0)
    power[1 : (n + 1) // 2] *= 2.0  # fold in the negative wavenumbers
    return np.arange(power.size) * 2.0 * np.pi / (n * spacing), power


def row_spacing(h: np.ndarray, spacing: float) -> float:
    """lambda_dom of V3 for east-west rows [m]: the wavelength at the peak of the north-south
    transect spectrum (DESIGN.md 7 allows it in place of the radial average), refined by a
    parabola in log power.

    Across E-W rows the N-S spectrum holds the rows' power on every transect, where the radial
    average spreads it over a ring that is empty away from the k_y axis. The search starts at L/2:
    a spacing is a repeat, and the one cycle of the fundamental (lambda = L) is not one. That bin
    holds the mean-height undulation between more and less developed patches, and the domain is
    meant to hold 8-16 spacings (DESIGN.md 4), not one. Grown fields have a broad N-S spectrum,
    nearly flat from the crest spacing up to the domain, so the peak moves from seed to seed;
    crest_spacing is the steadier figure.
    """
    k, power = transect_power_spectrum(h, spacing, axis=0)
    if power.size < 4:
        raise ValueError(f"row spacing needs a grid of at least 6 cells per side, got {h.shape}")
    return _peak_wavelength(k, power, 2)


def mean_crossing_stretches(profile: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Crests (highest point of each stretch above the profile's mean) and troughs (lowest of each
    stretch below it) of one periodic profile, as deviations from its mean [m]."""
    deviation = profile - profile.mean()
    above = deviation > 0
    starts = np.flatnonzero(above != np.roll(above, 1))
    if starts.size < 2:
        return np.zeros(0), np.zeros(0)
    deviation, above, starts = np.roll(deviation, -starts[0]), np.roll(above, -starts[0]), starts - starts[0]
    crest_stretch = above[starts]
    return (
        np.maximum.reduceat(deviation, starts)[crest_stretch],
        np.minimum.reduceat(deviation, starts)[~crest_stretch],
    )


def crest_to_trough(h: np.ndarray, axis: int = 0) -> float:
    """H of V3: mean crest-to-trough relief along the transects of ``axis`` (0: north-south) [m].

    Each transect is cut where it crosses its own mean; the highest point of a stretch above the
    mean is a crest, the lowest of a stretch below it a trough. H is the mean crest less the mean
    trough, averaged over transects. For a sinusoid it is 2 x amplitude, as 2 sqrt 2 RMS is
    (relief); for thin blades between wide flat troughs it stays the blade height, where
    2 sqrt 2 RMS falls short, and for flat-topped walls it does not overshoot as RMS does.
    """
    heights = [
        crests.mean() - troughs.mean()
        for crests, troughs in map(mean_crossing_stretches, _transects(h, axis))
        if crests.size
    ]
    return float(np.mean(heights)) if heights else 0.0


def crest_spacing(h: np.ndarray, spacing: float, axis: int = 0) -> float:
    """Mean distance between successive crests along the transects of ``axis`` (0: north-south) [m]:
    transect length over its number of crests (as in crest_to_trough). A check on row_spacing that
    needs no spectral peak; it is inf where no transect crosses its mean."""
    counts = [crests.size for crests, _ in map(mean_crossing_stretches, _transects(h, axis))]
    mean_count = float(np.mean(counts))
    return h.shape[axis] * spacing / mean_count if mean_count > 0 else float("inf")


def crest_radius(efolding_depth: float) -> float:
    """Half the onset wavelength, pi l [m]: two maxima closer than this are one form, since nothing narrower
    than l ablates apart from its surroundings (DESIGN.md 3.10, 7 *Grid convergence*)."""
    return float(np.pi * efolding_depth)


def crest_density(h: np.ndarray, spacing: float, radius: float = 0.0) -> float:
    """Crests per m^2 [m-2]: points above the mean surface and higher than every other point within
    ``radius`` [m] (periodic), at least their 8 neighbours. Where forms merge the count falls (V5).

    With radius 0 a crest is any cell above its 8 neighbours, so the count grows with every bump the grid
    resolves; crest_radius(l) counts the forms the growth makes, whatever the cell (DESIGN.md 7)."""
    from scipy import ndimage

    reach = max(radius, spacing * np.sqrt(2.0)) / spacing
    r = int(np.floor(reach + 1e-9))
    y, x = np.mgrid[-r : r + 1, -r : r + 1]
    footprint = x * x + y * y <= reach * reach + 1e-9
    footprint[r, r] = False
    neighbourhood = ndimage.maximum_filter(h, footprint=footprint, mode="wrap")
    peak = (h > neighbourhood) & (h > h.mean())
    return float(peak.sum()) / (h.size * spacing**2)


def season_history(snapshots: np.ndarray, spacing: float, crest_radius: float = 0.0) -> dict:
    """Spacing, height and crest count of each snapshot (V5): crest_spacing_m and crest_to_trough_m
    across the rows (N-S transects), their ratio, and crest_density_per_m2 (crests within ``crest_radius``
    [m] counted once)."""
    spacings = [crest_spacing(h, spacing) for h in snapshots]
    heights = [crest_to_trough(h) for h in snapshots]
    return {
        "crest_spacing_m": spacings,
        "crest_to_trough_m": heights,
        "spacing_to_height": [s / hh if hh > 0 else float("inf") for s, hh in zip(spacings, heights)],
        "crest_density_per_m2": [crest_density(h, spacing, crest_radius) for h in snapshots],
    }


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
    return {"ridge_azimuth_deg": ridge_azimuth, "ridge_deviation_from_east_west_deg": deviation, "coherence": coherence}


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
        return {
            "lean_north_deg": float("nan"),
            "north_wall_slope_deg": float("nan"),
            "south_wall_slope_deg": float("nan"),
            "steep_fraction": float(steep.mean()),
        }
    beta_n, beta_s = float(np.median(slope[north])), float(np.median(slope[south]))
    return {
        "lean_north_deg": 0.5 * (beta_n - beta_s),
        "north_wall_slope_deg": beta_n,
        "south_wall_slope_deg": beta_s,
        "steep_fraction": float(steep.mean()),
    }


def _extremum_positions(profile: np.ndarray) -> list[tuple[bool, int, float]]:
    """(is_crest, index, deviation) of the highest point of each stretch above a periodic profile's mean
    and of the lowest point of each stretch below it, in order; indices may run past the profile's end."""
    deviation = profile - profile.mean()
    above = deviation > 0
    starts = np.flatnonzero(above != np.roll(above, 1))
    if starts.size < 2:
        return []
    bounds = np.append(starts, starts[0] + profile.size)
    out = []
    for begin, end in zip(bounds[:-1], bounds[1:]):
        stretch = deviation[np.arange(begin, end) % profile.size]
        crest = bool(above[begin % profile.size])
        j = int(np.argmax(stretch) if crest else np.argmin(stretch))
        out.append((crest, int(begin + j), float(stretch[j])))
    return out


def axis_lean(h: np.ndarray, spacing: float) -> float:
    """Blade lean from the crest offset (V3's alternative, DESIGN.md 7): along each north-south transect,
    each crest's distance north of the midpoint between the troughs on either side, over its height
    above them; tau = atan(sum of offsets / sum of heights) over the crests taller than half the median
    [deg, positive = leaning north]. Unlike lean(), it reads the blade's axis, not its walls' slopes,
    so a grid that rounds the walls does not bias it. NaN where no transect has a crest between troughs."""
    offsets, heights = [], []
    for profile in _transects(h, 0):
        extrema = _extremum_positions(profile)
        for i, (crest, position, value) in enumerate(extrema):
            south, north = extrema[i - 1], extrema[(i + 1) % len(extrema)]
            if not crest or south[0] or north[0] or len(extrema) < 4:
                continue
            south_at = south[1] - (profile.size if i == 0 else 0)
            north_at = north[1] + (profile.size if i + 1 == len(extrema) else 0)
            offsets.append((position - 0.5 * (south_at + north_at)) * spacing)
            heights.append(value - 0.5 * (south[2] + north[2]))
    if not heights:
        return float("nan")
    offset, height = np.array(offsets), np.array(heights)
    tall = height > 0.5 * np.median(height)
    return float(np.degrees(np.arctan2(offset[tall].sum(), height[tall].sum())))


def relief(h: np.ndarray) -> dict:
    """RMS height, the relief 2 sqrt 2 RMS (crest to trough of near-sinusoidal rows, DESIGN.md V3)
    and the 1-99 % range [m]."""
    rms = float(np.std(h))
    lo, hi = np.percentile(h, [1, 99])
    return {"rms_height_m": rms, "relief_m": 2.0 * np.sqrt(2.0) * rms, "range_1_99_m": float(hi - lo)}


def aspect_histogram(
    h: np.ndarray, spacing: float, bins: int = 36, steep_deg: float = 30.0
) -> tuple[np.ndarray, np.ndarray]:
    """Histogram of downslope azimuth [deg] over steep facets: (bin edges, fraction per bin)."""
    p, q = irradiance.gradient(h, spacing)
    slope = np.degrees(np.arctan(np.hypot(p, q)))
    aspect = np.degrees(np.mod(np.arctan2(-p, -q), 2.0 * np.pi))
    counts, edges = np.histogram(aspect[slope > steep_deg], bins=bins, range=(0.0, 360.0))
    return edges, counts / max(counts.sum(), 1)


def aspect_table(h: np.ndarray, spacing: float, bins: int = 36, steep_deg: float = 30.0) -> dict:
    """aspect_histogram as JSON-able lists, to compare with Nicholson et al. (2016) (DESIGN.md 8)."""
    edges, fraction = aspect_histogram(h, spacing, bins, steep_deg)
    return {"bin_edges_deg": edges.tolist(), "fraction": fraction.tolist(), "steep_deg": steep_deg}


def morphology(h: np.ndarray, spacing: float, crest_radius: float = 0.0) -> dict:
    """All shape metrics of one field in a flat dict. spacing_to_height is V3's lambda_dom / H with
    lambda_dom = crest_spacing and H = crest_to_trough (both across the rows, north-south): a grown
    field's N-S spectrum is broad and its peak (row_spacing) jumps between bins from seed to seed,
    where the crest count is steady (DESIGN.md 7). crest_radius [m]: see crest_density."""
    out = relief(h)
    out["crest_to_trough_m"] = crest_to_trough(h, axis=0)
    out["row_spacing_m"] = row_spacing(h, spacing)
    out["crest_spacing_m"] = crest_spacing(h, spacing, axis=0)
    out["dominant_wavelength_m"] = dominant_wavelength(h, spacing)
    out["crest_density_per_m2"] = crest_density(h, spacing, crest_radius)
    out.update(ridge_orientation(h, spacing))
    out.update(lean(h, spacing))
    out["axis_lean_north_deg"] = axis_lean(h, spacing)
    height = out["crest_to_trough_m"]
    out["spacing_to_height"] = out["crest_spacing_m"] / height if height > 0 else float("inf")
    return out
