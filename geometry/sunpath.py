"""Where the sun is: declination, hour angle, and the sun's unit vector in the local frame.

Frame: x = east, y = north, z = up (metres elsewhere, unit vectors here). Latitude is negative in
the southern hemisphere; azimuths are clockwise from north (east = 90 deg). Formulas follow
DESIGN.md section 3.2 (Cooper 1969 declination).
"""

from __future__ import annotations

import datetime
from dataclasses import dataclass

import numpy as np

SECONDS_PER_DAY = 86400.0


def calendar_day(day_of_year: int) -> str:
    """A day of the year on the model's 365-day calendar, as a date: 1 -> '1 Jan', 355 -> '21 Dec'; days
    past 365 wrap into the next year."""
    date = datetime.date(2025, 1, 1) + datetime.timedelta(days=(int(day_of_year) - 1) % 365)  # 2025: 365 days
    return f"{date.day} {date:%b}"


def declination(day_of_year: float | np.ndarray) -> np.ndarray:
    """Solar declination [rad] on a day of the year (1 = 1 January), Cooper's formula."""
    return np.radians(23.45) * np.sin(2.0 * np.pi * (284.0 + np.asarray(day_of_year, float)) / 365.0)


def sun_vector(latitude: float, declination_rad: float | np.ndarray, hour_angle: float | np.ndarray) -> np.ndarray:
    """Unit vector toward the sun (east, north, up), shape (..., 3).

    latitude [deg], declination_rad [rad], hour_angle [rad] (0 at solar noon, positive afternoon).
    """
    phi = np.radians(latitude)
    delta = np.asarray(declination_rad, float)
    omega = np.asarray(hour_angle, float)
    east = -np.cos(delta) * np.sin(omega)
    north = np.cos(phi) * np.sin(delta) - np.sin(phi) * np.cos(delta) * np.cos(omega)
    up = np.sin(phi) * np.sin(delta) + np.cos(phi) * np.cos(delta) * np.cos(omega)
    return np.stack(np.broadcast_arrays(east, north, up), axis=-1)


def elevation_azimuth(sun: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Elevation [rad] above the horizon and azimuth [rad, clockwise from north] of sun vectors (..., 3)."""
    sun = np.asarray(sun, float)
    elevation = np.arcsin(np.clip(sun[..., 2], -1.0, 1.0))
    azimuth = np.mod(np.arctan2(sun[..., 0], sun[..., 1]), 2.0 * np.pi)
    return elevation, azimuth


def daylight_half_angle(latitude: float, declination_rad: float) -> float:
    """Hour angle of sunset [rad]: 0 in polar night, pi in polar day."""
    x = -np.tan(np.radians(latitude)) * np.tan(declination_rad)
    return float(np.arccos(np.clip(x, -1.0, 1.0)))


def noon_zenith_angle(latitude: float, declination_rad: float) -> float:
    """Solar zenith angle at local noon [rad]: |latitude - declination|."""
    return abs(np.radians(latitude) - declination_rad)


def growth_weighted_noon_zenith(latitude: float, start_day_of_year: int, relief_history: np.ndarray) -> float:
    """Noon zenith angle [rad] of a season averaged over its days, each weighted by that day's rise of the
    RMS relief (``relief_history``: RMS height before day 1 and after each day [m]). The lean is carved
    while the relief grows, so this is the sun the walls were cut under (DESIGN.md 7, V3); days when the
    relief fell or stood still weigh nothing. Falls back to the plain season mean if the relief never grew."""
    growth = np.maximum(np.diff(np.asarray(relief_history, float)), 0.0)
    days = start_day_of_year + np.arange(growth.size)
    zenith = np.array([noon_zenith_angle(latitude, float(declination(float(day)))) for day in days])
    if growth.sum() <= 0.0:
        return float(zenith.mean())
    return float(np.sum(zenith * growth) / growth.sum())


@dataclass(frozen=True)
class DailySun:
    """Sun positions that sample one day's daylight, each standing for an equal share of it."""

    vectors: np.ndarray  # (n, 3) unit vectors toward the sun (east, north, up)
    durations: np.ndarray  # (n,) seconds of daylight each position stands for [s]
    hour_angles: np.ndarray  # (n,) [rad]
    declination: float  # [rad]

    @property
    def elevations(self) -> np.ndarray:
        return elevation_azimuth(self.vectors)[0]

    @property
    def azimuths(self) -> np.ndarray:
        return elevation_azimuth(self.vectors)[1]


def daily_sun_positions(latitude: float, day_of_year: float, positions_per_day: int) -> DailySun:
    """Sample the daylight of one day at ``positions_per_day`` hour angles, evenly spaced.

    Midpoint sampling keeps every position above the horizon; each stands for daylight/n seconds.
    """
    if positions_per_day < 1:
        raise ValueError(f"geometry.sun_positions_per_day must be at least 1, got {positions_per_day}")
    delta = float(declination(day_of_year))
    half = daylight_half_angle(latitude, delta)
    if half <= 0.0:
        empty = np.zeros((0,))
        return DailySun(np.zeros((0, 3)), empty, empty, delta)
    step = 2.0 * half / positions_per_day
    hour_angles = -half + step * (np.arange(positions_per_day) + 0.5)
    vectors = sun_vector(latitude, delta, hour_angles)
    durations = np.full(positions_per_day, step / (2.0 * np.pi) * SECONDS_PER_DAY)
    keep = vectors[:, 2] > 0.0
    return DailySun(vectors[keep], durations[keep], hour_angles[keep], delta)
