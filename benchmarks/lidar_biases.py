"""Issue 29's science table: range biases per estimator for optical grain diameters 0.1 / 0.5 / 1 mm at
densities 300 and 550 kg/m3, on flat snow and on the demo's grown field under the ICESat-2 (11 m) and
airborne (1 m) footprints (render/lidar/LIDAR.md §7).

    python benchmarks/lidar_biases.py [--out benchmarks/results/lidar]

Every point is a lidar run of `configs/lidar/icesat2.yaml` with overrides. The penitente points share one
run folder, so the field grows once (the geometry stage's manifest matches) and only the lidar stage runs
again; each point's lidar folder is copied under --out/<point>/lidar, and render.lidar.table writes
biases.csv / biases.md there. A bare Lambertian plane is shot too, and waveforms.png shows the 532 nm
pulsed waveforms of the bare plane, flat snow and the grown field (1 mm grains, 550 kg/m3, ICESat-2).
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

from pipeline.config import load_config
from pipeline.runner import run_stages
from pipeline.stages import STAGES
from render.lidar.table import normalised_waveform, rows_of, write_table

CONFIG = Path("configs/lidar/icesat2.yaml")
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
    for label, folder in folders.items():
        ax.plot(*normalised_waveform(folder), label=label, lw=1.3)
    ax.axvline(0.0, color="0.5", ls=":", lw=0.8)
    ax.set_xlim(-1.5, 1.2)
    ax.set_xlabel("height of the return above the flat-equivalent surface [m]")
    ax.set_ylabel("pulsed waveform / its peak")
    ax.set_title("532 nm, 1.5 ns pulse: bare plane, flat snow and penitentes (11 m footprint)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main() -> None:
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
    write_table([row for run in runs for row in rows_of(run)], args.out)
    print(f"table: {args.out}/biases.md")
    bare = load_config(CONFIG, ["lidar.target=bare", "name=lidar_bare"])
    run_stages(bare, STAGES, quiet=True)
    shutil.copytree(Path(bare.runs_dir) / bare.name / "lidar", args.out / "bare" / "lidar", dirs_exist_ok=True)
    plot_waveforms(
        {
            "bare Lambertian plane": args.out / "bare",
            "flat snow": args.out / "flat_d1mm_rho550",
            "penitentes (demo field)": args.out / "penitentes_icesat2_d1mm_rho550",
        },
        args.out / "waveforms.png",
    )
    print(f"figure: {args.out}/waveforms.png")


if __name__ == "__main__":
    main()
