"""Snow as grains against the homogenised medium (issue 51 part 1, render/lidar/LIDAR.md §10).

A nadir beam into periodic packings of 2000 ice spheres (render.lidar.grains.pack_spheres), traced exactly in
geometric optics by the core (render/core/src/grains.cpp), against the homogenised half-space with the spheres'
own shape factors (B, g = 0.89) with identical source, receivers and binning: index matched, with the snow's
clock n_snow = (1 − φ) + B φ n_g, and with the linear-mixing clock 1 − φ + φ n_ice (Smith et al.'s ``v_eff.py``,
LIDAR.md §12). Densities 300 and 550 kg/m³, two packing seeds each, 0.5 mm grains, clear ice
at 532 nm (γ = 0.035 /m) and at 1064 nm (γ = 22 /m, where far fewer grains are met before absorption). At
550 kg/m³ the packing is also traced with 0.25 and 1 mm grains (seed 1).

    python benchmarks/grain_packing.py [--photons 50000] [--homogenised-photons 120000] [--seeds 1 2] [--spheres 16000]

Writes benchmarks/results/grain_packing.md and .csv (results/local/ with other arguments than these defaults).
"""

from __future__ import annotations

import argparse
import time

from _results import is_standard, start, write_results

from render.lidar.grains import (
    TraceSettings,
    compare,
    homogenised_preset,
    ice_refractive_index,
    pack_spheres,
    snow_clock,
    trace_homogenised,
    trace_packing,
)
from render.scene.optics import RHO_ICE

DENSITIES = (300.0, 550.0)
DIAMETER = 5e-4  # m
DENSE_SIZES = (2.5e-4, 1e-3)  # m, the second and third sizes at 550 kg/m3
COUNT = 2000  # spheres in the periodic cell, 12-15 grains wide (16 000 read the same within the seeds' scatter)
WINDOW_OPL = 0.5  # m: mean delays and R(t) shapes over OPL in [-2 mm, 0.5 m)
# Depth bins of the absorbed-energy profile [m], per wavelength: a tenth of an e-folding depth or less.
DEPTH_BIN = {532.0: 1e-2, 1064.0: 5e-4}
HOMOGENISED_SEEDS = (101, 102)


def settings(wavelength: float, photons: int, seed: int) -> TraceSettings:
    return TraceSettings(
        photons=photons,
        seed=seed,
        start_opl=-2e-3,
        bin_width_opl=2.5e-4,
        temporal_bins=4000,
        depth_bin_width=DEPTH_BIN[wavelength],
        depth_bins=800,
        threads=1,
    )


