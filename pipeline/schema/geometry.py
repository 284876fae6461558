"""Settings of the geometry stage: site and sun, snow/ice, ablation model, numerics, mesh, pictures.

Defaults describe Tapado Glacier, Chile (30.1 deg S) from 25 Nov for 40 days on a demo-sized grid;
site presets in configs/presets/sites/ override them. Symbols follow geometry/DESIGN.md section 4.
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, model_validator

from pipeline.schema.base import StrictModel

# Cells per physical length for a grid-independent field (geometry/DESIGN.md 7, *Grid convergence*).
CELLS_PER_CORRELATION_LENGTH = 4.0
CELLS_PER_EFOLDING_DEPTH = 1.5

# Keys of the constant-loss mode that geometry.meteorology replaces (geometry/DESIGN.md 3.9).
CONSTANT_LOSS_KEYS = ("sky_loss", "turbulent_loss_share", "melt_gain_threshold")


class MeteorologyConfig(StrictModel):
    """The site's air during the season, the forcing of the surface energy balance (key path
    geometry.meteorology.<field>; geometry/DESIGN.md 3.9, *Surface energy balance*). Season means, day and night."""

    air_temperature: float = Field(
        ..., ge=-60, le=30, description="Air temperature T_a at measurement_height, season mean [degC]."
    )
    vapour_pressure: float = Field(
        ..., gt=0, le=50, description="Water-vapour pressure e_a of the air, season mean (Guanaco 1.1) [hPa]."
    )
    wind_speed: float = Field(
        ..., ge=0, le=40, description="Wind speed u at measurement_height over the open field, season mean [m s-1]."
    )
    cloud_fraction: float = Field(
        0.0, ge=0, le=1, description="Cloud cover n; it raises the sky's emissivity as n^2 (Konzelmann 1994) [-]."
    )
    air_pressure: float = Field(
        ..., ge=300, le=1100, description="Air pressure p at the site, for the air density and the humidity [hPa]."
    )
    measurement_height: float = Field(
        2.0, gt=0, le=50, description="Height z of the temperature, humidity and wind measurements [m]."
    )
    roughness_length: float = Field(
        0.002,
        gt=0,
        le=0.5,
        description="Momentum roughness length z0 of the surface between the forms; the bulk transfer coefficient "
        "is C = kappa^2 / (ln(z/z0) ln(z/z0s)) (Winkler et al. 2009: 2 mm on smooth ice) [m].",
    )
    scalar_roughness_length: float = Field(
        0.001,
        gt=0,
        le=0.5,
        description="Roughness length z0s for heat and vapour (Winkler et al. 2009: 1 mm on smooth ice) [m].",
    )
    surface_emissivity: float = Field(0.99, ge=0.9, le=1, description="Longwave emissivity eps_s of snow and ice [-].")
    still_air_shelter_deg: float = Field(
        15.0,
        gt=0,
        lt=90,
        description="Ventilation of the balance: a cell gets the wind times clip(1 - Sx / tan(theta_v), 0, 1), Sx the "
        "shelter index of the horizons beyond geometry.wake_slope, so the air is still where the surroundings rise "
        "theta_v above the wake line on average (geometry/DESIGN.md 3.9) [estimate] [deg].",
    )

    @model_validator(mode="after")
    def _check_air(self) -> MeteorologyConfig:
        if self.measurement_height <= max(self.roughness_length, self.scalar_roughness_length):
            raise ValueError(
                "geometry.meteorology.measurement_height must lie above the roughness lengths "
                f"(z = {self.measurement_height} m, z0 = {self.roughness_length} m, "
                f"z0s = {self.scalar_roughness_length} m)"
            )
        return self


class GeometryConfig(StrictModel):
    """How a penitente field is grown, meshed and pictured (key path geometry.<field>)."""

    seed: int | None = Field(
        None,
        ge=0,
        le=2**63 - 1,
        description="Seed of the grown field alone; unset: the run's seed. Set it to keep one field while the run's "
        "seed draws other render noise, e.g. independent renders of the same field for error bars or a "
        "reference (benchmarks/crop_quality.py does) [-].",
    )
    # Site and season
    latitude: float = Field(-30.1, ge=-89.0, le=89.0, description="Site latitude phi, negative south [deg].")
    start_day_of_year: int = Field(
        329, ge=1, le=366, description="First simulated day (1 = 1 January; 329 = 25 Nov) [day]."
    )
    days: int = Field(40, ge=1, le=400, description="Simulated days of sun [day].")
    sun_positions_per_day: int = Field(12, ge=1, le=96, description="Sun positions sampling each day's daylight [-].")
    horizon_refreshes_per_day: int = Field(
        1, ge=1, le=24, description="Horizon/sky-view recomputations per day; geometry is frozen in between [-]."
    )
    direct_normal_irradiance: float = Field(
        1000.0, gt=0, le=1400, description="Clear-sky direct normal irradiance S_b with the sun at the zenith [W m-2]."
    )
    optical_depth: float = Field(
        0.08,
        ge=0,
        le=2,
        description="Broadband extinction per extra air mass, S_b(e) = S_b exp(-tau (1/sin e - 1)) [-].",
    )
    diffuse_fraction: float = Field(
        0.07, ge=0, le=1, description="Diffuse sky on a level surface as a fraction of S_b sin(e), S_d [-]."
    )

    # Material
    albedo: float = Field(
        0.55, gt=0, lt=1, description="Local broadband albedo a of a flat patch (snow 0.8, glacier ice 0.55) [-]."
    )
    density: float = Field(880.0, ge=50, le=917, description="Bulk density rho (snow 350-600, ice 830-917) [kg m-3].")

    # Ablation model
    ablation_efficiency: float = Field(
        1.0,
        gt=0,
        le=1,
        description="Fraction eps of the absorbed shortwave left after geometry.sky_loss that is spent on ablation; "
        "with sky_loss = 0 it alone stands for the longwave and turbulent losses (~0.5) [-].",
    )
    sky_loss: float = Field(
        90.0,
        ge=0,
        le=500,
        description="Net longwave + turbulent loss of a facet open to the sky, averaged over 24 h. Each facet loses it "
        "times its sky view factor and each day only the absorbed shortwave above that ablates (on flat "
        "Tapado ice this leaves ~46 % of the absorbed shortwave); 0 folds the loss into "
        "ablation_efficiency [W m-2].",
    )
    meteorology: MeteorologyConfig | None = Field(
        None,
        description="The site's air; when set, a surface energy balance per cell (longwave, sensible and latent heat "
        "in the wind each cell sees) decides how much of the absorbed light ablates and whether it melts or "
        "sublimates, replacing sky_loss, turbulent_loss_share and melt_gain_threshold (geometry/DESIGN.md 3.9); "
        "null: the constant loss to the sky [-].",
    )
    melt_enabled: bool = Field(
        True, description="Lliboutry switch on; false = sublimation only (cold lab, planets) [-]."
    )
    switch_proxy: Literal["shelter", "sky_view", "openness"] = Field(
        "shelter",
        description="Sheltering proxy of the Lliboutry switch: 'shelter' reads ventilation from the shelter index "
        "Sx (mean over azimuths of how far the surroundings rise above the point beyond the wake slope), first "
        "order in the relief, so a lower blade among taller ones starts to melt; 'openness' (sky view of a level "
        "receiver) and 'sky_view' (the facet's own) depart from 1 only at second order [-].",
    )
    shelter_full_melt_deg: float = Field(
        45.0,
        gt=0,
        lt=90,
        description="Shelter proxy: mean rise of the surroundings above the wake slope at which the air is still "
        "and the surface fully melts, w = Sx / tan(theta_m) [deg].",
    )
    wake_slope: float = Field(
        1.0 / 6.0,
        ge=0,
        le=1,
        description="Shelter proxy: slope of the separated wake behind a crest; a crest shelters points below a "
        "line falling 1 in 6 from it, the flow reattaching ~6 step heights downstream of a backward-facing step "
        "(Le, Moin & Kim 1997) [-].",
    )
    turbulent_loss_share: float = Field(
        0.5,
        ge=0,
        le=1,
        description="Share of geometry.sky_loss that is turbulent (sensible + latent) exchange with the wind; it "
        "stops where the air is still, so a facet loses sky_loss x V_sky x (1 - share x w). The rest is net "
        "longwave [estimate] [-].",
    )
    melt_gain_threshold: float = Field(
        1.0,
        ge=0,
        le=10,
        description="Melt needs a net gain: in each horizon period a cell melts only as far as its mean absorbed "
        "shortwave exceeds this multiple of its loss rate sky_loss x V_sky (opening over 50 W m-2); below it the "
        "surface stays under 0 C and sublimates. 1 is the physical choice and gives the 65 S latitude null "
        "(geometry/DESIGN.md 3.9); 0 = off, every sheltered cell melts, whatever the sun (the model before "
        "issue 27) [-].",
    )
    switch_centre: float = Field(
        0.85, gt=0, lt=1, description="Sky-view proxies: switch centre V_c, below it cells start to melt [-]."
    )
    switch_width: float = Field(
        0.3, gt=0, le=1, description="Sky-view proxies: switch width dV, melt is complete at V_c - dV [-]."
    )
    optical_efolding_depth: float = Field(
        0.06,
        ge=0,
        le=10,
        description="e-folding depth l of absorbed sunlight, z_e = 1/k_e of render/scene/OPTICS.md §5, broadband "
        "(absorption-weighted: near-infrared mm, visible 0.3-1 m in bubbly ice) [estimate]. Diffuse light spreads "
        "the absorbed energy over l, 1/(1 + (k l)^2) in Fourier space, so the wavelength that grows first is "
        "lambda* = 2 pi l (geometry/DESIGN.md 3.10); 0 = no spreading [m].",
    )
    diffusivity: float = Field(
        0.0,
        ge=0,
        le=1e-5,
        description="Diffusive regulariser D; with A_B it selects lambda* = 4 pi D / A_B. Runs on flux time like A_B. "
        "Without A_B it only smooths, and at metre-field grids it rounds the 2-4 cell blade walls [m2 s-1].",
    )
    hyperdiffusivity: float = Field(0.0, ge=0, le=1e-8, description="Fourth-order regulariser K [m4 s-1].")
    scattered_light_coefficient: float = Field(
        0.0,
        ge=0,
        le=1e-5,
        description="Betterton kernel coefficient A_B = 0.5 F/(rho L) at the reference flux; 0 = off [m s-1].",
    )
    scattered_light_reference_flux: float = Field(
        1000.0,
        gt=0,
        description="Horizontal flux F at which A_B and D apply; both run on flux time (the time integral of the "
        "actual horizontal flux over F), so lambda* = 4 pi D / A_B at any sun [W m-2].",
    )
    max_slope_deg: float = Field(
        85.0, gt=45, lt=90, description="Slope clamp of the height field (overhang limit) [deg]."
    )

    # Grid, initial state and numerics
    grid_cells: int = Field(128, ge=16, le=2048, description="Cells per side of the periodic square grid N [-].")
    domain_size: float = Field(8.0, gt=0, le=1e4, description="Side L of the periodic domain [m].")
    initial_roughness_rms: float = Field(
        0.02,
        gt=0,
        description="RMS height of the initial roughness, correlated over initial_correlation_length "
        "(geometry/DESIGN.md 3.12) [m].",
    )
    initial_correlation_length: float | None = Field(
        0.15,
        gt=0,
        description="Correlation length lc of the initial roughness, C(r) = rms^2 exp(-r^2/lc^2): the start is one "
        "continuous random surface, the same at every grid for one seed, and grids with cells of at most lc/4 "
        "resolve it (geometry/DESIGN.md 3.12, 7). Glacier ice at the season's start [estimate]. null = white "
        "noise, whose slopes grow as the cells shrink (linear-stability starts such as the lab preset) [m].",
    )
    initial_wavelength: float | None = Field(
        None,
        gt=0,
        description="Override: centre of a band-limited initial noise, which then imposes the spacing (it takes "
        "precedence over initial_correlation_length); null (the default) lets the growth select the spacing [m].",
    )
    azimuths: int = Field(16, ge=8, le=64, description="Horizon azimuths M [-].")
    bounces: int = Field(2, ge=0, le=8, description="Terrain-reflection (radiosity) bounces n_b [-].")
    cfl: float = Field(0.5, gt=0, le=1, description="Hamilton-Jacobi CFL number of the recession sub-steps [-].")
    slope_order: Literal[1, 2] = Field(
        2,
        description="Order of the upwind slopes of the recession and the direct beam: 2 second-order ENO with a minmod switch (the default), 1 "
        "first-order upwind, whose numerical diffusion shrinks with the cell and made the field follow the grid "
        "(geometry/DESIGN.md 6.1, 7) [-].",
    )
    snapshots: int = Field(24, ge=2, le=400, description="Height-field snapshots kept for the time-lapse [-].")

    # Mesh
    base_thickness: float = Field(2.0, gt=0, description="Solid below the deepest trough (>= 5 e-folding depths) [m].")
    max_triangles: int = Field(
        60000, ge=1000, le=20_000_000, description="Triangle budget of the PLY; larger meshes are decimated [-]."
    )
    mesh_tiles: int = Field(1, ge=1, le=8, description="Periodic copies of the field per side in the mesh [-].")

    # Pictures
    preview_size: int = Field(800, ge=128, le=4096, description="Width of preview.png and hillshade.png [px].")
    timelapse_fps: int = Field(8, ge=1, le=60, description="Frame rate of timelapse.mp4 [frames/s].")

    @property
    def spacing(self) -> float:
        """Grid spacing [m]."""
        return self.domain_size / self.grid_cells

    def resolution_warnings(self) -> list[str]:
        """Why this grid may not hold a grid-independent field, with a grid that would (geometry/DESIGN.md 7,
        *Grid convergence*): cells must resolve the start's correlation length and the e-folding depth l."""
        warnings = []
        lengths = []  # (config key, physical length [m], cells it needs)
        if self.initial_wavelength is None and self.initial_correlation_length is not None:
            lengths.append(
                ("geometry.initial_correlation_length", self.initial_correlation_length, CELLS_PER_CORRELATION_LENGTH)
            )
        if self.melt_enabled and self.optical_efolding_depth > 0:
            lengths.append(("geometry.optical_efolding_depth", self.optical_efolding_depth, CELLS_PER_EFOLDING_DEPTH))
        if lengths:
            key, length, cells = min(lengths, key=lambda entry: entry[1] / entry[2])
            finest = length / cells
            if self.spacing > finest * (1.0 + 1e-9):
                grid = 1 << math.ceil(math.log2(self.domain_size / finest))
                warnings.append(
                    f"geometry.grid_cells = {self.grid_cells} gives {100 * self.spacing:.3g} cm cells, coarser than "
                    f"{key} / {cells:g} = {100 * finest:.3g} cm ({key} = {length} m): the grown field then depends on "
                    f"the grid. Set geometry.grid_cells: {grid} (or shrink geometry.domain_size to "
                    f"{self.grid_cells * finest:.3g} m) to resolve it"
                )
        if self.melt_enabled and self.initial_wavelength is None and self.initial_correlation_length is None:
            warnings.append(
                "geometry.initial_correlation_length is null: a white-noise start steepens and loses its long waves "
                "as the cells shrink, so the grown field follows the grid; set a correlation length (Tapado 0.15 m)"
            )
        if self.slope_order == 1:
            warnings.append(
                "geometry.slope_order = 1: first-order upwind slopes carry a numerical diffusion that shrinks with "
                "the cell, so the season runs late on coarse grids (6.25 cm cells: H and the albedo drop a third and "
                "a half short); set geometry.slope_order: 2"
            )
        return warnings

    @model_validator(mode="after")
    def _check_resolution(self) -> GeometryConfig:
        spacing = self.domain_size / self.grid_cells
        if self.initial_wavelength is not None and self.initial_wavelength < 4 * spacing:
            raise ValueError(
                f"geometry.initial_wavelength ({self.initial_wavelength} m) must span at least 4 cells "
                f"({4 * spacing:.4g} m); raise it or raise geometry.grid_cells"
            )
        if self.initial_wavelength is not None and self.initial_wavelength > self.domain_size / 2:
            raise ValueError(
                f"geometry.initial_wavelength ({self.initial_wavelength} m) must fit twice in "
                f"geometry.domain_size ({self.domain_size} m)"
            )
        if self.switch_width > self.switch_centre:
            raise ValueError("geometry.switch_width must not exceed geometry.switch_centre")
        if self.meteorology is not None:
            # A key at its default is not a choice (a dumped config carries every key), so only changed ones clash.
            both = [
                f"geometry.{key}"
                for key in CONSTANT_LOSS_KEYS
                if key in self.model_fields_set and getattr(self, key) != type(self).model_fields[key].default
            ]
            if both:
                raise ValueError(
                    f"{', '.join(both)} and geometry.meteorology are both set: the surface energy balance of "
                    "geometry.meteorology replaces the constant loss to the sky. Remove "
                    f"{', '.join(both)}, or set geometry.meteorology: null to keep the constant loss"
                )
        return self
