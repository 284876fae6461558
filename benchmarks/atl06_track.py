"""Issue 51's photon-counting table: the bias of an ATL06-like surface finder (render/lidar/atl06.py) over the six
flat snows of the lidar bias table (optical diameter 0.1 / 0.5 / 1 mm at 300 and 550 kg/m3) and over the demo's
grown penitente field, for ATLAS's strong and weak beams, by day and by night (render/lidar/LIDAR.md §9).

    .venv/bin/python benchmarks/atl06_track.py [--length 5000] [--reuse] [--penitentes-lidar runs/<name>/lidar]

Every surface is first a lidar run of `configs/lidar/icesat2.yaml` (11 m footprint, 1.5 ns pulse) whose 532 nm
impulse response (Warren & Brandt 2008 ice) the tracks draw their photons from. Flat snow renders 16 x 16 pixels
for 20 s (the snow is the same under every pixel); the penitentes 48 x 48 pixels for 60 s over the tiled field,
which the geometry stage grows first (about 3 min). Each track is `--length` metres of shots; the bias is the
mean over segments of h_li minus the true surface (the flat-equivalent height), its spread the standard deviation
over segments. A third beam, "strong x4", is the strong beam at the ATBD test data's white-surface rate. Writes
benchmarks/results/atl06.md and atl06.csv (results/local/ with another --length or --penitentes-lidar), prints the
acceptance checks and the time of 1 km, and rewrites the README's table from atl06.csv (``--readme`` does only that;
tests/render/lidar/test_lidar_atl06.py fails while the two differ). --reuse takes the shots a past run copied under benchmarks/results/atl06/
(git-ignored); --penitentes-lidar takes the penitentes' shot from another lidar run (a field grown by another
version of the demo).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import shutil
import time
from pathlib import Path

import numpy as np
from _results import REPO, RESULTS, is_standard, start, write_results

from common.atomic import write_text_atomic
from pipeline.config import load_config
from pipeline.runner import run_stages
from pipeline.stages import STAGES
from render.lidar.atl06 import track
from render.lidar.photons import STRONG, WEAK, Beam, background_rate, signal_photons_per_shot
from render.lidar.waveform import surface_impulse

CONFIG = Path("configs/lidar/icesat2.yaml")
GRAINS = {"0.1": 0.0001, "0.5": 0.0005, "1": 0.001}  # optical diameter [mm] -> [m]
DENSITIES = (300, 550)
SUN_ELEVATION_DEG = 30.0  # "day": the sun 30 degrees up; "night": no background
# A strong beam 4x brighter: the rate the ATBD's reference test data give a white surface (12 photons a shot over 16
# channels, SmithB/IS2_land_ice_ATBD make_fpb_test_data.m), the sensitivity to the link budget's assumed efficiencies.
STRONG_X4 = Beam("strong x4", 4 * STRONG.energy_share, STRONG.channels, STRONG.dead_time_ns)
FLAT = ["lidar.target=flat_snow", "lidar.pixels=16", "lidar.time_budget_s=20", "name=atl06_flat"]
PENITENTES = ["lidar.pixels=48", "lidar.time_budget_s=60", "name=atl06_penitentes"]
README = REPO / "README.md"
# The README's lidar section holds the table between these lines; the script writes what lies between.
README_START = "<!-- ATL06-like table: benchmarks/atl06_track.py writes it from benchmarks/results/atl06.csv -->"
README_END = "<!-- end of the ATL06-like table -->"


def surfaces() -> list[tuple[str, str, list[str]]]:
    """(label, folder name, config overrides) of every surface."""
    points = [
        (
            f"flat, {density} kg/m3, {grain} mm",
            f"flat_d{grain}mm_rho{density}",
            [*FLAT, f"lidar.density={density}", f"lidar.optical_diameter={d}"],
        )
        for grain, d in GRAINS.items()
        for density in DENSITIES
    ]
    return [*points, ("penitentes (demo field and firn)", "penitentes", PENITENTES)]


def render_shot(label: str, overrides: list[str], folder: Path) -> Path:
    """Render the surface's shot (the pipeline skips it when its run is up to date) and copy its lidar folder to
    ``folder``."""
    cfg = load_config(CONFIG, overrides)
    t0 = time.perf_counter()
    run_stages(cfg, STAGES, quiet=True)
    if folder.exists():
        shutil.rmtree(folder)
    shutil.copytree(Path(cfg.runs_dir) / cfg.name / "lidar", folder)
    print(f"{label}: shot rendered in {time.perf_counter() - t0:.0f} s", flush=True)
    return folder


def shot_of(folder: Path) -> dict:
    """A lidar folder's 532 nm (Warren & Brandt) impulse response and what the tracks need from its summary."""
    with np.load(folder / "waveform.npz") as data:
        impulse = np.asarray(data["impulse"][:, 0], np.float64)
        bin_width_opl = float(data["bin_width_opl"])
        reference_height = float(data["reference_height"])
    summary = json.loads((folder / "summary.json").read_text())
    return {
        "impulse": impulse,
        "bin_width_opl": bin_width_opl,
        "reference_height": reference_height,
        "truth": summary["reference_heights_m"]["flat_equivalent"],
        "albedo": summary["channels"][0]["apparent_reflectance"],
        "waveform_median": -summary["channels"][0]["bias_m"]["median"]["flat_equivalent"],
        "footprint": summary["config"]["footprint_diameter"],
    }


