"""Which stage a field is at: pitted, suncups or penitentes (DESIGN.md 7, *Stages*).

Pure numpy (scipy.ndimage for the labelling). Heights [m], slopes [deg]; the grid is periodic.
"""

from __future__ import annotations

import numpy as np

from geometry import irradiance, metrics

# Thresholds of stage_label, justified in DESIGN.md 7, *Stages*, from the demo's fields on days 0-120.
PITTED_MIN_SPACING_TO_HEIGHT = 3.0  # forms shallower than a third of their spacing are pits in a flat surface
PITTED_MAX_SKEWNESS = -1.0  # or pits cut into a plateau: a long tail of low heights ...
PITTED_MIN_UPPER_THIRD = 0.5  # ... with most of the ground still in the top third of the range
PENITENTE_MAX_CONNECTIVITY = 0.6  # the top third falls apart into separate blades and rows
NEAR_FLAT_DEG = 15.0
STAGES = ("pitted", "suncups", "penitentes")


def height_skewness(h: np.ndarray) -> float:
    """Third standardised moment of the heights over all cells [-]: negative for pits in a plateau,
    positive for blades over wide troughs, 0 for a sinusoid."""
    deviation = np.asarray(h, float) - np.mean(h)
    variance = float(np.mean(deviation**2))
    return float(np.mean(deviation**3) / variance**1.5) if variance > 0 else 0.0


def upper_third(h: np.ndarray) -> np.ndarray:
    """Cells in the top third of the height range, the 1-99 % range of metrics.relief: a lone spike or pit
    does not move it, and a finer grid, which resolves sharper extremes, hardly does."""
    lo, hi = np.percentile(h, [1.0, 99.0])
    return np.asarray(h) > lo + 2.0 / 3.0 * (hi - lo)


def slope_deg(h: np.ndarray, spacing: float) -> np.ndarray:
    """Slope angle of each cell from central differences on the periodic grid [deg]."""
    p, q = irradiance.gradient(h, spacing)
    return np.degrees(np.arctan(np.hypot(p, q)))


def near_flat_upper_fraction(h: np.ndarray, spacing: float, flat_deg: float = NEAR_FLAT_DEG) -> float:
    """Share of all cells that lie in the top third of the range and slope less than flat_deg [-]: the
    plateau between hollows."""
    return float(np.mean(upper_third(h) & (slope_deg(h, spacing) < flat_deg)))


def periodic_labels(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """4-connected components of a boolean mask on a periodic grid: (labels 1..count, 0 outside; count).
    scipy labels the open grid; parts that touch across an edge are then merged."""
    from scipy import ndimage

    labels, count = ndimage.label(mask)
    parent = np.arange(count + 1)

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return int(i)

    for a, b in ((labels[0, :], labels[-1, :]), (labels[:, 0], labels[:, -1])):
        for i, j in zip(a[(a > 0) & (b > 0)], b[(a > 0) & (b > 0)]):
            ri, rj = root(int(i)), root(int(j))
            if ri != rj:
                parent[max(ri, rj)] = min(ri, rj)
    roots = np.array([root(i) for i in range(count + 1)])
    unique, merged = np.unique(roots[labels], return_inverse=True)
    merged = merged.reshape(labels.shape)
    if unique[0] != 0:  # no cell outside the mask: labels start at 1
        merged += 1
    return merged, int(unique.size - (unique[0] == 0))


def largest_part_fraction(mask: np.ndarray) -> float:
    """Area of the largest periodic 4-connected part of mask over the mask's area [-] (1 for an empty mask)."""
    labels, count = periodic_labels(mask)
    if count == 0:
        return 1.0
    sizes = np.bincount(labels.ravel())[1:]
    return float(sizes.max() / sizes.sum())


def median_set_connectivity(h: np.ndarray) -> float:
    """Largest connected part of the area above the median height, over that area [-]: 1 for one plateau
    with holes, 1/n for n separate rows or blades of equal size. Blades still joined by saddles above the
    median read 1 too, so the label reads the top third (upper_set_connectivity)."""
    return largest_part_fraction(np.asarray(h) > np.median(h))


def upper_set_connectivity(h: np.ndarray) -> float:
    """Largest connected part of the top third of the range (upper_third), over its area [-]: near 1 for the
    plateau between suncups, near 1/n for n separate blades or rows of penitentes."""
    return largest_part_fraction(upper_third(h))


def half_height_width_ratio(h: np.ndarray) -> float:
    """Blade width at half height over crest spacing, across the rows (north-south transects) [-].

    Each transect is cut at half its relief, midway between its mean crest and mean trough (crests and
    troughs as in metrics.crest_to_trough); the share of its length above that level is the mean width
    at half height over the mean spacing. 0.5 for a sinusoid, more for a plateau between hollows, less
    for knife-edged blades over wide troughs."""
    shares = []
    for profile in np.asarray(h, float).T:
        crests, troughs = metrics.mean_crossing_stretches(profile)
        if crests.size:
            level = profile.mean() + 0.5 * (crests.mean() + troughs.mean())
            shares.append(float(np.mean(profile > level)))
    return float(np.mean(shares)) if shares else float("nan")


def stage_label(spacing_to_height: float, skewness: float, upper_third_fraction: float, connectivity: float) -> str:
    """pitted, suncups or penitentes (DESIGN.md 7, *Stages*). Pitted: shallow forms (crest spacing over crest to
    trough above 3), or pits in a plateau (skewness below -1 with over half the ground in the top third).
    Penitentes: the top third in separate parts (its largest part under 60 % of it). Suncups: deep hollows in
    one connected high ground."""
    shallow = spacing_to_height > PITTED_MIN_SPACING_TO_HEIGHT
    if shallow or (skewness < PITTED_MAX_SKEWNESS and upper_third_fraction > PITTED_MIN_UPPER_THIRD):
        return "pitted"
    return "penitentes" if connectivity < PENITENTE_MAX_CONNECTIVITY else "suncups"


def stage_metrics(h: np.ndarray, spacing: float) -> dict:
    """The shape numbers that tell the stages apart, and the stage (DESIGN.md 7, *Stages*)."""
    height = metrics.crest_to_trough(h)
    spacing_to_height = metrics.crest_spacing(h, spacing) / height if height > 0 else float("inf")
    numbers = {
        "height_skewness": height_skewness(h),
        "upper_third_fraction": float(np.mean(upper_third(h))),
        "near_flat_upper_fraction": near_flat_upper_fraction(h, spacing),
        "median_set_connectivity": median_set_connectivity(h),
        "upper_set_connectivity": upper_set_connectivity(h),
        "half_height_width_to_spacing": half_height_width_ratio(h),
    }
    stage = stage_label(
        spacing_to_height,
        numbers["height_skewness"],
        numbers["upper_third_fraction"],
        numbers["upper_set_connectivity"],
    )
    return {**numbers, "stage": stage}


def stage_history(snapshots: np.ndarray, spacing: float) -> dict:
    """stage_metrics of each snapshot, as lists under the same keys."""
    rows = [stage_metrics(h, spacing) for h in snapshots]
    return {key: [row[key] for row in rows] for key in rows[0]} if rows else {}