def point(density: float, diameter: float, seeds: list[int], args: argparse.Namespace) -> list[dict[str, object]]:
    rows: list[dict[str, object]] = []
    for wavelength in (532.0, 1064.0):
        preset = homogenised_preset(density, diameter, wavelength)
        clock = snow_clock(density, wavelength)
        t0 = time.process_time()
        # The preset in two halves of its own seeds: their spread is the homogenised side's standard error.
        halves = [settings(wavelength, args.homogenised_photons // 2, seed) for seed in HOMOGENISED_SEEDS]
        plain_halves = [trace_homogenised(preset, h) for h in halves]
        clocked_halves = [trace_homogenised(preset, h, clock) for h in halves]
        index_matched = plain_halves[0].merged(plain_halves[1])
        clocked = clocked_halves[0].merged(clocked_halves[1])
        phi = density / RHO_ICE
        linear_clock = 1.0 - phi + phi * ice_refractive_index(wavelength)
        linear = trace_homogenised(preset, halves[0], linear_clock).merged(
            trace_homogenised(preset, halves[1], linear_clock)
        )
        # The other forms only show how little the phase function matters: a quarter of the photons.
        forms = settings(wavelength, args.homogenised_photons // 4, HOMOGENISED_SEEDS[0])
        geometric = trace_homogenised(homogenised_preset(density, diameter, wavelength, "geometric"), forms)
        isotropic = trace_homogenised(homogenised_preset(density, diameter, wavelength, "isotropic"), forms)
        homogenised_cpu = time.process_time() - t0
        # e-folding fit from 5 transport lengths down two diffusion e-folding depths
        fit_from = 5.0 / preset.reduced_scattering
        fit = (fit_from, fit_from + 2.0 * preset.e_folding_depth)
        efold_halves = [h.e_folding_depth(*fit) for h in plain_halves]
        delay_halves = [h.mean_delay(WINDOW_OPL) for h in clocked_halves]
        albedo_halves = [h["albedo"] for h in plain_halves]
        for seed in seeds:
            packing = pack_spheres(density / RHO_ICE, diameter, args.spheres, seed)
            t0 = time.process_time()
            traced = trace_packing(packing, settings(wavelength, args.photons, seed), wavelength)
            cpu = time.process_time() - t0
            c = compare(
                traced,
                index_matched,
                clocked,
                density=density,
                window_opl=WINDOW_OPL,
                fit_depths=fit,
                wavelength_nm=wavelength,
            )
            row: dict[str, object] = {
                "density": density,
                "diameter_mm": diameter * 1e3,
                "seed": seed,
                "wavelength_nm": wavelength,
                **c,
            }
            row.update(
                efold_homogenised_se=abs(efold_halves[0] - efold_halves[1]) / 2.0,
                delay_clocked_se=abs(delay_halves[0] - delay_halves[1]) / 2.0,
                albedo_homogenised_se=abs(albedo_halves[0] - albedo_halves[1]) / 2.0,
                albedo_geometric=geometric["albedo"],
                albedo_isotropic=isotropic["albedo"],
                efold_geometric=geometric.e_folding_depth(*fit),
                efold_isotropic=isotropic.e_folding_depth(*fit),
                delay_geometric=geometric.mean_delay(WINDOW_OPL),
                linear_clock=linear_clock,
                delay_ratio_linear=c["delay_packing"] / linear.mean_delay(WINDOW_OPL),
                spheres=args.spheres,
                sphere_hits=traced["sphere_hits"],
                interactions=traced["interactions"],
                tir=traced["total_internal_reflections"],
                cpu_s=cpu,
                homogenised_cpu_s=homogenised_cpu,
                ns_per_interaction=cpu / args.photons / traced["interactions"] * 1e9,
                fit_from=fit[0],
                fit_to=fit[1],
            )
            rows.append(row)
            print(
                f"rho {density:.0f} d {diameter * 1e3:.2f} mm seed {seed} {wavelength:.0f} nm: "
                f"delay {c['delay_packing'] * 1e3:.2f} / {c['delay_clocked'] * 1e3:.2f} mm, "
                f"albedo {c['albedo_packing']:.4f} / {c['albedo_homogenised']:.4f}, "
                f"e-fold {c['efold_packing'] * 1e3:.1f} / {c['efold_homogenised'] * 1e3:.1f} mm, cpu {cpu:.0f} s",
                flush=True,
            )
    return rows


def verdict(row: dict[str, object]) -> str:
    ok_delay = abs(float(row["delay_ratio_clocked"]) - 1.0) <= 0.05
    ok_albedo = abs(float(row["albedo_packing"]) - float(row["albedo_homogenised"])) <= 0.01
    ok_efold = abs(float(row["efold_ratio"]) - 1.0) <= 0.10
    failed = [name for name, ok in (("delay", ok_delay), ("albedo", ok_albedo), ("e-fold", ok_efold)) if not ok]
    return "pass" if not failed else "fails " + ", ".join(failed)


def tables(rows: list[dict[str, object]]) -> str:
    def key(r: dict[str, object]) -> str:
        return f"| {r['density']:.0f} | {r['diameter_mm']:.2f} | {r['seed']} | {r['wavelength_nm']:.0f} "

    def f(r: dict[str, object], name: str, scale: float = 1.0, digits: int = 3) -> str:
        return f"{float(r[name]) * scale:.{digits}f}"

    lines = [
        f"Packing (P, {rows[0]['spheres']} spheres a periodic cell) against the homogenised preset (H: σ_e = 3φ/d, "
        "g = 0.89, σ_a = Bγφ, B = 1.254), index matched, with the snow's clock (H·n) and with the linear-mixing clock "
        f"1 − φ + φ n_ice (H·n_lin). Mean delays are the flux exits' mean OPL below {WINDOW_OPL} m, in mm; "
        "KS is the largest gap between the distribution functions of R(t) within that window. Acceptance: delay "
        "with the clock within 5 %, albedo within 0.01, e-folding depth within 10 %.",
        "",
        "| ρ [kg/m³] | d [mm] | seed | λ [nm] | n_snow | delay P | delay H | delay H·n | P/H | P/(H·n) | KS P–H | "
        "KS P–H·n | delay P, cone | delay H·n, cone | n_lin | P/(H·n_lin) | verdict |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            key(r) + f"| {f(r, 'snow_clock')} | {f(r, 'delay_packing', 1e3, 2)} | {f(r, 'delay_homogenised', 1e3, 2)} "
            f"| {f(r, 'delay_clocked', 1e3, 2)} ± {f(r, 'delay_clocked_se', 1e3, 2)} | {f(r, 'delay_ratio_homogenised')} | {f(r, 'delay_ratio_clocked')} "
            f"| {f(r, 'shape_ks_homogenised')} | {f(r, 'shape_ks_clocked')} | {f(r, 'delay_packing_cone', 1e3, 2)} "
            f"| {f(r, 'delay_clocked_cone', 1e3, 2)} | {f(r, 'linear_clock')} | {f(r, 'delay_ratio_linear')} "
            f"| {verdict(r)} |"
        )
    lines += [
        "",
        "Diffuse albedo and e-folding depth of the absorbed energy (least squares of its logarithm from 5 ℓ* down "
        "two diffusion e-folding depths), for the packing and the homogenised media: the preset (H, ± half the gap "
        "between its two halves of photons), its no-diffraction form (σ_e = 3φ/(2d), g = 0.78) and its isotropic "
        "reduced form (σ_s′, g = 0), these two with a quarter of the photons.",
        "",
        "| ρ [kg/m³] | d [mm] | seed | λ [nm] | albedo P | albedo H | H geometric | H isotropic | e-fold P [mm] | "
        "e-fold H [mm] | ± | P/H | H geometric [mm] | H isotropic [mm] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            key(r)
            + f"| {f(r, 'albedo_packing', 1, 4)} | {f(r, 'albedo_homogenised', 1, 4)} | {f(r, 'albedo_geometric', 1, 4)} "
            f"| {f(r, 'albedo_isotropic', 1, 4)} | {f(r, 'efold_packing', 1e3, 2)} | {f(r, 'efold_homogenised', 1e3, 2)} "
            f"| {f(r, 'efold_homogenised_se', 1e3, 2)} "
            f"| {f(r, 'efold_ratio')} | {f(r, 'efold_geometric', 1e3, 2)} | {f(r, 'efold_isotropic', 1e3, 2)} |"
        )
    lines += [
        "",
        "The clock's ingredients: ice path over air path in the packing, of all photons and of the exits in the "
        "delay window, against B φ/(1 − φ); all photons' geometric path per metre of homogenised path against "
        "1 − φ + B φ; total internal reflections (none can occur in a sphere); and the tracer's cost.",
        "",
        "| ρ [kg/m³] | d [mm] | seed | λ [nm] | ice/air | ice/air, window | B φ/(1 − φ) | path/path H | 1 − φ + B φ "
        "| TIR | sphere hits per photon | ns per interaction |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            key(r) + f"| {f(r, 'ice_per_air')} | {f(r, 'ice_per_air_window')} | {f(r, 'ice_per_air_expected')} "
            f"| {f(r, 'path_per_path')} | {f(r, 'path_per_path_expected')} | {f(r, 'tir', 1, 0)} "
            f"| {f(r, 'sphere_hits', 1, 0)} | {f(r, 'ns_per_interaction', 1, 0)} |"
        )
    return "\n".join(lines)


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--photons", type=int, default=50000, help="photons per packing run")
    parser.add_argument(
        "--homogenised-photons", type=int, default=120000, help="photons of the homogenised preset (two seeds)"
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2], help="packing seeds")
    parser.add_argument("--spheres", type=int, default=COUNT, help="spheres in the periodic cell")
    args = parser.parse_args()
    rows: list[dict[str, object]] = []
    for density in DENSITIES:
        rows += point(density, DIAMETER, args.seeds, args)
    for diameter in DENSE_SIZES:
        rows += point(DENSITIES[-1], diameter, args.seeds[:1], args)
    write_results("grain_packing", tables(rows), run, rows=rows, standard=is_standard(parser, args))


if __name__ == "__main__":
    main()