def row_of(surface: str, shot: dict, beam: Beam, light: str, length: float, seed: int) -> dict:
    rate = background_rate(min(shot["albedo"], 1.0), SUN_ELEVATION_DEG if light == "day" else None)
    result = track(
        shot["impulse"],
        shot["bin_width_opl"],
        shot["reference_height"],
        length,
        beam,
        seed=seed,
        background_hz=rate,
        footprint_diameter=shot["footprint"],
    )
    s = result.segments
    valid = s["valid"]
    height = s["h_li"][valid] - shot["truth"]
    return {
        "surface": surface,
        "beam": beam.name,
        "light": light,
        "signal_per_shot": signal_photons_per_shot(shot["impulse"], beam),
        "background_mhz": rate / 1e6,
        "segments": f"{int(valid.sum())}/{valid.size}",
        "bias_cm": 100 * height.mean(),
        "spread_cm": 100 * height.std(ddof=1),
        "bias_without_fpb_cm": 100 * (height - s["fpb_med_corr"][valid]).mean(),
        "fpb_cm": 100 * s["fpb_med_corr"][valid].mean(),
        "window_m": s["window"][valid].mean(),
        "photons_per_segment": s["n_photons"][valid].mean(),
        "waveform_median_cm": 100 * shot["waveform_median"],
    }


def acceptance() -> list[str]:
    """The figures tests/render/lidar/test_lidar_atl06.py asserts, over 2 km of a bare plane of albedo 0.9."""
    bin_width, z_ref = 0.005, 0.5
    impulse = surface_impulse(0.0, 0.9 / math.pi, z_ref, 0.0, bin_width, 400)
    plane = z_ref - 0.5 * (int(np.flatnonzero(impulse)[0]) + 0.5) * bin_width

    def mean_and_error(values):
        independent = values[::2]
        return 100 * values.mean(), 100 * independent.std(ddof=1) / math.sqrt(independent.size)

    lines = []
    ideal = track(impulse, bin_width, z_ref, 2000.0, STRONG, seed=21, dead_time=False, slope=0.01)
    bias, error = mean_and_error(ideal.segments["h_li"] - plane - ideal.surface_offset)
    lines.append(f"no dead time, no background, 1 % slope: bias {bias:+.3f} cm, standard error {error:.3f} cm")
    bright = Beam("bright", 4 * STRONG.energy_share, 16, STRONG.dead_time_ns)
    dead = track(impulse, bin_width, z_ref, 2000.0, bright, seed=22, dead_time=True).segments
    bias, error = mean_and_error(dead["h_li"] - plane)
    raw = 100 * np.mean(dead["h_li"] - dead["fpb_med_corr"] - plane)
    lines.append(
        f"dead time, {signal_photons_per_shot(impulse, bright):.1f} photons a shot: bias {bias:+.3f} cm "
        f"(standard error {error:.3f} cm) corrected, {raw:+.3f} cm without the first-photon-bias correction"
    )
    rate = background_rate(0.9, 60.0)
    day = track(
        impulse, bin_width, z_ref, 2000.0, STRONG, seed=23, dead_time=False, background_hz=rate, window=(-5, 25)
    )
    bias, error = mean_and_error(day.segments["h_li"] - plane)
    lines.append(f"day background {rate / 1e6:.1f} MHz: bias {bias:+.3f} cm, standard error {error:.3f} cm")
    return lines


