"""The references' roulette depth on the demo's field (render/core/DESIGN.md §12, *Roulette depth from the
medium*): for each snow, the steady volpath reference at ``reference.rr_depth: auto``, at ten times the depth
auto chose, and at the fixed 3000 the demo used before, all at the demo's seed, so that they share their paths
up to the shallower depth and differ only by the roulette: a paired comparison, precise at a few samples. The
film is the demo's camera 4x coarser (80 x 60) at 16 spp (``REDUCED``), 16x cheaper than the demo's reference.
Prints, per channel, each depth's mean against the deep one's, the share the model expected it to miss, and
its time; writes the table to benchmarks/results/roulette_depth.md and .csv (results/local/ with other arguments).

Each snow and seed is one pipeline run (``runs/rr_<snow>_s<seed>``) whose reference stage is rendered again at
each depth; its geometry and scene are grown once and reused.

    .venv/bin/python benchmarks/roulette_depth.py [--snow fresh_snow ...] [--seeds 1 2]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from _results import is_standard, start, write_results

ROOT = Path(__file__).resolve().parents[1]
FINE_GRAIN = [  # the finest grain of configs/sweeps/grain_density.yaml, at the demo's density
    "scene.media.snow.preset=null",
    "scene.media.snow.physical.kind=snow",
    "scene.media.snow.physical.density=550.0",
    "scene.media.snow.physical.optical_radius=0.0002",
    "scene.media.snow.physical.absorption_enhancement=1.6",
]
SNOWS = {
    "fresh_snow": ["scene.media.snow.preset=fresh_snow"],
    "penitente_firn": [],
    "fine_0.2mm": FINE_GRAIN,
}
REDUCED = ["reference.downsample=4", "reference.spp=16", "reference.spp_per_pass=16"]
SHORT = {"fresh_snow": "fresh", "penitente_firn": "firn", "fine_0.2mm": "fine"}
FIXED_DEPTH = 3000


def steady_reference(snow: str, depth: int | str, seed: int) -> tuple[np.ndarray, dict]:
    """The demo's steady reference for ``snow`` at roulette ``depth``, field and reference grown and rendered at
    ``seed``: its per-channel mean and timing.json."""
    name = f"rr_{SHORT[snow]}_s{seed}"
    sets = [f"name={name}", f"seed={seed}", "reference.transient=false", f"reference.rr_depth={depth}"]
    sets += [*REDUCED, *SNOWS[snow]]
    command = [sys.executable, "-m", "pipeline", "run", "configs/demo.yaml", "-q"]
    command += [arg for s in sets for arg in ("--set", s)]
    command += [arg for stage in ("geometry", "scene", "reference") for arg in ("--stage", stage)]
    subprocess.run(command, cwd=ROOT, check=True)
    folder = ROOT / "runs" / name / "reference"
    timing = json.loads((folder / "timing.json").read_text(encoding="utf-8"))
    return np.load(folder / "steady.npy").reshape(-1, 3).mean(axis=0), timing


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--snow", nargs="+", choices=list(SNOWS), default=list(SNOWS))
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2], help="seeds of the field and the renders")
    args = parser.parse_args()
    lines = [
        "| snow | seed | depth | rr_depth | expected missed | mean / deep (R / G / B) | steady reference [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    rows = []
    for snow in args.snow:
        for seed in args.seeds:
            auto_mean, auto_timing = steady_reference(snow, "auto", seed)
            runs = {
                "auto": (auto_mean, auto_timing),
                "10x auto": steady_reference(snow, 10 * auto_timing["roulette"]["rr_depth"], seed),
                "fixed": steady_reference(snow, FIXED_DEPTH, seed),
            }
            deep_mean = runs["10x auto"][0]
            for label, (mean, timing) in runs.items():
                ratio = " / ".join(f"{r:.4f}" for r in mean / deep_mean)
                roulette = timing["roulette"]
                lines.append(
                    f"| {snow} | {seed} | {label} | {roulette['rr_depth']} | {roulette['missed']:.2%} | {ratio} | "
                    f"{timing['steady']['seconds']:.0f} |"
                )
                print(lines[-1], flush=True)
                rows.append(
                    {
                        "snow": snow,
                        "seed": seed,
                        "depth": label,
                        "rr_depth": roulette["rr_depth"],
                        "expected_missed": roulette["missed"],
                        **{f"mean_over_deep_{c}": float(r) for c, r in zip("RGB", mean / deep_mean)},
                        "steady_reference_s": timing["steady"]["seconds"],
                    }
                )
    print("\n".join(lines))
    intro = (
        "The steady reference's mean at each roulette depth over the mean 10x deeper than auto chose, per channel, "
        "on the demo's camera at 80 x 60 and 16 spp; expected missed: the model's share of the light left out.\n\n"
    )
    write_results("roulette_depth", intro + "\n".join(lines), run, rows=rows, standard=is_standard(parser, args))


if __name__ == "__main__":
    main()
