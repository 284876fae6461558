"""Photon counting: the shots of an ICESat-2-like beam drawn from a rendered impulse response (LIDAR.md §9).

ATLAS records photon events, not waveforms. Per shot a beam returns a Poisson number of signal photons whose
arrival times follow the impulse response seen through the pulse, plus solar background photons spread evenly in
time, and each detector channel is blind for a dead time after it fires. Pure numpy, no I/O.

    LinkBudget, Beam, STRONG, WEAK       the instrument (values and sources: LIDAR.md §9.1)
    signal_photons_per_shot(...)         mean detected signal photons of one shot from the impulse response
    background_rate(...)                 detected solar background photons per second (0 at night)
    draw_shots(...)                      photon events of shots, keyed by (seed, shot index)
    apply_dead_time(...)                 the non-paralysable dead time of each channel

Heights are in the impulse response's frame: a photon that travelled OPL L from the reference plane z = z_ref is
placed at z_ref − L/2. Random numbers come from one stream per (seed, shot index), so a shot's photons do not
depend on which other shots are drawn with it (chunking) or in what order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.units import SPEED_OF_LIGHT
from render.lidar.waveform import pulse_sigma_opl

PLANCK = 6.62607015e-34  # J s, exact (SI 2019)


@dataclass(frozen=True)
class LinkBudget:
    """The radiometry shared by every beam (LIDAR.md §9.1 gives each value's source or marks it assumed)."""

    wavelength: float = 532e-9  # [m]
    photons_per_pulse: float = 300e12  # all six beams together, leaving the instrument [-]
    telescope_diameter: float = 0.8  # [m]
    altitude: float = 500e3  # range to the surface at nadir [m]
    optical_efficiency: float = 0.5  # receiver optics and filter, assumed [-]
    detector_efficiency: float = 0.15  # photon detection probability of a channel, assumed [-]
    atmospheric_transmission: float = 0.9  # one way, clear polar air, assumed [-]
    pulse_fwhm_ns: float = 1.5  # transmitted pulse with the detector's timing jitter [ns]
    shot_spacing: float = 0.7  # along track, 10 kHz at about 7 km/s ground speed [m]
    filter_bandwidth_nm: float = 0.03  # receiver passband, assumed [nm]
    field_of_view: float = 83e-6  # receiver full angle, assumed [rad]
    solar_irradiance: float = 1.85  # top of atmosphere at 532 nm, assumed [W m-2 nm-1]

    @property
    def photon_energy(self) -> float:
        """hc/λ [J]."""
        return PLANCK * SPEED_OF_LIGHT / self.wavelength

    @property
    def collection(self) -> float:
        """Telescope area over range squared [sr] times the two-way atmosphere and the receiver's efficiencies."""
        area = math.pi * self.telescope_diameter**2 / 4.0
        efficiency = self.atmospheric_transmission**2 * self.optical_efficiency * self.detector_efficiency
        return area / self.altitude**2 * efficiency


@dataclass(frozen=True)
class Beam:
    """One ATLAS beam: its share of the transmitted photons, its detector channels and their dead time."""

    name: str
    energy_share: float  # of LinkBudget.photons_per_pulse [-]
    channels: int  # independent detector channels (pixels) [-]
    dead_time_ns: float  # per channel, non-paralysable [ns]

    @property
    def dead_time_opl(self) -> float:
        """The dead time as optical path [m] (c·τ; τ/2 of it in range)."""
        return SPEED_OF_LIGHT * self.dead_time_ns * 1e-9


# Three strong and three weak beams, strong ≈ 4 × weak in energy: 4/15 and 1/15 of the pulse each. The dead time
# is the ATBD reference code's detector model (t_dead = 3.2 ns; LIDAR.md §9.1).
STRONG = Beam("strong", 4.0 / 15.0, 16, 3.2)
WEAK = Beam("weak", 1.0 / 15.0, 4, 3.2)


def signal_photons_per_shot(impulse, beam: Beam, budget: LinkBudget = LinkBudget()) -> float:
    """Mean detected signal photons of one shot: N_tx · Σ_k I_k · A/R² · T² η_opt η_det.

    ``impulse`` is the footprint's impulse response in radiance per unit irradiance per bin [sr⁻¹] (the lidar
    stage's ``waveform.npz`` ``impulse``); Σ I_k = (apparent reflectance)/π, so a Lambertian plane of albedo a
    gives N_tx · (a/π) · A/R² · T² η_opt η_det.
    """
    total = float(np.sum(np.asarray(impulse, dtype=np.float64)))
    if not (math.isfinite(total) and total >= 0):
        raise ValueError(f"the impulse response must be finite and non-negative, its sum is {total}")
    return budget.photons_per_pulse * beam.energy_share * total * budget.collection


def background_rate(albedo: float, sun_elevation_deg: float | None, budget: LinkBudget = LinkBudget()) -> float:
    """Detected solar background photons per second of one beam [Hz]; ``sun_elevation_deg`` None (night): 0.

    Sunlight E·sin(elevation)·Δλ, attenuated once on the way down, reflected by a Lambertian surface of
    ``albedo`` (radiance a·E/π) and seen over the receiver's field of view Ω = π(θ/2)² with the telescope area
    A, attenuated once more on the way up: R = E sin e Δλ · T · (a/π) · Ω A · T η_opt η_det / (hc/λ).
    """
    if sun_elevation_deg is None or sun_elevation_deg <= 0:
        return 0.0
    downwelling = budget.solar_irradiance * math.sin(math.radians(sun_elevation_deg)) * budget.filter_bandwidth_nm
    solid_angle = math.pi * (0.5 * budget.field_of_view) ** 2
    area = math.pi * budget.telescope_diameter**2 / 4.0
    efficiency = budget.atmospheric_transmission**2 * budget.optical_efficiency * budget.detector_efficiency
    return downwelling * albedo / math.pi * solid_angle * area * efficiency / budget.photon_energy


@dataclass(frozen=True)
class PhotonEvents:
    """Photon events of a set of shots, ordered by shot. Heights [m] in the impulse response's frame."""

    shot: np.ndarray  # int64 shot index
    height: np.ndarray  # float64 [m]
    channel: np.ndarray  # int16 detector channel of the beam
    signal: np.ndarray  # bool: from the laser (True) or the sun (False)

    def __len__(self) -> int:
        return int(self.shot.size)

    def subset(self, keep: np.ndarray) -> PhotonEvents:
        return PhotonEvents(self.shot[keep], self.height[keep], self.channel[keep], self.signal[keep])


def _cumulative(impulse: np.ndarray) -> np.ndarray:
    weights = np.clip(np.asarray(impulse, dtype=np.float64), 0.0, None)
    total = weights.sum()
    if not total > 0:
        raise ValueError("the impulse response holds no energy: nothing to draw photons from")
    return np.cumsum(weights) / total


def draw_shots(
    shots,
    impulses,
    bin_width_opl: float,
    reference_height: float,
    beam: Beam,
    *,
    seed: int,
    budget: LinkBudget = LinkBudget(),
    background_hz: float = 0.0,
    window: tuple[float, float] = (-15.0, 15.0),
    surface_offset=None,
    impulse_index=None,
    dead_time: bool = True,
) -> PhotonEvents:
    """Photon events of ``shots`` (indices) seen by ``beam`` (LIDAR.md §9.2).

    ``impulses`` is one impulse response (bins of ``bin_width_opl`` from OPL 0, [sr⁻¹]) or several (n, bins);
    ``impulse_index[i]`` picks the one shot i sees (default 0). ``surface_offset[i]`` [m] lifts shot i's returns
    (a slope along track). Per shot, from the stream keyed by (seed, shot index):

    1. signal: Poisson(N̄) photons, N̄ = ``signal_photons_per_shot``; each photon's OPL is a bin drawn with the
       impulse response's weights, uniform within the bin, plus the Gaussian pulse (FWHM ``pulse_fwhm_ns``);
    2. background: Poisson(R · 2ΔH/c) photons uniform over the telemetry ``window`` (heights about the shot's
       surface offset, as ATLAS's telemetry band follows the surface; ΔH its span);
    3. a channel, uniform over the beam's channels, for every photon;

    then photons outside the window are dropped (the telemetry band) and, with ``dead_time``, each channel's
    dead time is applied (``apply_dead_time``).
    """
    shot_index = np.asarray(shots, dtype=np.int64).ravel()
    table = np.atleast_2d(np.asarray(impulses, dtype=np.float64))
    cumulative = [_cumulative(row) for row in table]
    means = np.array([signal_photons_per_shot(row, beam, budget) for row in table])
    which = np.zeros(shot_index.size, np.int64) if impulse_index is None else np.asarray(impulse_index, np.int64)
    offset = np.zeros(shot_index.size) if surface_offset is None else np.asarray(surface_offset, np.float64)
    low, high = window
    if not high > low:
        raise ValueError(f"the telemetry window must be (lowest, highest) height in metres, got {window}")
    background_mean = background_hz * 2.0 * (high - low) / SPEED_OF_LIGHT
    sigma_opl = pulse_sigma_opl(budget.pulse_fwhm_ns)
    heights, shot_of, channels, is_signal, lifted = [], [], [], [], []
    for i, shot in enumerate(shot_index):
        rng = np.random.default_rng([int(seed), int(shot)])
        n_signal = rng.poisson(means[which[i]])
        n_background = rng.poisson(background_mean)
        bins = np.searchsorted(cumulative[which[i]], rng.random(n_signal), side="right")
        opl = (bins + rng.random(n_signal)) * bin_width_opl + sigma_opl * rng.standard_normal(n_signal)
        signal_heights = reference_height - 0.5 * opl + offset[i]
        background_heights = low + (high - low) * rng.random(n_background) + offset[i]
        count = n_signal + n_background
        heights.append(np.concatenate((signal_heights, background_heights)))
        channels.append(rng.integers(0, beam.channels, count))
        is_signal.append(np.arange(count) < n_signal)
        shot_of.append(np.full(count, shot, np.int64))
        lifted.append(np.full(count, offset[i]))
    if not heights:
        empty = np.zeros(0)
        return PhotonEvents(empty.astype(np.int64), empty, empty.astype(np.int16), empty.astype(bool))
    events = PhotonEvents(
        np.concatenate(shot_of),
        np.concatenate(heights),
        np.concatenate(channels).astype(np.int16),
        np.concatenate(is_signal),
    )
    band = events.height - np.concatenate(lifted)  # heights about each shot's surface offset
    events = events.subset((band >= low) & (band <= high))
    return apply_dead_time(events, beam.dead_time_opl) if dead_time else events


def apply_dead_time(events: PhotonEvents, dead_time_opl: float) -> PhotonEvents:
    """Keep the photons a non-paralysable detector records: in each (shot, channel), a photon arriving less than
    the dead time (``dead_time_opl`` of OPL, i.e. half of it in height) after the last recorded one is lost.
    Arrival order is falling height. Vectorised over channels: one pass per rank of arrival within a channel."""
    if len(events) == 0 or dead_time_opl <= 0:
        return events
    arrival_opl = -2.0 * events.height  # later arrival = lower height; only differences matter
    order = np.lexsort((arrival_opl, events.channel, events.shot))
    shot, channel, arrival = events.shot[order], events.channel[order], arrival_opl[order]
    new_group = np.ones(shot.size, bool)
    new_group[1:] = (shot[1:] != shot[:-1]) | (channel[1:] != channel[:-1])
    group = np.cumsum(new_group) - 1
    starts = np.flatnonzero(new_group)
    rank = np.arange(shot.size) - starts[group]
    kept = np.zeros(shot.size, bool)
    last = np.full(starts.size, -np.inf)
    for r in range(int(rank.max()) + 1):
        at = np.flatnonzero(rank == r)
        live = arrival[at] - last[group[at]] >= dead_time_opl
        kept[at[live]] = True
        last[group[at[live]]] = arrival[at[live]]
    keep = np.zeros(shot.size, bool)
    keep[order[kept]] = True
    return events.subset(keep)


__all__ = [
    "STRONG",
    "WEAK",
    "Beam",
    "LinkBudget",
    "PhotonEvents",
    "apply_dead_time",
    "background_rate",
    "draw_shots",
    "signal_photons_per_shot",
]