def markdown(rows: list[dict], checks: list[str], timing: str, length: float) -> str:
    """The results' text: the table of ``rows`` (row_of), the acceptance checks and the time of 1 km."""
    header = (
        "| surface | beam | light | signal photons a shot | background [MHz] | segments | bias [cm] | spread [cm] "
        "| bias without FPB correction [cm] | FPB correction [cm] | window [m] | photons a segment "
        "| waveform median [cm] |\n" + "|---" * 13 + "|\n"
    )
    body = "".join(
        f"| {r['surface']} | {r['beam']} | {r['light']} | {r['signal_per_shot']:.2f} | {r['background_mhz']:.2f} "
        f"| {r['segments']} | {r['bias_cm']:+.2f} | {r['spread_cm']:.2f} | {r['bias_without_fpb_cm']:+.2f} "
        f"| {r['fpb_cm']:+.2f} | {r['window_m']:.2f} | {r['photons_per_segment']:.0f} | {r['waveform_median_cm']:+.2f} |\n"
        for r in rows
    )
    text = (
        f"ATL06-like heights from photon counting, {length / 1000:g} km per track. "
        "Height bias = mean over 40 m segments of h_li minus the flat-equivalent surface (negative: below it); "
        "spread: standard deviation over segments. Waveform median: the pulsed waveform's median as a height "
        "(lidar stage, same impulse response).\n\n" + header + body + "\nChecks (bare plane, 2 km):\n\n"
    )
    return text + "".join(f"- {line}\n" for line in checks) + f"\n{timing}\n"


def readme_table(rows: list[dict]) -> str:
    """The README's compact table of ``rows`` (row_of's, or atl06.csv's as text): bias ± spread [cm] of each surface
    for the strong and weak beams by day and night, and the waveform median."""
    cell = {
        (r["surface"], r["beam"], r["light"]): f"{float(r['bias_cm']):+.1f} ± {float(r['spread_cm']):.1f}" for r in rows
    }
    median = {r["surface"]: f"{float(r['waveform_median_cm']):+.1f}" for r in rows}
    columns = [(beam, light) for beam in ("strong", "weak") for light in ("day", "night")]
    header = (
        "| surface | "
        + " | ".join(f"{beam}, {light}" for beam, light in columns)
        + " | waveform median |\n"
        + "|---" * (len(columns) + 2)
        + "|\n"
    )
    body = "".join(
        f"| {surface} | " + " | ".join(cell[(surface, *column)] for column in columns) + f" | {median[surface]} |\n"
        for surface in median
    )
    return header + body


def readme_with_table(text: str, rows: list[dict]) -> str:
    """``text`` (the README) with ``readme_table(rows)`` between its markers."""
    if README_START not in text or README_END not in text:
        raise ValueError(f"README.md lacks the lines {README_START!r} and {README_END!r} that hold the ATL06 table")
    before, rest = text.split(README_START, 1)
    return before + README_START + "\n\n" + readme_table(rows) + "\n" + README_END + rest.split(README_END, 1)[1]


def csv_rows(path: Path = RESULTS / "atl06.csv") -> list[dict]:
    """The rows of the committed table, as text."""
    with path.open(newline="", encoding="utf-8") as file:
        return list(csv.DictReader(file))


def write_readme(rows: list[dict]) -> None:
    write_text_atomic(README, readme_with_table(README.read_text(encoding="utf-8"), rows))
    print(f"README table: {README}")


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--length", type=float, default=5000.0, help="metres of track per row")
    parser.add_argument(
        "--reuse", action="store_true", help="take the shots copied under benchmarks/results/atl06 by a past run"
    )
    parser.add_argument(
        "--penitentes-lidar", type=Path, help="the lidar folder of a penitente run to use instead of rendering one"
    )
    parser.add_argument(
        "--readme", action="store_true", help="only rewrite the README's table from benchmarks/results/atl06.csv"
    )
    args = parser.parse_args()
    if args.readme:
        write_readme(csv_rows())
        return
    shots = {}
    for label, slug, overrides in surfaces():
        folder = RESULTS / "atl06" / slug
        if slug == "penitentes" and args.penitentes_lidar is not None:
            folder = args.penitentes_lidar
        elif not (args.reuse and (folder / "waveform.npz").is_file()):
            render_shot(label, overrides, folder)
        shots[label] = shot_of(folder)
    first = next(iter(shots.values()))
    t0 = time.perf_counter()
    row_of("timing", first, STRONG, "day", 1000.0, seed=0)
    timing = f"1 km of strong-beam track by day (photons and surface finding): {time.perf_counter() - t0:.2f} s"
    print(timing, flush=True)
    rows = []
    for seed, (label, shot) in enumerate(shots.items()):
        for beam in (STRONG, WEAK, STRONG_X4):
            for light in ("day", "night"):
                rows.append(row_of(label, shot, beam, light, args.length, seed=seed))
                r = rows[-1]
                print(
                    f"{label} {beam.name} {light}: bias {r['bias_cm']:+.2f} cm spread {r['spread_cm']:.2f}", flush=True
                )
    checks = acceptance()
    print("\n".join(checks))
    standard = is_standard(parser, args, ignore=("reuse",))
    path = write_results("atl06", markdown(rows, checks, timing, args.length), run, rows=rows, standard=standard)
    print(f"table: {path}")
    if standard:
        write_readme(rows)


if __name__ == "__main__":
    main()
