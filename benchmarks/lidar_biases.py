"""Issue 29's science table: range biases per estimator for optical grain diameters 0.1 / 0.5 / 1 mm at
densities 300 and 550 kg/m3, on flat snow and on the demo's grown field under the ICESat-2 (11 m) and
airborne (1 m) footprints (render/lidar/LIDAR.md §7).

    python benchmarks/lidar_biases.py [--out benchmarks/results/lidar]

Every point is a lidar run of `configs/lidar/icesat2.yaml` with overrides. The penitente points share one
run folder, so the field grows once (the geometry stage's manifest matches) and only the lidar stage runs
again; each point's lidar folder is copied under --out/<point>/lidar. The table (render.lidar.table's rows) goes
to docs/lidar/biases.md and biases.csv, which the site includes (docs/benchmarks/lidar.md). A bare Lambertian
plane is shot too, and docs/lidar/waveforms.png shows the 532 nm pulsed waveforms of the bare plane, flat snow
and the grown field (1 mm grains, 550 kg/m3, ICESat-2).
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

from _results import REPO, start, write_results

from common.atomic import save_figure_atomic
from pipeline.config import load_config
from pipeline.runner import run_stages
from pipeline.stages import STAGES
from render.lidar.table import normalised_waveform, rows_of, write_table

CONFIG = Path("configs/lidar/icesat2.yaml")
TABLE = REPO / "docs" / "lidar"  # the site's copy of the table and the figure
GRAINS = {"d0.1mm": 0.0001, "d0.5mm": 0.0005, "d1mm": 0.001}
DENSITIES = (300, 550)
FOOTPRINTS = {"icesat2": 11.0, "airborne": 1.0}


def points() -> list[tuple[str, list[str]]]:
    out = []
    for grain, diameter in GRAINS.items():
        for density in DENSITIES:
            common = [f"lidar.optical_diameter={diameter}", f"lidar.density={density}"]
            out.append((f"flat_{grain}_rho{density}", [*common, "lidar.target=flat_snow", "name=lidar_flat"]))
            for footprint, size in FOOTPRINTS.items():
                out.append(
                    (
                        f"penitentes_{footprint}_{grain}_rho{density}",
                        [*common, f"lidar.footprint_diameter={size}", "name=lidar_penitentes"],
                    )
                )
    return out


def plot_waveforms(folders: dict[str, Path], path: Path) -> None:
    """The 532 nm (Warren & Brandt) pulsed waveforms of ``folders`` (label -> point folder) against the height
    of the return, each normalised to its peak."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4), dpi=150)
    highest = 0.0
    for label, folder in folders.items():
        height, pulsed = normalised_waveform(folder)
        ax.plot(height, pulsed, label=label, lw=1.3)
        highest = max(highest, float(height[pulsed > 1e-3].max()))
    ax.axvline(0.0, color="0.5", ls=":", lw=0.8)
    # Up to where the last waveform (the penitentes' ridges) falls to 1e-3 of its peak; the left is the tail.
    ax.set_xlim(-2.0, highest + 0.1)
    ax.set_xlabel("height of the return above the flat-equivalent surface [m]")
    ax.set_ylabel("pulsed waveform / its peak")
    ax.set_title("532 nm, 1.5 ns pulse: bare plane, flat snow and penitentes (11 m footprint)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure_atomic(fig, path)
    plt.close(fig)


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/lidar"))
    args = parser.parse_args()
    runs = []
    for name, overrides in points():
        cfg = load_config(CONFIG, overrides)
        t0 = time.perf_counter()
        run_stages(cfg, STAGES, quiet=True)
        folder = args.out / name
        if folder.exists():
            shutil.rmtree(folder)
        shutil.copytree(Path(cfg.runs_dir) / cfg.name / "lidar", folder / "lidar")
        runs.append(folder)
        print(f"{name}: {time.perf_counter() - t0:.1f} s", flush=True)
    rows = [row for folder in runs for row in rows_of(folder)]
    _, markdown = write_table(rows, args.out)
    intro = (
        "Range bias [cm] of each estimator, per point, channel and reference height (render/lidar/LIDAR.md): "
        "the estimator's range minus the reference's; positive: the surface reads low.\n\n"
    )
    write_results("biases", intro + markdown.read_text(encoding="utf-8"), run, rows=rows, folder=TABLE)
    print(f"table: {TABLE.relative_to(REPO)}/biases.md")
    bare = load_config(CONFIG, ["lidar.target=bare", "name=lidar_bare"])
    run_stages(bare, STAGES, quiet=True)
    shutil.copytree(Path(bare.runs_dir) / bare.name / "lidar", args.out / "bare" / "lidar", dirs_exist_ok=True)
    plot_waveforms(
        {
            "bare Lambertian plane": args.out / "bare",
            "flat snow": args.out / "flat_d1mm_rho550",
            "penitentes (demo field)": args.out / "penitentes_icesat2_d1mm_rho550",
        },
        TABLE / "waveforms.png",
    )
    print(f"figure: {TABLE.relative_to(REPO)}/waveforms.png")


if __name__ == "__main__":
    main()
