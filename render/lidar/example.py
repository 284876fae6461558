"""The worked example of LIDAR.md §6: ρ = 300 kg/m³, d = 0.5 mm, 532 nm. Regenerate its numbers with

    python -m render.lidar.example

Optics from render.lidar.optics, diffusion from render.lidar.diffusion, and a 1.5 ns pulse through the
area-integrated response (a footprint much wider than ℓ* on flat snow) for the estimators of render.lidar.waveform.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

from render.lidar.diffusion import (
    Boundary,
    bin_average,
    mean_path_length,
    mode_path_length,
    reflectance_time_integral,
    total_reflectance,
)
from render.lidar.optics import SnowOptics, snow_optics
from render.lidar.waveform import RangeEstimates, convolve_pulse, estimate_ranges

PULSE_FWHM_NS = 1.5  # ICESat-2 ATLAS (lidar.md section 1)
WINDOW_OPL = 20.0  # m of OPL after the surface: 10 m of range, where an altimeter's window would end
BIN_WIDTH_OPL = 1e-3  # m


@dataclass(frozen=True)
class BoundaryExample:
    boundary: Boundary
    albedo: float  # ∫ R dL [-]
    mean_path: float  # ⟨L⟩ [m]
    mean_range_bias: float  # ⟨L⟩/2 [m]
    mode_range_bias: float  # mode of R(L) / 2 [m]
    estimates: RangeEstimates  # 1.5 ns pulse, window of WINDOW_OPL; ranges from the surface [m]


def boundary_example(snow: SnowOptics, boundary: Boundary) -> BoundaryExample:
    medium = snow.diffusion_medium(boundary)
    start = -1.0  # the surface sits at OPL 0: a range is then a bias against the flat surface
    bins = round((WINDOW_OPL - start) / BIN_WIDTH_OPL)
    impulse = BIN_WIDTH_OPL * bin_average(partial(total_reflectance, medium), start, BIN_WIDTH_OPL, bins)
    waveform = convolve_pulse(impulse, BIN_WIDTH_OPL, PULSE_FWHM_NS)
    return BoundaryExample(
        boundary=boundary,
        albedo=reflectance_time_integral(medium),
        mean_path=mean_path_length(medium),
        mean_range_bias=0.5 * mean_path_length(medium),
        mode_range_bias=0.5 * mode_path_length(medium),
        estimates=estimate_ranges(waveform, start, BIN_WIDTH_OPL, pulse_fwhm_ns=PULSE_FWHM_NS),
    )


def worked_example(
    density: float = 300.0,
    grain_diameter: float = 0.5e-3,
    ice_data_set: str = "warren_brandt_2008",
    asymmetry: float = 0.86,
    wavelength_nm: float = 532.0,
) -> tuple[SnowOptics, list[BoundaryExample]]:
    snow = snow_optics(density, grain_diameter, wavelength_nm, ice_data_set=ice_data_set, asymmetry=asymmetry)
    return snow, [boundary_example(snow, boundary) for boundary in ("zero", "extrapolated")]


def report(snow: SnowOptics, cases: list[BoundaryExample]) -> str:
    medium = snow.diffusion_medium("zero")
    lines = [
        f"snow: rho {snow.density:g} kg/m3, d {snow.grain_diameter * 1e3:g} mm, {snow.wavelength_nm:g} nm, "
        f"{snow.ice_data_set}, B {snow.absorption_enhancement:g}, g {snow.asymmetry:g}",
        f"gamma_ice {snow.ice_absorption:.5f} m-1, sigma_e {snow.extinction:.1f} m-1, sigma_a {snow.absorption:.5f} m-1, "
        f"sigma_s' {snow.reduced_scattering:.1f} m-1, l* {snow.transport_mean_free_path * 1e3:.3f} mm, "
        f"mu_eff {medium.effective_attenuation:.3f} m-1",
        "| boundary | albedo | <L> (m) | mean-range bias (m) | mode-range bias (mm) |"
        " first return | peak | median | centroid | Gaussian fit (mm, 1.5 ns pulse) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for case in cases:
        e = case.estimates
        lines.append(
            f"| {case.boundary} | {case.albedo:.4f} | {case.mean_path:.4f} | {case.mean_range_bias:.4f} | "
            f"{case.mode_range_bias * 1e3:.3f} | {e.first_return * 1e3:.2f} | {e.peak * 1e3:.2f} | "
            f"{e.median * 1e3:.2f} | {e.centroid * 1e3:.1f} | {e.gaussian_fit * 1e3:.2f} |"
        )
    return "\n".join(lines)


def main() -> None:
    print(report(*worked_example()))
    print()
    print("lidar.md's assumptions (g = 0.845):")
    print(report(*worked_example(asymmetry=0.845)))
    print()
    print("Picard et al. 2016 ice:")
    print(report(*worked_example(ice_data_set="picard_2016")))
    print()
    print("1064 nm (Warren & Brandt 2008):")
    print(report(*worked_example(wavelength_nm=1064.0)))


if __name__ == "__main__":
    main()
