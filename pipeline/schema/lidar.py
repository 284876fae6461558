"""A laser altimeter over the scene's snow: the lidar stage (render/lidar/LIDAR.md)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from pipeline.schema.base import StrictModel


class LidarConfig(StrictModel):
    """One instrument over one target (key path lidar.<field>). A run with ``enabled`` grows the field
    (when the target is the penitentes) and runs the lidar stage; it renders no camera view."""

    enabled: bool = Field(False, description="Run the lidar stage instead of the scene -> compare chain [-].")
    target: Literal["penitentes", "flat_snow", "bare"] = Field(
        "penitentes",
        description="penitentes: the grown field (tiled periodically to cover the footprint); flat_snow: a flat "
        "half-space of the same snow; bare: an opaque Lambertian flat surface, the zero-bias check [-].",
    )
    density: float = Field(300.0, gt=50, lt=917, description="Snow density [kg m-3].")
    optical_diameter: float = Field(
        5e-4, gt=1e-5, le=5e-3, description="Optical grain diameter d = 6 / (rho_ice SSA) [m]."
    )
    form: Literal["isotropic_reduced", "full"] = Field(
        "isotropic_reduced",
        description="Phase function: isotropic with sigma_s' = sigma_s (1 - g) (the diffusion-exact form the "
        "dense snow renders with), or Henyey-Greenstein with the 532 nm g [-].",
    )
    bare_albedo: float = Field(0.5, gt=0, le=1, description="target bare: Lambertian albedo [-].")
    footprint_diameter: float = Field(11.0, gt=0.01, le=100, description="Laser footprint, 1/e2 diameter [m].")
    film_side_footprints: float = Field(
        2.0,
        ge=1.2,
        le=6,
        description="Side of the square the receiver film covers, in footprint diameters (2: the Gaussian weighs "
        "3e-4 of its peak at the edge) [-].",
    )
    pixels: int = Field(64, ge=4, le=1024, description="Receiver film pixels per side [px].")
    pulse_fwhm_ns: float = Field(1.5, gt=0, le=100, description="Gaussian pulse, full width at half maximum [ns].")
    range_bin: float = Field(0.005, gt=1e-4, le=0.5, description="Width of a waveform bin in range c t / 2 [m].")
    tail_range: float = Field(
        1.5, gt=0, le=50, description="Range recorded below the lowest surface point: the subsurface tail [m]."
    )
    first_return_threshold: float = Field(
        0.5, gt=0, lt=1, description="First-return estimator: fraction of the pulsed waveform's peak [-]."
    )
    group_index: float | None = Field(
        None,
        ge=1,
        le=2,
        description="The snow's clock: time per metre of path in the homogenised snow, in units of 1/c (the snow "
        "medium's region index). null: (1 - phi) + B phi n_g, phi = density/917, B = 1.6, n_g the group index of "
        "ice at 532 nm, for all three channels (render/lidar/LIDAR.md §5.1); 1: the index-matched clock, light at "
        "c [-].",
    )
    depth: float | None = Field(
        None,
        gt=0,
        le=50,
        description="Snow below the lowest surface point [m]; null: six diffusion lengths 1/mu_eff at 532 nm, at "
        "least 1 m [-].",
    )
    iterations: int = Field(64, ge=1, le=10**7, description="Render iterations (one path per film pixel each) [-].")
    time_budget_s: float | None = Field(
        None, gt=0, description="Stop the render after this many seconds instead of counting iterations [s]."
    )
    path_max_survival: float = Field(
        0.999,
        gt=0.9,
        lt=1,
        description="Roulette survival cap per collision of the shot's camera paths [-]. A path that scatters N times "
        "gains weight as e^(N (1 - cap)); in fine-grained snow late paths scatter thousands of times, so 0.9999 "
        "removes their fireflies at over twice the time (render/lidar/LIDAR.md §8).",
    )

    @model_validator(mode="after")
    def _pulse_resolved(self) -> LidarConfig:
        fwhm_range = 0.5 * 0.299792458 * self.pulse_fwhm_ns
        if self.range_bin > fwhm_range / 4:
            raise ValueError(
                f"lidar.range_bin {self.range_bin} m does not resolve a {self.pulse_fwhm_ns} ns pulse "
                f"({fwhm_range:.3g} m of range at half maximum); use at most {fwhm_range / 4:.3g} m"
            )
        return self
